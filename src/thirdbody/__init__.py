"""thirdbody: a deformable third-body particle between two rigid plates, by FFT-accelerated BEM.

Public API::

    Material(E, nu)                     elastic constants (Pa, -)
    Grid(n, spacing)                    a window of cells (m)
    solve_normal(gap, grid, material, force=... | approach=...)   -> NormalContact
    reference.hertz, reference.mindlin  analytic solutions to check runs against
    citations()                         the papers behind the methods used
"""

from ._citations import citations
from .bem import (
    ContactAtEdgeError,
    ConvergenceError,
    Grid,
    NormalContact,
    set_workers,
    solve_normal,
)
from .material import Material

__version__ = "0.1.0"

__all__ = [
    "ContactAtEdgeError",
    "ConvergenceError",
    "Grid",
    "Material",
    "NormalContact",
    "__version__",
    "citations",
    "set_workers",
    "solve_normal",
]
