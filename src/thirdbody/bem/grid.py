"""Uniform windows of rectangular cells on which the boundary-element fields live, and the
transfers between them: 2x2 coarsening and its piecewise-constant inverse (the solvers'
coarse-to-fine starts), and boxes (sub-windows) cut out of a window and put back.

Fields are cell-centre values in arrays of shape ``(ny, nx)`` (rows along y), or
``(k, ny, nx)`` for k components; coordinates and spacings are in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.fft import next_fast_len


def _pair(value, name: str, kind=int) -> tuple:
    if np.ndim(value) == 0:
        value = (value, value)
    if len(value) != 2:
        raise ValueError(f"Grid.{name} must be a scalar or a pair (x, y), got {value!r}")
    return tuple(kind(v) for v in value)


@dataclass(frozen=True)
class Grid:
    """A window of ``nx`` x ``ny`` cells with uniform spacing.

    Fields on the grid are arrays of shape ``(ny, nx)``: rows run along y, columns along x.
    Values are cell-centre values (pressure in Pa is uniform over a cell).

    Parameters
    ----------
    n : int or (int, int)
        Number of cells, ``n`` or ``(nx, ny)``; at least 2 in each direction.
    spacing : float or (float, float)
        Cell size in m, ``h`` or ``(dx, dy)``; > 0.
    center : (float, float)
        World coordinates (m) of the window's centre. With an even number of cells the centre falls
        on a cell corner.
    """

    n: tuple[int, int] | int
    spacing: tuple[float, float] | float
    center: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        nx, ny = _pair(self.n, "n", int)
        dx, dy = _pair(self.spacing, "spacing", float)
        if nx < 2 or ny < 2:
            raise ValueError(f"Grid.n must be at least 2 cells in x and y, got {(nx, ny)}")
        if not (math.isfinite(dx) and math.isfinite(dy) and dx > 0 and dy > 0):
            raise ValueError(f"Grid.spacing must be finite and > 0 m, got {(dx, dy)}")
        cx, cy = _pair(self.center, "center", float)
        object.__setattr__(self, "n", (nx, ny))
        object.__setattr__(self, "spacing", (dx, dy))
        object.__setattr__(self, "center", (cx, cy))

    @property
    def nx(self) -> int:
        return self.n[0]

    @property
    def ny(self) -> int:
        return self.n[1]

    @property
    def dx(self) -> float:
        return self.spacing[0]

    @property
    def dy(self) -> float:
        return self.spacing[1]

    @property
    def shape(self) -> tuple[int, int]:
        """Array shape of a field, ``(ny, nx)``."""
        return (self.ny, self.nx)

    @property
    def cell_area(self) -> float:
        """Area of one cell in m^2."""
        return self.dx * self.dy

    @property
    def x(self) -> np.ndarray:
        """Cell-centre x coordinates (m), shape ``(nx,)``."""
        return self.center[0] + (np.arange(self.nx) - (self.nx - 1) / 2) * self.dx

    @property
    def y(self) -> np.ndarray:
        """Cell-centre y coordinates (m), shape ``(ny,)``."""
        return self.center[1] + (np.arange(self.ny) - (self.ny - 1) / 2) * self.dy

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates ``(X, Y)`` as 2-D arrays of shape ``(ny, nx)``, in m."""
        return np.meshgrid(self.x, self.y, indexing="xy")

    def paraboloid(self, radius_x: float, radius_y: float | None = None,
                   x0: float = 0.0, y0: float = 0.0) -> np.ndarray:
        """Gap (m) of a paraboloid ``(x-x0)^2/(2 R_x) + (y-y0)^2/(2 R_y)`` at the cell centres.

        The Hertzian approximation of a body with principal radii of curvature R_x, R_y (m) whose
        apex touches the plane at (x0, y0).
        """
        radius_y = radius_x if radius_y is None else radius_y
        if radius_x <= 0 or radius_y <= 0:
            raise ValueError(f"paraboloid radii must be > 0 m, got {(radius_x, radius_y)}")
        X, Y = self.mesh()
        return (X - x0) ** 2 / (2 * radius_x) + (Y - y0) ** 2 / (2 * radius_y)

    def ellipsoid(self, semi_axes: tuple[float, float, float],
                  x0: float = 0.0, y0: float = 0.0) -> np.ndarray:
        """Exact gap (m) under an upright ellipsoid with semi-axes (A, B, C), C vertical.

        ``C (1 - sqrt(1 - x^2/A^2 - y^2/B^2))`` with the apex at (x0, y0); ``inf`` outside the
        ellipsoid's footprint. Written in a form without cancellation near the apex.
        """
        A, B, C = (float(s) for s in semi_axes)
        if min(A, B, C) <= 0:
            raise ValueError(f"ellipsoid semi_axes must be > 0 m, got {semi_axes!r}")
        X, Y = self.mesh()
        q = ((X - x0) / A) ** 2 + ((Y - y0) / B) ** 2
        with np.errstate(invalid="ignore"):
            gap = C * q / (1.0 + np.sqrt(1.0 - q))
        return np.where(q <= 1.0, gap, np.inf)


