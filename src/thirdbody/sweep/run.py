"""Running a sweep: one case on a worker (:func:`run_case`) and the whole sweep on a dask
client (:func:`run_sweep`)."""

from __future__ import annotations

import contextlib
import json
import os
import time
import traceback
import warnings
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..io.config import parse_config
from ..io.results import run_to_file
from .cases import UnreadableCase, _CaseData, _read_case, _set_aside
from .spec import Case, Sweep
from .summary import _summary_names, summarize


# --- one case (runs on a worker) -------------------------------------------------------------
def run_case(data: dict, base_dir: str, cases_dir: str, case_id: str, *,
             sweep_values: dict | None = None, fft_threads: int = 1) -> dict:
    """Run one case to ``cases_dir/<case_id>.nc``; never raises for a failing case.

    Resumes the file a killed attempt left behind. Returns a small record: ``case``,
    ``status`` (``complete``, ``failed: ...`` for a run stopped by a failed step, or
    ``error: ...`` when the case raised, its traceback written to ``<case_id>.error.txt``),
    ``steps``, ``elapsed`` (s), ``resumed``, ``worker`` (host:pid) and ``reused`` when a
    complete file was already there.
    """
    import dask

    from .. import Simulation, SimulationStoppedWarning, __version__, set_workers

    _relax_malloc_trim()
    path = Path(cases_dir) / f"{case_id}.nc"
    error_path = path.with_suffix(".error.txt")
    record = {"case": case_id, "worker": f"{os.uname().nodename}:{os.getpid()}",
              "resumed": False, "steps": 0, "elapsed": 0.0}
    start = time.perf_counter()
    try:
        set_workers(fft_threads)
        try:
            found = _read_case(path, ())
        except UnreadableCase:
            record["set_aside"] = str(_set_aside(path))
            found = None
        if found is not None and not found.partial:
            # an earlier attempt of this sweep finished the file (a worker killed between
            # writing it and reporting back): the case was computed, not already done
            return {**record, "status": found.status, "reused": True}
        config = parse_config(data, source=f"case {case_id}", base_dir=base_dir)
        particle, plates, load, numerics = config.build()
        sim = Simulation(particle, plates, load, **numerics)
        # continue a partial file only if this version made it with these inputs; anything
        # else (an older thirdbody, a foreign file) starts the case afresh
        resume = (found is not None and found.version == __version__
                  and found.inputs == json.dumps(sim.inputs()))
        if not resume:
            path.unlink(missing_ok=True)
            sim.preflight()
        attrs = {"config": config.to_toml(), "sweep_case": case_id,
                 "sweep_values": json.dumps(sweep_values or {})}
        # a local lock for the NetCDF writes: inside a worker xarray would otherwise take a
        # distributed lock through the scheduler for every write (slower, and failing with
        # "ConnectionPool is closed" when the sweep is stopped)
        with warnings.catch_warnings(), dask.config.set(scheduler="synchronous"):
            warnings.simplefilter("ignore", SimulationStoppedWarning)
            ds = run_to_file(sim, path, resume=resume, attrs=attrs)
        error_path.unlink(missing_ok=True)
        return {**record, "status": sim.status, "steps": int(ds.sizes.get("step", 0)),
                "resumed": resume, "elapsed": time.perf_counter() - start}
    except Exception as exc:                    # recorded; the sweep goes on
        message = f"error: {type(exc).__name__}: {exc}"
        tmp = error_path.with_name(error_path.name + ".tmp")
        tmp.write_text(f"{message}\n\n{traceback.format_exc()}")
        os.replace(tmp, error_path)
        return {**record, "status": message, "elapsed": time.perf_counter() - start}


#: Dask settings of the LocalCluster's workers: without dask's ``MALLOC_TRIM_THRESHOLD_`` (see
#: :func:`_relax_malloc_trim`) and without the statistical profiler (a stack sample every
#: 10 ms) cases run faster (measured in the docs' performance page). Start the workers of your
#: own cluster with the same (docs: sweeps).
LOCAL_WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                       "distributed.worker.profile.enabled": False}

