"""μ_eff of a monolayer of identical spheres against μ_pp and the packing: frustrated rolling
(issue 26, DESIGN §3d).

Identical spheres (R = 1 mm, E = 1 GPa, ν = 0.3) stand on the lower plate of a periodic box in
one of four packings, pressed into their neighbours by ``--press`` of 2R (centres that much
closer than touching), loaded by 0.5 N each (μ = ``--mu`` at both plates), then the upper plate
slides ``--slide`` along +x in ``--steps`` equal steps, the force held. The packings:

============  ==============================================  ======================
packing       lattice                                         area fraction
============  ==============================================  ======================
loose         square, 0.1 % of 2R apart (nothing touches)     π/4 (1 + 10⁻³)⁻² ≈ 0.78
chains        rows along x, touching, 4R apart in y           π/8 ≈ 0.39
square        square, touching                                π/4 ≈ 0.79
hexagonal     rows along x, touching, 60° neighbours          π/(2√3) ≈ 0.91
============  ==============================================  ======================

The reference is a moment balance that does not use the run's contact forces. A sphere that
rolls without slip at both plates under the plate's shift turns about y by Δs/(2R), so at a pair
contact of horizontal normal n its surface and its neighbour's move vertically against each
other at 2 ω R |n_x|: every pair contact with n_x ≠ 0 slides and its friction μ_pp N is
vertical, at the lever R from the centre. Summed over the lattice, the moment of the plates'
tangential forces (F_T at R above and below every centre) balances them:
F_T = μ_pp Σ_pairs N |n_x|, with N Hertz's force at the lattice's overlap
(δ = press · 2R, 1/R* = 2/R, the pair's E*). So μ_eff = μ_pp Σ_pairs N |n_x| / F_N:
μ_pp N / (0.5 N) for chains and the square lattice (one x-pair per sphere: the y-pairs turn
together without rubbing), 2 μ_pp N / (0.5 N) for the hexagonal one (|n_x| = 1, ½, ½), zero for
the loose lattice. It holds while μ_eff stays below the plates' μ (past it the spheres slide at
a plate). Run:

    .venv/bin/python benchmarks/monolayer_friction.py
    .venv/bin/python benchmarks/monolayer_friction.py --packings square --mu-pp 0.5 --press 3e-3

It prints, per packing and μ_pp, the measured μ_eff of the last step against the reference,
the mean turn about y over Δs/(2R), the pair contacts that slide, and the Newton passes.
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

import thirdbody as tb
from thirdbody.network import Body
from thirdbody.network.cluster import ClusterNumerics, solve_cluster
from thirdbody.shapes import Sphere

R = 1e-3                                   # m
MATERIAL = tb.Material(1e9, 0.3)
E_STAR_PAIR = MATERIAL.E / (2 * (1 - MATERIAL.nu ** 2))   # 1/E* = Σ (1 − ν²)/E
LOAD = 0.5                                 # N per sphere
PACKINGS = ("loose", "chains", "square", "hexagonal")


def packing(name: str, press: float) -> tuple[list[Body], tuple[float, float], float]:
    """The spheres, the periodic box (m) and the sum of |n_x| over the touching pairs per
    sphere (the moment balance's geometry) of one packing."""
    close = 2 * R * (1 - press)            # centre distance of touching neighbours
    if name == "hexagonal":
        nx, ny, dx, dy, stagger, per_sphere = 3, 4, close, close * math.sqrt(3) / 2, 0.5, 2.0
    elif name == "chains":
        nx, ny, dx, dy, stagger, per_sphere = 3, 3, close, 4 * R, 0.0, 1.0
    elif name == "square":
        nx, ny, dx, dy, stagger, per_sphere = 3, 3, close, close, 0.0, 1.0
    elif name == "loose":
        gap = 2 * R * (1 + 1e-3)
        nx, ny, dx, dy, stagger, per_sphere = 3, 3, gap, gap, 0.0, 0.0
    else:
        raise ValueError(f"packing must be one of {PACKINGS}, got {name!r}")
    bodies = [Body(Sphere(R), MATERIAL,
                   centre=(dx * (i + 0.5 + stagger * (j % 2)), dy * (j + 0.5), R))
              for j in range(ny) for i in range(nx)]
    return bodies, (nx * dx, ny * dy), per_sphere


def hertz_pair_force(press: float) -> float:
    """Hertz's force (N) between two spheres of radius R pressed 2R·press into each other."""
    return 4 / 3 * E_STAR_PAIR * math.sqrt(R / 2) * (2 * R * press) ** 1.5


def shear(name: str, mu_pp: float, mu: float, press: float, slide: float, steps: int,
          resolution: float) -> dict:
    """Compress one packing, slide it; the last step's μ_eff and what the reference needs."""
    bodies, box, per_sphere = packing(name, press)
    n = len(bodies)
    numerics = ClusterNumerics(resolution=resolution, tol=1e-5)
    start = time.perf_counter()
    result = solve_cluster(bodies, mu_up=mu, mu_low=mu, mu_pp=mu_pp, force=n * LOAD, box=box,
                           numerics=numerics)
    passes, history = [result.iterations], []
    for _ in range(steps):
        result = solve_cluster(list(result.bodies), result.histories, mu_up=mu, mu_low=mu,
                               mu_pp=mu_pp, force=n * LOAD, gap_start=result.gap,
                               plate_shift=(slide / steps, 0.0), box=box, numerics=numerics)
        passes.append(result.iterations)
        history.append((float(result.plate_force[0] / (n * LOAD)),
                        float(np.mean(result.rotation[:, 1]) / (slide / steps / (2 * R)))))
    pairs = [c for c in result.contacts if not isinstance(c.j, str)]
    plates = [c for c in result.contacts if isinstance(c.j, str)]
    reference = mu_pp * per_sphere * hertz_pair_force(press) / LOAD
    return dict(
        packing=name, n=n, mu_pp=mu_pp, fraction=n * math.pi * R ** 2 / (box[0] * box[1]),
        mu_eff=float(result.plate_force[0] / (n * LOAD)), reference=reference,
        turn=float(np.mean(result.rotation[:, 1]) / (slide / steps / (2 * R))),
        pairs=len(pairs), sliding_pairs=sum(c.sliding for c in pairs),
        pair_force=float(np.mean([c.normal_force for c in pairs])) if pairs else 0.0,
        plate_slides=sum(c.sliding for c in plates), passes=passes, history=history,
        seconds=time.perf_counter() - start)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packings", nargs="+", default=list(PACKINGS), choices=PACKINGS)
    parser.add_argument("--mu-pp", nargs="+", type=float, default=[0.0, 0.1, 0.3, 0.5])
    parser.add_argument("--mu", type=float, default=0.5, help="friction at both plates")
    parser.add_argument("--press", type=float, default=1e-3,
                        help="neighbours' overlap as a fraction of 2R")
    parser.add_argument("--slide", type=float, default=10e-6, help="sliding distance, m")
    parser.add_argument("--steps", type=int, default=2, help="sliding steps (the first loads "
                        "the pairs' stick zones)")
    parser.add_argument("--resolution", type=float, default=20.0, help="cells per size")
    args = parser.parse_args(argv)
    print(f"Hertz pair force at press {args.press:g}: {hertz_pair_force(args.press):.5g} N; "
          f"{LOAD} N a sphere, mu = {args.mu} at the plates, {args.resolution:g} cells per size")
    print("| packing | area fraction | μ_pp | μ_eff | moment balance (Hertz) | ratio | "
          "turn / (Δs/2R) | pair N / Hertz | sliding pairs | plate contacts sliding | "
          "passes | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in args.packings:
            for mu_pp in args.mu_pp:
                r = shear(name, mu_pp, args.mu, args.press, args.slide, args.steps,
                          args.resolution)
                ratio = r["mu_eff"] / r["reference"] if r["reference"] > 0 else float("nan")
                hertz = r["pair_force"] / hertz_pair_force(args.press) if r["pairs"] else 0.0
                print(f"| {r['packing']} ({r['n']}) | {r['fraction']:.3f} | {mu_pp:g} | "
                      f"{r['mu_eff']:.4g} | {r['reference']:.4g} | {ratio:.3f} | "
                      f"{r['turn']:.4f} | {hertz:.3f} | {r['sliding_pairs']}/{r['pairs']} | "
                      f"{r['plate_slides']} | {'+'.join(map(str, r['passes']))} | "
                      f"{r['seconds']:.0f} |", flush=True)
                if args.steps > 2:
                    print("  per step (μ_eff, turn / (Δs/2R)): " + ", ".join(
                        f"({m:.4g}, {t:.3f})" for m, t in r["history"]), flush=True)


if __name__ == "__main__":
    main()
