"""Boundary-element core: grids, influence coefficients, FFT operators and contact solvers.

This layer knows nothing of particles: it solves contact of a rigid flat plate on an elastic
half-space given a gap.
"""

from .grid import Grid
from .normal import ContactAtEdgeError, ConvergenceError, NormalContact, solve_normal
from .operator import get_workers, normal_operator, set_workers, tangential_operator

__all__ = [
    "ContactAtEdgeError",
    "ConvergenceError",
    "Grid",
    "NormalContact",
    "get_workers",
    "normal_operator",
    "set_workers",
    "solve_normal",
    "tangential_operator",
]