_MALLOC_RELAXED = False


def _relax_malloc_trim() -> None:
    """Undo, in this worker process, the ``MALLOC_TRIM_THRESHOLD_`` that dask's nanny sets.

    That variable freezes glibc's adaptive mmap threshold, so every FFT-sized temporary array
    (> 128 KiB) is mmap'ed and page-faulted afresh, which slows the cases down. The
    LocalCluster this module starts does not set it; in workers of other clusters this raises
    the mmap and trim thresholds with ``mallopt`` (glibc only; elsewhere nothing happens).
    """
    global _MALLOC_RELAXED
    if _MALLOC_RELAXED or "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    _MALLOC_RELAXED = True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 64 << 20)          # M_MMAP_THRESHOLD: 64 MiB
        libc.mallopt(-1, 128 << 20)         # M_TRIM_THRESHOLD: 128 MiB
    except (OSError, AttributeError):
        pass




# --- the driver ------------------------------------------------------------------------------
@dataclass
class SweepReport:
    """What a sweep did: ``records`` by case id (the run_case records, with ``skipped`` for the
    cases already finished), and the summary dataset."""

    out: Path
    cases: list[Case]
    records: dict[str, dict]
    summary: Any
    elapsed: float
    figures: list[Path] = field(default_factory=list)
    #: unreadable case files moved aside (original, new name) before their cases were rerun
    set_aside: list[tuple[Path, Path]] = field(default_factory=list)

    @property
    def computed(self) -> int:
        return sum(not r.get("skipped") for r in self.records.values())

    @property
    def skipped(self) -> int:
        return sum(bool(r.get("skipped")) for r in self.records.values())

    @property
    def failures(self) -> dict[str, str]:
        """Case id → status, for every case that did not complete."""
        return {k: r["status"] for k, r in self.records.items() if r["status"] != "complete"}


def run_sweep(sweep: Sweep, out: str | Path, *, client=None, scheduler: str | None = None,
              workers: int | None = None, plots: bool = True, connect_timeout: float = 30.0,
              progress: Callable[[dict, int, int], None] | None = None,
              cases: list[Case] | None = None) -> SweepReport:
    """Run every case of ``sweep`` that is not finished in ``out``, then summarise.

    ``client``: an existing :class:`dask.distributed.Client` (left open); else ``scheduler``
    (``tcp://host:port`` of a running cluster, reached within ``connect_timeout`` seconds, else
    OSError and nothing is written); else a LocalCluster of ``workers`` single-threaded
    processes (default: the number of cores), closed at the end. ``progress(record, done,
    total)`` is called after every case. ``cases``: ``sweep.cases()`` if already computed.
    Raises :class:`SweepError` (before writing anything) for an invalid sweep.
    """
    start = time.perf_counter()
    cases = sweep.cases() if cases is None else cases
    out = Path(out)
    cases_dir = out / "cases"
    records: dict[str, dict] = {}
    finished: dict[str, _CaseData] = {}     # read once, for the skip and for the summary
    todo = []
    set_aside: list[tuple[Path, Path]] = []
    for case in cases:
        path = cases_dir / case.filename
        try:
            found = _read_case(path, _summary_names())
        except UnreadableCase:
            set_aside.append((path, _set_aside(path)))
            found = None
        if found is None or found.partial:
            todo.append(case)
        else:
            finished[case.case_id] = found
            records[case.case_id] = {"case": case.case_id, "status": found.status,
                                     "skipped": True}
    total = len(cases)
    text = sweep.to_toml()
    if not todo and not set_aside and _up_to_date(out, text, cases, plots):
        # a finished sweep run again: report it, touch nothing
        from ..io import open_results

        if progress:
            for r in list(records.values()):
                progress(r, len(records), total)
        return SweepReport(out, cases, records, open_results(out / "summary.nc"),
                           time.perf_counter() - start, [])
    with _dask_client(client if todo else None, scheduler, workers, needed=bool(todo),
                      timeout=connect_timeout) as dask:
        cases_dir.mkdir(parents=True, exist_ok=True)   # only once the cluster is reachable
        if not (out / "sweep.toml").is_file() or (out / "sweep.toml").read_text() != text:
            (out / "sweep.toml").write_text(text)
        if progress:
            for r in list(records.values()):
                progress(r, len(records), total)
        if todo:
            _run_tasks(dask, todo, cases_dir, records, total, progress, base_dir=sweep.base_dir)
    summary = summarize(sweep, out, cases, records, finished)
    figures = []
    if plots:
        from ..plot import save_state_map

        figures = save_state_map(summary, out)
    return SweepReport(out, cases, records, summary, time.perf_counter() - start, figures,
                       set_aside)


