"""Narrow phase: the common normal and the closest points of two bodies, from vertical rays only.

The method uses nothing of a shape but :meth:`Shape.surfaces` (the lowest and highest heights
along vertical rays at an orientation), so it treats spheres, ellipsoids, potatoes and meshes
alike, in any orientation:

1. **Frame.** With a normal estimate n (first the direction between the centroids), both bodies
   are turned so that n is vertical (:func:`~thirdbody.network.frame.contact_frame`): a below,
   b above. The vertical gap g(x, y) = z_low,b − z_up,a is scanned on the common footprint
   (the intersection of the two bounding discs, about 48 samples across and four per feature
   length); its lowest sample starts the local search.
2. **Local search.** Around the current point the two surfaces are modelled by quadratics from
   a 3 x 3 stencil of rays (central differences: slopes g_a, g_b, Hessians H_a, H_b). The model
   gives in one linear solve the two points where the surfaces have parallel normals and the
   segment joining them lies along that normal (the definition of the common normal):
   ∇z_a(ξ_a) = ∇z_b(ξ_b) = s and ξ_b − ξ_a = −G s, G the gap between them, i.e.
   (H_a − H_b + G H_b H_a) ξ_a = g_b − g_a − G H_b g_a. The normal becomes (−s, 1) normalised,
   the frame is rebuilt about it at the new midpoint and the stencil shrinks; the iteration stops
   when the slope s and the steps vanish (Newton's method on the model: quadratic convergence
   for smooth surfaces). At the fixed point the vertical is the common normal, the gap at the
   origin is the signed separation, and the two surface points are the closest points.
3. **Every minimum.** In the final frame the footprint is scanned again; a sample lower than
   the separation found, or a sample whose gap minus a curvature allowance (half its largest
   second difference) is, is searched locally, and if it leads to a lower minimum of the gap
   the iteration restarts there. For non-convex bodies the result is the deepest of the local
   minima; the contact window (:mod:`~thirdbody.network.contact`) takes every cell below its
   bound, so shallower spots are not lost. Two convex bodies (ellipsoids) have a convex
   vertical gap, whose one minimum is the one found: they are not rescanned.

Started ``near`` a known contact point (the cluster solver's last pass), the local search
begins there at its smallest stencil, without the first scan.

For convex bodies that do not overlap this is the distance between them (every vertical segment
from a to b is at least as long as the shortest one); for overlapping ones it is the common
normal through the deepest overlap, the separation is then negative.

Faceted meshes have no curvature inside a facet: their stencil spans at least three edges, so
the normal is a smoothed one, accurate to about the facet angle (refine the mesh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .body import Body
from .frame import Seen, contact_frame, seen_gap

__all__ = ["Approach", "closest_approach"]

#: coarse samples across the smaller body's footprint diameter (at most)
SCAN_SAMPLES = 48
_MAX_RESTARTS = 4


@dataclass(frozen=True, eq=False)
class Approach:
    """The closest approach of two bodies a and b.

    Attributes
    ----------
    normal : (3,) array
        Unit common normal at the closest points, world frame, pointing from a to b.
    point_a, point_b : (3,) arrays
        The closest points on a's and on b's surface, world frame, m.
    separation : float
        Signed distance from point_a to point_b along ``normal``, m: > 0 apart, 0 touching,
        < 0 the undeformed bodies overlap (the rigid approach is −separation).
    iterations : int
        Iterations of the local search (all restarts).
    slope : float
        The remaining slope |s| of the surfaces in the final frame (rad): the angle between
        ``normal`` and the surfaces' own normals at the closest points.
    converged : bool
        The local search met its tolerance (a faceted mesh may stop at its facet angle).
    """

    normal: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    separation: float
    iterations: int
    slope: float
    converged: bool

    @property
    def midpoint(self) -> np.ndarray:
        """Midpoint of the closest points, world frame, m (the contact frame's origin)."""
        return 0.5 * (self.point_a + self.point_b)

    @property
    def frame(self):
        """World -> contact-frame rotation (:func:`~thirdbody.network.frame.contact_frame`)."""
        return contact_frame(self.normal)


def _smoothing(body: Body) -> float:
    """The shortest length (m) over which the body's surface heights may be differentiated:
    three facet edges for a mesh, zero for an analytic shape."""
    edge = getattr(body.shape, "max_edge", 0.0)
    return 3.0 * float(edge) if edge else 0.0


def _scan_spacing(a: Body, b: Body) -> float:
    size = min(a.size, b.size)
    feature = min(a.shape.feature_length, b.shape.feature_length)
    return min(2.0 * size / SCAN_SAMPLES, feature / 4.0)


@dataclass
class _Scan:
    x: np.ndarray       # (nx,)
    y: np.ndarray       # (ny,)
    gap: np.ndarray     # (ny, nx), +inf where a ray misses a body
    allowance: np.ndarray


def footprint_box(a: Body, b: Body, frame, origin) -> tuple[float, float, float, float] | None:
    """The frame rectangle (x0, x1, y0, y1), m, holding every vertical ray that can meet both
    bodies (the intersection of their bounding discs' boxes), or None if empty. ``frame``: the
    world -> frame rotation, or its matrix."""
    F = frame if isinstance(frame, np.ndarray) else frame.as_matrix()
    ca = F @ (a.centre - origin)
    cb = F @ (b.centre - origin)
    x0, x1 = max(ca[0] - a.size, cb[0] - b.size), min(ca[0] + a.size, cb[0] + b.size)
    y0, y1 = max(ca[1] - a.size, cb[1] - b.size), min(ca[1] + a.size, cb[1] + b.size)
    if x0 >= x1 or y0 >= y1:
        return None
    return x0, x1, y0, y1


def allowance(g: np.ndarray) -> np.ndarray:
    """Half the largest second difference (along x, y and both diagonals) of sampled gaps at
    each sample, >= 0 (0 where a neighbour is missing): a bound, with a factor 2 for a smooth
    surface, on how far the gap can dip below a sample between it and its neighbours."""
    finite = np.where(np.isfinite(g), g, np.nan)
    padded = np.pad(finite, 1, constant_values=np.nan)
    c = padded[1:-1, 1:-1]
    ny, nx = c.shape
    out = np.zeros_like(c)
    for (a0, a1), (b0, b1) in (((1, 0), (1, 2)), ((0, 1), (2, 1)), ((0, 0), (2, 2)),
                               ((0, 2), (2, 0))):
        second = padded[a0:a0 + ny, a1:a1 + nx] + padded[b0:b0 + ny, b1:b1 + nx] - 2.0 * c
        out = np.fmax(out, np.where(np.isnan(second), 0.0, 0.5 * second))
    return np.where(np.isfinite(g), np.maximum(out, 0.0), 0.0)


class _Frame:
    """The contact frame about a normal (:func:`contact_frame`) with its matrices: every product
    has the bits of the ``Rotation`` method it replaces (``R.apply(v)`` is ``R.as_matrix() @ v``
    bit for bit), without scipy's overhead per call."""

    __slots__ = ("_back", "matrix", "rotation")

    def __init__(self, normal) -> None:
        self.rotation = contact_frame(normal)
        self.matrix = self.rotation.as_matrix()
        self._back = None

    def back(self, v) -> np.ndarray:
        """Frame -> world: ``rotation.inv().apply(v)`` for a 3-vector."""
        if self._back is None:
            self._back = self.rotation.inv().as_matrix()
        return self._back @ np.asarray(v, dtype=float)


def _seen(a: Body, b: Body, F: _Frame, origin) -> tuple[Seen, Seen]:
    """Bodies a and b seen from the frame F at ``origin``."""
    return Seen(a, F.rotation, origin, F.matrix), Seen(b, F.rotation, origin, F.matrix)


def _scan(a: Body, b: Body, F: _Frame, origin, spacing: float) -> _Scan | None:
    box = footprint_box(a, b, F.matrix, origin)
    if box is None:
        return None
    x0, x1, y0, y1 = box
    # samples on multiples of the spacing, so that scans of nearby frames line up
    x = spacing * np.arange(math.floor(x0 / spacing), math.ceil(x1 / spacing) + 1)
    y = spacing * np.arange(math.floor(y0 / spacing), math.ceil(y1 / spacing) + 1)
    X, Y = np.meshgrid(x, y)
    gap = seen_gap(*_seen(a, b, F, origin), X, Y)
    if not np.isfinite(gap).any():
        return None
    return _Scan(x, y, gap, allowance(gap))


def _stencil(a: Body, b: Body, frame, origin, h: float):
    """Heights of a's upper and b's lower surface on the 3 x 3 stencil of step h (m) about the
    frame origin: slopes, Hessians and values at the centre, or None if a ray misses."""
    F = frame.as_matrix()
    return _stencil_seen(Seen(a, frame, origin, F), Seen(b, frame, origin, F), h)


def _stencil_seen(sa: Seen, sb: Seen, h: float):
    """:func:`_stencil` of two bodies seen from the frame."""
    offsets = np.array([-h, 0.0, h])
    X, Y = np.meshgrid(offsets, offsets)        # [j, i]: y index j, x index i
    _, za = sa.heights(X, Y)
    zb, _ = sb.heights(X, Y)
    if not (np.isfinite(za).all() and np.isfinite(zb).all()):
        return None
    out = []
    for z in (za, zb):
        grad = np.array([z[1, 2] - z[1, 0], z[2, 1] - z[0, 1]]) / (2 * h)
        hxx = (z[1, 2] - 2 * z[1, 1] + z[1, 0]) / h**2
        hyy = (z[2, 1] - 2 * z[1, 1] + z[0, 1]) / h**2
        hxy = (z[2, 2] - z[2, 0] - z[0, 2] + z[0, 0]) / (4 * h**2)
        out.append((float(z[1, 1]), grad, np.array([[hxx, hxy], [hxy, hyy]])))
    return out


def _model_step(sa, sb, trust: float):
    """Solve the quadratic model for the common-normal points (module docstring): returns
    (ξ_a, ξ_b, s, z_a(ξ_a), z_b(ξ_b)) in frame coordinates, steps limited to ``trust`` (m)."""
    (za0, ga, Ha), (zb0, gb, Hb) = sa, sb

    def za(xi):
        return za0 + ga @ xi + 0.5 * xi @ Ha @ xi

    def zb(xi):
        return zb0 + gb @ xi + 0.5 * xi @ Hb @ xi

    G = zb0 - za0
    xa = np.zeros(2)
    for _ in range(3):
        M = Ha - Hb + G * (Hb @ Ha)
        rhs = gb - ga - G * (Hb @ ga)
        xa = np.linalg.lstsq(M, rhs, rcond=1e-12)[0]
        length = float(np.linalg.norm(xa))
        if length > trust:
            xa *= trust / length
        s = ga + Ha @ xa
        xb = xa - G * s
        G = zb(xb) - za(xa)
    s = ga + Ha @ xa
    return xa, xb, s, za(xa), zb(xb)


def _local(a: Body, b: Body, normal: np.ndarray, origin: np.ndarray, h: float, tol: float,
           max_iter: int):
    """The local common-normal search from a normal and a frame origin near the contact.
    Returns (normal, origin, iterations, slope, converged) or None if the stencil leaves a
    body."""
    size = min(a.size, b.size)
    h_final = max(1e-5 * size, _smoothing(a), _smoothing(b))
    h = max(h, h_final)
    trust = 0.25 * size
    best = None
    for it in range(1, max_iter + 1):
        F = _Frame(normal)
        st = _stencil_seen(*_seen(a, b, F, origin), h)
        if st is None:
            if h <= h_final:
                return best
            h = max(0.5 * h, h_final)
            continue
        w, v = np.linalg.eigh(st[1][2] - st[0][2])
        if w[0] <= 0:
            # not a minimum of the gap here (a saddle or worse): go downhill along the
            # direction of negative curvature, keeping the normal
            down = v[:, 0] if (st[1][1] - st[0][1]) @ v[:, 0] <= 0 else -v[:, 0]
            origin = origin + F.back([*(max(h, 0.05 * size) * down), 0.0])
            h = max(h, min(0.05 * size, 4.0 * h))
            best = None
            continue
        xa, xb, s, za, zb = _model_step(*st, trust)
        slope = max(float(np.linalg.norm(st[0][1])), float(np.linalg.norm(st[1][1])))
        new_normal = F.back(np.array([-s[0], -s[1], 1.0]) / math.hypot(1.0, *s))
        mid = 0.5 * (np.array([*xa, za]) + np.array([*xb, zb]))
        new_origin = origin + F.back(mid)
        step = max(float(np.linalg.norm(xa)), float(np.linalg.norm(xb)))
        turn = float(np.linalg.norm(new_normal - normal))
        best = (normal, origin, it, slope, False)
        if h <= h_final and step <= tol * size and turn <= tol:
            return new_normal, new_origin, it, slope, True
        normal, origin = new_normal, new_origin
        # the stencil shrinks with the steps, down to the differentiation floor
        h = min(h, max(h_final, 4.0 * step, turn * size))
    return best


def _local_gap_minimum(a: Body, b: Body, F: _Frame, origin, x0: float, y0: float,
                       h: float,
                       floor: float, target: float,
                       max_iter: int = 30) -> tuple[float, float, float]:
    """Newton's method on the vertical gap alone, in a fixed frame, from (x0, y0), stopping as
    soon as the gap falls below ``target`` (m): returns the point (m) and the gap there (m)
    (used to test a scan sample for a deeper minimum)."""
    x, y = x0, y0
    seen = _seen(a, b, F, origin)
    best = (x, y, float(seen_gap(*seen, np.array(x), np.array(y))))
    for _ in range(max_iter):
        if best[2] < target:
            break
        offsets = np.array([-h, 0.0, h])
        X, Y = np.meshgrid(x + offsets, y + offsets)
        g = seen_gap(*seen, X, Y)
        if not np.isfinite(g).all():
            break
        k = np.unravel_index(np.argmin(g), g.shape)
        if g[k] < best[2]:
            best = (float(X[k]), float(Y[k]), float(g[k]))
        grad = np.array([g[1, 2] - g[1, 0], g[2, 1] - g[0, 1]]) / (2 * h)
        hxy = (g[2, 2] - g[2, 0] - g[0, 2] + g[0, 0]) / (4 * h * h)
        H = np.array([[(g[1, 2] - 2 * g[1, 1] + g[1, 0]) / h**2, hxy],
                      [hxy, (g[2, 1] - 2 * g[1, 1] + g[0, 1]) / h**2]])
        w, v = np.linalg.eigh(H)
        if w.min() > 0:
            step = -v @ ((v.T @ grad) / w)
            # the quadratic model's minimum, less an allowance for what it misses, stays
            # above the target: no deeper minimum here
            predicted = g[1, 1] + 0.5 * grad @ step
            if predicted - 0.25 * h * h * w.max() > target:
                break
        else:                                   # not convex here: go downhill by one stencil
            step = -grad / max(float(np.linalg.norm(grad)), 1e-300) * h
        length = float(np.linalg.norm(step))
        if length > 2 * h:
            step *= 2 * h / length
        x, y = x + step[0], y + step[1]
        if length < 1e-3 * h:
            if h <= floor:
                break
            h = max(0.25 * h, floor)
    g_end = float(seen_gap(*seen, np.array(x), np.array(y)))
    if g_end < best[2]:
        best = (x, y, g_end)
    return best


def closest_approach(a: Body, b: Body, *, tol: float = 1e-10, max_iter: int = 60,
                     normal=None, near=None, local: bool = False) -> Approach | None:
    """The common normal and closest points of bodies a and b (module docstring).

    Parameters
    ----------
    a, b : Body
    tol : float
        Convergence of the local search: relative step (to the smaller body's size) and normal
        change (rad).
    max_iter : int
        Iterations of one local search.
    normal : (3,) array, optional
        A first estimate of the normal from a to b (e.g. the previous step's); default: the
        direction from a's centroid to b's.
    near : (3,) array, optional
        A world point near the closest points (m; e.g. their midpoint at nearby poses) with
        ``normal``: the local search starts there instead of at the lowest sample of a scan of
        the footprint. Convex bodies (ellipsoids) have one minimum of the gap, so that is all;
        other shapes are still scanned for a deeper one (step 3). If the search from there
        fails, the scan is done as without ``near``.
    local : bool
        With ``normal`` and ``near``: the local search from there only, no scan for a deeper
        minimum and no other start (one contact of a pair that touches in several places facing
        different ways: :mod:`thirdbody.network.contact`). None if it fails.

    Returns
    -------
    Approach, or None when the bodies cannot touch: their bounding spheres (radius
    ``shape.size``) are apart, or no vertical ray of the frame meets both.
    """
    if not isinstance(a, Body) or not isinstance(b, Body):
        raise TypeError("closest_approach takes two Body objects")
    if not (tol > 0):
        raise ValueError(f"tol must be > 0, got {tol!r}")
    d = b.centre - a.centre
    distance = float(np.linalg.norm(d))
    if distance > (a.size + b.size) * (1.0 + 1e-12):
        return None
    towards = d / distance if distance > 0 else np.array([0.0, 0.0, 1.0])
    if local:
        if normal is None or near is None:
            raise ValueError("a local search needs a normal and a point near the contact")
        guess = np.asarray(normal, dtype=float).reshape(3)
        return _search(a, b, guess / np.linalg.norm(guess), tol, max_iter,
                       np.asarray(near, dtype=float).reshape(3), local=True)
    starts = [(towards, None)]
    if normal is not None:
        guess = np.asarray(normal, dtype=float).reshape(-1)
        length = float(np.linalg.norm(guess)) if guess.shape == (3,) else 0.0
        # a guess pointing away from b is no guess
        if math.isfinite(length) and length > 0 and guess @ towards > 0:
            starts.insert(0, (guess / length, None))
            if near is not None:
                point = np.asarray(near, dtype=float).reshape(-1)
                if point.shape == (3,) and np.isfinite(point).all():
                    starts.insert(0, (guess / length, point))
    best = None
    for n, point in starts:
        found = _search(a, b, n, tol, max_iter, point)
        if found is not None and (best is None or (found.converged and not best.converged)):
            best = found
        if best is not None and best.converged:
            break
    return best


def _search(a: Body, b: Body, n: np.ndarray, tol: float, max_iter: int,
            near: np.ndarray | None = None, local: bool = False) -> Approach | None:
    """closest_approach from one first normal estimate ``n`` (and a world point ``near`` the
    contact to start the local search at, instead of a scan's lowest sample)."""
    spacing = _scan_spacing(a, b)
    F = _Frame(n)
    if near is None:
        origin = 0.5 * (a.centre + b.centre)
        scan = _scan(a, b, F, origin, spacing)
        if scan is None:
            return None
        j, i = np.unravel_index(np.argmin(scan.gap), scan.gap.shape)
        start = (float(scan.x[i]), float(scan.y[j]))
    else:
        origin, start = near, (0.0, 0.0)
    h_start = spacing if near is None else 0.0
    size = min(a.size, b.size)
    floor = max(1e-5 * size, _smoothing(a), _smoothing(b))
    # the vertical gap of two convex bodies is convex: its one minimum is the one found
    convex = a.shape._convex and b.shape._convex
    iterations = 0
    best: Approach | None = None
    for _ in range(_MAX_RESTARTS):
        origin_k = origin + F.back([start[0], start[1], 0.0])
        # from a point near the contact the stencil starts at its smallest step
        found = _local(a, b, n, origin_k, h_start, tol, max_iter)
        h_start = spacing
        if found is None:
            break
        n_k, origin_k, its, slope, converged = found
        iterations += its
        F_k = _Frame(n_k)
        sa, sb = _seen(a, b, F_k, origin_k)
        _, z_up = sa.heights(0.0, 0.0)
        z_low, _ = sb.heights(0.0, 0.0)
        z_up, z_low = float(z_up), float(z_low)
        candidate = Approach(
            normal=n_k, point_a=origin_k + F_k.back([0.0, 0.0, z_up]),
            point_b=origin_k + F_k.back([0.0, 0.0, z_low]),
            separation=z_low - z_up, iterations=iterations, slope=slope, converged=converged)
        if best is None or (candidate.converged, -candidate.separation) > \
                (best.converged, -best.separation):
            best = candidate
        if (convex and converged) or local:
            break
        # a deeper minimum elsewhere in this frame? (non-convex bodies)
        F, origin, n = F_k, candidate.midpoint, n_k
        scan = _scan(a, b, F, origin, spacing)
        deeper = _deeper_start(a, b, F, origin, scan, best.separation, spacing, floor)
        if deeper is None:
            break
        start = deeper
    if best is None:
        return None
    return Approach(best.normal, best.point_a, best.point_b, best.separation, iterations,
                    best.slope, best.converged)


def _deeper_start(a, b, F, origin, scan: _Scan | None, separation: float, spacing: float,
                  floor: float) -> tuple[float, float] | None:
    """A frame point from which the gap falls below ``separation`` (m), or None."""
    if scan is None:
        return None
    X, Y = np.meshgrid(scan.x, scan.y)
    near = np.hypot(X, Y) <= 1.5 * spacing
    margin = 1e-9 * max(abs(separation), spacing)
    # samples below the separation anywhere, and samples that may dip below it between
    # themselves and their neighbours away from the point found
    suspects = (scan.gap < separation - margin) | \
        (~near & (scan.gap - scan.allowance < separation - margin))
    if not suspects.any():
        return None
    # one start per connected group of suspects: its lowest sample
    labels, count = ndimage.label(suspects, structure=np.ones((3, 3), dtype=bool))
    starts = []
    for k in range(1, count + 1):
        group = labels == k
        j, i = np.unravel_index(np.argmin(np.where(group, scan.gap, np.inf)), group.shape)
        starts.append((float(scan.gap[j, i]), float(X[j, i]), float(Y[j, i])))
    target = separation - margin
    for _, x0, y0 in sorted(starts)[:8]:
        x, y, g = _local_gap_minimum(a, b, F, origin, x0, y0, spacing / 2,
                                     max(floor, 1e-3 * spacing), target)
        if g < target and math.hypot(x, y) > spacing:
            return x, y
    return None
