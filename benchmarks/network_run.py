"""A network run of a dense random layer: how far and how fast (issue 25).

A periodic layer of polydisperse particles (``Layer.random(placement="relaxed",
periodic=True)``: lognormal sizes, mean 1 mm, std 0.2 mm or ``--size-std``; tilted up to 20°;
E = 1 GPa, ν = 0.3) is compressed under gap control in equal steps to a final compression, with
μ = μ_pp = 0.5, 20 cells per size and the equilibrium tolerance 1e-5, through
``thirdbody.Simulation(..., mu_pp=0.5)``. Per case the script prints the particles, the steps
completed, the wall time per step, the BEM passes per step, the particle contacts and
coordination at the last step done, and the run's status (the solver's own error when a step
fails). Wall times are from a shared 2-core machine: read them as orders of magnitude.

    .venv/bin/python benchmarks/network_run.py --boxes 6e-3 8e-3 --shapes sphere ellipsoid
"""

from __future__ import annotations

import argparse
import time
import warnings

import thirdbody as tb


def run(box: float, shape: str, fraction: float, stop: float, steps: int, seed: int,
        size_std: float = 0.2e-3) -> str:
    layer = tb.Layer.random(box=(box, box), material=tb.Material(1e9, 0.3),
                            area_fraction=fraction, size=1e-3, size_std=size_std,
                            distribution="lognormal", shape=shape, orientation="tilted",
                            max_tilt_deg=20.0, placement="relaxed", periodic=True, seed=seed)
    sim = tb.Simulation(layer, tb.Plates(0.5), tb.GapRamp(stop=stop, steps=steps), mu_pp=0.5,
                        resolution=20, network_tol=1e-5)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = sim.run()
    seconds = time.perf_counter() - start
    done = ds.sizes["step"]
    line = (f"{shape:9s} box {box * 1e3:4.1f} mm: {len(layer):3d} particles, {done}/{steps} "
            f"steps")
    if done:
        passes = [int(v) for v in ds.network_iterations.values]
        line += (f", {seconds / done:6.1f} s/step, passes {passes}"
                 f", last step: {int(ds.particle_contacts.values[-1])} particle contacts, "
                 f"coordination {float(ds.coordination.values[-1]):.2f}, "
                 f"{int(ds.loaded.values[-1])} loaded")
    if sim.status != "complete":
        line += f"\n    {sim.status}"
    return line


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--boxes", type=float, nargs="+", default=[6e-3, 8e-3],
                        help="box sides, m")
    parser.add_argument("--shapes", nargs="+", default=["sphere", "ellipsoid", "potato"])
    parser.add_argument("--fraction", type=float, default=0.6, help="area fraction of the "
                        "bounding discs")
    parser.add_argument("--stop", type=float, default=0.05, help="final compression")
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--size-std", type=float, default=0.2e-3, help="standard deviation "
                        "of the sizes, m (a narrow spread, 0.02e-3: every particle is pressed)")
    args = parser.parse_args(argv)
    for box in args.boxes:
        for shape in args.shapes:
            print(run(box, shape, args.fraction, args.stop, args.steps, args.seed, args.size_std),
                  flush=True)


if __name__ == "__main__":
    main()
