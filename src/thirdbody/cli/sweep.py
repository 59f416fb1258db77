"""``thirdbody sweep``: the Cartesian product of a sweep file on dask.distributed."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from .errors import fail
from .interrupts import interruptible
from .progress import Progress


def sweep(sweep_file: Annotated[Path, typer.Argument(help="sweep TOML file (base + axes)")],
          out: Annotated[Path, typer.Option("-o", "--out", help="output directory")] = Path(
              "sweep"),
          scheduler: Annotated[str | None, typer.Option(
              help="address of a running Dask scheduler, e.g. tcp://host:8786 "
                   "(default: start a local cluster)")] = None,
          workers: Annotated[int | None, typer.Option(
              min=1, help="worker processes of the local cluster (default: one per core)")]
          = None,
          dry_run: Annotated[bool, typer.Option(
              "--dry-run", help="list the cases (and which are done) and exit")] = False,
          plots: Annotated[bool, typer.Option(help="write the state map at the end")] = True,
          connect_timeout: Annotated[float, typer.Option(
              min=0.1, help="seconds to wait for --scheduler before giving up")] = 30.0,
          max_cases: Annotated[int, typer.Option(
              "--max-cases", min=1, help="refuse a sweep of more cases than this")] = 1000,
          quiet: Annotated[bool, typer.Option(
              "--quiet", "-q", help="print nothing but errors (exit codes unchanged)")] = False,
          ) -> None:
    """Run the Cartesian product of a sweep on dask.distributed: OUT/cases/<hash>.nc per case,
    OUT/summary.nc, OUT/summary.csv and OUT/state_map.png. A rerun skips finished cases.

    In a terminal a progress bar; otherwise (a log file, a pipe) a line per case, at most one
    every 10 s (every case that did not complete has its line), with the time elapsed and
    left."""
    interruptible()
    import warnings

    from ..simulation import SimulationStoppedWarning
    from ..sweep import SweepError, _case_status, load_sweep, run_sweep

    if scheduler and workers:
        fail("--workers applies to the local cluster only; with --scheduler the cluster's "
             "own workers run the cases")
    try:
        spec = load_sweep(sweep_file)
    except SweepError as exc:
        fail(str(exc))
    # the size and a rough cost at once, before any case is built
    count = math.prod(spec.shape)

    def say(text: str) -> None:
        if not quiet:
            typer.echo(text)

    say(f"{count} cases ({' x '.join(str(n) for n in spec.shape) or '1'}); "
               f"{spec.cost_estimate()}")
    if count > max_cases:
        fail(f"{count} cases exceed --max-cases {max_cases}; pass --max-cases {count} to "
             "run them")
    try:
        cases = spec.cases()
    except SweepError as exc:
        fail(str(exc))
    if dry_run:
        keys = [a.key for a in spec.axes]
        typer.echo("case              " + "  ".join(keys) + "  done")
        for c in cases:
            done = _case_status(out / "cases" / c.filename) or "-"
            typer.echo(f"{c.case_id}  " + "  ".join(f"{c.values[k]!s:>{len(k)}}" for k in keys)
                       + f"  {done}")
        typer.echo(f"{len(cases)} cases ({' x '.join(str(n) for n in spec.shape)})")
        return
    failed = 0
    with Progress(len(cases), "cases", quiet) as shown:
        shown.note("starting the cluster" if scheduler is None else f"connecting to {scheduler}")

        def progress(record: dict, done: int, total: int) -> None:
            nonlocal failed
            failed += record["status"] != "complete"
            what = "skipped (done)" if record.get("skipped") else record["status"][:40]
            shown.update(done, f"case {record['case']}: {what}; {failed} not complete",
                         always=record["status"] != "complete")
            if done == total:
                shown.note("writing the summary" + (" and the state map" if plots else ""))

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", SimulationStoppedWarning)
                report = run_sweep(spec, out, scheduler=scheduler, workers=workers,
                                   plots=plots, progress=progress,
                                   connect_timeout=connect_timeout, cases=cases)
        except KeyboardInterrupt:
            typer.echo(f"\ninterrupted: finished cases are kept in {out / 'cases'}; rerun the "
                       "same command to continue", err=True)
            raise typer.Exit(130) from None
        except OSError as exc:
            fail(f"cannot reach the Dask scheduler {scheduler}: {exc}" if scheduler
                 else str(exc))
    say(f"{len(cases)} cases: {report.computed} run, {report.skipped} already done, "
               f"{len(report.failures)} not complete, in {report.elapsed:.1f} s -> "
               f"{out / 'summary.nc'}")
    for case, status in report.failures.items():
        typer.echo(f"  {case}: {status}  (see {out / 'cases' / case}.error.txt or .nc)",
                   err=True)
    if report.failures:
        raise typer.Exit(1)
