"""One plate-particle interface: the cells that can touch, the gap under them, and the solves.

Windows live on a lattice shared by every step of a run: cell centres at (i Δ, j Δ) in the
particle frame (m) with integer i, j, so fields move between windows by integer offsets, without
interpolation (the tangential history needs this).

A solve at an orientation takes the cells that can touch from the footprint scan of
:class:`~thirdbody.particle.surface.Surfaces` (every spot, wherever it is), solves them as one
contact problem on the bounding box of those cells (cells in between are +inf: they share the
plate's rigid approach and interact through the half-space kernel, but cannot touch), and then
checks that nothing was left out: the approach must stay below the bound the cells were chosen
for, and no cell just outside them may lie below the approach. Otherwise the bound grows and the
solve is repeated from the last pressure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from ..bem import (
    ContactAtEdgeError,
    ElasticPair,
    Grid,
    NormalContact,
    TangentialContact,
    solve_normal,
)
from ..bem.tangential import restart_traction, solve_tangential_from
from ..material import Material
from ..orientation import key
from ..state import WarmStart
from .surface import LOWER, UPPER, Surfaces, dilate

__all__ = ["Interface", "InterfaceNormal", "Window", "count_spots", "remap"]

_ROUND = 8            # window sizes are multiples of this (the FFT operators are cached by size)
_ATTEMPTS = 12


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

    def slices(self, n: int) -> tuple[slice, slice]:
        """Row and column slices of this window in a (2n+1)² lattice array (origin at n)."""
        return (slice(self.j0 + n, self.j0 + n + self.ny),
                slice(self.i0 + n, self.i0 + n + self.nx))


def remap(field: np.ndarray, source: Window, target: Window) -> np.ndarray:
    """Copy a field (..., ny, nx) from one lattice window to another; zero where not covered."""
    out = np.zeros((*field.shape[:-2], target.ny, target.nx))
    i_lo, i_hi = max(source.i0, target.i0), min(source.i0 + source.nx, target.i0 + target.nx)
    j_lo, j_hi = max(source.j0, target.j0), min(source.j0 + source.ny, target.j0 + target.ny)
    if i_lo < i_hi and j_lo < j_hi:
        out[..., j_lo - target.j0:j_hi - target.j0, i_lo - target.i0:i_hi - target.i0] = \
            field[..., j_lo - source.j0:j_hi - source.j0, i_lo - source.i0:i_hi - source.i0]
    return out


def count_spots(contact: np.ndarray) -> int:
    """Number of separate contact spots: connected pieces of the contact set (cells touching
    at an edge or a corner belong to the same spot)."""
    _, n = ndimage.label(contact, structure=np.ones((3, 3), dtype=bool))
    return int(n)


@dataclass(frozen=True)
class InterfaceNormal:
    """A normal solve at one interface.

    Attributes
    ----------
    side : {"lower", "upper"}
    orientation : tuple
        Key of the orientation (:func:`thirdbody.orientation.key`).
    window : Window
    contact : NormalContact
        Its gap is measured from ``reference`` (m), the approach too.
    centroid : (float, float)
        Pressure centroid (x̄, ȳ), m, particle frame.
    reference : float
        Height z (m, particle frame) of the gap's zero: the lowest (upper plate: highest) point
        of the footprint scan.
    plate : float
        Height z (m) of the plate: ``reference + approach`` (lower) or ``reference − approach``
        (upper).
    spots : int
        Number of separate contact spots.
    """

    side: str
    orientation: tuple
    window: Window
    contact: NormalContact
    centroid: tuple[float, float]
    reference: float
    plate: float
    spots: int


def surface_approach(sol: InterfaceNormal) -> float:
    """Approach (m) of the plate measured from the lowest (upper plate: highest) surface cell
    of the solve's window (not from the scan's reference)."""
    g = sol.contact.gap
    return float(sol.contact.approach - g[np.isfinite(g)].min())


class Interface:
    """The upper or lower plate's contact with the particle.

    Parameters
    ----------
    side : {"lower", "upper"}
    material : Material
    spacing : float
        Cell size Δ, m.
    tol : float
        Tolerance of the normal and tangential solvers.
    """

    def __init__(self, side: str, material: Material, spacing: float,
                 tol: float = 1e-8) -> None:
        if side not in ("lower", "upper"):
            raise ValueError(f"side must be 'lower' or 'upper', got {side!r}")
        self.side, self.material = side, material
        self.pair = ElasticPair.rigid_plate(material)
        self.index = LOWER if side == "lower" else UPPER
        self.spacing, self.tol = float(spacing), tol
        #: the particle state's warm start (:meth:`thirdbody.particle.member.Member.bind`);
        #: without one, a private one
        self.warm = WarmStart()

    @property
    def last(self) -> InterfaceNormal | None:
        """The last normal solve at this plate (the next one's warm start)."""
        return self.warm.normal.get(self.side)

    @last.setter
    def last(self, value: InterfaceNormal | None) -> None:
        self.warm.normal[self.side] = value

    def _bound(self, surfaces: Surfaces, force: float) -> float:
        """A first bound (m) on the approach, from the last solve or a Hertz estimate. Only
        the cost depends on it: an approach beyond it widens the problem (module docstring)."""
        floor = 2.0 * surfaces.floor_allowance(self.index) + 2.0 * self.spacing * 1e-6
        if self.last is not None and self.last.contact.force > 0:
            # the approach grows like F^(2/3)
            ratio = force / self.last.contact.force
            guess = abs(self.last.contact.approach) * max(ratio, 1.0) ** (2 / 3)
            return max(1.5 * guess, floor)
        # Hertz with the shape's smallest curvature radius: an overestimate for a smooth body
        radius = surfaces.shape.feature_length
        hertz = (9 * force**2 / (16 * self.material.E_star**2 * radius)) ** (1 / 3)
        return max(2.0 * hertz, floor)

    def solve_normal(self, surfaces: Surfaces, *, force: float,
                     traction: tuple[Window, np.ndarray] | None = None) -> InterfaceNormal:
        """Frictionless normal contact at the orientation of ``surfaces`` under ``force`` (N);
        warm-started from the last solve at the same orientation. Every spot the plate can
        reach is in the problem (module docstring). ``traction``: with normal-tangential
        coupling, the shear tractions (Pa) on their window whose normal displacement the
        pressure must make room for."""
        n = surfaces.n
        orientation = key(surfaces.rotation)
        bound = self._bound(surfaces, force)
        extra = np.zeros((surfaces.cells, surfaces.cells), dtype=bool)
        warm = None
        if self.last is not None and self.last.orientation == orientation:
            warm = (self.last.window, self.last.contact.pressure)
        for _ in range(_ATTEMPTS):
            mask = surfaces.candidates(self.index, bound) | extra
            window = _window_around(mask, n)
            rows, cols = window.slices(n)
            gap = surfaces.gap(self.index, mask)[rows, cols]
            grid = window.grid(self.spacing)
            initial = None
            if warm is not None:
                initial = remap(warm[1], warm[0], window)
                if not initial.any():
                    initial = None
            shear = None if traction is None else remap(traction[1], traction[0], window)
            try:
                normal = solve_normal(gap, grid, self.pair, force=force, tol=self.tol,
                                      initial=initial, traction=shear)
            except ContactAtEdgeError:
                # the window holds the whole footprint with free cells around it: only a
                # contact over the whole particle (an approach beyond its size) gets there
                raise ContactAtEdgeError(
                    f"{self.side} interface: the contact spreads over the whole particle: the "
                    "load is far beyond the half-space model's range (contact size << "
                    "particle size)") from None
            delta = normal.approach
            warm = (window, normal.pressure)
            if delta >= bound:
                bound = max(2.0 * bound, 1.5 * delta)
                continue
            # cells just outside the mask must not lie below the approach
            ring = dilate(mask, 3) & ~mask
            low = ring & (surfaces.gap(self.index, ring) <= delta)
            if low.any():
                k = 2 * surfaces.stride + 1
                extra |= dilate(low, k)
                continue
            break
        else:  # pragma: no cover - the bound doubles each time
            raise RuntimeError(f"{self.side} interface: the contact cells did not settle")
        _check_half_space(normal.contact, window, surfaces, self.side)
        p = normal.pressure
        X, Y = grid.mesh()
        total = p.sum()
        centroid = (float((p * X).sum() / total), float((p * Y).sum() / total))
        reference = surfaces.reference[self.index]
        plate = reference + delta if self.index == LOWER else reference - delta
        solved = InterfaceNormal(self.side, orientation, window, normal, centroid, reference,
                                 plate, count_spots(normal.contact))
        self.last = solved
        return solved

    def solve_tangential(self, solution: InterfaceNormal, mu: float, force: tuple[float, float],
                         previous: tuple[Window, TangentialContact] | None = None,
                         twist: float | None = None, coupling: bool = False,
                         restart: tuple[Window, TangentialContact] | None = None,
                         tol: float | None = None) -> TangentialContact:
        """Partial-slip solve with the prescribed tangential force (N, on the particle) at this
        interface, carrying the history of ``previous`` (its window and its step) when given.
        ``twist``: the plate's total rotation about the particle's vertical axis, rad (default:
        the previous step's). ``coupling``: the pressure's change since ``previous`` (from zero
        without it) moves the surface tangentially (:func:`~thirdbody.bem.solve_tangential`).
        ``restart``: a step of the same load under a slightly different pressure (its window
        and step, e.g. the last coupled pass), to start the iteration from: its slip cells on
        their new friction limit (:func:`~thirdbody.bem.tangential.restart_traction`)."""
        start = guess = jacobian = None
        search_first = False
        if restart is not None:
            r_window, r_step = restart
            guess = r_step.shift
            jacobian = getattr(r_step, "search_jacobian", None)     # (older pickles: none)
            # no stick cell left: force control would fail again (it needs one to carry the
            # force); straight to the shift search from this step's shift
            search_first = _SEARCH_FIRST and not r_step.stick.any()
            start = restart_traction(remap(r_step.traction, r_window, solution.window),
                                     remap(r_step.slip, r_window, solution.window) > 0.5,
                                     solution.contact, mu)
        prev = None
        pressure = np.zeros(solution.window.ny * solution.window.nx).reshape(
            solution.window.ny, solution.window.nx)
        if previous is not None:
            p_window, p_step = previous
            traction = remap(p_step.traction, p_window, solution.window)
            prev = replace(p_step, traction=traction)
            pressure = remap(p_step.normal.pressure, p_window, solution.window)
        return solve_tangential_from(start, solution.contact, mu, shift_guess=guess,
                                     search_first=search_first, shift_jacobian=jacobian,
                                     force=np.asarray(force, dtype=float), previous=prev,
                                     tol=self.tol if tol is None else max(tol, self.tol),
                                     twist=twist, coupling=coupling,
                                     previous_pressure=pressure if coupling else None)


_SEARCH_FIRST = True


def _check_half_space(contact: np.ndarray, window: Window, surfaces: Surfaces,
                      side: str) -> None:
    """Refuse a contact as wide as the particle: the half-space model needs contacts much
    smaller than the particle (docs/methods/design.md §3)."""
    rows = np.flatnonzero(contact.any(axis=1))
    cols = np.flatnonzero(contact.any(axis=0))
    extent = max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1) * surfaces.spacing
    if extent > 1.5 * surfaces.shape.size:
        raise ContactAtEdgeError(
            f"{side} interface: the contact spreads over the whole particle ({extent:.3g} m "
            f"across, particle size {surfaces.shape.size:.3g} m): the load is far beyond the "
            "half-space model's range (contact size << particle size)")


def _window_around(mask: np.ndarray, n: int) -> Window:
    """The bounding box of ``mask`` (a (2n+1)² lattice array) with two free cells on each side,
    widened to a multiple of 8 cells and kept inside the lattice."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    size = 2 * n + 1

    def span(lo: int, hi: int) -> tuple[int, int]:
        lo, hi = lo - 2, hi + 3
        length = min(math.ceil((hi - lo) / _ROUND) * _ROUND, size)
        lo = min(max(lo - (length - (hi - lo)) // 2, 0), size - length)
        return lo, length

    j0, ny = span(int(rows[0]), int(rows[-1]))
    i0, nx = span(int(cols[0]), int(cols[-1]))
    return Window(i0 - n, j0 - n, nx, ny)
