"""Parameter sweeps: the Cartesian product of configuration values, run on dask.distributed.

A sweep file (TOML) names a base configuration and the axes to vary::

    base = "fig4a"                  # a config file (relative to this file) or a bundled example

    [axes]                          # any configuration key, dotted; a list or a range
    "plates.mu" = [0.2, 0.3, 0.4]   # plates.mu sets both plates (mu_up = mu_low)
    "particle.orientation_deg" = {start = -60, stop = 60, num = 5}     # inclusive linspace
    "particle.seed" = {start = 1, stop = 4, step = 1}                  # inclusive range

    [set]                           # optional: keys overridden on every case
    "load.steps" = 15
    "numerics.maps_every" = 0

Every case is checked like a configuration file before anything runs (:class:`SweepError` names
the case and the key). A case is identified by the hash of its resolved configuration and writes
``OUT/cases/<hash>.nc`` (the inputs, the resolved configuration and the sweep values are stored
in its attributes). Rerunning a sweep skips the cases already finished, resumes the ones a
killed worker left half done, and retries the ones that raised. A case that raises records its
traceback in ``OUT/cases/<hash>.error.txt``; the others go on. At the end the per-case
summaries, and the per-step scalars when every case has the same number of steps, are combined
along the sweep axes into ``OUT/summary.nc`` (and ``OUT/summary.csv``, one row per case), and
``OUT/state_map.png`` shows the behaviour and the total rotation over the first two axes.

The cases run as tasks on a :class:`dask.distributed.Client`: by default a ``LocalCluster`` of
single-threaded worker processes on this machine, or any existing cluster (``scheduler`` address).
Workers of a remote cluster need thirdbody installed and must see ``OUT`` (a shared file
system). A worker that dies has its task rescheduled by dask (up to
``distributed.scheduler.allowed-failures`` times, 3 by default); the new attempt resumes from
the steps the dead one wrote.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import itertools
import json
import math
import os
import time
import tomllib
import traceback
import warnings
from collections.abc import Callable, Iterable
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from . import schema
from .io.config import Config, ConfigError, parse_config
from .io.results import RESUME_VARIABLE, open_results, run_to_file, write_results
from .records import direction_sign
from .schema import BEHAVIOURS, STATES

__all__ = [
    "BEHAVIOURS",
    "STATES",
    "Axis",
    "Case",
    "Sweep",
    "SweepError",
    "SweepReport",
    "load_sweep",
    "run_case",
    "run_sweep",
    "summarize",
]

#: Behaviour of a case over its whole run (``behaviour`` in the summary): ``stick`` if no
#: particle turned, else the state in which the first particle to turn did; ``failed`` if a step
#: failed, ``error`` if the case raised, ``missing`` if it has no result (the codes of
#: :data:`thirdbody.schema.BEHAVIOURS`).
_BEHAVIOUR_CODE = {name: i for i, name in enumerate(BEHAVIOURS)}


class SweepError(ValueError):
    """An invalid sweep file: the message names the key (and the case) at fault."""


@dataclass(frozen=True)
class Axis:
    """One sweep axis: a dotted configuration key and its values."""

    key: str
    values: tuple
    name: str                 # the summary dimension's name

    @property
    def units(self) -> str:
        return schema.parameter_units(self.key)


@dataclass(frozen=True)
class Case:
    """One point of the sweep: its axis indices and values, and its resolved configuration."""

    index: tuple[int, ...]
    values: dict[str, Any]
    data: dict                # the raw configuration (TOML tables) of this case
    config: Config
    case_id: str              # hash of the resolved configuration

    @property
    def filename(self) -> str:
        return f"{self.case_id}.nc"


@dataclass(frozen=True)
class Sweep:
    """A base configuration, keys set on every case, and the axes of the Cartesian product."""

    base: dict
    axes: tuple[Axis, ...]
    overrides: dict = field(default_factory=dict)
    base_dir: str = "."
    source: str = "<sweep>"

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.axes)

    def cases(self) -> list[Case]:
        """Every case, in axis order (the first axis varies slowest), each one validated.

        Raises :class:`SweepError` listing the cases whose configuration is invalid.
        """
        cases, problems = [], []
        base = _deep_copy(self.base)
        for key, value in self.overrides.items():
            _set_key(base, key, value)
        ranges = [range(len(a.values)) for a in self.axes]
        for index in itertools.product(*ranges):
            values = {a.key: a.values[i] for a, i in zip(self.axes, index, strict=True)}
            data = _deep_copy(base)
            for key, value in values.items():
                _set_key(data, key, value)
            label = ", ".join(f"{k} = {v!r}" for k, v in values.items()) or "the base"
            try:
                config = parse_config(data, source=f"{self.source} (case {label})",
                                      base_dir=self.base_dir)
            except ConfigError as exc:
                problems.append(str(exc))
                continue
            cases.append(Case(index, values, data, config, case_id(config)))
        if problems:
            shown = problems[:5] + ([f"... and {len(problems) - 5} more"]
                                    if len(problems) > 5 else [])
            raise SweepError("\n".join(shown))
        return cases

    def cost_estimate(self) -> str:
        """A rough cost of the whole sweep, from the base's steps and resolution alone (axes
        that change them are not looked at): about 1.2 s per load step at 60 cells per
        particle size on one core (the bundled Fig. 4 sweep), scaling with the cells."""
        data = _deep_copy(self.base)
        for key, value in self.overrides.items():
            _set_key(data, key, value)
        load, numerics = data.get("load", {}), data.get("numerics", {})
        steps = load.get("steps") or len(load.get("forces", [])) or \
            (load.get("hold_steps", 0) + load.get("ramp_steps", 0)) or 50
        resolution = numerics.get("resolution", 80.0)
        if not isinstance(steps, int | float) or not isinstance(resolution, int | float):
            return "cost unknown"
        hours = math.prod(self.shape) * steps * 1.2 * (resolution / 60.0) ** 2 / 3600.0
        return (f"roughly {hours:.2g} core-hours ({steps} steps at {resolution:g} cells per "
                "particle size per case, ~1.2 s a step at 60)")

    def to_toml(self) -> str:
        """The sweep as TOML (base inline), to store next to the results."""
        def value(v) -> str:
            return json.dumps(list(v) if isinstance(v, tuple) else v)

        lines = ["# thirdbody sweep (resolved)", ""]
        lines += ["[axes]"] + [f'"{a.key}" = {value(list(a.values))}' for a in self.axes]
        if self.overrides:
            lines += ["", "[set]"] + [f'"{k}" = {value(v)}' for k, v in self.overrides.items()]
        for table, entries in self.base.items():
            lines += ["", f"[base.{table}]"]
            lines += [f"{k} = {value(v)}" for k, v in entries.items()]
        return "\n".join(lines) + "\n"


#: particle keys added to the configuration after the case hash was defined (None when unset)
_LATER_KEYS = ("azimuth_deg",)


def case_id(config: Config) -> str:
    """16 hex digits of the SHA-256 of the resolved configuration (canonical JSON), with the
    content of its mesh files: an edited mesh is a new case."""
    data = config.model_dump(mode="json", exclude={"base_dir"})
    # keys added since case ids were defined are left out when unset: earlier sweeps keep
    # their ids (and their finished cases)
    for table in [data.get("particle")] + list(data.get("particles") or []):
        for key in _LATER_KEYS:
            if table is not None and table.get(key) is None:
                table.pop(key, None)
    digests = config.mesh_digests()
    if digests:
        data["mesh_sha256"] = digests
    text = json.dumps(data, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# --- reading a sweep file --------------------------------------------------------------------
def load_sweep(path: str | Path) -> Sweep:
    """Read and check a sweep file (see the module docstring); :class:`SweepError` on problems."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise SweepError(f"cannot read sweep file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise SweepError(f"sweep file {path} is not UTF-8 text (a binary file?); a sweep "
                         "file is TOML") from None
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"sweep file {path} is not valid TOML: {exc}") from None
    return parse_sweep(data, base_dir=path.parent, source=str(path))


