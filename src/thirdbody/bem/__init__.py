"""Boundary-element core: grids, influence coefficients, FFT operators and contact solvers.

This layer knows nothing of particles: it solves contact of a rigid flat plate on an elastic
half-space given a gap.
"""

from .coupled import solve_coupled
from .grid import Grid
from .normal import ContactAtEdgeError, ConvergenceError, NormalContact, solve_normal
from .operator import (
    coupling_operator,
    get_workers,
    normal_operator,
    set_workers,
    tangential_operator,
)
from .pair import ElasticPair
from .tangential import FrictionLimitError, TangentialContact, solve_tangential

__all__ = [
    "ContactAtEdgeError",
    "ConvergenceError",
    "ElasticPair",
    "FrictionLimitError",
    "Grid",
    "NormalContact",
    "TangentialContact",
    "coupling_operator",
    "get_workers",
    "normal_operator",
    "set_workers",
    "solve_coupled",
    "solve_normal",
    "solve_tangential",
    "tangential_operator",
]
