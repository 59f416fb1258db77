"""How often the cluster solver finds the first compression step of a touching lattice, over
random radii: the failure rate on a hard, degenerate case (issue 25).

Each case is ``benchmarks/cluster_lattice.py``'s lattice at ``--gap 0`` (n × n spheres of
R = 1 mm times 1 + 5e-4 N(0, 1), touching their neighbours, in a periodic box) with one seed of
the radii, loaded by the first of 20 force steps (0.025 N a sphere, μ = 0.3 everywhere, 20 cells
per size, tol 1e-5). The spheres differ by about 0.5 µm: the upper plate meets the tallest
first, most pair contacts are open or closed by fractions of a micrometre, and the lightest
loaded spheres touch the plates over less than a cell, which makes the step a hard test of the
iteration's globalisation (kinks of the contact laws at the start, nearly free particles).

For every case the script runs each ``--variants`` setting of the solver's switches in the
same process, one after the other, and prints whether it converged, its passes and its CPU
seconds; at the end the converged share and the total CPU time of each variant. Run:

    .venv/bin/python benchmarks/cluster_robustness.py --sizes 4 5 --seeds 1-16 \\
        --variants main default

``--factors 1 2 4`` loads the same first step by 1, 2 and 4 times 0.025 N a sphere (the first
step of a compression in 20, 10 or 5 steps): how the failures depend on how far the plate
presses into the spread of the spheres' heights.

``--start apart`` shrinks every radius by half the largest pair overlap (:func:`apart`): a
start with no overlap, as a :class:`~thirdbody.layer.Layer` places them (the default start
presses pairs up to 1.5 µm into each other, a prestressed start no placement produces).

Variants: ``main`` is the solver before the switches below existed; ``default`` is the
solver as shipped (``trial``, ``entered`` and the way back on, ``lm`` off); ``noback`` is
``default`` without ``_WAY_BACK`` (the step back of groups stranded on the plateau of
contacts that slid in the step); ``lm``, ``entered`` and ``trial`` add one each to ``main``:
``_LEVENBERG_MARQUARDT`` (the damped step of groups), ``_ENTERED_BRANCHES`` (the re-solve on
the branches a step enters) and ``_NO_DESCENT_TRIAL`` (the BEM tries the Newton step that the
model sees no descent along).
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

from cluster_lattice import lattice
from thirdbody.network import Body, cluster
from thirdbody.network.cluster import ClusterConvergenceError, ClusterNumerics, solve_cluster
from thirdbody.shapes import Sphere

VARIANTS = {
    "main": {"_LEVENBERG_MARQUARDT": False, "_ENTERED_BRANCHES": 0, "_NO_DESCENT_TRIAL": False,
             "_WAY_BACK": False},
    "default": {"_LEVENBERG_MARQUARDT": False, "_ENTERED_BRANCHES": 2,
                "_NO_DESCENT_TRIAL": True, "_WAY_BACK": True},
    "noback": {"_LEVENBERG_MARQUARDT": False, "_ENTERED_BRANCHES": 2,
               "_NO_DESCENT_TRIAL": True, "_WAY_BACK": False},
    "lm": {"_LEVENBERG_MARQUARDT": True, "_ENTERED_BRANCHES": 0, "_NO_DESCENT_TRIAL": False,
           "_WAY_BACK": False},
    "entered": {"_LEVENBERG_MARQUARDT": False, "_ENTERED_BRANCHES": 2,
                "_NO_DESCENT_TRIAL": False, "_WAY_BACK": False},
    "trial": {"_LEVENBERG_MARQUARDT": False, "_ENTERED_BRANCHES": 0, "_NO_DESCENT_TRIAL": True,
              "_WAY_BACK": False},
    "all": {"_LEVENBERG_MARQUARDT": True, "_ENTERED_BRANCHES": 2, "_NO_DESCENT_TRIAL": True,
            "_WAY_BACK": True},
}


def seeds(text: str) -> list[int]:
    """'1-16' or '3' or '1,4,9'."""
    out: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        out.extend(range(int(first), int(last or first) + 1))
    return out


def apart(bodies: list[Body], side: float) -> list[Body]:
    """The lattice with every radius shrunk by half its largest pair overlap (nearest periodic
    image), each sphere still standing on the lower plate: a start with no overlap, its
    closest pair touching and the others apart by up to a few micrometres (a start a
    :class:`~thirdbody.layer.Layer` accepts)."""
    worst = 0.0
    for a, b in itertools.combinations(range(len(bodies)), 2):
        d = bodies[b].centre - bodies[a].centre
        d[:2] -= side * np.round(d[:2] / side)
        worst = max(worst, bodies[a].shape.radius + bodies[b].shape.radius
                    - float(np.linalg.norm(d)))
    # rounding must not leave the closest pair overlapping
    cut = 0.5 * worst * (1.0 + 1e-9)
    return [Body(Sphere(b.shape.radius - cut), b.material,
                 centre=(b.centre[0], b.centre[1], b.shape.radius - cut)) for b in bodies]


def first_step(n: int, seed: int, factor: float = 1.0,
               start: str = "touching") -> tuple[bool, int, float]:
    """(converged, passes, CPU seconds) of the first compression step of one lattice, its load
    (0.025 N a sphere) times ``factor``; ``start`` "apart": the lattice of :func:`apart`."""
    bodies, side = lattice(n, 5e-4, 0.0, seed)
    if start == "apart":
        bodies = apart(bodies, side)
    cpu = time.process_time()
    try:
        result = solve_cluster(bodies, {}, mu_up=0.3, mu_low=0.3, mu_pp=0.3,
                               force=factor * 0.5 * n * n / 20, box=(side, side),
                               numerics=ClusterNumerics(resolution=20.0, tol=1e-5))
    except ClusterConvergenceError:
        return False, 0, time.process_time() - cpu
    return True, result.iterations, time.process_time() - cpu


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 5])
    parser.add_argument("--seeds", type=seeds, default=seeds("1-8"))
    parser.add_argument("--variants", nargs="+", choices=sorted(VARIANTS),
                        default=["main", "default"])
    parser.add_argument("--factors", type=float, nargs="+", default=[1.0],
                        help="the first step's load times each of these (default 1: 0.025 N "
                             "a sphere)")
    parser.add_argument("--start", choices=["touching", "apart"], default="touching",
                        help="touching: the spread presses pairs into each other (overlaps "
                             "up to 1.5 µm at the start); apart: every radius shrunk by half "
                             "the largest overlap (no overlap, the closest pair touching)")
    args = parser.parse_args(argv)
    saved = {name: getattr(cluster, name) for name in VARIANTS["main"]}
    # converged, cases, CPU s
    totals = {(v, f): [0, 0, 0.0] for v in args.variants for f in args.factors}
    try:
        for n in args.sizes:
            for seed in args.seeds:
                line = [f"{n}x{n} seed {seed:3d}:"]
                for variant in args.variants:
                    for name, value in VARIANTS[variant].items():
                        setattr(cluster, name, value)
                    for factor in args.factors:
                        ok, passes, cpu = first_step(n, seed, factor, args.start)
                        total = totals[(variant, factor)]
                        total[0] += ok
                        total[1] += 1
                        total[2] += cpu
                        label = variant if len(args.factors) == 1 else f"{variant} x{factor:g}"
                        line.append(f"{label} {f'{passes:3d} passes' if ok else 'FAILED    '} "
                                    f"{cpu:6.1f} s")
                print("  ".join(line), flush=True)
    finally:
        for name, value in saved.items():
            setattr(cluster, name, value)
    for (variant, factor), (ok, cases, cpu) in totals.items():
        print(f"{variant}, first load x{factor:g}: {ok} of {cases} converged, CPU {cpu:.0f} s")


if __name__ == "__main__":
    main()
