"""The particle between the plates: inputs (:class:`Particle`, :class:`Plates`) and the
per-interface machinery (windows on a shared lattice, normal and tangential solves)."""

from .interface import Interface, InterfaceNormal, Window, remap
from .model import Particle, Plates

__all__ = ["Interface", "InterfaceNormal", "Particle", "Plates", "Window", "remap"]
