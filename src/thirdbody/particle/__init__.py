"""One particle between the plates: inputs (:class:`Particle`, :class:`Plates`), the
per-interface machinery (every spot on a shared lattice, normal and tangential solves), the
statics of the pair at an orientation, and the search for a stable orientation with its
kinematics. The driver (:mod:`thirdbody.simulation`) loops over these."""

from .interface import Interface, InterfaceNormal, Window, count_spots, remap
from .model import Particle, Plates
from .statics import Evaluation, PairStatics, StaticsError
from .surface import Surfaces
from .turning import Increments, Turn, TurningError, find_stable_orientation, turn_kinematics

__all__ = ["Evaluation", "Increments", "Interface", "InterfaceNormal", "PairStatics", "Particle",
           "Plates", "StaticsError", "Surfaces", "Turn", "TurningError", "Window", "count_spots",
           "find_stable_orientation", "remap", "turn_kinematics"]
