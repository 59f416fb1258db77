"""Cost of saving the results after every step (issue 15): the paper's Fig. 3 potato, 200 load
steps at 40 cells per particle size, run in memory (``Simulation.run``), run saving every step
in a child process while the next is computed (``run_to_file(background=True)``, what
``thirdbody run`` does) and run saving every step in the run's own process (``run_to_file``,
what a sweep's worker does), alternating in the same process, best of ``--repeat``. Reports the
ratios to the run in memory, the time per step saving adds to the run, the child's busy time
(the CPU the saving still costs, on the other core), how the saving splits (the first step
written whole, the appended steps, the final whole write) and the file size. Writes
``benchmarks/results/saving.md`` with ``--write``.

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


def _saving_run(steps: int, resolution: float, background: bool) -> dict:
    """One run saving every step; the writer's counters (from the child, in the background)."""
    made = []
    kind = results._BackgroundWriter if background else results._StepWriter
    original = kind.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        made.append(self)

    kind.__init__ = init
    try:
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "results.nc"
            start = time.perf_counter()
            ds = run_to_file(_sim(steps, resolution), path, background=background)
            total = time.perf_counter() - start
            size = path.stat().st_size
            start = time.perf_counter()
            ds.to_netcdf(Path(d) / "again.nc", engine="h5netcdf")
            final = time.perf_counter() - start
    finally:
        kind.__init__ = original
    (w,) = made
    if background:
        stats = dict(w.stats, run=w.seconds)
    else:
        stats = {"whole": w.whole, "appended": w.appended, "regrids": w.regrids,
                 "seconds": w.seconds, "busy": sum(w.seconds.values()), "run": None}
    return {"total": total, "final": final, "size": size, **stats}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--resolution", type=float, default=40.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", action="store_true", help=f"write {OUT}")
    args = ap.parse_args(argv)
    plain, child, here = [], [], []
    for _ in range(args.repeat):
        start = time.perf_counter()
        _sim(args.steps, args.resolution).run()
        plain.append(time.perf_counter() - start)
        child.append(_saving_run(args.steps, args.resolution, background=True))
        here.append(_saving_run(args.steps, args.resolution, background=False))
    a = min(plain)
    bg = min(child, key=lambda r: r["total"])
    fg = min(here, key=lambda r: r["total"])
    n = args.steps

    def ratios(runs):
        return ", ".join(f"{r['total'] / p:.3f}" for r, p in zip(runs, plain, strict=True))

    lines = [
        f"{n} steps of the Fig. 3 potato at resolution {args.resolution:g}, best of "
        f"{args.repeat} (alternating, same process):",
        "",
        "| | wall time (s) | ratio to the run in memory | added per step (ms) |",
        "|---|---:|---:|---:|",
        f"| run in memory | {a:.2f} | 1 | - |",
        f"| saving in a child process (`thirdbody run`) | {bg['total']:.2f} | "
        f"{bg['total'] / a:.3f} | {1000 * (bg['total'] - a) / n:.1f} |",
        f"| saving in the run's process (a sweep's worker) | {fg['total']:.2f} | "
        f"{fg['total'] / a:.3f} | {1000 * (fg['total'] - a) / n:.1f} |",
        "",
        f"The simulation takes {1000 * a / n:.1f} ms a step. With the child, the run spends "
        f"{1000 * bg['run'] / n:.2f} ms a step handing the step over (the resume snapshot, "
        f"pickling, the pipe) and waiting for the child at the end; the child is busy "
        f"{bg['busy']:.2f} s ({1000 * bg['busy'] / n:.1f} ms a step) on the other core: the CPU "
        f"time saving still costs. Its saving splits into the first step written whole "
        f"({bg['seconds']['whole']:.2f} s) and {bg['appended']} appended steps "
        f"({1000 * bg['seconds']['append'] / max(1, bg['appended']):.1f} ms each; the maps' "
        f"window enlarged in place {bg['regrids']} times). The final whole write, in the run "
        f"after the last step, takes ~{bg['final']:.2f} s. File: {bg['size'] / 1e6:.2f} MB.",
        "",
        f"Ratios of every round: child {ratios(child)}; the run's process {ratios(here)}.",
    ]
    text = "\n".join(lines)
    print(text)
    if args.write:
        OUT.write_text("# Saving every step (benchmarks/saving.py)\n\n" + text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
