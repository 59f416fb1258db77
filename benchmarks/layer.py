"""Time layers of polydisperse potatoes over 20 load steps: 10, 50 and 200 particles.

Each layer comes from :meth:`thirdbody.Layer.random` (lognormal sizes, mean 1 mm, std 4 %;
potatoes 1 : 0.8 : 0.7 with amplitude 0.08, random yaw and tilts up to 30°), placed at an area
fraction of 0.2 of bounding discs, so that the density does not change with N. The load ramps
to 2 N per particle (the tallest few carry it at first, then more and more) with μ_up = 0.15,
μ_low = 0.2, at 40 cells per particle size, in one process (one FFT thread). Reported: wall
time, time per particle-step and per loaded particle-step, the exponent of the wall time in N,
the normal / tangential / geometry shares, and the layer's final state.

    python benchmarks/layer.py [--counts 10 50 200] [--steps 20] [--resolution 40] [--md FILE]

Target (issue 12): 50 particles x 20 steps under 5 minutes on this 2-core machine.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import time
import warnings
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import thirdbody as tb  # noqa: E402


def layer(count: int, seed: int = 7) -> tb.Layer:
    side = math.sqrt(count * math.pi * (1.1e-3) ** 2 / 0.2)
    return tb.Layer.random(box=(side, side), material=tb.Material(1e9, 0.3), count=count,
                           size=1e-3, size_std=0.04e-3, distribution="lognormal",
                           shape="potato", amplitude=0.08, orientation="tilted",
                           max_tilt_deg=30.0, seed=seed)


def run(count: int, steps: int, resolution: float) -> dict:
    body = layer(count)
    sim = tb.Simulation(body, tb.Plates(0.15, 0.2), tb.LinearRamp(stop=2.0 * count, steps=steps),
                        resolution=resolution, maps_every=0)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ds = sim.run()
    wall = time.perf_counter() - start
    n = ds.sizes["step"]
    loaded_steps = int(ds.loaded.sum())
    parts = {k: float(ds[f"time_{k}"].sum()) for k in ("normal", "tangential", "geometry")}
    total = float(ds.time_total.sum())
    return {"particles": count, "status": sim.status, "steps": n, "wall_s": wall,
            "per_particle_step_ms": 1e3 * wall / max(n * count, 1),
            "per_loaded_particle_step_ms": 1e3 * wall / max(loaded_steps, 1),
            "loaded_final": int(ds.loaded[-1]) if n else 0,
            "fraction_stick_final": float(ds.fraction_stick[-1]) if n else math.nan,
            "fraction_roll_final": float(ds.fraction_roll[-1]) if n else math.nan,
            **{f"{k}_share": v / total for k, v in parts.items()}}


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 50, 200])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--resolution", type=float, default=40.0)
    parser.add_argument("--md", type=Path, default=None)
    args = parser.parse_args(argv)
    tb.set_workers(1)
    rows = []
    for count in args.counts:
        row = run(count, args.steps, args.resolution)
        rows.append(row)
        print(f"{count:4d} particles: {row['status']}, {row['wall_s']:.1f} s, "
              f"{row['per_particle_step_ms']:.1f} ms per particle-step, "
              f"{row['per_loaded_particle_step_ms']:.0f} ms per loaded particle-step, "
              f"{row['loaded_final']} loaded at the end ({row['fraction_roll_final']:.0%} "
              f"rolling); normal {row['normal_share']:.0%}, tangential "
              f"{row['tangential_share']:.0%}, geometry {row['geometry_share']:.0%}", flush=True)
    for a, b in itertools.pairwise(rows):
        exponent = math.log(b["wall_s"] / a["wall_s"]) / math.log(b["particles"] / a["particles"])
        print(f"wall time grows like N^{exponent:.2f} from {a['particles']} to {b['particles']}")
    if args.md:
        lines = ["| particles | status | wall (s) | ms / particle-step | ms / loaded "
                 "particle-step | loaded at the end | rolling at the end | normal | tangential "
                 "| geometry |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['particles']} | {r['status'][:30]} | {r['wall_s']:.1f} | "
                         f"{r['per_particle_step_ms']:.1f} | "
                         f"{r['per_loaded_particle_step_ms']:.0f} | {r['loaded_final']} | "
                         f"{r['fraction_roll_final']:.0%} | {r['normal_share']:.0%} | "
                         f"{r['tangential_share']:.0%} | {r['geometry_share']:.0%} |")
        args.md.parent.mkdir(parents=True, exist_ok=True)
        args.md.write_text("\n".join(lines) + "\n")
    return rows


if __name__ == "__main__":
    main()
