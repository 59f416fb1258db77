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

With ``--steps K`` the load is a compression program instead: F_N rises in K equal steps to
0.5 N per particle, each step started from the last one's poses, contact histories and gap (as
a run does). Per step it prints the passes, the BEM solves per contact, the wall time and its
shares (contact detection, BEM solves, the Newton model), and the particle contacts carrying
load; at the end the totals. A lattice touching at ``--gap 0`` with a spread of radii is a force
network: the larger spheres press their neighbours along oblique normals.

    .venv/bin/python benchmarks/cluster_lattice.py --sizes 8 --gap 0 --spread 5e-4 --steps 20

``--seed`` draws other radii; ``--first F`` loads the first step with F newtons a particle and
the others in equal steps from there to 0.5 N (a first step that presses the plate past the
spread of the heights: ``docs/methods/network.md``, how often the first step converges).

``--guess`` starts each step from the secant predictor a run uses (the last step's motion times
the ratio of the load increments: ``thirdbody.network.run._predicted``); ``--guess both`` runs
the program with and without it, alternating in one process, and prints the passes and CPU
seconds of each.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import thirdbody as tb
from thirdbody.loading import LoadStep
from thirdbody.network import Body
from thirdbody.network.cluster import ClusterConvergenceError, ClusterNumerics, solve_cluster
from thirdbody.network.run import _LastStep, _predicted
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


def compress(n: int, spread: float, gap: float, steps: int, resolution: float,
             guess: bool = False, seed: int = 1,
             first: float | None = None) -> tuple[int, float] | None:
    """F_N in ``steps`` equal steps to 0.5 N per particle, warm started step to step (and
    from the secant predictor if ``guess``); with ``first`` (N per particle) the first step
    loads that much and the others rise in equal steps from there. Returns the passes and the
    CPU seconds, or None when a step failed."""
    bodies, side = lattice(n, spread, gap, seed)
    per = (0.5 * np.arange(1, steps + 1) / steps if first is None
           else np.linspace(first, 0.5, steps))
    numerics = ClusterNumerics(resolution=resolution, tol=1e-5)
    histories, gap_start, total = {}, None, time.perf_counter()
    cpu = time.process_time()
    shares = {"narrow": 0.0, "contacts": 0.0, "newton": 0.0}
    passes = solves = 0
    last = None
    for k in range(1, steps + 1):
        start = time.perf_counter()
        force = n * n * float(per[k - 1])
        step = LoadStep("force", force)
        try:
            result = solve_cluster(bodies, histories, mu_up=0.3, mu_low=0.3, mu_pp=0.3,
                                   force=force, gap_start=gap_start, box=(side, side),
                                   numerics=numerics,
                                   guess=_predicted(last, step, gap_start) if guess else None)
        except (ClusterConvergenceError, ValueError) as exc:
            print(f"{n * n:4d} particles, step {k}: not converged after "
                  f"{time.perf_counter() - start:.1f} s: {exc}")
            return None
        seconds = time.perf_counter() - start
        if gap_start is not None:
            last = _LastStep("force", force, n * n * float(per[k - 1] - per[k - 2]), (0.0, 0.0),
                             result.translation, result.rotation, result.gap - gap_start)
        bodies, histories, gap_start = list(result.bodies), result.histories, result.gap
        pairs = [c for c in result.contacts if isinstance(c.j, int) and c.normal_force > 0]
        t = result.timings
        for name in shares:
            shares[name] += t.get(name, 0.0)
        passes += result.iterations
        solves += result.bem_solves
        print(f"{n * n:4d} particles, step {k:2d}: F_N {force:6.2f} N, "
              f"{result.iterations:2d} passes, "
              f"{result.bem_solves / max(len(result.contacts), 1):4.1f} BEM solves per contact, "
              f"{seconds:6.1f} s (detection {t.get('narrow', 0) / seconds:4.0%}, BEM "
              f"{t.get('contacts', 0) / seconds:4.0%}, model {t.get('newton', 0) / seconds:4.0%}),"
              f" {len(pairs)} loaded particle contacts", flush=True)
    wall = time.perf_counter() - total
    cpu = time.process_time() - cpu
    print(f"{n * n:4d} particles{' (guessed)' if guess else ''}: {steps} steps in {wall:.0f} s "
          f"({wall / steps:.1f} s/step, CPU {cpu:.0f} s), {passes / steps:.1f} passes/step, "
          f"{solves} BEM solves; detection {shares['narrow'] / wall:.0%}, BEM "
          f"{shares['contacts'] / wall:.0%}, model {shares['newton'] / wall:.0%}", flush=True)
    return passes, cpu


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 4, 6])
    parser.add_argument("--spread", type=float, default=5e-4, help="relative std of R")
    parser.add_argument("--gap", type=float, default=2e-4,
                        help="lattice gap / 2R (below 0: pressed in; write --gap=-1e-3)")
    parser.add_argument("--resolution", type=float, default=20.0)
    parser.add_argument("--steps", type=int, default=0,
                        help="a compression program of this many force steps (0: one solve)")
    parser.add_argument("--guess", choices=("no", "yes", "both"), default="no",
                        help="start each step from the secant predictor (both: A/B)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the radii")
    parser.add_argument("--first", type=float, default=None,
                        help="the first step's load, N per particle (default: 0.5 N / steps)")
    args = parser.parse_args(argv)
    for n in args.sizes:
        if args.steps:
            modes = {"no": [False], "yes": [True], "both": [True, False, True, False]}
            runs = {True: [], False: []}
            for guess in modes[args.guess]:
                out = compress(n, args.spread, args.gap, args.steps, args.resolution, guess,
                               args.seed, args.first)
                if out is not None:
                    runs[guess].append(out)
            if args.guess == "both" and runs[True] and runs[False]:
                best = {g: min(r[1] for r in runs[g]) for g in runs}
                print(f"{n * n:4d} particles: passes {runs[True][0][0]} guessed / "
                      f"{runs[False][0][0]} not; CPU best of {len(runs[True])}: "
                      f"{best[True]:.0f} / {best[False]:.0f} s = {best[True] / best[False]:.2f}")
            continue
        bodies, side = lattice(n, args.spread, args.gap, args.seed)
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
