"""The ``thirdbody`` command line: run, sweep, plot, export-vtk, examples, validate.

Exit codes: 0 success; 1 a run that stopped on a failed step, or a validation check out of
tolerance; 2 bad input (configuration, file, option); 130 interrupted (resume with --resume).
"""

from __future__ import annotations

import math
import shutil
import sys
import time
from importlib import resources
from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="A deformable third-body particle between two plates (FFT-BEM).")
examples_app = typer.Typer(help="The bundled example configurations (the paper's Figs. 3-5).",
                           invoke_without_command=True)
app.add_typer(examples_app, name="examples")


def _fail(message: str, code: int = 2) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


def _check_out(out: Path) -> None:
    """Refuse an output directory that cannot be one, before anything is written: a file, a
    path below a file, or a place without write permission (exit 2)."""
    import os

    if out.exists() and not out.is_dir():
        _fail(f"-o {out}: exists and is not a directory")
    ancestor = out
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        _fail(f"-o {out}: {ancestor} is a file, not a directory")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        _fail(f"-o {out}: no permission to write in {ancestor}")


LOCK_NAME = ".thirdbody.lock"


#: seconds a run waits for the lock of a run that was killed while its child process finishes
#: saving the steps it was sent (see thirdbody.io.results._BackgroundWriter)
LOCK_WAIT = 60.0


def _gone(pid: str) -> bool:
    """Whether no process has the id ``pid`` (the lock file's text)."""
    import os

    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except (ValueError, OSError):
        return False
    return False


def _wait_for_lock(handle, holder: str) -> bool:
    """The run that holds the lock (pid ``holder``) is dead: its child process that saves the
    results still holds it for the steps it was sent. Wait for it (at most LOCK_WAIT s)."""
    import fcntl

    typer.echo(f"waiting for the killed run's (pid {holder}) saving of its last steps to "
               "finish", err=True)
    deadline = time.monotonic() + LOCK_WAIT
    while time.monotonic() < deadline:
        time.sleep(0.05)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except OSError:
            continue
    return False


