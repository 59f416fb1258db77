"""Vectorised root finding along many rays at once (private helpers of ``thirdbody.shapes``).

A ray function ``fun(idx, z)`` evaluates an implicit function (negative inside the body) on the
rays ``idx`` (integer array) at the abscissae ``z`` (same shape as ``idx``, or broadcastable).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
RayFunction = Callable[[IntArray, FloatArray], FloatArray]

_GOLDEN = 0.5 * (3.0 - np.sqrt(5.0))


def illinois(
    fun: RayFunction,
    idx: IntArray,
    a: FloatArray,
    b: FloatArray,
    fa: FloatArray,
    fb: FloatArray,
    xtol: float,
    maxiter: int = 200,
) -> FloatArray:
    """Refine brackets ``[a, b]`` with ``fa·fb <= 0`` to width <= ``xtol`` (Illinois method).

    The Illinois modification of regula falsi (Dowell & Jarratt 1971) keeps the bracket and
    converges superlinearly; every fourth step is a bisection as a safeguard. All rays are
    processed together; converged ones drop out. Returns the root estimate of each bracket.
    """
    a = np.array(a, dtype=float)
    b = np.array(b, dtype=float)
    fa = np.array(fa, dtype=float)
    fb = np.array(fb, dtype=float)
    root = np.where(np.abs(fa) <= np.abs(fb), a, b)
    act = np.flatnonzero((np.abs(b - a) > xtol) & (fa != 0.0) & (fb != 0.0))
    for it in range(maxiter):
        if act.size == 0:
            break
        aa, bb, ffa, ffb = a[act], b[act], fa[act], fb[act]
        with np.errstate(divide="ignore", invalid="ignore"):
            c = bb - ffb * (bb - aa) / (ffb - ffa)
        lo, hi = np.minimum(aa, bb), np.maximum(aa, bb)
        bad = ~((c > lo) & (c < hi))
        if it % 4 == 3:
            bad[:] = True
        c = np.where(bad, 0.5 * (aa + bb), c)
        fc = fun(idx[act], c)
        flip = np.signbit(fc) != np.signbit(ffb)
        # Illinois: if the new point falls on the same side as b, halve the stale f(a).
        new_a = np.where(flip, bb, aa)
        # (After a bisection step the retained value is left as it is.)
        new_fa = np.where(flip, ffb, np.where(bad, ffa, 0.5 * ffa))
        a[act], fa[act], b[act], fb[act] = new_a, new_fa, c, fc
        root[act] = c
        keep = (np.abs(c - new_a) > xtol) & (fc != 0.0)
        act = act[keep]
    return root


def golden_minimum(
    fun: RayFunction, idx: IntArray, a: FloatArray, b: FloatArray, iterations: int = 60
) -> tuple[FloatArray, FloatArray]:
    """Vectorised golden-section search for the minimum of each ray function on ``[a, b]``.

    Returns ``(z, f)`` of the lowest value seen. Stops early for rays where a negative value has
    been found (callers only need to know whether the function dips below zero, and where).
    """
    a = np.array(a, dtype=float)
    b = np.array(b, dtype=float)
    x1 = a + _GOLDEN * (b - a)
    x2 = b - _GOLDEN * (b - a)
    f1 = fun(idx, x1)
    f2 = fun(idx, x2)
    best_z = np.where(f1 <= f2, x1, x2)
    best_f = np.minimum(f1, f2)
    act = np.flatnonzero(best_f >= 0.0)
    for _ in range(iterations):
        if act.size == 0:
            break
        left = f1[act] <= f2[act]
        aa, bb = a[act], b[act]
        bb = np.where(left, x2[act], bb)
        aa = np.where(left, aa, x1[act])
        nx1 = np.where(left, aa + _GOLDEN * (bb - aa), x2[act])
        nx2 = np.where(left, x1[act], bb - _GOLDEN * (bb - aa))
        znew = np.where(left, nx1, nx2)
        fnew = fun(idx[act], znew)
        nf1 = np.where(left, fnew, f2[act])
        nf2 = np.where(left, f1[act], fnew)
        a[act], b[act], x1[act], x2[act], f1[act], f2[act] = aa, bb, nx1, nx2, nf1, nf2
        better = fnew < best_f[act]
        best_z[act] = np.where(better, znew, best_z[act])
        best_f[act] = np.where(better, fnew, best_f[act])
        act = act[best_f[act] >= 0.0]
    return best_z, best_f


#: samples per coarse interval of :func:`_sample` (every fourth sample is evaluated first)
_COARSE_STRIDE = 4
#: safety factor on the Lipschitz bound when :func:`_sample` skips an interval
_SKIP_MARGIN = 1.0


def _sample(fun: RayFunction, rays: IntArray, z: FloatArray, lh: FloatArray) -> FloatArray:
    """``fun`` on every ray at the abscissae ``z`` (m, n), or a stand-in where it cannot matter.

    Every fourth sample (and the last) is evaluated first. Between two such samples a and b each
    skipped sample lies within two spacings h of a or b, so with |f'| <= L (``lh`` = L h per
    ray) they are all > L h if min(f(a), f(b)) > 3 L h, and all < 0 if max(f(a), f(b)) < -2 L h.
    Such intervals (with a factor :data:`_SKIP_MARGIN` on L) are filled with +inf or -inf: the
    callers only look at the signs there and at sampled minima below L h, so they make the same
    decisions, from the same evaluated values, as with every sample evaluated. The other
    intervals, about the surface crossings, are evaluated in full, in one call of ``fun``
    (what it saves is in the docs' performance page).
    """
    m, n = z.shape
    coarse = np.unique(np.r_[np.arange(0, n, _COARSE_STRIDE), n - 1])
    f = np.empty((m, n))
    f[:, coarse] = fun(rays[:, None], z[:, coarse])
    fa, fb = f[:, coarse[:-1]], f[:, coarse[1:]]
    reach = _COARSE_STRIDE // 2          # spacings from a skipped sample to the nearer end
    lh = (_SKIP_MARGIN * lh)[:, None]
    outside = np.minimum(fa, fb) > (reach + 1) * lh
    inside = np.maximum(fa, fb) < -reach * lh
    # every skipped column with its interval: (column, interval index)
    cols = (coarse[:-1, None] + np.arange(1, _COARSE_STRIDE)[None, :]).ravel()
    owner = np.repeat(np.arange(coarse.size - 1), _COARSE_STRIDE - 1)
    real = cols < coarse[1:][owner]              # the last interval may be shorter
    cols, owner = cols[real], owner[real]
    f[:, cols] = np.where(outside[:, owner], np.inf, np.where(inside[:, owner], -np.inf, np.nan))
    rr, cc = np.nonzero(~(outside | inside)[:, owner])
    if rr.size:
        f[rr, cols[cc]] = fun(rays[rr], z[rr, cols[cc]])
    return f


def extreme_roots(
    fun: RayFunction,
    z_start: FloatArray,
    z_end: FloatArray,
    n_samples: int,
    lipschitz: float,
    xtol: float,
) -> tuple[FloatArray, FloatArray]:
    """First and last roots of ``fun`` on ``[z_start, z_end]`` for every ray (NaN if none).

    ``fun`` must be positive (outside) at both ends and Lipschitz with constant ``lipschitz``
    along the rays. Each ray is sampled at ``n_samples`` equally spaced points. Sign changes
    bracket crossings; a sampled local minimum that is positive but within ``lipschitz·h`` of
    zero (h the sample spacing) may hide a thin sliver of body between samples, so it is
    searched with golden section and, when it dips below zero, yields two more brackets. The
    lowest and highest brackets are then refined by :func:`illinois` to ``xtol``.
    """
    m = z_start.shape[0]
    z_first = np.full(m, np.nan)
    z_last = np.full(m, np.nan)
    if m == 0:
        return z_first, z_last
    rays = np.arange(m)
    t = np.linspace(0.0, 1.0, n_samples)
    span = z_end - z_start
    z = z_start[:, None] + span[:, None] * t[None, :]
    step = span / (n_samples - 1)
    f = _sample(fun, rays, z, lipschitz * step)

    inside = f < 0.0
    if inside[:, 0].any() or inside[:, -1].any():
        raise RuntimeError("ray sampling range does not enclose the body")
    any_in = inside.any(axis=1)
    r_in = rays[any_in]
    j_first = np.argmax(inside[any_in], axis=1)
    j_last = n_samples - 1 - np.argmax(inside[any_in, ::-1], axis=1)
    # Brackets (ray, lower end, upper end, f at lower end, f at upper end).
    lo_r = [r_in]
    lo_a = [z[r_in, j_first - 1]]
    lo_b = [z[r_in, j_first]]
    lo_fa = [f[r_in, j_first - 1]]
    lo_fb = [f[r_in, j_first]]
    hi_r = [r_in]
    hi_a = [z[r_in, j_last]]
    hi_b = [z[r_in, j_last + 1]]
    hi_fa = [f[r_in, j_last]]
    hi_fb = [f[r_in, j_last + 1]]

    mid = f[:, 1:-1]
    cand = (mid > 0.0) & (mid <= f[:, :-2]) & (mid <= f[:, 2:]) & (mid < lipschitz * step[:, None])
    cr, ck = np.nonzero(cand)
    if cr.size:
        ck = ck + 1
        zm, fm = golden_minimum(fun, cr, z[cr, ck - 1], z[cr, ck + 1])
        dip = fm < 0.0
        cr, ck, zm, fm = cr[dip], ck[dip], zm[dip], fm[dip]
        lo_r.append(cr)
        lo_a.append(z[cr, ck - 1])
        lo_b.append(zm)
        lo_fa.append(f[cr, ck - 1])
        lo_fb.append(fm)
        hi_r.append(cr)
        hi_a.append(zm)
        hi_b.append(z[cr, ck + 1])
        hi_fa.append(fm)
        hi_fb.append(f[cr, ck + 1])

    def pick(
        rs: list[IntArray],
        aa: list[FloatArray],
        bb: list[FloatArray],
        fas: list[FloatArray],
        fbs: list[FloatArray],
        lowest: bool,
    ) -> tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Per ray, the bracket lowest in z (``lowest``) or highest in z."""
        r = np.concatenate(rs)
        a_ = np.concatenate(aa)
        b_ = np.concatenate(bb)
        fa_ = np.concatenate(fas)
        fb_ = np.concatenate(fbs)
        order = np.lexsort((a_ if lowest else -b_, r))
        r, a_, b_, fa_, fb_ = r[order], a_[order], b_[order], fa_[order], fb_[order]
        first = np.ones(r.size, dtype=bool)
        first[1:] = r[1:] != r[:-1]
        return r[first], a_[first], b_[first], fa_[first], fb_[first]

    lr, la, lb, lfa, lfb = pick(lo_r, lo_a, lo_b, lo_fa, lo_fb, lowest=True)
    hr, ha, hb, hfa, hfb = pick(hi_r, hi_a, hi_b, hi_fa, hi_fb, lowest=False)
    roots = illinois(
        fun,
        np.concatenate([lr, hr]),
        np.concatenate([la, ha]),
        np.concatenate([lb, hb]),
        np.concatenate([lfa, hfa]),
        np.concatenate([lfb, hfb]),
        xtol,
    )
    z_first[lr] = roots[: lr.size]
    z_last[hr] = roots[lr.size :]
    return z_first, z_last
