"""Uniform windows of rectangular cells on which the boundary-element fields live."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


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
