"""A layer two grains thick, compressed, then sheared: the effective friction of a packing whose
grains interlock (issue 26).

Spheres of R = 1 mm (E = 1 GPa, ν = 0.3) in a periodic box: an n × n square bottom layer on
the lower plate (spacing 2R (1 + 1e-4), neighbours just apart) and an n × n top layer, each
top sphere in a pocket of four bottom ones (placed with ``PlacedParticle(z=...)`` 0.1 µm above
touching them). Plates μ = 0.5, μ_pp from ``--mu-pp``, 20 cells per size, ``--tol`` 1e-3 (at
1e-4, the tolerance floor of 20 cells, μ_pp = 0.3 stalls at 14 µm and 0.6 in its first
sliding step; μ_pp = 0.3 needs 3e-3 to pass 14 µm). Pressed by 0.5 N per top sphere in
three steps, then the upper plate slides ``--distance`` along x in ``--steps`` equal steps,
the force held (a step that does not converge is cut into halves up to 4 times). Per step it
prints the wall time so far, the passes, the sub-steps, the gap, μ_eff, the dilatancy and the
energy residual.

With μ_pp = 0 the packing is a mechanism: no pair contact can turn a sphere, so each top
sphere's moment balance leaves its upper contact no tangential force, and μ_eff is 0 whatever
the packing (the bottom layer rolls on the lower plate, the top one rolls over it).

With friction enough between the grains the layer locks: each top sphere, stuck to the upper
plate, rolls without slip over the pair of bottom spheres ahead of it, which stay put. Rigid
kinematics then give the plate's path (no energy is dissipated, so μ_eff = dh/ds): in the
vertical plane of its motion the top centre C turns about the pair's axis B at the distance
ρ = √(4R² − (a/2)²), d = B − C = ρ (sin φ, −cos φ), and rolling at the pair and at the plate
gives dh/ds = ρ sin φ / (2R + ρ cos φ), with cos φ = cos φ₀ + Δh/ρ as it rises by Δh
(sin φ₀ = a/(2ρ) in the pocket): 0.2929 at the start, falling as it climbs. ``mu_rolling``
below; the run prints it beside μ_eff.

    .venv/bin/python benchmarks/gouge.py --mu-pp 0.3 --distance 100e-6 --steps 50 --tol 3e-3
    .venv/bin/python benchmarks/gouge.py --mu-pp 0 --distance 100e-6 --steps 10
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

import thirdbody as tb
from _progress import slide_progress
from thirdbody.shapes import Sphere

R = 1e-3                        # m
MATERIAL = tb.Material(1e9, 0.3)
SPREAD = 1e-4                   # the bottom layer's spacing 2R (1 + SPREAD)
LIFT = 1e-7                     # m: the top layer above touching the bottom one


def two_layers(n: int) -> tb.Layer:
    """The n × n bottom layer and the n × n top layer in its pockets, periodic."""
    a = 2 * R * (1 + SPREAD)
    top = R + math.sqrt(4 * R * R - 2 * (a / 2) ** 2) + LIFT
    side = n * a
    placed = []
    for shift, z in ((0.25, None), (0.75, top)):
        for i in range(n):
            for j in range(n):
                xy = (-side / 2 + a * (i + shift), -side / 2 + a * (j + shift))
                placed.append(tb.PlacedParticle(tb.Particle(Sphere(R), MATERIAL), xy, z=z))
    return tb.Layer(placed, box=(side, side), periodic=True)


def mu_rolling(rise: float) -> float:
    """μ_eff = dh/ds of the locked two layers (module docstring) after the top layer rose by
    ``rise`` (m) from its pocket: top spheres rolling without slip over the fixed bottom pairs
    ahead of them, stuck to the upper plate."""
    a = 2 * R * (1 + SPREAD)
    rho = math.sqrt(4 * R * R - (a / 2) ** 2)
    cos = math.sqrt(1 - (a / (2 * rho)) ** 2) + rise / rho
    sin = math.sqrt(1 - cos * cos)
    return rho * sin / (2 * R + rho * cos)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=2, help="n: n x n spheres in each layer")
    parser.add_argument("--mu-pp", type=float, default=0.3, help="friction between spheres")
    parser.add_argument("--distance", type=float, default=100e-6, help="sliding distance, m")
    parser.add_argument("--steps", type=int, default=50, help="sliding steps")
    parser.add_argument("--tol", type=float, default=1e-3,
                        help="network tol (1e-4 stalls for mu_pp 0.3 at 14 µm and 0.6 at once)")
    parser.add_argument("--out", default=None, help="write the results here (.nc)")
    args = parser.parse_args(argv)
    n = args.size
    program = tb.Slide(force=0.5 * n * n, distance=args.distance, steps=args.steps,
                       compress_steps=3)
    sim = tb.Simulation(two_layers(n), tb.Plates(0.5), program, mu_pp=args.mu_pp,
                        resolution=20, network_tol=args.tol, network_cutbacks=4)
    def extra(v: dict) -> str:
        rise = v.get("dilatancy", np.nan)
        return (f", gap {v.get('plate_gap', np.nan) * 1e3:.6f} mm, dilatancy {rise * 1e6:.4g} um "
                f"(rolling over the bottom pairs: mu_eff "
                f"{mu_rolling(rise) if rise >= 0 else np.nan:.5g}), "
                f"energy residual {v.get('energy_residual', np.nan):.2e}")

    progress = slide_progress(extra)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = sim.run(progress=progress)
    print(f"{2 * n * n} spheres in two layers, mu_pp {args.mu_pp}: {sim.status}, "
          f"{time.perf_counter() - progress.start:.0f} s wall")
    if args.out:
        from thirdbody.io.results import write_results

        write_results(ds, args.out)


if __name__ == "__main__":
    main()
