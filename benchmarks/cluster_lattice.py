"""A periodic square array of nearly identical spheres between the plates, solved by
``thirdbody.network.cluster.solve_cluster``: how the cluster solver scales with the number of
particles, and where it stops converging (issue 25).

Each sphere (R = 1 mm times 1 + spread·N(0, 1), E = 1 GPa, ν = 0.3) stands on the lower plate at
the nodes of an n × n square lattice of spacing 2R(1 + gap) in a periodic box of n times the
spacing; the upper plate presses with F_N = 0.5 N per particle; μ = 0.3 at the plates and
between the particles. For each n the script prints the contacts, the Newton passes, the BEM
solves and the wall time, or the solver's own error (a box of 2 × 2 is refused: a pair could
meet through two images). Run:

    .venv/bin/python benchmarks/cluster_lattice.py --sizes 3 4 6 --spread 5e-4 --gap 2e-4
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import thirdbody as tb
from thirdbody.network import Body
from thirdbody.network.cluster import ClusterConvergenceError, ClusterNumerics, solve_cluster
from thirdbody.shapes import Sphere

R = 1e-3        # m
MATERIAL = tb.Material(1e9, 0.3)


def lattice(n: int, spread: float, gap: float, seed: int = 1) -> tuple[list[Body], float]:
    """The spheres of an n × n lattice standing on the lower plate, and the box side (m)."""
    rng = np.random.default_rng(seed)
    spacing = 2 * R * (1 + gap)
    bodies = []
    for i in range(n):
        for j in range(n):
            r = R * (1 + spread * rng.standard_normal())
            bodies.append(Body(Sphere(r), MATERIAL,
                               centre=(spacing * (i + 0.5), spacing * (j + 0.5), r)))
    return bodies, n * spacing


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 4, 6])
    parser.add_argument("--spread", type=float, default=5e-4, help="relative std of R")
    parser.add_argument("--gap", type=float, default=2e-4,
                        help="lattice gap / 2R (below 0: pressed in; write --gap=-1e-3)")
    parser.add_argument("--resolution", type=float, default=20.0)
    args = parser.parse_args(argv)
    for n in args.sizes:
        bodies, side = lattice(n, args.spread, args.gap)
        start = time.perf_counter()
        try:
            result = solve_cluster(bodies, mu_up=0.3, mu_low=0.3, mu_pp=0.3,
                                   force=0.5 * n * n, box=(side, side),
                                   numerics=ClusterNumerics(resolution=args.resolution,
                                                            tol=1e-5))
        except (ClusterConvergenceError, ValueError) as exc:
            print(f"{n * n:4d} particles: not converged after "
                  f"{time.perf_counter() - start:.1f} s: {exc}")
            continue
        print(f"{n * n:4d} particles: {len(result.contacts)} contacts, "
              f"{result.iterations} passes, {result.bem_solves} BEM solves, "
              f"{time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
