"""Analytic references: Hertz, Cattaneo–Mindlin, Mindlin–Deresiewicz, Spence, rigid particle.

Small pure functions in SI units that the tests compare the solvers against and that users can
call to check their own runs. ``rigid`` (the rigid-particle criterion, the paper's eqs 1–5) lives
in :mod:`thirdbody.rigid` and is re-exported here.
"""

from .. import rigid
from . import hertz, mindlin, spence

__all__ = ["hertz", "mindlin", "rigid", "spence"]