def parse_sweep(data: dict, base_dir: str | Path = ".", source: str = "<sweep>") -> Sweep:
    """Build a :class:`Sweep` from the tables of a sweep file."""
    unknown = sorted(set(data) - {"base", "axes", "set"})
    if unknown:
        raise SweepError(f"{source}: unknown key(s) {', '.join(unknown)} (allowed: base, axes, "
                         "set)")
    if "base" not in data:
        raise SweepError(f"{source}: base: required (a configuration file, a bundled example "
                         "name, or a [base] table)")
    base, base_dir = _load_base(data["base"], Path(base_dir), source)
    raw_axes = data.get("axes")
    if not isinstance(raw_axes, dict) or not raw_axes:
        raise SweepError(f"{source}: axes: required, a table of 'key = [values]' or "
                         "'key = {start, stop, num | step}'")
    flat = _flatten(raw_axes, is_leaf=lambda v: isinstance(v, list) or _is_range(v))
    overrides = _flatten(data.get("set", {}), is_leaf=lambda v: not isinstance(v, dict))
    axes = []
    for key, spec in flat.items():
        values = _axis_values(key, spec, source)
        if len(set(map(repr, values))) != len(values):
            raise SweepError(f"{source}: axes.{key}: repeated values {values!r}")
        axes.append(values)
    names = [k.rsplit(".", 1)[-1] for k in flat]
    names = [n if names.count(n) == 1 else k.replace(".", "_")
             for n, k in zip(names, flat, strict=True)]
    sweep = Sweep(base=base, overrides=overrides, base_dir=str(base_dir), source=source,
                  axes=tuple(Axis(k, tuple(v), n)
                             for (k, v, n) in zip(flat, axes, names, strict=True)))
    both = [k for k in flat if k in overrides]
    if both:
        raise SweepError(f"{source}: {', '.join(both)}: both an axis and in [set]")
    return sweep


