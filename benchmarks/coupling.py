"""Cost of normal-tangential coupling: one coupled load step against the uncoupled one.

Cases of ``normal_contact.py`` (circle, long ellipse, two spots, rough sphere), ν = 0.3
(β = 0.29), μ = 0.3, on N x N cells. Each case is loaded as a history: W = 0.9 N, then W = 1 N
(both with Q = 0), then the measured steps from that state:

* ``normal``: W from 0.9 N to 1 N with Q = 0 (Spence's inward slip under a growing load);
* ``shear``: Q = 0.5 μW along x at W = 1 N (a Cattaneo step);
* ``both``: from W = 0.9 N with Q = 0.45 μ N to W = 1 N with Q = 0.5 μ N (both grow, as the
  particle's demand grows with its load).

In the ``normal`` step the uncoupled tangential solve is trivial (no shear, no history), while the
coupled one solves Spence's partial slip: that ratio holds a problem the uncoupled step does not
have. ``floor`` is what any coupled method must at least do, over the uncoupled step: one
normal solve that sees the converged shear plus one tangential solve under the converged
pressure (with the step's history, started as the uncoupled step starts them); ``tangential``
is that tangential solve alone: no coupled method can beat it, since every one of them has to
solve the coupled step's friction problem (in the ``normal`` step, Spence's slip annulus, which
the uncoupled step does not have). ``coupled / floor`` is the coupled step over its floor (both
measured here), the yardstick of the coupled method itself.

Uncoupled means :func:`solve_normal` then :func:`solve_tangential` with the previous step's
history, as the particle runs them; coupled means :func:`solve_coupled` (Panagiotopoulos passes).
Times are the best of 3 in this process, one thread; the ratio is what to read. Residuals are
recomputed here from the fields: the normal complementarity of the coupled gap
g + K_zz p + K_zt τ − δ, and |ΣτΔA − Q|/Q.

    python benchmarks/coupling.py [--sizes 128 256] [--cases ...] [--out benchmarks/results]

``--compare-start``: the ``normal`` step only, started from the previous step stretched (what
:func:`solve_coupled` does under a growing normal load with no tangential load) against the
coarse passes (that predictor switched off), alternating in one process, CPU time
(``time.process_time``), best of 3, each over the floor.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "THIRDBODY_WORKERS"):
    os.environ[_var] = "1"

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

import thirdbody as tb  # noqa: E402
from normal_contact import E_YOUNG, NU, make_problem  # noqa: E402
from thirdbody.bem import (  # noqa: E402
    ElasticPair,
    coupled,
    coupling_operator,
    normal_operator,
    solve_coupled,
)

MU = 0.3
REPEAT = 3


def _uncoupled(gap, grid, mat, force, q, previous):
    normal = tb.solve_normal(gap, grid, mat, force=force,
                             initial=None if previous is None else previous.normal.pressure)
    return tb.solve_tangential(normal, MU, force=(q, 0.0), previous=previous)


def _coupled(gap, grid, mat, force, q, previous):
    return solve_coupled(gap, grid, mat, MU, force=force, tangential_force=(q, 0.0),
                         previous=previous)


def _problem(case: str, n: int) -> dict:
    """``normal_contact``'s cases, and two harder ones for the box the passes run on:
    ``ellipse10_30deg``, the 10:1 ellipse turned by 30° (its bounding box is far larger than
    the contact), and ``filling``, a circle whose contact spans 80 % of the window (no box)."""
    if case == "ellipse10_30deg":
        prob = make_problem("ellipse10", n)
        c = (np.arange(n) - (n - 1) / 2) * prob["h"]
        x, y = c[None, :], c[:, None]
        u = x * np.cos(np.pi / 6) + y * np.sin(np.pi / 6)
        v = -x * np.sin(np.pi / 6) + y * np.cos(np.pi / 6)
        return {**prob, "gap": u**2 / (2 * 0.2) + v**2 / (2 * 0.02)}
    if case == "filling":
        prob = make_problem("circle", n)
        # the same sphere on a window 0.3125 as wide: a = 0.4 of the window, not 1/8
        return {**prob, "h": prob["h"] * 0.3125, "gap": prob["gap"] * 0.3125**2}
    return make_problem(case, n)


def _normal_half(gap, grid, mat, force, previous, converged):
    return tb.solve_normal(gap, grid, mat, force=force, initial=previous.normal.pressure,
                           traction=converged.traction)


def _tangential_half(q, previous, converged):
    return tb.solve_tangential(converged.normal, MU, force=(q, 0.0), previous=previous,
                               coupling=True)


def _residual(step, gap, pair) -> float:
    """Normal complementarity of the coupled problem, from the fields, relative to max u."""
    n = step.normal
    grid = n.grid
    u = normal_operator(grid.shape, grid.spacing, pair.E_star)(n.pressure)
    u = u + coupling_operator(grid.shape, grid.spacing, pair.coupling_modulus).normal(
        step.traction)
    s = np.where(np.isfinite(gap), gap, 1.0) + u - n.approach
    inside = np.abs(s[n.contact]).max()
    outside = np.maximum(-s[~n.contact], 0).max()
    return float(max(inside, outside) / np.abs(u).max())


def _best(fn, *args, clock=time.perf_counter):
    """The best of :data:`REPEAT` calls by ``clock`` (s), and the last call's result."""
    best, out = np.inf, None
    for _ in range(REPEAT):
        t0 = clock()
        out = fn(*args)
        best = min(best, clock() - t0)
    return best, out


