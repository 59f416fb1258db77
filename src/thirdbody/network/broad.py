"""Broad phase: the pairs of bodies whose bounding spheres overlap (docs/methods/design.md
§3c).

Each body is enclosed in the sphere of radius ``shape.size`` about its centroid (the largest
centroid-surface distance), so two bodies can only touch when their centres are at most
``r_i + r_j`` apart. The pairs are found with a KD-tree (``scipy.spatial.cKDTree``), in
O(n log n) rather than by testing all n(n-1)/2 pairs.

A periodic box (the representative volume of a layer) is periodic in x and y, not in z: a body
near one side meets the images of those near the other. Each pair then comes with the shift,
a multiple of the box sides, to add to body j's centre so that it is the nearest image of j
(the minimum image convention, valid because the box is at least twice the largest cut-off,
r_i + r_j; smaller boxes are refused).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["CandidatePairs", "candidate_pairs"]


@dataclass(frozen=True, eq=False)
class CandidatePairs:
    """Pairs (i, j), i < j, whose bounding spheres overlap, sorted by (i, j).

    Attributes
    ----------
    pairs : (k, 2) int array
        Body indices, i < j.
    shifts : (k, 3) array
        World vector (m) to add to body j's centre: the image of j that meets i. Zero without a
        periodic box; otherwise (m_x L_x, m_y L_y, 0) with integers m.
    """

    pairs: np.ndarray
    shifts: np.ndarray

    def __len__(self) -> int:
        return int(self.pairs.shape[0])

    def __iter__(self):
        for (i, j), s in zip(self.pairs, self.shifts, strict=True):
            yield int(i), int(j), s.copy()


def _validated(centres, radii, box):
    c = np.asarray(centres, dtype=float)
    if c.ndim != 2 or c.shape[1] != 3 or not np.isfinite(c).all():
        raise ValueError(f"centres must be a finite (n, 3) array in m, got shape {c.shape}")
    r = np.asarray(radii, dtype=float)
    if r.shape != (c.shape[0],) or not np.isfinite(r).all() or (r <= 0).any():
        raise ValueError(f"radii must be {c.shape[0]} finite numbers > 0 m (one per centre), "
                         f"got shape {r.shape}")
    if box is None:
        return c, r, None
    b = np.asarray(box, dtype=float)
    if b.shape != (2,) or not np.isfinite(b).all() or (b <= 0).any():
        raise ValueError(f"box must be two finite lengths (L_x, L_y) > 0 m, got {box!r}")
    cutoff = 2.0 * float(r.max()) if r.size else 0.0
    if b.min() < 2.0 * cutoff:
        raise ValueError(f"box {tuple(b)} m is smaller than twice the largest contact distance "
                         f"2 r_max = {cutoff:.6g} m: a pair could meet through two images")
    return c, r, b


def candidate_pairs(centres, radii, box=None) -> CandidatePairs:
    """The pairs of bounding spheres that overlap or touch: |c_j + shift − c_i| <= r_i + r_j.

    Parameters
    ----------
    centres : (n, 3) array
        World positions of the centroids, m.
    radii : (n,) array
        Bounding-sphere radii (``shape.size``), m, > 0.
    box : (L_x, L_y), optional
        Periodic box sides in x and y, m (z is not periodic). Centres may lie outside
        [0, L): they are wrapped. Each side must be at least twice the largest r_i + r_j.

    Returns
    -------
    CandidatePairs
    """
    c, r, b = _validated(centres, radii, box)
    n = c.shape[0]
    empty = CandidatePairs(np.zeros((0, 2), dtype=np.int64), np.zeros((0, 3)))
    if n < 2:
        return empty
    r_max = float(r.max())
    if b is None:
        tree = cKDTree(c)
        points = c
    else:
        # a box periodic in x and y; in z a period long enough that nothing meets its image
        low = c[:, 2].min()
        span = float(c[:, 2].max() - low)
        period_z = 2.0 * (span + 2.0 * r_max) + 1.0
        points = np.column_stack([np.mod(c[:, 0], b[0]), np.mod(c[:, 1], b[1]), c[:, 2] - low])
        # mod can round up to the period itself, which cKDTree refuses
        points[:, 0] = np.where(points[:, 0] >= b[0], 0.0, points[:, 0])
        points[:, 1] = np.where(points[:, 1] >= b[1], 0.0, points[:, 1])
        tree = cKDTree(points, boxsize=(b[0], b[1], period_z))
    # every neighbour within r_i + r_max, then the exact test with r_i + r_j
    found = tree.query_ball_point(points, r + r_max)
    ii = np.repeat(np.arange(n), [len(f) for f in found])
    jj = np.fromiter((j for f in found for j in f), dtype=np.int64, count=ii.size)
    keep = ii < jj
    ii, jj = ii[keep], jj[keep]
    d = c[jj] - c[ii]
    shifts = np.zeros((ii.size, 3))
    if b is not None:
        shifts[:, :2] = -b * np.round(d[:, :2] / b)
        d = d + shifts
    touching = np.einsum("ij,ij->i", d, d) <= (r[ii] + r[jj]) ** 2
    ii, jj, shifts = ii[touching], jj[touching], shifts[touching]
    order = np.lexsort((jj, ii))
    if not order.size:
        return empty
    return CandidatePairs(np.column_stack([ii, jj])[order].astype(np.int64), shifts[order])
