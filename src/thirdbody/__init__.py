"""thirdbody: a deformable third-body particle between two rigid plates, by FFT-accelerated BEM.

Public API::

    Material(E, nu)                     elastic constants (Pa, -)
    Grid(n, spacing)                    a window of cells (m)
    solve_normal(gap, grid, material, force=... | approach=...)   -> NormalContact
    solve_tangential(normal, mu, force=... | shift=..., previous=...) -> TangentialContact
    reference.hertz, reference.mindlin  analytic solutions to check runs against
    citations()                         the papers behind the methods used
"""

from ._citations import citations
from .bem import (
    ContactAtEdgeError,
    ConvergenceError,
    FrictionLimitError,
    Grid,
    NormalContact,
    TangentialContact,
    set_workers,
    solve_normal,
    solve_tangential,
)
from .material import Material

__version__ = "0.1.0"

__all__ = [
    "ContactAtEdgeError",
    "ConvergenceError",
    "FrictionLimitError",
    "Grid",
    "Material",
    "NormalContact",
    "TangentialContact",
    "__version__",
    "citations",
    "set_workers",
    "solve_normal",
    "solve_tangential",
]
