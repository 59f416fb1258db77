"""The particle's two surfaces at one orientation, on the run's lattice, and where a plate can
touch them.

The lattice has cell centres at (i Δ, j Δ) in the particle frame (centroid at the origin, world
axes, m). The body's horizontal footprint lies inside the disc of radius ``shape.size`` (the
largest centroid-surface distance), so lattice indices −n..n with n = ⌈size/Δ⌉ + 2 hold it with
two empty cells to spare.

**Finding every spot (docs/methods/design.md §4).** A plate at height ``z_ref + δ`` (lower plate;
the upper one mirrors it) can only touch cells whose initial gap ``g = z_low − z_ref`` is below δ,
because the elastic displacement of a loaded half-space is positive everywhere. Each connected piece
of {g < δ} holds a local minimum of g, possibly far from the lowest point. So the whole footprint
is scanned first on a coarse sub-lattice (every ``stride``-th cell, about 48 samples across the
particle and at least 4 per :attr:`~thirdbody.shapes.Shape.feature_length`). A coarse sample is a
candidate if its gap, less a curvature allowance (half its largest second difference, twice
what a quadratic surface can dip between samples), is below the bound; the candidates,
dilated by one coarse cell and then by ``stride`` fine cells, form the mask of fine cells that
are evaluated and handed to the solver. Everything outside the mask is +inf (cannot touch).
After the solve, :class:`~thirdbody.particle.interface.Interface` checks that the approach stayed
below the bound and that no fine cell just outside the mask is below the approach, and widens
the mask otherwise.

Ray evaluations are lazy and cached on the lattice: the march and the bisection of a turn, and
the two plates, never ask for the same ray twice at one orientation.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy import ndimage

from ..orientation import Rotation
from ..shapes import Shape

__all__ = ["LOWER", "UPPER", "Surfaces"]

LOWER, UPPER = 0, 1

#: coarse samples across the particle's footprint diameter (at most; finer for small features)
SCAN_SAMPLES = 48


def scan_stride(shape: Shape, spacing: float) -> int:
    """Fine cells between coarse scan samples: about :data:`SCAN_SAMPLES` across the footprint
    and at least four samples per feature length, never below one."""
    target = min(2.0 * shape.size / SCAN_SAMPLES, shape.feature_length / 4.0)
    return max(1, int(target / spacing))


class Surfaces:
    """Lower and upper surface heights z (m) of a shape at one orientation, on the lattice of
    spacing ``spacing`` (m), evaluated on demand.

    ``z[LOWER]``, ``z[UPPER]`` are (2n+1, 2n+1) arrays indexed ``[j + n, i + n]`` for lattice
    cell (i, j); NaN where not evaluated yet, +inf (lower) / −inf (upper) where the ray misses.
    ``reference[side]`` is the lowest (highest) height found by the coarse scan: the zero of
    that side's gap.
    """

    def __init__(self, shape: Shape, rotation: Rotation, spacing: float,
                 stride: int | None = None) -> None:
        self.shape, self.rotation, self.spacing = shape, rotation, float(spacing)
        self.n = math.ceil(shape.size / self.spacing) + 2
        size = 2 * self.n + 1
        self.z = np.full((2, size, size), np.nan)
        self.geometry_time = 0.0
        self.rays = 0
        self.stride = int(stride or scan_stride(shape, self.spacing))
        m = self.n // self.stride
        self.coarse_index = self.stride * np.arange(-m, m + 1) + self.n   # array indices
        sel = np.zeros((size, size), dtype=bool)
        sel[np.ix_(self.coarse_index, self.coarse_index)] = True
        # rays outside the footprint disc miss the body: skip them (they stay +-inf)
        lat = (np.arange(size) - self.n) * self.spacing
        X, Y = np.meshgrid(lat, lat)
        outside = np.hypot(X, Y) > shape.size + 1.5 * self.spacing
        self.z[LOWER][outside] = np.inf
        self.z[UPPER][outside] = -np.inf
        self.ensure(sel)
        coarse = self.z[:, self.coarse_index][:, :, self.coarse_index]
        lower, upper = coarse[LOWER], coarse[UPPER]
        if not np.isfinite(lower).any():
            raise ValueError("the footprint scan found no body: is the shape's size right?")
        self.reference = (float(lower[np.isfinite(lower)].min()),
                          float(upper[np.isfinite(upper)].max()))
        #: coarse gaps (m, >= 0, +inf off the body) and their curvature allowances, per side
        self.coarse_gap = (lower - self.reference[LOWER], self.reference[UPPER] - upper)
        self.allowance = tuple(_allowance(g) for g in self.coarse_gap)

    # --- lattice ---------------------------------------------------------------------------
    @property
    def cells(self) -> int:
        """Lattice cells across the scanned square, 2n + 1."""
        return 2 * self.n + 1

    def ensure(self, mask: np.ndarray) -> None:
        """Evaluate the rays of the (2n+1)² ``mask`` not evaluated yet."""
        todo = mask & np.isnan(self.z[LOWER])
        if not todo.any():
            return
        start = time.perf_counter()
        jj, ii = np.nonzero(todo)
        x = (ii - self.n) * self.spacing
        y = (jj - self.n) * self.spacing
        z_low, z_up = self.shape.surfaces(self.rotation, x, y)
        miss = np.isnan(z_low) | np.isnan(z_up)
        self.z[LOWER][jj, ii] = np.where(miss, np.inf, z_low)
        self.z[UPPER][jj, ii] = np.where(miss, -np.inf, z_up)
        self.rays += int(todo.sum())
        self.geometry_time += time.perf_counter() - start

    def gap(self, side: int, mask: np.ndarray) -> np.ndarray:
        """Gap (m) of ``side`` on the whole lattice: evaluated on ``mask``, +inf elsewhere."""
        self.ensure(mask)
        if side == LOWER:
            g = self.z[LOWER] - self.reference[LOWER]
        else:
            g = self.reference[UPPER] - self.z[UPPER]
        return np.where(mask, g, np.inf)

    # --- where contact is possible ------------------------------------------------------------
    def candidates(self, side: int, bound: float) -> np.ndarray:
        """Lattice mask of the cells whose gap may be below ``bound`` (m), from the scan."""
        g, allowance = self.coarse_gap[side], self.allowance[side]
        hit = (g - allowance) < bound
        hit = dilate(hit, 3)
        mask = np.zeros((self.cells, self.cells), dtype=bool)
        mask[np.ix_(self.coarse_index, self.coarse_index)] = hit
        k = 2 * self.stride + 1
        return dilate(mask, k)

    def floor_allowance(self, side: int) -> float:
        """The curvature allowance at the scan's lowest sample of ``side`` (m): the depth by
        which the true extreme may lie beyond the reference."""
        g = self.coarse_gap[side]
        k = np.unravel_index(np.argmin(g), g.shape)
        return float(self.allowance[side][k])


def dilate(mask: np.ndarray, k: int) -> np.ndarray:
    """``mask`` (bool) dilated by a k x k square (k odd), nothing beyond its edges: the same as
    ``ndimage.binary_dilation`` with that structure, as two running maxima along the axes
    (k operations per cell instead of k², a tenth of the time on a 321² lattice, k = 9)."""
    out = ndimage.maximum_filter1d(np.asarray(mask, dtype=np.uint8), k, axis=0, mode="constant")
    return ndimage.maximum_filter1d(out, k, axis=1, mode="constant").astype(bool)


def _allowance(g: np.ndarray) -> np.ndarray:
    """Half the largest second difference (along x, y and both diagonals) of the coarse gap at
    each sample, >= 0. For a quadratic surface the dip below a sample within half a sample
    spacing in x and y is at most a quarter of the second difference (reached diagonally), so
    this bounds the dip of a smooth surface between samples with a factor 2."""
    big = np.where(np.isfinite(g), g, np.nan)
    padded = np.pad(big, 1, constant_values=np.nan)
    c = padded[1:-1, 1:-1]
    out = np.zeros_like(g)
    for (a0, a1), (b0, b1) in (((1, 0), (1, 2)), ((0, 1), (2, 1)), ((0, 0), (2, 2)),
                               ((0, 2), (2, 0))):
        ny, nx = c.shape
        s = padded[a0:a0 + ny, a1:a1 + nx] + padded[b0:b0 + ny, b1:b1 + nx] - 2.0 * c
        out = np.fmax(out, np.where(np.isnan(s), 0.0, 0.5 * s))
    return np.where(np.isfinite(g), np.maximum(out, 0.0), 0.0)
