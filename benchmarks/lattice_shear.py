"""A touching lattice of spheres compressed, then sheared: how far a dense layer slides today
(issue 26).

The n × n lattice of ``cluster_lattice.py`` (R = 1 mm times 1 + 5e-4 N(0, 1), touching, in a
periodic box; ``--seed`` draws the radii) runs through ``thirdbody.Simulation`` as a network run:
μ = μ_pp = 0.3, 20 cells per size, tol 1e-5, compressed to 0.5 N a sphere in 5 steps, then the
upper plate slides ``--distance`` along x in ``--steps`` equal steps with the force held (a step
that does not converge is cut into halves up to ``--cutbacks`` times). Per step it prints the
wall time so far, the Newton passes, the sub-steps and μ_eff; at the end the run's status.

    .venv/bin/python benchmarks/lattice_shear.py --size 4 --distance 400e-6 --steps 40
    .venv/bin/python benchmarks/lattice_shear.py --size 10 --distance 4e-3 --steps 100 --cutbacks 4
"""

from __future__ import annotations

import argparse
import time
import warnings

import thirdbody as tb
from _progress import slide_progress
from cluster_lattice import MATERIAL, lattice
from thirdbody.shapes import Sphere


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=4, help="n: n x n spheres")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--distance", type=float, default=400e-6, help="sliding distance, m")
    parser.add_argument("--steps", type=int, default=40, help="sliding steps")
    parser.add_argument("--cutbacks", type=int, default=3,
                        help="halvings of a step that does not converge (network.cutbacks)")
    args = parser.parse_args(argv)
    n = args.size
    bodies, side = lattice(n, 5e-4, 0.0, args.seed)
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(b.shape.radius), MATERIAL),
                                        (b.centre[0] - side / 2, b.centre[1] - side / 2))
                      for b in bodies], box=(side, side), periodic=True)
    program = tb.Slide(force=0.5 * n * n, distance=args.distance, steps=args.steps,
                       compress_steps=5)
    sim = tb.Simulation(layer, tb.Plates(0.3), program, mu_pp=0.3, resolution=20,
                        network_tol=1e-5, network_cutbacks=args.cutbacks)
    progress = slide_progress()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim.run(progress=progress)
    print(f"{n * n} spheres: {sim.status}, {time.perf_counter() - progress.start:.0f} s wall")


if __name__ == "__main__":
    main()