def _cpu_best(fn, *args):
    return _best(fn, *args, clock=time.process_time)


def _compare_start(cases, sizes, mat) -> None:
    """The ``normal`` step from the stretched previous step against the coarse start."""
    stretched = coupled._normal_growth
    print("| case | N | floor s | coarse start / floor (passes) | stretched / floor (passes) "
          "| max Δp / max p |\n|---|---|---|---|---|---|")
    for case in cases:
        for n in sizes:
            prob = _problem(case, n)
            grid = tb.Grid(n, prob["h"])
            gap = prob["gap"]
            coupled._normal_growth = lambda *args: False
            first = _coupled(gap, grid, mat, 0.9, 0.0, None)
            best, out = {False: np.inf, True: np.inf}, {}
            for _ in range(REPEAT):
                for on in (False, True):
                    coupled._normal_growth = stretched if on else (lambda *args: False)
                    t0 = time.process_time()
                    out[on] = _coupled(gap, grid, mat, 1.0, 0.0, first)
                    best[on] = min(best[on], time.process_time() - t0)
            coupled._normal_growth = stretched
            t_n, _ = _cpu_best(_normal_half, gap, grid, mat, 1.0, first, out[False])
            t_t, _ = _cpu_best(_tangential_half, 0.0, first, out[False])
            floor = t_n + t_t
            p = out[False].normal.pressure
            dp = np.abs(out[True].normal.pressure - p).max() / p.max()
            print(f"| {case} | {n} | {floor:.3f} | {best[False] / floor:.2f} "
                  f"({out[False].coupling_passes}) | {best[True] / floor:.2f} "
                  f"({out[True].coupling_passes}) | {dp:.1e} |", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--cases", nargs="+", default=["circle", "ellipse10", "two_spots", "rough",
                                                   "ellipse10_30deg", "filling"])
    ap.add_argument("--out", type=Path, default=None, help="write coupling.md here")
    ap.add_argument("--compare-start", action="store_true",
                    help="the normal step: stretched previous step against the coarse start")
    args = ap.parse_args(argv)
    mat = tb.Material(E_YOUNG, NU)
    if args.compare_start:
        _compare_start(args.cases, args.sizes, mat)
        return 0
    pair = ElasticPair.rigid_plate(mat)
    rows = []
    head = ("| case | N | step | uncoupled s | coupled s | ratio | floor | coupled / floor "
            "| passes | tangential | coupled residual | shift of x̄ / a |\n" + "|---" * 12 + "|")
    print(head)
    for case in args.cases:
        for n in args.sizes:
            prob = _problem(case, n)
            grid = tb.Grid(n, prob["h"])
            gap = prob["gap"]
            for name, fn in (("u", _uncoupled), ("c", _coupled)):
                first = fn(gap, grid, mat, 0.9, 0.0, None)
                base = fn(gap, grid, mat, 1.0, 0.0, first)
                if name == "u":
                    u_first, u_base = first, base
                else:
                    c_first, c_base = first, base
            u_mixed = _uncoupled(gap, grid, mat, 0.9, 0.45 * MU, u_first)
            c_mixed = _coupled(gap, grid, mat, 0.9, 0.45 * MU, c_first)
            for label, force, q, (u_prev, c_prev) in (
                    ("normal", 1.0, 0.0, (u_first, c_first)),
                    ("shear", 1.0, 0.5 * MU, (u_base, c_base)),
                    ("both", 1.0, 0.5 * MU, (u_mixed, c_mixed))):
                t_u, u = _best(_uncoupled, gap, grid, mat, force, q, u_prev)
                t_c, c = _best(_coupled, gap, grid, mat, force, q, c_prev)
                # the floor of any coupled method: one normal solve that sees the converged
                # shear and one tangential solve under the converged pressure, each started as
                # the uncoupled step starts them
                t_n, _ = _best(_normal_half, gap, grid, mat, force, c_prev, c)
                t_t, _ = _best(_tangential_half, q, c_prev, c)
                X, _ = grid.mesh()
                a = np.sqrt(c.normal.area / np.pi)
                shift = ((c.normal.pressure * X).sum() / c.normal.pressure.sum()
                         - (u.normal.pressure * X).sum() / u.normal.pressure.sum()) / a
                line = (f"| {case} | {n} | {label} | {t_u:.3f} | {t_c:.3f} | {t_c / t_u:.1f} "
                        f"| {(t_n + t_t) / t_u:.1f} | {t_c / (t_n + t_t):.2f} "
                        f"| {c.coupling_passes} | {t_t / t_u:.1f} "
                        f"| {_residual(c, gap, pair):.1e} | {shift:+.4f} |")
                print(line, flush=True)
                rows.append(line)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        text = (f"# Coupled step against uncoupled step\n\n`python benchmarks/coupling.py "
                f"--sizes {' '.join(map(str, args.sizes))}`; ν = {NU}, μ = {MU}, one thread, best "
                f"of {REPEAT}.\n\n{head}\n" + "\n".join(rows) + "\n")
        (args.out / "coupling.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
