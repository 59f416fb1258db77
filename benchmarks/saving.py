"""Cost of saving the results after every step (issue 15): the paper's Fig. 3 potato, 200 load
steps at 40 cells per particle size, run in memory (``Simulation.run``) and run saving every
step (``run_to_file``, what ``thirdbody run`` does), alternating in the same process, best of
``--repeat``. Reports the ratio (saving / not saving), the time per step each adds, how the
saving time splits (the first step written whole, the appended steps, the final whole write),
and the file size. Writes ``benchmarks/results/saving.md`` with ``--write``.

    python benchmarks/saving.py [--steps 200] [--resolution 40] [--repeat 3] [--write]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from importlib import resources
from pathlib import Path

import thirdbody as tb
from thirdbody.io import load_config, results, run_to_file

OUT = Path(__file__).parent / "results" / "saving.md"


def _sim(steps: int, resolution: float) -> tb.Simulation:
    text = (resources.files("thirdbody") / "examples" / "fig3.toml").read_text()
    text = text.replace("steps = 30", f"steps = {steps}").replace(
        "resolution = 80.0", f"resolution = {resolution}")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "c.toml"
        path.write_text(text)
        body, plates, load, numerics = load_config(path).build()
    return tb.Simulation(body, plates, load, **numerics)


def _saving_run(steps: int, resolution: float) -> dict:
    writers = []
    original = results._StepWriter.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        writers.append(self)

    results._StepWriter.__init__ = init
    try:
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "results.nc"
            start = time.perf_counter()
            ds = run_to_file(_sim(steps, resolution), path)
            total = time.perf_counter() - start
            size = path.stat().st_size
            start = time.perf_counter()
            ds.to_netcdf(Path(d) / "again.nc", engine="h5netcdf")
            final = time.perf_counter() - start
    finally:
        results._StepWriter.__init__ = original
    (w,) = writers
    return {"total": total, "first": w.seconds["whole"], "append": w.seconds["append"],
            "appended": w.appended, "whole": w.whole, "regrids": w.regrids, "final": final,
            "size": size}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--resolution", type=float, default=40.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", action="store_true", help=f"write {OUT}")
    args = ap.parse_args(argv)
    plain, saving = [], []
    for _ in range(args.repeat):
        start = time.perf_counter()
        _sim(args.steps, args.resolution).run()
        plain.append(time.perf_counter() - start)
        saving.append(_saving_run(args.steps, args.resolution))
    a = min(plain)
    best = min(saving, key=lambda r: r["total"])
    b = best["total"]
    per_append = 1000 * best["append"] / max(1, best["appended"])
    lines = [
        f"{args.steps} steps of the Fig. 3 potato at resolution {args.resolution:g}, best of "
        f"{args.repeat} (alternating, same process):",
        "",
        "| | wall time (s) |",
        "|---|---:|",
        f"| run in memory | {a:.2f} |",
        f"| run saving every step | {b:.2f} |",
        f"| ratio | {b / a:.3f} (+{100 * (b / a - 1):.1f} %) |",
        f"| saving, per step | {1000 * (b - a) / args.steps:.1f} ms |",
        f"| the simulation, per step | {1000 * a / args.steps:.1f} ms |",
        "",
        f"Saving splits into the first step written whole ({best['first']:.2f} s), "
        f"{best['appended']} appended steps ({per_append:.1f} ms each; the maps' window "
        f"enlarged in place {best['regrids']} times) and the final whole write "
        f"(~{best['final']:.2f} s). File: {best['size'] / 1e6:.2f} MB. Ratios of the other "
        "rounds: " + ", ".join(f"{r['total'] / p:.3f}" for r, p in zip(saving, plain,
                                                                      strict=True)) + ".",
    ]
    text = "\n".join(lines)
    print(text)
    if args.write:
        OUT.write_text("# Saving every step (benchmarks/saving.py)\n\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