def _lock(out: Path):
    """An exclusive lock on the output directory for as long as the run lasts (fcntl; released
    when the process ends, however it ends). A second run into the same directory exits 2 and
    names the holder's pid. Returns the open lock file: keep it open."""
    import fcntl
    import os

    handle = (out / LOCK_NAME).open("a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.seek(0)
        holder = handle.read().strip() or "unknown"
        if not (_gone(holder) and _wait_for_lock(handle, holder)):
            handle.close()
            _fail(f"-o {out} is in use by another thirdbody run (pid {holder}); wait for it or "
                  "choose another --out")
    handle.seek(0)
    handle.truncate()
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    return handle


def _open_or_fail(results: Path, missing: str = ""):
    """The results file loaded, or exit 2 if it is missing (message prefixed by ``missing``)
    or unreadable."""
    from .io import open_results

    if not results.exists():
        _fail(f"{missing}{results} does not exist")
    try:
        return open_results(results)
    except (OSError, ValueError) as exc:
        _fail(f"cannot read {results}: {exc}")


def _resumable(results: Path, sim) -> None:
    """Every check of ``--resume`` that needs only reading: the file exists, holds an
    unfinished run, and was made with the same inputs (exit 2 otherwise)."""
    import json

    from .io.results import RESUME_VARIABLE

    saved = _open_or_fail(results, "nothing to resume: ")
    if RESUME_VARIABLE not in saved:
        _fail(f"{results} holds a finished run ({saved.attrs.get('status')}); nothing to "
              "resume")
    try:
        inputs = json.loads(str(saved.attrs.get("inputs", "")))
    except ValueError:
        inputs = None
    if inputs != json.loads(json.dumps(sim.inputs())):
        _fail(f"cannot resume {results}: it was made with different inputs (compare "
              f"{results.parent / 'config.toml'} with this configuration)")


def _examples() -> dict[str, Path]:
    """Bundled examples by name: the TOML configurations, and ``fig2`` (a Python script: the
    single-interface partial-slip example, run with ``python fig2.py --out DIR``)."""
    root = resources.files("thirdbody") / "examples"
    found = {p.name.removesuffix(".toml"): Path(str(p)) for p in root.iterdir()
             if p.name.endswith(".toml")}
    found["fig2"] = Path(str(root / "fig2_partial_slip.py"))
    return found


@app.command()
def run(config: Annotated[Path, typer.Argument(help="TOML configuration file")],
        out: Annotated[Path, typer.Option("-o", "--out", help="output directory")] = Path("out"),
        resume: Annotated[bool, typer.Option(help="continue the run saved in OUT")] = False,
        print_config: Annotated[bool, typer.Option(
            "--print-config", help="print the resolved configuration and exit")] = False,
        plots: Annotated[bool, typer.Option(help="write the figures at the end")] = True,
        ) -> None:
    """Run a simulation: OUT/results.nc (written after every step), OUT/config.toml, figures."""
    # the imports first, while Ctrl-C still ends the process quietly: a KeyboardInterrupt in
    # the middle of rich's imports ended it with SIGINT after the handler below had run
    import rich.progress  # noqa: F401

    from . import io, simulation  # noqa: F401

    _interruptible()
    results = out / "results.nc"
    try:
        _run(config, out, results, resume, print_config, plots)
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


def _steps_on_disk(results: Path) -> tuple[int, bool]:
    """Completed steps in a results file (0 if there is none or it cannot be read), and
    whether it holds a finished run (no resume state)."""
    steps, done = 0, False
    if results.is_file():
        try:
            from .io import RESUME_VARIABLE, open_results

            saved = open_results(results)
            steps, done = int(saved.sizes.get("step", 0)), RESUME_VARIABLE not in saved
        except (OSError, ValueError):
            pass
    return steps, done


def _run(config: Path, out: Path, results: Path, resume: bool, print_config: bool,
         plots: bool) -> None:
    import warnings

    from .io import ConfigError, load_config, run_to_file
    from .simulation import Simulation, SimulationError, SimulationStoppedWarning

    try:
        cfg = load_config(config)
    except ConfigError as exc:
        _fail(str(exc))
    if print_config:
        typer.echo(cfg.to_toml())
        return
    body, plates, load, numerics = cfg.build()
    try:
        sim = Simulation(body, plates, load, **numerics)
    except ValueError as exc:
        _fail(str(exc))
    # every check first; only then is anything written (the directory, its lock, config.toml)
    _check_out(out)
    if resume:
        _resumable(results, sim)
    elif results.exists():
        _fail(f"{results} exists: use --resume to continue it, or another --out")
    else:
        try:
            sim.preflight()
        except ValueError as exc:
            _fail(f"invalid configuration {config}: {exc}")
        except SimulationError as exc:
            _fail(f"invalid configuration {config}: {exc}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _fail(f"-o {out}: cannot create it: {exc.strerror}")
    lock = _lock(out)  # held until the process exits (and by the child saving the results)
    if not resume:
        if results.exists():            # written by a run that held the lock before us
            _fail(f"{results} exists: use --resume to continue it, or another --out")
        (out / "config.toml").write_text(cfg.to_toml())
    n = len(sim.schedule)
    start = time.perf_counter()
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(TextColumn("{task.description}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total}"), TimeRemainingColumn(),
                  transient=False) as bar:
        task = bar.add_task("starting", total=n)

        def progress(r) -> None:
            bar.update(task, completed=r.step + 1, description=str(r))

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", SimulationStoppedWarning)
                ds = run_to_file(sim, results, resume=resume, progress=progress,
                                 attrs={"config": cfg.to_toml()}, background=True,
                                 keep_fds=(lock.fileno(),))
        except (FileNotFoundError, ValueError) as exc:
            _fail(str(exc))
    elapsed = time.perf_counter() - start
    steps = ds.sizes.get("step", 0)
    # results.nc is final: from here on Ctrl-C lets the figures finish (an interrupt in the
    # middle of matplotlib's or pandas' imports broke them with a traceback), then exits 130
    interrupted = _defer_interrupts()
    if plots and steps:
        from .plot import save_all

        save_all(ds, out)
    typer.echo(f"{sim.status}: {steps} of {n} steps in {elapsed:.1f} s -> {results}")
    if interrupted:
        typer.echo(f"\ninterrupted at the end: {results} holds {steps} completed step(s), "
                   "the whole run", err=True)
        raise typer.Exit(130)
    if sim.status != "complete":
        raise typer.Exit(1)


@app.command()
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
          ) -> None:
    """Run the Cartesian product of a sweep on dask.distributed: OUT/cases/<hash>.nc per case,
    OUT/summary.nc, OUT/summary.csv and OUT/state_map.png. A rerun skips finished cases."""
    _interruptible()
    import warnings

    from .simulation import SimulationStoppedWarning
    from .sweep import SweepError, _case_status, load_sweep, run_sweep

    if scheduler and workers:
        _fail("--workers applies to the local cluster only; with --scheduler the cluster's "
              "own workers run the cases")
    try:
        spec = load_sweep(sweep_file)
    except SweepError as exc:
        _fail(str(exc))
    # the size and a rough cost at once, before any case is built
    count = math.prod(spec.shape)
    typer.echo(f"{count} cases ({' x '.join(str(n) for n in spec.shape) or '1'}); "
               f"{spec.cost_estimate()}")
    if count > max_cases:
        _fail(f"{count} cases exceed --max-cases {max_cases}; pass --max-cases {count} to "
              "run them")
    try:
        cases = spec.cases()
    except SweepError as exc:
        _fail(str(exc))
    if dry_run:
        keys = [a.key for a in spec.axes]
        typer.echo("case              " + "  ".join(keys) + "  done")
        for c in cases:
            done = _case_status(out / "cases" / c.filename) or "-"
            typer.echo(f"{c.case_id}  " + "  ".join(f"{c.values[k]!s:>{len(k)}}" for k in keys)
                       + f"  {done}")
        typer.echo(f"{len(cases)} cases ({' x '.join(str(n) for n in spec.shape)})")
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    failed = 0
    with Progress(TextColumn("{task.description}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total} cases"), TimeRemainingColumn(),
                  transient=False) as bar:
        task = bar.add_task("starting the cluster", total=len(cases))

        def progress(record: dict, done: int, total: int) -> None:
            nonlocal failed
            failed += record["status"] != "complete"
            what = "skipped (done)" if record.get("skipped") else record["status"][:40]
            bar.update(task, completed=done, description=(
                f"{record['case']}: {what}; {failed} not complete"))

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
            _fail(f"cannot reach the Dask scheduler {scheduler}: {exc}" if scheduler
                  else str(exc))
    typer.echo(f"{len(cases)} cases: {report.computed} run, {report.skipped} already done, "
               f"{len(report.failures)} not complete, in {report.elapsed:.1f} s -> "
               f"{out / 'summary.nc'}")
    for case, status in report.failures.items():
        typer.echo(f"  {case}: {status}  (see {out / 'cases' / case}.error.txt or .nc)",
                   err=True)
    if report.failures:
        raise typer.Exit(1)


@app.command()
def plot(results: Annotated[Path, typer.Argument(
        help="a results.nc file, or a sweep's summary.nc")],
         out: Annotated[Path | None, typer.Option("-o", "--out",
                                                  help="directory (default: next to it)")] = None,
         ) -> None:
    """Redraw every figure from a results file (or the state map from a sweep summary)."""
    from .plot import save_all

    ds = _open_or_fail(results)
    title = str(ds.attrs.get("title", ""))
    if not title.startswith("thirdbody") and "behaviour" not in ds:
        _fail(f"{results} is not a thirdbody results file (no 'thirdbody' title attribute); "
              "plot reads the results.nc of `thirdbody run` or a sweep's summary.nc")
    if "behaviour" in ds:                       # a sweep's summary.nc
        from .plot import save_state_map

        written = save_state_map(ds, out or results.parent)
    else:
        written = save_all(ds, out or results.parent)
    for path in written:
        typer.echo(str(path))


@app.command("export-vtk")
def export_vtk(results: Annotated[Path, typer.Argument(help="a results.nc file")],
               out: Annotated[Path, typer.Argument(help="directory for the .vtu/.pvd files")],
               ) -> None:
    """Write each particle's surface at its pose with pressure, traction and stick/slip status
    on it, one .vtu file per load step plus a .pvd time series (ParaView)."""
    from .io.vtk import export_vtk_cli

    code = export_vtk_cli(results, out)
    if code:
        raise typer.Exit(code)


@examples_app.callback()
def examples(ctx: typer.Context) -> None:
    """List the bundled examples."""
    if ctx.invoked_subcommand is None:
        for name, path in sorted(_examples().items()):
            if path.suffix == ".py":
                first = ("Fig. 2: partial slip of a tilted ellipsoid on a plate shifted in steps "
                         "(a script: python fig2.py --out DIR)")
            else:
                first = path.read_text().splitlines()[0].lstrip("# ")
            typer.echo(f"{name:12s} {first}")


@examples_app.command("copy")
def examples_copy(name: Annotated[str, typer.Argument(help="example name")],
                  directory: Annotated[Path, typer.Argument(help="where to copy it")]) -> None:
    """Copy an example configuration so you can edit it."""
    found = _examples()
    if name not in found:
        _fail(f"no example {name!r}; choose one of: {', '.join(sorted(found))}")
    directory.mkdir(parents=True, exist_ok=True)
    target = directory / f"{name}{found[name].suffix}"
    shutil.copyfile(found[name], target)
    typer.echo(str(target))
    if found[name].suffix == ".toml":       # a mesh file next to the configuration goes along
        import tomllib

        mesh = tomllib.loads(found[name].read_text()).get("particle", {}).get("file")
        if mesh and not Path(mesh).is_absolute():
            shutil.copyfile(found[name].parent / mesh, directory / mesh)
            typer.echo(str(directory / mesh))


@app.command()
def validate() -> None:
    """Run the analytic checks at a quick resolution and print computed vs analytic values."""
    rows = _validation_rows()
    width = max(len(r[0]) for r in rows)
    typer.echo(f"{'check':{width}s}  {'computed':>12s}  {'analytic':>12s}  {'error':>9s}  "
               f"{'tolerance':>9s}  ok")
    bad = 0
    for name, computed, analytic, tol in rows:
        err = abs(computed / analytic - 1) if analytic else abs(computed)
        ok = err <= tol
        bad += not ok
        typer.echo(f"{name:{width}s}  {computed:12.6g}  {analytic:12.6g}  {err:9.2e}  "
                   f"{tol:9.1e}  {'yes' if ok else 'NO'}")
    if bad:
        typer.echo(f"{bad} check(s) out of tolerance", err=True)
        raise typer.Exit(1)


def _validation_rows() -> list[tuple[str, float, float, float]]:
    import numpy as np

    import thirdbody as tb
    from thirdbody import rigid
    from thirdbody.reference import hertz, mindlin
    from thirdbody.shapes import Ellipsoid

    rows = []
    mat = tb.Material(210e9, 0.3)
    L, W, R = 1e-3, 1.0, 4 * mat.E_star * (1e-3 / 8) ** 3 / 3
    grid = tb.Grid(128, L / 128)
    normal = tb.solve_normal(grid.paraboloid(R), grid, mat, force=W)
    ref = hertz.sphere(W, R, mat.E_star)
    rows += [("Hertz sphere 128²: approach (m)", normal.approach, ref.approach, 1e-3),
             ("Hertz sphere 128²: peak pressure (Pa)", float(normal.pressure.max()),
              ref.peak_pressure, 3e-3)]
    mu = 0.5
    t = tb.solve_tangential(normal, mu, force=0.5 * mu * W)
    cm = mindlin.cattaneo_mindlin(0.5 * mu * W, W, mu, R, mat.E, mat.nu)
    rows += [("Cattaneo-Mindlin Q=0.5μP: shift (m)", float(t.shift[0]), cm.shift, 1e-2),
             ("Cattaneo-Mindlin Q=0.5μP: stick radius (m)",
              math.sqrt(t.stick_area / math.pi), cm.stick_radius, 0.05)]
    q_star = 0.8 * mu * W
    loaded = tb.solve_tangential(normal, mu, force=q_star)
    unloaded = tb.solve_tangential(normal, mu, force=0.0, previous=loaded)
    md = mindlin.mindlin_deresiewicz_unloading(0.0, q_star, W, mu, R, mat.E, mat.nu)
    rows.append(("Mindlin-Deresiewicz unloaded to 0: shift (m)", float(unloaded.shift[0]),
                 md.shift, 2e-2))
    A, B, C = 1e-3, 0.8e-3, 0.6e-3
    sim = tb.Simulation(tb.Particle(Ellipsoid((A, B, C)), mat, 20.0), tb.Plates(0.6),
                        tb.ForceTable([0.5]), resolution=400, maps_every=0)
    ds = sim.run()
    rows.append(("rigid criterion: steel ellipsoid θ=20°, |F'_x|/F_N",
                 float(np.abs(ds.tangential_force.sel(component="x")[0]) / ds.normal_force[0]),
                 rigid.ellipsoid_xi(A, C, math.radians(20.0)), 2e-3))
    sim = tb.Simulation(tb.Particle(Ellipsoid((A, B, C)), mat, 20.0), tb.Plates(0.3),
                        tb.ForceTable([1.0]), resolution=100, maps_every=0)
    ds = sim.run()
    rows.append(("rigid equilibrium angle, μ=0.3 (deg)",
                 float(ds.orientation.sel(component="y")[0]),
                 math.degrees(rigid.ellipsoid_equilibrium_angle(A, C, math.radians(20.0), 0.3)),
                 5e-3))
    return rows


def _defer_interrupts() -> list[int]:
    """From now on Ctrl-C is recorded, not raised (for the rest of the process): returns the
    list the signal numbers go to."""
    import signal

    seen: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: seen.append(signum))
    return seen


def _interruptible() -> None:
    """From here on Ctrl-C is a KeyboardInterrupt, which the command handles (it says what is
    on disk). Until then (the imports, typer's parsing, which turns a KeyboardInterrupt into a
    silent exit 130) it ends the process with one line (thirdbody._interrupt)."""
    from ._interrupt import restore

    restore()


def main() -> None:  # pragma: no cover - console entry point
    try:
        app(prog_name="thirdbody")
    except KeyboardInterrupt:
        sys.stderr.write("\ninterrupted\n")
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
