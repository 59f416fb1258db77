"""One plate-particle interface: its window of cells, the gap under it, and its contact solves.

Windows live on a lattice shared by every step of a run: cell centres at (i Δ, j Δ) in world
coordinates (m) with integer i, j, so a window that grows or moves between steps maps fields onto
the new window by an integer offset, without interpolation (the tangential history needs this).

A window is centred on the plate's first-contact point (the particle's lowest or highest point at
orientation θ) and starts at ``min_cells`` across. When the contact, or the set of cells that
could enter contact (gap below the approach), reaches its edge, the window doubles and the solve
is repeated: a contact is never truncated.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ..bem import (
    ContactAtEdgeError,
    Grid,
    NormalContact,
    TangentialContact,
    solve_normal,
    solve_tangential,
)
from ..material import Material
from ..shapes import Shape

__all__ = ["Interface", "InterfaceNormal", "Window"]

_MAX_CELLS = 4096


@dataclass(frozen=True)
class Window:
    """Cells ``i0 .. i0+nx-1`` (x) and ``j0 .. j0+ny-1`` (y) of the lattice of spacing Δ (m)."""

    i0: int
    j0: int
    nx: int
    ny: int

    def grid(self, spacing: float) -> Grid:
        return Grid((self.nx, self.ny), spacing,
                    center=((self.i0 + (self.nx - 1) / 2) * spacing,
                            (self.j0 + (self.ny - 1) / 2) * spacing))

    def enlarged(self, factor: int = 2) -> Window:
        nx, ny = self.nx * factor, self.ny * factor
        return Window(self.i0 - (nx - self.nx) // 2, self.j0 - (ny - self.ny) // 2, nx, ny)

    @staticmethod
    def around(x: float, y: float, cells: int, spacing: float) -> Window:
        """A ``cells`` x ``cells`` window whose centre is within half a cell of (x, y) (m)."""
        i = math.floor(x / spacing + 0.5) - cells // 2
        j = math.floor(y / spacing + 0.5) - cells // 2
        return Window(i, j, cells, cells)


def remap(field: np.ndarray, source: Window, target: Window) -> np.ndarray:
    """Copy a field (..., ny, nx) from one lattice window to another; zero where not covered."""
    out = np.zeros((*field.shape[:-2], target.ny, target.nx))
    i_lo, i_hi = max(source.i0, target.i0), min(source.i0 + source.nx, target.i0 + target.nx)
    j_lo, j_hi = max(source.j0, target.j0), min(source.j0 + source.ny, target.j0 + target.ny)
    if i_lo < i_hi and j_lo < j_hi:
        out[..., j_lo - target.j0:j_hi - target.j0, i_lo - target.i0:i_hi - target.i0] = \
            field[..., j_lo - source.j0:j_hi - source.j0, i_lo - source.i0:i_hi - source.i0]
    return out


@dataclass(frozen=True)
class InterfaceNormal:
    """A normal solve at one interface: the contact and its pressure centroid (world, m)."""

    side: str
    theta: float
    window: Window
    contact: NormalContact
    centroid: tuple[float, float]


class Interface:
    """The upper or lower plate's contact with the particle.

    Parameters
    ----------
    side : {"lower", "upper"}
    shape : Shape
    material : Material
    spacing : float
        Cell size Δ, m.
    min_cells : int
        Starting window size (cells across).
    tol : float
        Tolerance of the normal and tangential solvers.
    """

    def __init__(self, side: str, shape: Shape, material: Material, spacing: float,
                 min_cells: int = 32, tol: float = 1e-8) -> None:
        if side not in ("lower", "upper"):
            raise ValueError(f"side must be 'lower' or 'upper', got {side!r}")
        self.side, self.shape, self.material = side, shape, material
        self.spacing, self.tol = float(spacing), tol
        self.cells = int(min_cells)
        self._gap_cache: dict[tuple[float, Window], np.ndarray] = {}
        self.last: InterfaceNormal | None = None
        self.geometry_time = 0.0

    # geometry -----------------------------------------------------------------------------
    def extreme_point(self, theta: float) -> np.ndarray:
        """World point (x, y, z), m, where this plate first touches the particle."""
        if self.side == "lower":
            return self.shape.lowest_point(theta)
        return self.shape.highest_point(theta)

    def gap(self, theta: float, window: Window) -> np.ndarray:
        """Initial separation (m) between plate and particle on the window (inf where missed)."""
        key = (float(theta), window)
        if key not in self._gap_cache:
            start = time.perf_counter()
            X, Y = window.grid(self.spacing).mesh()
            fn = self.shape.gap_lower if self.side == "lower" else self.shape.gap_upper
            if len(self._gap_cache) > 16:
                self._gap_cache.clear()
            self._gap_cache[key] = np.asarray(fn(theta, X, Y), dtype=float)
            self.geometry_time += time.perf_counter() - start
        return self._gap_cache[key]

    def window_for(self, theta: float) -> Window:
        x, y, _ = self.extreme_point(theta)
        return Window.around(float(x), float(y), self.cells, self.spacing)

    # solves -------------------------------------------------------------------------------
    def solve_normal(self, theta: float, *, force: float | None = None,
                     approach: float | None = None) -> InterfaceNormal:
        """Frictionless normal contact at orientation ``theta`` (rad) under ``force`` (N) or a
        prescribed ``approach`` (m); warm-started from the last solve at the same orientation."""
        window = self.window_for(theta)
        while True:
            gap = self.gap(theta, window)
            initial = None
            if self.last is not None and self.last.theta == theta:
                initial = remap(self.last.contact.pressure, self.last.window, window)
                if not initial.any():
                    initial = None
            grid = window.grid(self.spacing)
            try:
                normal = solve_normal(gap, grid, self.material, force=force, approach=approach,
                                      tol=self.tol, initial=initial)
            except ContactAtEdgeError:
                window = self._grow(window)
                continue
            # cells on the window's border that could have come into contact: grow
            border = np.concatenate([gap[0], gap[-1], gap[:, 0], gap[:, -1]])
            if border.min() <= normal.approach:
                window = self._grow(window)
                continue
            break
        p = normal.pressure
        X, Y = grid.mesh()
        total = p.sum()
        centroid = (float((p * X).sum() / total), float((p * Y).sum() / total))
        self.last = InterfaceNormal(self.side, float(theta), window, normal, centroid)
        return self.last

    def _grow(self, window: Window) -> Window:
        footprint = 2 * self.shape.size / self.spacing      # the particle's width, cells
        if window.nx >= footprint:
            raise ContactAtEdgeError(
                f"{self.side} interface: the contact spreads over the whole particle "
                f"(window {window.nx} cells of {self.spacing:.3g} m): the load is far beyond "
                "the half-space model's range (contact size << particle size)")
        if window.nx * 2 > _MAX_CELLS:
            raise ContactAtEdgeError(
                f"{self.side} interface: the contact does not fit in a {window.nx}-cell window "
                f"(cell size {self.spacing:.3g} m); use a coarser resolution")
        self.cells = max(self.cells, window.nx * 2)
        return window.enlarged(2)

    def solve_tangential(self, solution: InterfaceNormal, mu: float, force: tuple[float, float],
                         previous: tuple[Window, TangentialContact] | None = None,
                         ) -> TangentialContact:
        """Partial-slip solve with the prescribed tangential force (N, on the particle) at this
        interface, carrying the history of ``previous`` (its window and its step) when given."""
        prev = None
        if previous is not None:
            p_window, p_step = previous
            traction = remap(p_step.traction, p_window, solution.window)
            prev = replace(p_step, traction=traction)
        return solve_tangential(solution.contact, mu, force=np.asarray(force, dtype=float),
                                previous=prev, tol=self.tol)