def _up_to_date(out: Path, text: str, cases: list[Case], plots: bool) -> bool:
    """Whether ``out`` already holds this sweep's summary of exactly these finished cases:
    the same sweep.toml, summary.nc and .csv (and the state map, if plots are wanted) newer
    than every case file."""
    files = [out / "sweep.toml", out / "summary.nc", out / "summary.csv"]
    if plots:
        files.append(out / "state_map.png")
    if not all(f.is_file() for f in files) or files[0].read_text() != text:
        return False
    newest = max((out / "cases" / c.filename).stat().st_mtime_ns for c in cases) \
        if cases else 0
    return min(f.stat().st_mtime_ns for f in files[1:]) >= newest


def _quiet_logs() -> None:
    """Raise dask's, tornado's and asyncio's loggers to CRITICAL in this process."""
    import logging

    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


@contextmanager
def _dask_client(client, scheduler: str | None, workers: int | None, needed: bool,
                 timeout: float = 30.0):
    """The given client (left open), or a new one on ``scheduler`` or on a new LocalCluster
    (closed on exit); None when nothing needs computing."""
    if client is not None or not needed:
        yield client
        return
    from dask.distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler, timeout=f"{timeout}s") as own:
            yield own
        return
    import logging
    import signal

    import dask

    # the workers ignore Ctrl-C: only this process handles it (it cancels the cases and shuts
    # the cluster down), so no worker dies mid-case and reports a bogus error
    with dask.config.set(LOCAL_WORKER_CONFIG):
        try:
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:                  # not the main thread
            previous = None
        try:
            cluster = LocalCluster(
                n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                processes=True, host="127.0.0.1", dashboard_address=":0",
                silence_logs=logging.ERROR)
        finally:
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        own = Client(cluster)
        try:
            yield own
        except KeyboardInterrupt:
            # closing the cluster after an interrupt logs connection errors and may fail: not
            # for the user, who gets one line from the command
            _quiet_logs()
            # the workers too: one whose heartbeat meets the closing scheduler logs an ERROR
            # with a traceback to the terminal they share with this process
            with contextlib.suppress(Exception):
                own.run(_quiet_logs, on_error="ignore", callback_timeout=5)
            for close in (own.close, cluster.close):
                with contextlib.suppress(Exception):
                    close(timeout=10)
            raise
        own.close()
        cluster.close()


def _run_tasks(client, todo: list[Case], cases_dir: Path, records: dict, total: int, progress,
               base_dir: str) -> None:
    from dask.distributed import as_completed

    futures = {}
    where = str(cases_dir.resolve())
    for case in todo:
        fut = client.submit(run_case, case.data, base_dir, where,
                            case.case_id, sweep_values=case.values,
                            key=f"thirdbody-case-{case.case_id}", pure=False)
        futures[fut] = case
    try:
        for fut in as_completed(futures):
            case = futures[fut]
            if fut.status == "finished":
                record = fut.result()
            elif fut.status == "cancelled":     # the sweep is being stopped: not an error
                continue
            else:                               # e.g. KilledWorker after repeated deaths
                exc = fut.exception()
                record = {"case": case.case_id,
                          "status": f"error: {type(exc).__name__}: {exc}"}
                (cases_dir / f"{case.case_id}.error.txt").write_text(record["status"] + "\n")
            records[case.case_id] = record
            if progress:
                progress(record, len(records), total)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise
