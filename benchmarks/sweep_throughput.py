"""Sweep throughput on dask.distributed: cases per minute with 1 and 2 workers, and the
per-task overhead compared with running the same cases one by one in this process.

The cases are the bundled ``sweep_fig4`` sweep cut down to ``--mus`` × ``--orientations`` (the
Fig. 4 potato, ``--steps`` load steps, resolution 60, no maps). Three runs, each into a fresh
directory so that nothing is skipped:

1. by itself: every case through :func:`thirdbody.sweep.run_case` in this process, one after
   the other (the same work as ``thirdbody run``: preflight, a results file written per step);
2. ``run_sweep`` on a LocalCluster of 1 worker process (cluster start-up included);
3. ``run_sweep`` on a LocalCluster of 2 worker processes.

Every case runs single-threaded in all three. Two overheads are reported: the wall time of the
1-worker sweep against the one-by-one run, per case, and the part of the sweep's wall time not
spent inside the cases (cluster start-up, task shipping, the summary), per case. The machine is
shared and noisy: the three runs are repeated ``--repeat`` times in turn, the best of each is
kept; read the ratios.

    python benchmarks/sweep_throughput.py [--mus 0.2 0.3 0.4 0.5] [--orientations -50 0]
                                          [--steps 10] [--repeat 2] [--md FILE]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from thirdbody.sweep import parse_sweep, run_case, run_sweep  # noqa: E402


def make_sweep(mus: list[float], orientations: list[float], steps: int):
    return parse_sweep({
        "base": "fig4a",
        "axes": {"plates.mu": mus, "particle.orientation_deg": orientations},
        "set": {"load.steps": steps, "numerics.resolution": 60.0, "numerics.maps_every": 0},
    })


def by_itself(sweep, directory: Path) -> tuple[float, list[dict]]:
    (directory / "cases").mkdir(parents=True)
    start = time.perf_counter()
    records = [run_case(c.data, sweep.base_dir, str(directory / "cases"), c.case_id)
               for c in sweep.cases()]
    return time.perf_counter() - start, records


def on_cluster(sweep, directory: Path, workers: int) -> tuple[float, list[dict]]:
    start = time.perf_counter()
    report = run_sweep(sweep, directory, workers=workers, plots=False)
    return time.perf_counter() - start, list(report.records.values())


def main(argv: list[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mus", type=float, nargs="+", default=[0.2, 0.3, 0.4, 0.5])
    parser.add_argument("--orientations", type=float, nargs="+", default=[-50.0, 0.0])
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--md", type=Path, default=None, help="write the table here too")
    args = parser.parse_args(argv)
    sweep = make_sweep(args.mus, args.orientations, args.steps)
    n = len(sweep.cases())
    best: dict[str, tuple[float, list[dict]]] = {}
    runs = {"alone": lambda d: by_itself(sweep, d), "w1": lambda d: on_cluster(sweep, d, 1),
            "w2": lambda d: on_cluster(sweep, d, 2)}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):
            for name, run in runs.items():
                wall, records = run(Path(tmp) / f"{name}{k}")
                print(f"  {name} (repeat {k}): {wall:.1f} s", flush=True)
                if name not in best or wall < best[name][0]:
                    best[name] = (wall, records)
    (t0, alone), (t1, rec1), (t2, rec2) = best["alone"], best["w1"], best["w2"]
    failed = [r["status"] for r in (*alone, *rec1, *rec2) if r["status"] != "complete"]
    per_case = t0 / n
    inside1 = sum(r["elapsed"] for r in rec1)
    rows = [
        ("one by one, in process", t0, 1.0),
        ("sweep, 1 worker", t1, t0 / t1),
        ("sweep, 2 workers", t2, t0 / t2),
    ]
    lines = [
        f"Sweep throughput: {n} cases (Fig. 4 potato, {args.steps} steps, resolution 60), "
        f"{os.cpu_count()} cores, best of {args.repeat}",
        "",
        "| run | wall time (s) | cases / min | speed-up vs one by one |",
        "|---|---:|---:|---:|",
    ]
    lines += [f"| {name} | {t:.1f} | {60 * n / t:.1f} | {ratio:.2f}x |" for name, t, ratio in rows]
    lines += [
        "",
        f"- 1 worker vs one by one: {(t1 - t0) / n:+.2f} s per case, "
        f"{100 * (t1 - t0) / t0:+.0f} % (a case takes {per_case:.2f} s on average)",
        f"- 1 worker, outside the cases (start-up, shipping, summary): "
        f"{(t1 - inside1) / n:.2f} s per case, {t1 - inside1:.1f} s in all",
        f"- 2 workers vs 1: {t1 / t2:.2f}x",
        f"- cases not complete: {len(failed)}" + (f" ({failed[:3]})" if failed else ""),
    ]
    text = "\n".join(lines)
    print(text)
    if args.md:
        args.md.write_text(text + "\n")
    return text


if __name__ == "__main__":
    main()
