"""Time the paper's Fig. 3 example end to end: per load step and per kind of work.

Runs the Fig. 3 case of ``examples/paper_figures.py`` (a potato compressed between two plates
with equal friction) at the README's default resolution, in one process, one FFT thread, and
reports the wall time, the time per load step, and the share spent in normal solves, tangential
solves and geometry (vertical-ray gaps of the shape), from the per-step timers that every
results dataset carries (``time_normal``, ``time_tangential``, ``time_geometry``).

    python benchmarks/simulation_fig3.py [--resolution 80] [--steps 30] [--json FILE]

Targets: under 20 s (issue 11, with every contact spot found) and under 5 s (issue 13) on this
2-core machine at the default resolution.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "examples"))

import thirdbody as tb  # noqa: E402
from paper_figures import MATERIAL, PARTICLES, cases, potato  # noqa: E402


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=float, default=80.0)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    tb.set_workers(1)
    name, plates, load = cases(3, args.steps)[0]
    sim = tb.Simulation(tb.Particle(potato(3), MATERIAL, PARTICLES[3][3]), plates, load,
                        resolution=args.resolution, maps_every=5)
    start = time.perf_counter()
    ds = sim.run()
    wall = time.perf_counter() - start
    n = ds.sizes["step"]
    parts = {k: float(ds[f"time_{k}"].sum()) for k in ("normal", "tangential", "geometry")}
    steps_total = float(ds.time_total.sum())
    other = max(steps_total - sum(parts.values()), 0.0)
    result = {
        "case": name, "status": sim.status, "resolution": args.resolution,
        "cell_size_m": sim.cell_size, "steps": n, "wall_s": wall,
        "per_step_s": wall / max(n, 1), "turning_steps": int(ds.turned.sum()),
        "evaluations": int(ds.turn_evaluations.sum()),
        "most_spots": int(ds.spots.max()),
        **{f"{k}_share": v / steps_total for k, v in parts.items()},
        "other_share": other / steps_total,
        "set_up_s": wall - steps_total,
    }
    print(f"Fig. 3 ({name}), resolution {args.resolution:g} (cell {sim.cell_size * 1e6:.2f} µm), "
          f"{n} steps: {sim.status}")
    print(f"  wall {wall:.1f} s, {result['per_step_s']:.2f} s per step, "
          f"{result['turning_steps']} turning steps ({result['evaluations']} orientations "
          f"evaluated), at most {result['most_spots']} spots per plate, set-up "
          f"{result['set_up_s']:.1f} s")
    print("  share of step time: " + ", ".join(
        f"{k} {100 * result[f'{k}_share']:.0f} %" for k in ("normal", "tangential", "geometry",
                                                           "other")))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
