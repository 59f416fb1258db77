"""``thirdbody run``: one simulation into an output directory (results.nc, config.toml,
figures), resumable after Ctrl-C, a crash or a kill."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from .errors import fail
from .interrupts import defer_interrupts, interruptible
from .lock import lock, unlock
from .progress import Progress, step_text


def run(config: Annotated[Path, typer.Argument(help="TOML configuration file")],
        out: Annotated[Path, typer.Option("-o", "--out", help="output directory")] = Path("out"),
        resume: Annotated[bool, typer.Option(help="continue the run saved in OUT")] = False,
        print_config: Annotated[bool, typer.Option(
            "--print-config", help="print the resolved configuration and exit")] = False,
        plots: Annotated[bool, typer.Option(help="write the figures at the end")] = True,
        quiet: Annotated[bool, typer.Option(
            "--quiet", "-q", help="print nothing but errors (exit codes unchanged)")] = False,
        ) -> None:
    """Run a simulation: OUT/results.nc (written after every step), OUT/config.toml, figures.

    In a terminal a progress bar; otherwise (a log file, a pipe) a line per step, at most one
    every 10 s, with the time elapsed and left."""
    # the imports first, while Ctrl-C still ends the process quietly: a KeyboardInterrupt in
    # the middle of rich's imports ended it with SIGINT after the handler below had run
    import rich.progress  # noqa: F401

    from .. import io, simulation  # noqa: F401

    interruptible()
    results = out / "results.nc"
    try:
        _run(config, out, results, resume, print_config, plots, quiet)
    except KeyboardInterrupt:
        results.with_name(results.name + ".tmp").unlink(missing_ok=True)
        done, finished = _steps_on_disk(results)
        if finished:
            typer.echo(f"\ninterrupted: {results} holds {done} completed step(s), the whole "
                       f"run; draw its figures with `thirdbody plot {results}`", err=True)
        elif done:
            typer.echo(f"\ninterrupted: {results} holds {done} completed step(s); continue "
                       f"with `thirdbody run {config} -o {out} --resume`", err=True)
        else:
            typer.echo("\ninterrupted before the first step completed: nothing was saved; "
                       f"run `thirdbody run {config} -o {out}` again to start", err=True)
        raise typer.Exit(130) from None


def check_out(out: Path) -> None:
    """Refuse an output directory that cannot be one, before anything is written: a file, a
    path below a file, or a place without write permission (exit 2)."""
    import os

    if out.exists() and not out.is_dir():
        fail(f"-o {out}: exists and is not a directory")
    ancestor = out
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        fail(f"-o {out}: {ancestor} is a file, not a directory")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        fail(f"-o {out}: no permission to write in {ancestor}")


def open_or_fail(results: Path, missing: str = ""):
    """The results file loaded, or exit 2 if it is missing (message prefixed by ``missing``)
    or unreadable."""
    from ..io import open_results

    if not results.exists():
        fail(f"{missing}{results} does not exist")
    try:
        return open_results(results)
    except (OSError, ValueError) as exc:
        fail(f"cannot read {results}: {exc}")


def _resumable(results: Path, sim) -> None:
    """Every check of ``--resume`` that needs only reading: the file exists, holds an
    unfinished run, and was made with the same inputs (exit 2 otherwise)."""
    import json

    from ..io.results import RESUME_VARIABLE

    saved = open_or_fail(results, "nothing to resume: ")
    if RESUME_VARIABLE not in saved:
        fail(f"{results} holds a finished run ({saved.attrs.get('status')}); nothing to "
             "resume")
    try:
        inputs = json.loads(str(saved.attrs.get("inputs", "")))
    except ValueError:
        inputs = None
    if inputs != json.loads(json.dumps(sim.inputs())):
        fail(f"cannot resume {results}: it was made with different inputs (compare "
             f"{results.parent / 'config.toml'} with this configuration)")


def _steps_on_disk(results: Path) -> tuple[int, bool]:
    """Completed steps in a results file (0 if there is none or it cannot be read), and
    whether it holds a finished run (no resume state)."""
    steps, done = 0, False
    if results.is_file():
        try:
            from ..io import RESUME_VARIABLE, open_results

            saved = open_results(results)
            steps, done = int(saved.sizes.get("step", 0)), RESUME_VARIABLE not in saved
        except (OSError, ValueError):
            pass
    return steps, done


def _run(config: Path, out: Path, results: Path, resume: bool, print_config: bool,
         plots: bool, quiet: bool) -> None:
    import warnings

    from ..io import ConfigError, load_config, run_to_file
    from ..simulation import Simulation, SimulationError, SimulationStoppedWarning

    try:
        cfg = load_config(config)
    except ConfigError as exc:
        fail(str(exc))
    if print_config:
        typer.echo(cfg.to_toml())
        return
    body, plates, load, numerics = cfg.build()
    try:
        sim = Simulation(body, plates, load, **numerics)
    except ValueError as exc:
        fail(str(exc))
    # every check first; only then is anything written (the directory, its lock, config.toml)
    check_out(out)
    if resume:
        _resumable(results, sim)
    elif results.exists():
        fail(f"{results} exists: use --resume to continue it, or another --out")
    else:
        try:
            sim.preflight()
        except ValueError as exc:
            fail(f"invalid configuration {config}: {exc}")
        except SimulationError as exc:
            fail(f"invalid configuration {config}: {exc}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fail(f"-o {out}: cannot create it: {exc.strerror}")
    held = lock(out)  # held until the run ends (and by the child saving the results)
    try:
        if not resume:
            if results.exists():            # written by a run that held the lock before us
                fail(f"{results} exists: use --resume to continue it, or another --out")
            (out / "config.toml").write_text(cfg.to_toml())
        n = len(sim.schedule)
        start = time.perf_counter()
        with Progress(n, "steps", quiet) as shown:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", SimulationStoppedWarning)
                    ds = run_to_file(sim, results, resume=resume,
                                     progress=lambda r: shown.update(r.step + 1, step_text(r)),
                                     attrs={"config": cfg.to_toml()}, background=True,
                                     keep_fds=(held.fileno(),))
            except (FileNotFoundError, ValueError) as exc:
                fail(str(exc))
        elapsed = time.perf_counter() - start
        steps = ds.sizes.get("step", 0)
        # results.nc is final: from here on Ctrl-C lets the figures finish (an interrupt in the
        # middle of matplotlib's or pandas' imports broke them with a traceback), then exits 130
        interrupted = defer_interrupts()
        if plots and steps:
            from ..plot import save_all

            shown.note(f"drawing the figures in {out}")
            save_all(ds, out)
        if not quiet:
            typer.echo(f"{sim.status}: {steps} of {n} steps in {elapsed:.1f} s -> {results}")
        if interrupted:
            typer.echo(f"\ninterrupted at the end: {results} holds {steps} completed step(s), "
                       "the whole run", err=True)
            raise typer.Exit(130)
        if sim.status != "complete":
            raise typer.Exit(1)
    finally:
        unlock(out, held)
