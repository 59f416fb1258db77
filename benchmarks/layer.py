"""Time layers of polydisperse potatoes over 20 load steps: 10, 50 and 200 particles, on 1 and
2 worker processes.

Each layer comes from :meth:`thirdbody.Layer.random` (lognormal sizes, mean 1 mm, std 4 %;
potatoes 1 : 0.8 : 0.7 with amplitude 0.08, random yaw and tilts up to 30°) at an area
fraction of 0.1 of bounding discs, so that the density does not change with N (denser layers
roll particles into each other, which stops the run: there is no particle-particle contact
yet). The load ramps to 2 N per particle (the tallest few carry it at first, then more and
more) with μ_up = 0.15, μ_low = 0.2, at 40 cells per particle size, one FFT thread. With 2
workers the turns of a round run in 2 processes. Reported: wall time, time per particle-step
and per loaded particle-step, the exponent of the wall time in N, the normal / tangential /
geometry shares, the final state, and whether the 2-worker results equal the 1-worker ones.

    python benchmarks/layer.py [--counts 10 50 200] [--workers 1 2] [--steps 20] [--md FILE]

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

import numpy as np  # noqa: E402

import thirdbody as tb  # noqa: E402


def layer(count: int, seed: int = 7) -> tb.Layer:
    side = math.sqrt(count * math.pi * (1.1e-3) ** 2 / 0.1)
    return tb.Layer.random(box=(side, side), material=tb.Material(1e9, 0.3), count=count,
                           size=1e-3, size_std=0.04e-3, distribution="lognormal",
                           shape="potato", amplitude=0.08, orientation="tilted",
                           max_tilt_deg=30.0, seed=seed)


def run(count: int, steps: int, resolution: float, workers: int) -> tuple[dict, object]:
    body = layer(count)
    sim = tb.Simulation(body, tb.Plates(0.15, 0.2), tb.LinearRamp(stop=2.0 * count, steps=steps),
                        resolution=resolution, maps_every=0, workers=workers)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ds = sim.run()
    wall = time.perf_counter() - start
    n = ds.sizes["step"]
    loaded_steps = int(ds.loaded.sum())
    parts = {k: float(ds[f"time_{k}"].sum()) for k in ("normal", "tangential", "geometry")}
    total = max(float(ds.time_total.sum()), 1e-300)
    return {"particles": count, "workers": workers, "status": sim.status, "steps": n,
            "wall_s": wall, "turn_evaluations": int(ds.turn_evaluations.sum()),
            "per_particle_step_ms": 1e3 * wall / max(n * count, 1),
            "per_loaded_particle_step_ms": 1e3 * wall / max(loaded_steps, 1),
            "loaded_final": int(ds.loaded[-1]) if n else 0,
            "fraction_stick_final": float(ds.fraction_stick[-1]) if n else math.nan,
            "fraction_roll_final": float(ds.fraction_roll[-1]) if n else math.nan,
            **{f"{k}_share": v / total for k, v in parts.items()}}, ds


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 50, 200])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--resolution", type=float, default=40.0)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--md", type=Path, default=None)
    args = parser.parse_args(argv)
    tb.set_workers(1)
    rows = []
    for count in args.counts:
        first = None
        for workers in args.workers:
            row, ds = run(count, args.steps, args.resolution, workers)
            if first is None:
                first = ds
                row["same_as_first"] = True
            else:
                row["same_as_first"] = all(
                    np.array_equal(first[v].values, ds[v].values,
                                   equal_nan=first[v].dtype.kind == "f")
                    for v in first.data_vars if not v.startswith("time_"))
            rows.append(row)
            print(f"{count:4d} particles, {workers} worker(s): {row['status'][:60]}, "
                  f"{row['wall_s']:.1f} s, {row['per_particle_step_ms']:.1f} ms per "
                  f"particle-step, {row['per_loaded_particle_step_ms']:.0f} ms per loaded "
                  f"particle-step, {row['loaded_final']} loaded at the end "
                  f"({row['fraction_roll_final']:.0%} rolling); normal "
                  f"{row['normal_share']:.0%}, tangential {row['tangential_share']:.0%}, "
                  f"geometry {row['geometry_share']:.0%}; same results as the first: "
                  f"{row['same_as_first']}", flush=True)
    for w in args.workers:
        mine = [r for r in rows if r["workers"] == w]
        for a, b in itertools.pairwise(mine):
            exponent = math.log(b["wall_s"] / a["wall_s"]) / math.log(b["particles"]
                                                                     / a["particles"])
            print(f"{w} worker(s): wall time grows like N^{exponent:.2f} from "
                  f"{a['particles']} to {b['particles']}")
    if args.md:
        lines = ["| particles | workers | status | wall (s) | ms / particle-step | ms / loaded "
                 "particle-step | loaded at the end | rolling at the end | normal | tangential "
                 "| geometry | = 1 worker |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['particles']} | {r['workers']} | {r['status'][:30]} | "
                         f"{r['wall_s']:.1f} | "
                         f"{r['per_particle_step_ms']:.1f} | "
                         f"{r['per_loaded_particle_step_ms']:.0f} | {r['loaded_final']} | "
                         f"{r['fraction_roll_final']:.0%} | {r['normal_share']:.0%} | "
                         f"{r['tangential_share']:.0%} | {r['geometry_share']:.0%} | "
                         f"{r['same_as_first']} |")
        args.md.parent.mkdir(parents=True, exist_ok=True)
        args.md.write_text("\n".join(lines) + "\n")
    return rows


if __name__ == "__main__":
    main()
