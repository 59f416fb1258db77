"""Where two bodies can touch, on the contact frame's lattice (the every-spot logic of the plates,
:mod:`thirdbody.particle.surface`, for a pair).

The lattice has cell centres at (i Δ, j Δ) in the contact frame (origin at the midpoint of the
closest points, z along the normal), integer i, j. The gap from first touch is
g₀ = z_low,b − z_up,a − σ, σ the closest approach's separation, so g₀ >= 0 with its zero at the
closest points. Under an approach δ only cells with g₀ < δ can touch: both bodies' elastic
displacements are positive under a compressive pressure (every influence coefficient is).

**Every spot.** The common footprint of the two bodies (the intersection of their bounding
discs) is scanned on a coarse sub-lattice of stride k, the power of two with k Δ at most 1/24
of the smaller body's size and a quarter of the smaller feature length. A sample is a
candidate when its gap less a curvature allowance (half its largest second difference: twice
the dip of a quadratic between samples) is below the bound β on the approach; the candidates
and their neighbours are then sampled four times finer, and so on down to the cells. Every connected
piece of {g₀ < β}, wherever it lies, is found this way, and only the neighbourhood of those
pieces is evaluated cell by cell. Cells left out cannot be below β (if the allowance bounds the
dip, which holds for surfaces smooth on the scale of the samples); in the solver's window they
are +inf. A faceted mesh's first touch may be a lowest cell below σ: the caller then lowers the
zero (:meth:`Lattice.lower_zero`).

The window is the bounding box of the cells below β with two free cells on each side (rounded
up to a multiple of 8 cells, as the plates' windows are). After a solve the caller checks that
the approach stayed below β and that no cell next to the evaluated ones is below the approach,
and grows β or the evaluated set otherwise (and the solver's own edge check grows β): the window
grows with the contact and never cuts it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from ..particle.interface import Window
from .frame import Seen, seen_gap
from .narrow import SCAN_SAMPLES, allowance, footprint_box

__all__ = ["Lattice", "carry_field"]

_ROUND = 8
_REFINE = 4         # each level is this many times finer than the last


class Lattice:
    """The gap g₀ (m) of bodies a (below) and b (above) on the contact frame's lattice of
    spacing ``spacing`` (m), evaluated on demand and cached by cell.

    Parameters
    ----------
    a, b : Body
    frame : Rotation
        World -> contact frame.
    origin : (3,) array
        World position of the frame origin (cell (0, 0)), m.
    zero : float
        The gap's zero level: the closest approach's separation σ, m.
    spacing : float
        Cell size Δ, m.
    others : sequence of (3,) arrays
        World points of the pair's other contacts (where the bodies also touch, facing other
        ways): a cell nearer to one of them than to ``origin`` belongs to that contact, and its
        gap is +inf here (the bisecting plane of the two points splits the surfaces).
    """

    def __init__(self, a, b, frame, origin, zero: float, spacing: float, others=()) -> None:
        self.a, self.b, self.frame = a, b, frame
        self.origin = np.asarray(origin, dtype=float)
        F = frame.as_matrix()
        # each other point q (frame coordinates): cells with x q_x + y q_y > |q|²/2 are its
        self._others = [F @ (np.asarray(q, dtype=float) - self.origin) for q in others]
        self._seen = (Seen(a, frame, self.origin, F), Seen(b, frame, self.origin, F))
        box = footprint_box(a, b, frame, self.origin)
        if box is None:
            raise ValueError("the bodies' footprints do not overlap in the contact frame")
        self._setup(zero, spacing, min(a.size, b.size),
                    min(a.shape.feature_length, b.shape.feature_length), box)

    def _setup(self, zero: float, spacing: float, size: float, feature: float,
               box: tuple[float, float, float, float]) -> None:
        """The scan's stride from the smaller body's ``size`` and ``feature`` length (m) and the
        footprint ``box`` (x0, x1, y0, y1), m, in lattice coordinates."""
        self.zero, self.spacing = float(zero), float(spacing)
        # evaluated cells: sorted keys (i << 32) + (j mod 2³²) and their gaps
        self._keys = np.zeros(0, dtype=np.int64)
        self._values = np.zeros(0)
        self.rays = 0
        target = min(2.0 * size / SCAN_SAMPLES, feature / 4.0)
        self.stride = 1 << max(0, math.floor(math.log2(max(target / self.spacing, 1.0))))
        x0, x1, y0, y1 = (v / self.spacing for v in box)
        k = self.stride
        self.footprint = (k * math.floor(x0 / k), k * math.ceil(x1 / k),
                          k * math.floor(y0 / k), k * math.ceil(y1 / k))

    def _rays(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The raw gap (m, before the zero level is taken off) at lattice coordinates x, y (m);
        +inf where a ray misses."""
        gap = seen_gap(*self._seen, x, y)
        for q in self._others:
            gap = np.where(x * q[0] + y * q[1] > 0.5 * float(q @ q), np.inf, gap)
        return gap

    def gap(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """g₀ (m) at cells (i, j) (integer arrays of one shape); +inf where a ray misses."""
        i = np.asarray(i, dtype=np.int64)
        j = np.asarray(j, dtype=np.int64)
        keys = (i.ravel() << 32) + (j.ravel() & 0xFFFFFFFF)
        pos = np.searchsorted(self._keys, keys)
        pos_ok = np.minimum(pos, max(self._keys.size - 1, 0))
        known = (self._keys.size > 0) & (self._keys[pos_ok] == keys) if self._keys.size else \
            np.zeros(keys.size, dtype=bool)
        out = np.where(known, self._values[pos_ok] if self._keys.size else 0.0, np.nan)
        if not known.all():
            todo_keys, first = np.unique(keys[~known], return_index=True)
            ti = i.ravel()[~known][first]
            tj = j.ravel()[~known][first]
            values = self._rays(ti * self.spacing, tj * self.spacing) - self.zero
            self.rays += todo_keys.size
            merged = np.concatenate([self._keys, todo_keys])
            order = np.argsort(merged, kind="stable")
            self._keys = merged[order]
            self._values = np.concatenate([self._values, values])[order]
            where = np.searchsorted(self._keys, keys[~known])
            out[~known] = self._values[where]
        return out.reshape(i.shape)

    def lower_zero(self, depth: float) -> None:
        """Move the gap's zero level down by ``depth`` (m): every g₀ grows by it."""
        self.zero -= float(depth)
        self._values = self._values + float(depth)

    def candidates(self, bound: float) -> tuple[tuple[int, int], np.ndarray]:
        """The cells that may lie below ``bound`` (m) and their neighbours, from the coarse scan
        refined level by level (module docstring): ``((i0, j0), mask)`` with mask[j − j0, i − i0]
        True for every evaluated cell; every cell outside has g₀ >= bound."""
        k = self.stride
        fx0, fx1, fy0, fy1 = self.footprint
        i0, j0 = fx0 // k, fy0 // k
        mask = np.ones(((fy1 - fy0) // k + 1, (fx1 - fx0) // k + 1), dtype=bool)
        while True:
            jj, ii = np.nonzero(mask)
            g = np.full(mask.shape, np.nan)
            g[jj, ii] = self.gap((ii + i0) * k, (jj + j0) * k)
            hit = mask & ((g - allowance(g)) < bound)
            if k == 1:
                # the cells themselves, and one more ring as a neighbourhood
                grown = ndimage.binary_dilation(hit, structure=np.ones((3, 3), dtype=bool))
                return _evaluated(self, (i0, j0), mask | grown)
            f = min(_REFINE, k)
            hit = ndimage.binary_dilation(hit, structure=np.ones((3, 3), dtype=bool))
            rows, cols = np.nonzero(hit)
            if rows.size == 0:
                return (i0 * k, j0 * k), np.zeros((1, 1), dtype=bool)
            # the next level: every sample within one old sample spacing of a kept sample
            k_next = k // f
            ni0, nj0 = (cols.min() + i0 - 1) * f, (rows.min() + j0 - 1) * f
            shape = ((rows.max() - rows.min() + 2) * f + 1, (cols.max() - cols.min() + 2) * f + 1)
            seeds = np.zeros(shape, dtype=bool)
            seeds[(rows - rows.min() + 1) * f, (cols - cols.min() + 1) * f] = True
            mask = ndimage.binary_dilation(seeds, structure=np.ones((2 * f + 1, 2 * f + 1),
                                                                   dtype=bool))
            i0, j0, k = ni0, nj0, k_next


def _evaluated(lattice: Lattice, corner: tuple[int, int], mask: np.ndarray):
    jj, ii = np.nonzero(mask)
    lattice.gap(ii + corner[0], jj + corner[1])
    return corner, mask


def union(first: tuple[tuple[int, int], np.ndarray],
          second: tuple[tuple[int, int], np.ndarray]) -> tuple[tuple[int, int], np.ndarray]:
    """The union of two lattice masks given as (corner (i0, j0), mask[j − j0, i − i0])."""
    (ci, cj), m1 = first
    (di, dj), m2 = second
    i0, j0 = min(ci, di), min(cj, dj)
    i1 = max(ci + m1.shape[1], di + m2.shape[1])
    j1 = max(cj + m1.shape[0], dj + m2.shape[0])
    out = np.zeros((j1 - j0, i1 - i0), dtype=bool)
    out[cj - j0:cj - j0 + m1.shape[0], ci - i0:ci - i0 + m1.shape[1]] |= m1
    out[dj - j0:dj - j0 + m2.shape[0], di - i0:di - i0 + m2.shape[1]] |= m2
    return (i0, j0), out


def ring(corner: tuple[int, int], mask: np.ndarray,
         width: int = 1) -> tuple[tuple[int, int], np.ndarray]:
    """The cells within ``width`` cells of ``mask`` but not in it, as (corner, mask)."""
    padded = np.pad(mask, width)
    grown = ndimage.binary_dilation(padded, structure=np.ones((2 * width + 1,) * 2, dtype=bool))
    return (corner[0] - width, corner[1] - width), grown & ~padded


def occupied(window: Window, *fields: np.ndarray) -> Window | None:
    """The smallest window holding the cells of ``window`` where some field (each
    (..., ny, nx) on it) is non-zero; None if all are zero. A contact's history window: the
    cells its traction and pressure occupy, not the solved window with its free margin (which
    held as the next window, margin and all, would grow by a margin every step)."""
    live = np.zeros((window.ny, window.nx), dtype=bool)
    for f in fields:
        f = np.asarray(f)
        live |= (f != 0).reshape(-1, window.ny, window.nx).any(axis=0)
    if not live.any():
        return None
    rows, cols = np.flatnonzero(live.any(axis=1)), np.flatnonzero(live.any(axis=0))
    return Window(window.i0 + int(cols[0]), window.j0 + int(rows[0]),
                  int(cols[-1] - cols[0]) + 1, int(rows[-1] - rows[0]) + 1)


def window_around(cells: np.ndarray, corner: tuple[int, int],
                  extra: Window | None = None) -> Window:
    """The bounding box of ``cells`` (a mask with cell (i, j) at [j − j0, i − i0]) with two free
    cells on each side, widened to a multiple of 8 cells, and holding ``extra`` if given."""
    rows = np.flatnonzero(cells.any(axis=1))
    cols = np.flatnonzero(cells.any(axis=0))
    lo_i, hi_i = int(cols[0]) + corner[0], int(cols[-1]) + corner[0]
    lo_j, hi_j = int(rows[0]) + corner[1], int(rows[-1]) + corner[1]
    if extra is not None:
        lo_i, hi_i = min(lo_i, extra.i0), max(hi_i, extra.i0 + extra.nx - 1)
        lo_j, hi_j = min(lo_j, extra.j0), max(hi_j, extra.j0 + extra.ny - 1)

    def span(lo: int, hi: int) -> tuple[int, int]:
        lo, hi = lo - 2, hi + 3
        length = max(math.ceil((hi - lo) / _ROUND) * _ROUND, _ROUND)
        return lo - (length - (hi - lo)) // 2, length

    i0, nx = span(lo_i, hi_i)
    j0, ny = span(lo_j, hi_j)
    return Window(i0, j0, nx, ny)


def window_gap(lattice: Lattice, window: Window, corner: tuple[int, int],
               mask: np.ndarray) -> np.ndarray:
    """g₀ (m) on ``window``: the evaluated cells of ``mask`` (corner as in
    :meth:`Lattice.candidates`), +inf elsewhere."""
    out = np.full((window.ny, window.nx), np.inf)
    jj, ii = np.nonzero(mask)
    i, j = ii + corner[0], jj + corner[1]
    inside = (i >= window.i0) & (i < window.i0 + window.nx) & \
             (j >= window.j0) & (j < window.j0 + window.ny)
    out[j[inside] - window.j0, i[inside] - window.i0] = lattice.gap(i[inside], j[inside])
    return out


def carry_field(field: np.ndarray, source_grid, target_grid, angle: float,
                offset: np.ndarray, vector: bool) -> np.ndarray:
    """A field (..., ny, nx) of one contact frame's lattice expressed on another's.

    A point with old frame coordinates p sits at q = Rot(angle) p + offset in the new frame
    (``offset``: the old origin's tangential position in the new frame, m). Each new cell takes
    the bilinear interpolation of the old field at Rot(−angle)(q − offset) (zero outside the old
    window); with ``vector`` the field's first axis holds 2-vector components, which are turned
    by ``angle``. When the move is a whole number of cells without rotation the values are
    copied exactly.
    """
    f = np.asarray(field, dtype=float)
    if vector and f.shape[0] != 2:
        raise ValueError("a vector field has 2 components on its first axis")
    h_old = source_grid.dx
    X, Y = target_grid.mesh()
    c, s = math.cos(angle), math.sin(angle)
    px = c * (X - offset[0]) + s * (Y - offset[1])
    py = -s * (X - offset[0]) + c * (Y - offset[1])
    x0, y0 = source_grid.x[0], source_grid.y[0]
    u = (px - x0) / h_old
    v = (py - y0) / h_old
    ny, nx = f.shape[-2:]
    snapped_u, snapped_v = np.rint(u), np.rint(v)
    exact = (abs(angle) < 1e-14 and np.abs(u - snapped_u).max() < 1e-9
             and np.abs(v - snapped_v).max() < 1e-9)
    if exact:
        iu, iv = snapped_u.astype(np.int64), snapped_v.astype(np.int64)
        ok = (iu >= 0) & (iu < nx) & (iv >= 0) & (iv < ny)
        out = np.zeros((*f.shape[:-2], *X.shape))
        out[..., ok] = f[..., iv[ok], iu[ok]]
    else:
        iu, iv = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        fu, fv = u - iu, v - iv
        out = np.zeros((*f.shape[:-2], *X.shape))
        for du, dv, w in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)),
                          (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
            cu, cv = iu + du, iv + dv
            ok = (cu >= 0) & (cu < nx) & (cv >= 0) & (cv < ny)
            out[..., ok] += w[ok] * f[..., cv[ok], cu[ok]]
    if vector:
        out = np.stack([c * out[0] - s * out[1], s * out[0] + c * out[1]])
    return out
