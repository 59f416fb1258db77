"""Tangential steps on the normal benchmark's hard contacts: CG iterations, residual and time.

For each case of ``normal_contact.py`` (long ellipse, two spots, rough sphere) and each N, the
frictionless normal solution under W = 1 N is followed by one partial-slip step with μ = 0.3:
Q = 0.5 μW along x, and Q = 0.35 μW along both x and y. thirdbody only (no peer solves these
free-space partial-slip problems at ν > 0, see ``tangential_cattaneo.py``); one thread.

    python benchmarks/tangential_hard.py [--sizes 128 256 512] [--cases ...]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "THIRDBODY_WORKERS"):
    os.environ[_var] = "1"

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import thirdbody as tb  # noqa: E402
from normal_contact import E_YOUNG, FORCE, NU, make_problem  # noqa: E402

MU = 0.3


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512])
    ap.add_argument("--cases", nargs="+", default=["ellipse10", "two_spots", "rough"])
    args = ap.parse_args(argv)
    mat = tb.Material(E_YOUNG, NU)
    print(f"{'case':<10} {'N':>5}  {'Q':<10} {'CG its':>6} {'residual':>9} {'time s':>8}")
    for case in args.cases:
        for n in args.sizes:
            prob = make_problem(case, n)
            normal = tb.solve_normal(prob["gap"], tb.Grid(n, prob["h"]), mat, force=FORCE)
            for label, q in (("x", (0.5 * MU * FORCE, 0.0)),
                             ("diagonal", (0.35 * MU * FORCE, 0.35 * MU * FORCE))):
                start = time.perf_counter()
                step = tb.solve_tangential(normal, MU, force=q)
                elapsed = time.perf_counter() - start
                print(f"{case:<10} {n:5d}  {label:<10} {step.iterations:6d} "
                      f"{step.residual:9.1e} {elapsed:8.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