def _load_base(spec, sweep_dir: Path, source: str) -> tuple[dict, Path]:
    if isinstance(spec, dict):
        return spec, sweep_dir
    if not isinstance(spec, str):
        raise SweepError(f"{source}: base: a file name, an example name or a table; got "
                         f"{spec!r}")
    candidates = [sweep_dir / spec, sweep_dir / f"{spec}.toml"]
    bundled = resources.files("thirdbody") / "examples"
    candidates += [Path(str(bundled / spec)), Path(str(bundled / f"{spec}.toml"))]
    for path in candidates:
        if path.is_file():
            try:
                return tomllib.loads(path.read_text()), path.parent
            except tomllib.TOMLDecodeError as exc:
                raise SweepError(f"{source}: base {path} is not valid TOML: {exc}") from None
    raise SweepError(f"{source}: base: no file {spec!r} next to the sweep file and no bundled "
                     "example of that name (see `thirdbody examples`)")


def _is_range(v) -> bool:
    return isinstance(v, dict) and {"start", "stop"} <= set(v) and set(v) <= {
        "start", "stop", "num", "step"}


def _flatten(table: dict, is_leaf: Callable, prefix: str = "") -> dict:
    out = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if is_leaf(v) or not isinstance(v, dict):
            out[key] = v
        else:
            out.update(_flatten(v, is_leaf, key + "."))
    return out


def _axis_values(key: str, spec, source: str) -> list:
    where = f"{source}: axes.{key}"
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where}: an empty list")
        return spec
    if not _is_range(spec):
        raise SweepError(f"{where}: a list of values or {{start, stop, num}} / "
                         f"{{start, stop, step}}; got {spec!r}")
    start, stop = spec["start"], spec["stop"]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (start, stop)):
        raise SweepError(f"{where}: start and stop must be numbers; got {spec!r}")
    if ("num" in spec) == ("step" in spec):
        raise SweepError(f"{where}: give exactly one of num and step; got {spec!r}")
    if "num" in spec:
        num = spec["num"]
        if not isinstance(num, int) or num < 1:
            raise SweepError(f"{where}.num: an integer >= 1; got {num!r}")
        values = np.linspace(start, stop, num) if num > 1 else np.array([start])
    else:
        step = spec["step"]
        if not isinstance(step, int | float) or step == 0 or (stop - start) * step < 0:
            raise SweepError(f"{where}.step: a non-zero number going from start towards stop; "
                             f"got {step!r}")
        count = math.floor((stop - start) / step * (1 + 1e-12) + 1e-9) + 1
        values = start + step * np.arange(count)
    if all(isinstance(v, int) for v in (start, stop, spec.get("step", 1))) and "num" not in spec:
        return [int(v) for v in values]
    return [float(f"{v:.12g}") for v in values]