def coarse_grid(grid: Grid) -> Grid:
    """The window with cells twice as large (2x2 blocks; an odd last row/column is padded), the
    grid of :func:`restrict`'s fields."""
    nx, ny = grid.n
    dx, dy = grid.spacing
    cx, cy = grid.center
    c_nx, c_ny = (nx + 1) // 2, (ny + 1) // 2
    return Grid((c_nx, c_ny), (2 * dx, 2 * dy),
                center=(cx + (c_nx - nx / 2) * dx, cy + (c_ny - ny / 2) * dy))


def restrict(field: np.ndarray) -> np.ndarray:
    """Average 2x2 blocks of a (ny, nx) field (an odd trailing row/column is repeated)."""
    ny, nx = field.shape
    if ny % 2 or nx % 2:
        field = np.pad(field, ((0, ny % 2), (0, nx % 2)), mode="edge")
    return 0.25 * (field[0::2, 0::2] + field[1::2, 0::2] + field[0::2, 1::2]
                   + field[1::2, 1::2])


def prolong(field: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A coarse (ny, nx) field on the finer grid of ``shape``: each value on its 2x2 block."""
    return np.kron(field, np.ones((2, 2)))[: shape[0], : shape[1]]


def bounding_box(mask: np.ndarray, margin: int) -> tuple[slice, slice]:
    """(rows, columns) of the bounding box of ``mask`` widened by ``margin`` cells, rounded up
    to a multiple of 8 cells (so operators are shared between calls) and kept inside the
    window; the whole window if ``mask`` is empty."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    ny, nx = mask.shape
    if rows.size == 0:
        return slice(0, ny), slice(0, nx)
    j0, j1 = max(rows[0] - margin, 0), min(rows[-1] + 1 + margin, ny)
    i0, i1 = max(cols[0] - margin, 0), min(cols[-1] + 1 + margin, nx)
    j0, j1 = _round_up(j0, j1, ny)
    i0, i1 = _round_up(i0, i1, nx)
    return slice(j0, j1), slice(i0, i1)


def _round_up(a: int, b: int, n: int) -> tuple[int, int]:
    size = min(-(-(b - a) // 8) * 8, n)
    b = min(a + size, n)
    return b - size, b


def fast_span(a: int, b: int, n: int) -> slice:
    """Widen [a, b) inside [0, n) to a length whose FFTs are fast (5-smooth), if it fits."""
    size = next_fast_len(b - a, real=True)
    if size > n:
        return slice(a, b)
    lo = max(0, min(a - (size - (b - a)) // 2, n - size))
    return slice(lo, lo + size)


def outside(box: tuple[slice, slice], shape: tuple[int, int]) -> np.ndarray:
    """The cells of a window of ``shape`` outside ``box``, a bool (ny, nx) mask."""
    mask = np.ones(shape, dtype=bool)
    mask[box] = False
    return mask


def embed(field: np.ndarray, box: tuple[slice, slice], shape: tuple[int, int]) -> np.ndarray:
    """A field (..., ny_box, nx_box) on a box, on the whole window of ``shape`` (zero outside
    the box)."""
    out = np.zeros((*field.shape[:-2], *shape), dtype=field.dtype)
    out[(..., *box)] = field
    return out