def _set_key(data: dict, key: str, value) -> None:
    """Set a dotted key in the raw configuration tables; ``plates.mu`` sets both plates."""
    *tables, leaf = key.split(".")
    node = data
    for t in tables:
        node = node.setdefault(t, {})
        if not isinstance(node, dict):
            raise SweepError(f"{key}: {t} is not a table")
    if key == "plates.mu":
        node.pop("mu_low", None)
        node["mu_up"] = value
        return
    node[leaf] = list(value) if isinstance(value, tuple) else value


def _deep_copy(data: dict) -> dict:
    return json.loads(json.dumps(data))


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

    from . import Simulation, SimulationStoppedWarning, __version__, set_workers

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


#: Dask settings of the LocalCluster's workers, measured on the Fig. 4 sweep: without dask's
#: ``MALLOC_TRIM_THRESHOLD_`` (see :func:`_relax_malloc_trim`) cases run 20-40 % faster, and
#: without the statistical profiler (a stack sample every 10 ms) another 10-20 %. Start the
#: workers of your own cluster with the same (README).
LOCAL_WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                       "distributed.worker.profile.enabled": False}

_MALLOC_RELAXED = False


def _relax_malloc_trim() -> None:
    """Undo, in this worker process, the ``MALLOC_TRIM_THRESHOLD_`` that dask's nanny sets.

    That variable freezes glibc's adaptive mmap threshold, so every FFT-sized temporary array
    (> 128 KiB) is mmap'ed and page-faulted afresh: measured here, 20-40 % slower cases. The
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


class UnreadableCase(OSError):
    """A case file exists but cannot be read (damaged, or locked by HDF5 on a network file
    system). It is never deleted: a run moves it aside (:func:`_set_aside`) and recomputes."""


def _set_aside(path: Path) -> Path:
    """Rename an unreadable case file to ``<name>.unreadable-<n>`` (kept for inspection)."""
    n = 1
    while (target := path.with_name(f"{path.name}.unreadable-{n}")).exists():
        n += 1
    path.rename(target)
    return target


def _case_status(path: Path) -> str | None:
    """The status of a finished case file, None (absent or partial), or ``"unreadable"``.
    Reads only: changes nothing on disk (``--dry-run``)."""
    try:
        case = _read_case(path, ())
    except UnreadableCase:
        return "unreadable"
    if case is None or case.partial:
        return None
    return case.status


@dataclass
class _CaseData:
    status: str
    partial: bool                       # holds a resume state: the run is not finished
    inputs: str                         # the ``inputs`` attribute (JSON)
    version: str                        # the thirdbody version that wrote it
    arrays: dict[str, np.ndarray]
    attrs: dict[str, dict]


_KEPT_ATTRS = ("units", "long_name", "flag_values", "flag_meanings")


def _read_case(path: Path, names: Iterable[str]) -> _CaseData | None:
    """Read a case file's status and the per-step variables ``names`` straight through h5py
    (ten times faster than xarray for the summary). None if there is no file; an unreadable
    file raises :class:`UnreadableCase` and is left as it is."""
    import h5py

    if not path.exists():
        return None
    try:
        with h5py.File(path, "r") as f:
            old = int(np.ravel(f.attrs.get("thirdbody_format", 1))[0]) < schema.FORMAT_VERSION
            arrays, attrs = {}, {}
            for name in () if old else names:
                if name in f:
                    arrays[name] = f[name][()]
                    attrs[name] = {k: _text(v) for k, v in f[name].attrs.items()
                                   if k in _KEPT_ATTRS}
            case = _CaseData(_text(f.attrs.get("status", "complete")), RESUME_VARIABLE in f,
                             _text(f.attrs.get("inputs", "")),
                             _text(f.attrs.get("thirdbody_version", "")), arrays, attrs)
        if old and not case.partial:        # an earlier format: read in today's form
            ds = open_results(path)
            for name in names:
                if name in ds:
                    case.arrays[name] = ds[name].values
                    case.attrs[name] = {k: v for k, v in ds[name].attrs.items()
                                        if k in _KEPT_ATTRS}
        return case
    except OSError as exc:
        raise UnreadableCase(f"{path}: {exc}") from None


def _text(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray) and value.dtype.kind in "SO":
        return " ".join(_text(v) for v in value)
    return value


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
        from .io import open_results

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
        from .plot import save_state_map

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


# --- the summary -----------------------------------------------------------------------------
#: what a case's scalar summary reads, besides the variables whose steps the summary keeps
_SUMMARY_INPUTS = ("turned", "state", "quaternion", "ratio", "compression", "total_force",
                   "time_total", "tangential_force", "loaded", "fraction_stick",
                   "fraction_roll", "fraction_rotate")


def _summary_names() -> tuple[str, ...]:
    """The variables a case file is read for: the scalar summary's inputs and every variable
    whose per-step values the summary keeps (:attr:`thirdbody.schema.Variable.summary`)."""
    kept = (v.name for v in schema.VARIABLES.values() if v.summary)
    return tuple(dict.fromkeys((*_SUMMARY_INPUTS, *kept)))


def _total_rotation(case: _CaseData) -> tuple[float, float]:
    """The angle (degrees) from the initial to the final orientation of a case's one particle,
    signed by the side of +y its axis points to (for the paper's turns about y: the change of
    θ), and the azimuth of its axis (degrees from +x)."""
    from scipy.spatial.transform import Rotation

    try:
        start = Rotation.from_quat(json.loads(case.inputs)["quaternion"])
    except (ValueError, KeyError, TypeError):
        return math.nan, math.nan
    vector = np.degrees((Rotation.from_quat(case.arrays["quaternion"][-1, 0]) * start.inv())
                        .as_rotvec())
    angle = float(np.linalg.norm(vector))
    if angle == 0:
        return 0.0, math.nan
    sign = -1.0 if vector[1] < 0 or (vector[1] == 0 and vector[0] < 0) else 1.0
    return sign * angle, math.degrees(math.atan2(vector[1], vector[0]))


def _case_summary(case: _CaseData) -> dict:
    """Scalar summaries of one case's per-step results: the first step in which a particle
    turned, the final compression, loaded count and state fractions; the behaviour is the
    state in which the first particle to turn did (``stick`` if none did); for a case of one
    particle also its total rotation, final state and signed final ratios."""
    a = case.arrays
    out: dict[str, Any] = {v.name: v.fill if isinstance(v.fill, int | float) else math.nan
                           for v in schema.by_kind("summary")}
    n = len(a.get("state", ()))
    out.update(steps_done=n, behaviour=_BEHAVIOUR_CODE["failed"], compute_time=0.0)
    if n == 0:
        return out
    turned = a["turned"].astype(bool)                      # (step, particle)
    steps = np.flatnonzero(turned.any(axis=1))
    out.update(turning_steps=int(steps.size), final_compression=float(a["compression"][-1]),
               compute_time=float(np.sum(a["time_total"])),
               final_loaded=float(a["loaded"][-1]),
               final_fraction_stick=float(a["fraction_stick"][-1]),
               final_fraction_roll=float(a["fraction_roll"][-1]),
               final_fraction_rotate=float(a["fraction_rotate"][-1]))
    first = "stick"
    if steps.size:
        k = steps[0]
        out.update(first_turn_force=float(a["total_force"][k]),
                   first_turn_compression=float(a["compression"][k]))
        first = STATES[int(a["state"][k][np.flatnonzero(turned[k])[0]])]
    if turned.shape[1] == 1:
        # a case that never turned did not rotate: exactly 0, not the round-off of q q0⁻¹
        total, azimuth = _total_rotation(case) if steps.size else (0.0, math.nan)
        sign = float(direction_sign(a["tangential_force"][:, 0])[-1])
        out.update(total_rotation=total, turn_azimuth=azimuth,
                   final_state=int(a["state"][-1, 0]),
                   final_ratio_up=sign * float(a["ratio"][-1, 0, 0]),
                   final_ratio_low=sign * float(a["ratio"][-1, 0, 1]))
    if case.status == "complete" and not case.partial:
        out["behaviour"] = _BEHAVIOUR_CODE.get(first, _BEHAVIOUR_CODE["failed"])
    return out


def summarize(sweep: Sweep, out: str | Path, cases: list[Case] | None = None,
              records: dict[str, dict] | None = None,
              loaded: dict[str, _CaseData] | None = None):
    """Combine the finished cases in ``out/cases`` along the sweep axes: writes
    ``out/summary.nc`` and ``out/summary.csv`` and returns the dataset. ``loaded``: case
    files already read (by case id), not read again."""
    import xarray as xr

    out = Path(out)
    cases = cases if cases is not None else sweep.cases()
    records = records or {}
    shape = sweep.shape
    dims = tuple(a.name for a in sweep.axes)
    summaries = {v.name: v for v in schema.by_kind("summary")}
    scalars = {name: np.full(shape, np.nan) for name in summaries}
    status = np.full(shape, "missing", dtype=object)
    ids = np.full(shape, "", dtype=object)
    datasets = {}
    rows = []
    for case in cases:
        rec = records.get(case.case_id, {})
        path = out / "cases" / case.filename
        ids[case.index] = case.case_id
        summ = {}
        data_ = (loaded or {}).get(case.case_id)
        if data_ is None:
            try:
                data_ = _read_case(path, _summary_names())
            except UnreadableCase:          # reported as missing; the file stays
                data_ = None
        if data_ is not None:
            summ = _case_summary(data_)
            if data_.partial:
                summ["behaviour"] = _BEHAVIOUR_CODE["missing"]
                status[case.index] = "incomplete"
            else:
                status[case.index] = data_.status
            datasets[case.index] = data_
        else:
            summ = {"behaviour": _BEHAVIOUR_CODE["missing"]}
        if str(rec.get("status", "")).startswith("error"):
            status[case.index] = rec["status"]
            summ["behaviour"] = _BEHAVIOUR_CODE["error"]
        for name, value in summ.items():
            scalars[name][case.index] = value
        rows.append({**{a.key: case.values[a.key] for a in sweep.axes}, "case": case.case_id,
                     "status": status[case.index],
                     **{k: summ.get(k, math.nan) for k in summaries}})
    data = {}
    for name, var in summaries.items():
        values = scalars[name]
        if var.dtype != "float64":
            fill = var.fill if not var.flags else var.flags.index(var.fill)
            values = np.nan_to_num(values, nan=fill).astype(var.dtype)
        data[name] = (dims, values, var.attrs)
    data["final_state"][2].update(flag_values=np.arange(len(STATES), dtype=np.int8),
                                  flag_meanings=" ".join(STATES))
    data["status"] = (dims, status.astype(str), {"long_name": "case status"})
    data["case"] = (dims, ids.astype(str), {"long_name": "case id: file cases/<case>.nc"})
    coords = {a.name: (a.name, _coord(a.values), {"config_key": a.key, "units": a.units})
              for a in sweep.axes}
    complete = [d for d in datasets.values() if d.status == "complete" and not d.partial]
    if len({len(d.arrays["state"]) for d in complete}) == 1:
        # per-step values share one step axis (per-particle ones: and one particle count)
        n_steps = len(complete[0].arrays["state"])
        same_particles = len({d.arrays["state"].shape[1] for d in complete}) == 1
        coords["step"] = ("step", np.arange(n_steps), {"long_name": "load step index"})
        for var in schema.VARIABLES.values():
            if not var.summary or (var.kind == "particle" and not same_particles):
                continue
            lead = (n_steps,) if var.kind == "step" else (
                n_steps, complete[0].arrays["state"].shape[1])
            arr = np.full((*shape, *lead, *var.shape), np.nan)
            for index, d in datasets.items():
                values = d.arrays[var.name][:n_steps]
                if values.shape[1:] == arr.shape[len(shape) + 1:]:
                    arr[index][:len(values)] = values
            if var.flags:
                arr = np.nan_to_num(arr, nan=-1).astype(np.int8)
            extra = ("step",) if var.kind == "step" else ("step", "particle")
            data[var.name] = ((*dims, *extra, *var.tail), arr, var.attrs)
            for d in var.tail:
                coords[d] = (d, list(schema.DIMENSIONS[d].labels))
            if var.kind == "particle":
                coords["particle"] = ("particle", np.arange(lead[1]),
                                      {"long_name": "particle index (layer order)"})
    from ._version import __version__

    summary = xr.Dataset(data, coords=coords, attrs={
        "title": "thirdbody sweep summary", "thirdbody_version": __version__,
        "sweep": sweep.to_toml(), "cases": len(cases),
        "failed": int(sum(1 for s in status.flat if s != "complete"))})
    write_results(summary, out / "summary.nc")
    _write_csv(out / "summary.csv", rows)
    return summary


def _coord(values: Iterable) -> np.ndarray:
    values = list(values)
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return np.asarray(values)
    return np.asarray([json.dumps(v) if not isinstance(v, str) else v for v in values])


def _write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: BEHAVIOURS[int(v)] if k == "behaviour" and v == v else v
                             for k, v in row.items()})
    os.replace(tmp, path)
