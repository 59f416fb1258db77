"""Results files: NetCDF (HDF5, via xarray and h5netcdf), saved after every load step.

The file on disk is always a complete, valid dataset of the steps done so far: a reader can
open it while the run goes on, and a run killed at any moment (Ctrl-C, SIGKILL, a crash) loses
at most the step in progress. Each save goes to a temporary file that then replaces the results
file atomically (``os.replace``). The first step a process saves is written whole; every
later one is *appended*: the file is copied (a byte copy, about 1 ms per MB) and the new
step's rows are written at the end of its unlimited dimensions (``step``, ``map_step``,
``event``, a network run's ``contact``). The maps sit on a lattice window with room to grow;
when a contact outgrows it, the window is enlarged in place (with room to spare again, so this
happens a few times per run). While a run goes on, the maps of the file can therefore sit on a
larger window than the finished file's, padded with zeros (no contact).

While a run is incomplete the file also holds what ``--resume`` needs: ``_resume_state`` (the
pickled solver state, of a size that does not grow with the run) and ``_resume_step`` (each
step's record and maps, pickled, along ``step``). The finished file is written whole, without
them, and is the same as an uninterrupted run's (the per-step wall-time variables ``time_*``
aside). Only resume files you made yourself: the state is a Python pickle.

With ``run_to_file(..., background=True)`` (what ``thirdbody run`` does) the steps are written
by a child process while the run computes the next one (:class:`_BackgroundWriter`): the run
spends about 1 ms a step handing a step over instead of the 5-25 ms of writing it.
"""

from __future__ import annotations

import base64
import json
import math
import os
import pickle
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["RESUME_VARIABLE", "STEP_HISTORY_VARIABLE", "open_results", "run_to_file",
           "write_results"]

RESUME_VARIABLE = "_resume_state"
STEP_HISTORY_VARIABLE = "_resume_step"
#: dimensions that grow as the run goes on (unlimited in an unfinished file)
_GROWING = ("step", "map_step", "event", "contact", "resume_bytes", "map_j", "map_i")
#: the maps' lattice dimensions (y, x)
_MAP_DIMS = ("map_j", "map_i")
#: the maps' metre coordinates, on (particle, lattice dimension)
_MAP_COORDS = {"map_x": "map_i", "map_y": "map_j"}
#: room to grow given to the maps' window when it must be enlarged: this fraction of its size
#: on every side, at least _MARGIN_CELLS cells
_MARGIN = 0.25
_MARGIN_CELLS = 4


def write_results(ds, path: str | Path, resume_state: bytes | None = None) -> None:
    """Write ``ds`` to ``path`` atomically (temporary file, then rename); with ``resume_state``
    (a complete :func:`thirdbody.checkpoint.snapshot`) stored for ``--resume``."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    if resume_state is not None:
        ds = ds.assign({RESUME_VARIABLE: _blob_variable(resume_state)})
    ds.to_netcdf(tmp, engine="h5netcdf")
    os.replace(tmp, path)


def open_results(path: str | Path):
    """Load a results file into memory (the file is not kept open), in today's form: a file
    of an earlier format (see :data:`thirdbody.schema.FORMAT_VERSION`) is converted on reading
    (:func:`upgrade`)."""
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return upgrade(ds.load())


def _size_from_config(ds) -> float:
    """The particle's size (m) from the configuration stored in a results dataset (NaN
    without one, or when it cannot be built here, e.g. a moved mesh file)."""
    try:
        from .config import body_from_results

        return float(body_from_results(ds).shape.size)
    except Exception:
        return math.nan


def file_format(ds) -> int:
    """The file format version a results dataset was written in (1: before the attribute)."""
    return int(ds.attrs.get("thirdbody_format", 1))


def upgrade(ds):
    """A results dataset of file format 1 in today's form; others unchanged.

    Format 1 wrote a single particle without the ``particle`` dimension (its maps on metre
    dimensions ``map_x``, ``map_y``) and a layer's maps on cell indices only. The conversion
    adds the ``particle`` dimension (size 1), the step's totals of a layer (``total_force``,
    ``loaded``, the state fractions, the plate's force and moment), ``load_share``, the static
    variables and the event table, and the maps' metre coordinates. A particle's ``size`` is
    not in a format-1 file of one particle: it comes from the stored configuration (NaN if
    that cannot be built). The result says ``upgraded_from_format``."""
    import xarray as xr

    from .. import schema
    from ..records import _dim_attrs, _events_from_arrays

    version = file_format(ds)
    if "step" not in ds.dims:
        return ds       # not a results file (the caller says so)
    if version >= schema.FORMAT_VERSION:
        return _added_variables(ds)
    inputs = json.loads(ds.attrs.get("inputs", "{}"))
    if "particle" not in ds.dims:
        layer_level = {v.name for v in schema.by_kind("step")} & set(ds.data_vars)
        cell = float(inputs.get("cell_size", math.nan))
        out = {}
        rename = {"map_x": "map_i", "map_y": "map_j"}
        for name, var in ds.data_vars.items():
            if name in layer_level or not {"step", "map_step"} & set(var.dims):
                out[name] = (var.dims, var.values, var.attrs)
            else:       # a particle's: the particle dimension after step (map_step)
                dims = [rename.get(d, d) for d in var.dims]
                out[name] = ((dims[0], "particle", *dims[1:]), var.values[:, None],
                             var.attrs)
        coords = {name: (c.dims, c.values, c.attrs) for name, c in ds.coords.items()
                  if name not in rename}
        new = xr.Dataset(out, coords=coords, attrs=dict(ds.attrs))
        if "map_x" in ds.dims:
            new = new.assign_coords(
                map_i=("map_i", np.rint(ds.map_x.values / cell).astype(int),
                       _dim_attrs("map_i")),
                map_j=("map_j", np.rint(ds.map_y.values / cell).astype(int),
                       _dim_attrs("map_j")))
        state = ds.state.values
        unloaded = schema.STATES.index("unloaded")
        loaded = (state != unloaded).astype(np.int64)
        n = np.maximum(loaded, 1)
        F = ds.normal_force.values
        fx, fy = ds.tangential_force.sel(component="x").values, \
            ds.tangential_force.sel(component="y").values
        h = ds.plate_gap.values
        px = ds.position.sel(component="x").values + ds.centroid.sel(
            interface="upper", component="x").values
        py = ds.position.sel(component="y").values + ds.centroid.sel(
            interface="upper", component="y").values
        step_values = {
            "total_force": F, "loaded": loaded,
            "fraction_stick": (state == schema.STATES.index("stick")) * loaded / n,
            "fraction_roll": np.isin(state, [1, 2]) * loaded / n,
            "fraction_rotate": (state == schema.STATES.index("rotate")) * loaded / n,
            "plate_force": np.stack([fx, fy], axis=-1) * loaded[:, None],
            "plate_moment": np.nan_to_num(np.stack([py * F - h * fy, h * fx - px * F],
                                                   axis=-1)) * loaded[:, None],
            "share_error": np.zeros(len(state)),
        }
        for name, values in step_values.items():
            var = schema.VARIABLES[name]
            new[name] = (var.dims, np.asarray(values, dtype=var.dtype), var.attrs)
        new["load_share"] = (("step", "particle"), (F > 0).astype(float)[:, None],
                             schema.VARIABLES["load_share"].attrs)
        static = {"x0": [0.0], "y0": [0.0], "size": [_size_from_config(ds)],
                  "cell_size": [cell], "shape": [str(inputs.get("shape", ""))]}
        for name, values in static.items():
            var = schema.VARIABLES[name]
            new[name] = (var.dims, var.array(values, (1,)), var.attrs)
        events = _events_from_arrays(ds.step.values, [[schema.STATES[c]] for c in state],
                                     ds.turned.values.astype(bool)[:, None], F[:, None],
                                     ds.rotation_angle.values[:, None])
        for name, values in events.items():
            var = schema.VARIABLES[name]
            new[name] = (var.dims, var.array(values, (len(values),)), var.attrs)
        new = new.assign_coords(particle=("particle", [0], _dim_attrs("particle")))
        ds = new
    if "map_i" in ds.dims and "map_x" not in ds.coords:
        cells = ds.cell_size.values
        ds = ds.assign_coords(
            map_x=(("particle", "map_i"), cells[:, None] * ds.map_i.values[None, :],
                   {"units": "m", "long_name": "x of the cell centre (particle frame)"}),
            map_y=(("particle", "map_j"), cells[:, None] * ds.map_j.values[None, :],
                   {"units": "m", "long_name": "y of the cell centre (particle frame)"}))
    return _added_variables(ds).assign_attrs(thirdbody_format=schema.FORMAT_VERSION,
                                             upgraded_from_format=version)


#: per-step and per-particle variables that came with network runs, within format 2: a file
#: written before them holds the layer model's run, whose values they are given when it is read
#: (None: the variable's blank)
_NETWORK_ERA = {"fraction_slide": 0.0, "plate_normal_force": None, "translation": None,
                "particle_contacts": None, "coordination": None, "both_plates_force": None,
                "network_residual": None, "network_iterations": None, "network_substeps": None,
                # sliding plates: a file written before them never slid (plate_shift and
                # sliding_distance 0, mu_eff_sliding and dilatancy NaN); mu_eff from its
                # plate_force and total_force
                "plate_shift": None, "sliding_distance": None, "mu_eff": None,
                "mu_eff_magnitude": None, "mu_eff_sliding": None, "dilatancy": None,
                # the energy balance of a network run's step (NaN before it)
                "plate_work": None, "elastic_energy": None, "dissipation": None,
                "energy_residual": None, "contact_elastic_energy": None,
                "contact_dissipation": None, "contact_shift_increment": None,
                "contact_rolling_i": None, "contact_rolling_j": None}


def _added_variables(ds):
    """``ds`` with the variables of :data:`_NETWORK_ERA` it lacks, as a run of the layer model
    has them today: ``plate_normal_force`` is ``normal_force`` at both plates,
    ``fraction_slide`` 0, ``mu_eff`` (and its magnitude) ``plate_force`` / ``total_force``,
    the others their blank (NaN, or 0 for counts and the plate's shift). Any other missing
    variable stays missing (the reader that needs it says so)."""
    from .. import schema

    if set(ds.dims) - set(schema.DIMENSIONS):
        return ds       # a sweep's summary (its axes are dimensions): it keeps what it has
    added = {}
    for name in _NETWORK_ERA:
        var = schema.VARIABLES[name]
        if name in ds.variables or any(d not in ds.dims for d in var.dims[:2]
                                       if d in ("particle", "contact")):
            continue
        lead = tuple(ds.sizes[d] for d in var.dims[:2 if var.kind == "particle" else 1])
        if var.name == "plate_normal_force" and "normal_force" in ds:
            F = ds.normal_force.transpose("step", "particle").values
            values = np.repeat(F[..., None], 2, axis=-1)
        elif var.name in ("mu_eff", "mu_eff_magnitude") and {"plate_force",
                                                             "total_force"} <= set(ds):
            force = ds.plate_force.transpose("step", "component").values
            total = ds.total_force.values
            rows = [var.derive({"plate_force": f, "total_force": float(t)})
                    for f, t in zip(force, total, strict=True)]
            values = var.array(rows, lead)
        else:
            fill = _NETWORK_ERA.get(var.name)
            count = int(np.prod(lead))
            values = var.array([var.blank() if fill is None else fill] * count, lead)
        added[var.name] = (var.dims, values, var.attrs)
    return ds.assign(added) if added else ds


def _blob_variable(blob: bytes) -> tuple:
    return (("resume_bytes",), np.frombuffer(blob, dtype=np.uint8),
            {"long_name": "pickled state to resume the run"})


def _encode(obj) -> str:
    return base64.b64encode(pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)).decode("ascii")


def _decode(text) -> object:
    return pickle.loads(base64.b64decode(str(text)))


def saved_snapshot(saved) -> tuple[bytes, int]:
    """The complete resume snapshot stored in an unfinished results dataset ``saved`` (as
    written by :func:`run_to_file`, or by an earlier version that stored it in one piece), and
    how many maps entries its per-step history holds (0 for the earlier format)."""
    from ..checkpoint import with_history

    blob = saved[RESUME_VARIABLE].values.tobytes()
    if STEP_HISTORY_VARIABLE not in saved:
        return blob, 0
    records, maps = [], []
    for text in saved[STEP_HISTORY_VARIABLE].values:
        record, new_maps = _decode(text)
        records.append(record)
        maps.extend(new_maps)
    return with_history(blob, records, maps), len(maps)


def _contains(outer: tuple[int, int, int, int], inner: tuple[int, int, int, int]) -> bool:
    return (outer[0] <= inner[0] and outer[1] <= inner[1]
            and inner[0] + inner[2] <= outer[0] + outer[2]
            and inner[1] + inner[3] <= outer[1] + outer[3])


def _padded(frame: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    i0, j0, nx, ny = frame
    mx = max(_MARGIN_CELLS, int(np.ceil(_MARGIN * nx)))
    my = max(_MARGIN_CELLS, int(np.ceil(_MARGIN * ny)))
    return i0 - mx, j0 - my, nx + 2 * mx, ny + 2 * my


class _StepWriter:
    """The per-step checkpoint of :func:`run_to_file`: appends each completed step to the file
    (see the module docstring), or writes it whole when it must."""

    def __init__(self, path: Path, attrs: dict, history: list[str], n_maps: int = 0) -> None:
        self.path, self.attrs = path, attrs
        self.tmp = path.with_name(path.name + ".tmp")
        self.history = list(history)    # _resume_step of the steps saved so far
        self.n_maps = n_maps            # entries of sim.maps in that history
        self.frame: tuple[int, int, int, int] | None = None   # the file's maps window
        self.fresh = True               # nothing saved by this process yet: write whole
        self.load_value_attrs: dict | None = None   # as in the file since the last whole write
        self.whole = 0                  # how many times the dataset was written whole
        self.appended = 0
        self.regrids = 0                # how many times the maps' window grew
        self.seconds = {"whole": 0.0, "append": 0.0}    # wall time saving, by kind

    def __call__(self, sim, state) -> None:
        self.save(sim, sim.snapshot(state, history=False))

    def save(self, sim, blob: bytes) -> None:
        """Save the steps of ``sim`` not saved yet, with the resume snapshot ``blob`` (made
        with ``history=False``)."""
        from ..records import map_frame, maps_step, union_frames

        new_records = sim.records[len(self.history):]
        new_maps = sim.maps[self.n_maps:]
        for record in new_records:      # one, but several when resuming the earlier format
            mine = (new_maps if len(new_records) == 1 else
                    [m for m in new_maps if maps_step(m) == record.step])
            self.history.append(_encode((record, mine)))
        start = time.perf_counter()
        if self.fresh or (new_maps and self.frame is None):
            if sim.maps:
                self.frame = _padded(map_frame(sim.maps))
            self._write_whole(sim, blob)
            self.fresh = False
            self.seconds["whole"] += time.perf_counter() - start
        else:
            old = self.frame
            if new_maps and not _contains(self.frame, map_frame(new_maps)):
                self.frame = _padded(union_frames([old, map_frame(new_maps)]))
            self._append(sim, blob, new_maps, old)
            self.seconds["append"] += time.perf_counter() - start
        self.n_maps = len(sim.maps)

    def _write_whole(self, sim, blob: bytes) -> None:
        ds = sim.dataset(frame=self.frame).assign_attrs(self.attrs)
        self.load_value_attrs = {k: ds["load_value"].attrs[k] for k in ("units", "long_name")}
        ds = ds.assign({
            RESUME_VARIABLE: _blob_variable(blob),
            STEP_HISTORY_VARIABLE: ("step", np.array(self.history, dtype=object),
                                    {"long_name": "pickled record and maps of the step, to "
                                                  "resume the run"}),
        })
        ds.to_netcdf(self.tmp, engine="h5netcdf",
                     unlimited_dims=[d for d in _GROWING if d in ds.dims],
                     encoding={name: {"chunksizes": _chunks(var)}
                               for name, var in ds.variables.items() if var.dims})
        _bound_scales(self.tmp)
        os.replace(self.tmp, self.path)
        self.whole += 1

    def _append(self, sim, blob: bytes, new_maps: list, old_frame) -> None:
        """Copy the file, grow its unlimited dimensions by the new step's rows and write them
        (with h5py: h5netcdf's per-write bookkeeping costs ~0.1 s a step), then rename."""
        import h5py

        record = sim.records[-1]
        tail = _Columns(sim.dataset(records=sim.records[-2:], maps=new_maps, frame=self.frame,
                                    raw=True))
        rows = {"step": np.flatnonzero(tail["step"].values == record.step)}
        if new_maps:
            rows["map_step"] = np.arange(tail.sizes["map_step"])
        if "event" in tail.dims:
            rows["event"] = np.flatnonzero(tail["event_step"].values == record.step)
        if "contact" in tail.dims:
            rows["contact"] = np.flatnonzero(tail["contact_step"].values == record.step)
        shutil.copyfile(self.path, self.tmp)
        with h5py.File(self.tmp, "r+") as f:
            if self.frame != old_frame:
                _regrid(f, tail, old_frame, self.frame)
                self.regrids += 1
            for dim, take in rows.items():
                if not len(take):
                    continue
                n = h5py.h5d.open(f.id, dim.encode()).shape[0]
                names = [name for name, var in tail.variables.items()
                         if var.dims and var.dims[0] == dim]
                if dim not in names:            # a dimension without a coordinate
                    _extend(f, dim, n, None, n + len(take))
                for name in names:
                    _extend(f, name, n, tail.variables[name].values[take])
                if dim == "step":
                    _extend(f, STEP_HISTORY_VARIABLE, n,
                            np.array(self.history[n:], dtype=object))
            units = {k: tail["load_value"].attrs[k] for k in ("units", "long_name")}
            if units != self.load_value_attrs:          # a program mixing force and gap
                f["load_value"].attrs.update(units)
                self.load_value_attrs = units
            _extend(f, "resume_bytes", 0, None, len(blob))
            _extend(f, RESUME_VARIABLE, 0, np.frombuffer(blob, dtype=np.uint8))
        os.replace(self.tmp, self.path)
        self.appended += 1


class _BackgroundWriter:
    """The per-step checkpoint of :func:`run_to_file` with ``background``: a :class:`_StepWriter`
    run in a child process (``python -m thirdbody.io._writer``, a fresh interpreter: nothing of
    this process's threads or locks), so that the simulation computes the next step while the
    last one is written.

    Each step the run sends the child what it needs: the records and maps not sent yet (maps
    only on the steps that store them) and the resume snapshot (the solver state), compressed.
    The whole step goes into the pipe before the run goes on, so nothing waits in this
    process's memory: if the run is killed, only the step in progress is lost. The child
    reports each step it has saved; when it is more than :data:`_MAX_BEHIND` steps behind,
    the run waits for it, so that the file follows the run. The bound holds from the moment the
    child says it is ready (its interpreter started and the writer received, a second or two):
    until then the run goes on, its steps waiting in the pipe, which the child saves even if the
    run is killed. A short run then overlaps its last steps and its own final work with the
    child's start instead of waiting for it.

    The child runs in its own session: Ctrl-C, sent to the terminal's process group, does not
    reach it, and :meth:`close` lets it save every step it was sent. If the run is killed, the
    child still saves the steps in the pipe and exits at its end; it holds ``keep_fds`` (the
    CLI's lock on the output directory) until it is done. An error in the child (a full disk,
    say) is raised in the run at its next step, or by :meth:`close`; if the child dies, the run
    stops with a RuntimeError. Either way the file holds the steps saved before."""

    def __init__(self, writer: _StepWriter, sim, keep_fds: tuple[int, ...] = ()) -> None:
        import subprocess
        import sys

        self.path = writer.path
        self.sent: tuple[int, int] | None = None    # records, maps sent (None: nothing yet)
        self.saved = len(writer.history)             # steps the child has reported saved
        self.stats: dict = {}                        # the child's counters, after close()
        self.seconds = 0.0                           # wall time of the run spent here
        self.frame_bytes: list[int] = []             # the size of each step sent
        self.ready = False                           # the child has received the writer
        start = time.perf_counter()
        self.proc = subprocess.Popen([sys.executable, "-m", "thirdbody.io._writer"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     start_new_session=True, pass_fds=keep_fds)
        self.fd, self.replies = self.proc.stdin.fileno(), self.proc.stdout.fileno()
        _widen(self.fd)
        os.set_blocking(self.fd, False)
        self.backlog = bytearray()      # bytes of the frame being sent that the pipe has not
        self._send(_pickled((writer, _Datasets(sim))))  # taken yet: none once _send returns
        self.seconds += time.perf_counter() - start

    def __call__(self, sim, state) -> None:
        import zlib

        start = time.perf_counter()
        self._check()
        n, m = self.sent or (0, 0)          # the first time: the whole history (a resumed run)
        blob = zlib.compress(sim.snapshot(state, history=False), 1)
        self._send(_pickled((sim.records[n:], sim.maps[m:], blob, sim.status)))
        self.sent = (len(sim.records), len(sim.maps))
        if self.ready:
            self._wait_for(len(sim.records) - _MAX_BEHIND)
        self.seconds += time.perf_counter() - start

    def _send(self, data: bytes) -> None:
        """Put ``data`` into the pipe as one frame, waiting while the pipe is full."""
        import select

        self.backlog += _frame(data)
        self.frame_bytes.append(len(self.backlog))
        while self.backlog:
            try:
                done = os.write(self.fd, self.backlog)
            except BlockingIOError:
                select.select([self.replies], [self.fd], [], 1.0)
                self._check()
                continue
            except OSError:                 # the child is gone
                self._check(wait=True)
                raise
            del self.backlog[:done]

    def _wait_for(self, steps: int) -> None:
        """Wait until the child has saved at least ``steps`` steps."""
        import select

        while self.saved < steps:
            select.select([self.replies], [], [], 1.0)
            self._check()

    def _check(self, wait: bool = False) -> None:
        """Read the child's reports: the steps saved so far; raise its error, if it sent one;
        a RuntimeError if it died."""
        import select

        if wait:
            self.proc.wait()
        while select.select([self.replies], [], [], 0)[0]:
            try:
                kind, value = pickle.loads(_read_frame(self.replies))
            except (EOFError, OSError, pickle.UnpicklingError):
                time.sleep(0.01)        # the child has closed its end: it is exiting
                break
            if kind == "saved":
                self.saved = value
            elif kind == "ready":
                self.ready = True
            elif kind == "error":
                raise value
            elif kind == "done":
                self.stats = value
                return
        if self.proc.poll() is not None:
            raise RuntimeError(f"the process saving the results died (exit code "
                               f"{self.proc.returncode}); {self.path} holds the steps saved "
                               "before")

    def close(self) -> None:
        """Let the child save every step it was sent and exit; raise its error, if any."""
        start = time.perf_counter()
        try:
            self._send(b"")                 # the end
        finally:
            self.proc.stdin.close()
            self.proc.wait()
            self.seconds += time.perf_counter() - start
        try:
            self._check()       # the report, or the error; without either, "died"
        finally:
            self.proc.stdout.close()


class _Datasets:
    """What a :class:`_StepWriter` in another process needs of a Simulation: the records and
    maps so far, the status, and :meth:`dataset` (as :meth:`Simulation.dataset`)."""

    def __init__(self, sim) -> None:
        self.spec = sim.dataset_spec()
        self.records: list = []
        self.maps: list = []
        self.status = "running"

    def dataset(self, records=None, maps=None, frame=None, raw=False):
        return self.spec.build(self.records if records is None else records,
                               self.maps if maps is None else maps, self.status,
                               frame=frame, raw=raw)


def _pickled(item) -> bytes:
    return pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)


def _frame(data: bytes) -> bytes:
    return len(data).to_bytes(8, "little") + data


def _read_exactly(fd: int, n: int) -> bytes:
    parts = []
    while n:
        part = os.read(fd, min(n, 1 << 20))
        if not part:
            raise EOFError
        parts.append(part)
        n -= len(part)
    return b"".join(parts)


def _read_frame(fd: int) -> bytes:
    return _read_exactly(fd, int.from_bytes(_read_exactly(fd, 8), "little"))


def serve(reader: int = 0, replies: int = 1) -> None:
    """The child of :class:`_BackgroundWriter` (``python -m thirdbody.io._writer``): read the
    writer, then save each step the run sends until it sends the end or its end of the pipe
    closes (the run ended or was killed), reporting each step saved on ``replies``; then
    report how it went."""
    import zlib

    import dask
    import h5netcdf  # noqa: F401 - imported while the run computes its first step
    import xarray  # noqa: F401

    busy = 0.0
    try:
        writer, sim = pickle.loads(_read_frame(reader))
        _reply(replies, ("ready", None))
        # xarray takes its write lock from dask's scheduler: a local one here
        with dask.config.set(scheduler="synchronous"):
            while True:
                try:
                    data = _read_frame(reader)
                except EOFError:            # the run was killed: what came in is saved
                    break
                if not data:
                    break
                start = time.perf_counter()
                records, maps, blob, sim.status = pickle.loads(data)
                sim.records.extend(records)
                sim.maps.extend(maps)
                writer.save(sim, zlib.decompress(blob))
                busy += time.perf_counter() - start
                _reply(replies, ("saved", len(sim.records)))
        reply = ("done", {"whole": writer.whole, "appended": writer.appended,
                          "regrids": writer.regrids, "seconds": dict(writer.seconds),
                          "busy": busy})
    except BaseException as exc:            # reported to the run, which raises it
        reply = ("error", exc)
    try:
        pickle.dumps(reply)
    except Exception:                       # an exception that does not pickle
        reply = ("error", RuntimeError(f"saving the results failed: {reply[1]!r}"))
    _reply(replies, reply)


def _reply(replies: int, message: tuple) -> None:
    """Send ``message`` to the run (nobody to tell if it is gone: the steps are saved all the
    same)."""
    data = _frame(pickle.dumps(message))
    try:
        while data:
            data = data[os.write(replies, data):]
    except OSError:
        pass


#: the pipe to the writing child holds this many bytes (Linux's default limit for a user)
_PIPE_BYTES = 1 << 20
#: the run waits for the child when the child is more than this many steps behind
_MAX_BEHIND = 3


def _widen(fd: int) -> None:
    """Enlarge the kernel buffer of the pipe ``fd`` (Linux; elsewhere a no-op). What it holds
    survives the run: the child reads it all even if the run is killed."""
    try:
        import fcntl

        fcntl.fcntl(fd, getattr(fcntl, "F_SETPIPE_SZ", 1031), _PIPE_BYTES)
    except (ImportError, OSError):
        pass


#: rows per HDF5 chunk along a growing dimension (one per map step for the maps): one chunk
#: holds many steps, so that appending a step seldom allocates one
_CHUNK_ROWS = {"step": 64, "event": 64, "contact": 256, "resume_bytes": 1 << 14, "map_step": 1}


def _chunks(var) -> tuple[int, ...]:
    first = var.dims[0]
    rows = _CHUNK_ROWS.get(first, 64 if first in _GROWING else var.shape[0])   # 64: map x, y
    return (max(1, rows), *[max(1, n) for n in var.shape[1:]])


class _Column:
    def __init__(self, entry: tuple) -> None:
        dims = entry[0]
        self.dims = (dims,) if isinstance(dims, str) else tuple(dims)
        self.values = np.asarray(entry[1])
        self.attrs = entry[2] if len(entry) > 2 else {}


class _Columns:
    """The few Dataset features :meth:`_StepWriter._append` needs, on the raw variables of
    :func:`~thirdbody.records.to_dataset` (building a Dataset costs ~4 ms a step)."""

    def __init__(self, raw: dict) -> None:
        self.variables = {name: _Column(entry) for name, entry in raw.items()}
        self.sizes = {d: n for v in self.variables.values()
                      for d, n in zip(v.dims, v.values.shape, strict=True)}
        self.dims = set(self.sizes)

    def __getitem__(self, name: str) -> _Column:
        return self.variables[name]


def _regrid(f, tail, old: tuple[int, int, int, int], new: tuple[int, int, int, int]) -> None:
    """Move the maps of the open h5py file ``f`` from the lattice window ``old`` to ``new``
    (cells (i0, j0, nx, ny); zeros where ``new`` goes beyond ``old``, cropped where it is
    smaller) and write the new window's coordinates (cell indices and metres), taken from
    ``tail`` (a dataset on ``new``)."""
    ydim, xdim = _MAP_DIMS
    di, dj = old[0] - new[0], old[1] - new[1]       # old cell (0, 0) in the new window
    xs = slice(max(0, -di), min(old[2], new[2] - di))
    ys = slice(max(0, -dj), min(old[3], new[3] - dj))
    for name, var in tail.variables.items():
        if var.dims[-2:] != (ydim, xdim):
            continue
        d = f[name]
        values = d[...]
        moved = np.zeros((*values.shape[:-2], new[3], new[2]), dtype=values.dtype)
        moved[..., ys.start + dj:ys.stop + dj, xs.start + di:xs.stop + di] = values[..., ys, xs]
        d.resize(moved.shape)
        d[...] = moved
    for dim in (ydim, xdim):
        d = f[dim]
        d.resize(tail.sizes[dim], axis=0)
        d[...] = tail[dim].values
    for name in _MAP_COORDS:
        d = f[name]
        d.resize(tail[name].values.shape)
        d[...] = tail[name].values


#: the length up to which a growing dimension's scale can be extended (see _bound_scales)
_MAX_ROWS = 1 << 40


def _bound_scales(path: Path) -> None:
    """Give the scale of each growing dimension in the file ``path`` a finite maximum length
    instead of an unlimited one; the variables along it stay unlimited.

    Why: for an unlimited dimension, h5netcdf finds the length by dereferencing every
    variable along it, and it does so each time it asks a variable for its shape, so that
    xarray's opening costs (variables along ``step``)² dereferences: 2-10 s for an unfinished
    results file against a few tens of ms for h5netcdf to read the step count. A bounded
    scale's length is its own, read at once; appending extends it with the variables."""
    import h5py

    with h5py.File(path, "r+") as f:
        for dim in _GROWING:
            if dim not in f or f[dim].maxshape != (None,):
                continue
            old = f[dim]
            attached = [(f[ref], int(axis)) for ref, axis in old.attrs.get("REFERENCE_LIST", [])]
            for var, axis in attached:
                var.dims[axis].detach_scale(old)
            name = old.attrs["NAME"]
            attrs = [(k, old.attrs[k], old.attrs.get_id(k).dtype) for k in old.attrs
                     if k not in ("CLASS", "NAME", "REFERENCE_LIST")]
            data, chunks = old[...], old.chunks
            del f[dim]
            new = f.create_dataset(dim, data=data, maxshape=(_MAX_ROWS,), chunks=chunks)
            new.make_scale(name.decode("ascii") if isinstance(name, bytes) else str(name))
            for k, value, dtype in attrs:
                new.attrs.create(k, value, dtype=dtype)
            for var, axis in attached:
                var.dims[axis].attach_scale(new)


def _extend(f, name: str, n: int, rows: np.ndarray | None, total: int | None = None) -> None:
    """Resize dataset ``name`` of the open h5py file ``f`` along its first axis to ``n`` +
    len(``rows``) (or ``total``) and write ``rows`` from index ``n`` on (h5py's low-level API:
    its high-level one costs ~0.3 ms a dataset)."""
    import h5py

    d = h5py.h5d.open(f.id, name.encode())
    shape = d.shape
    total = n + len(rows) if total is None else total
    d.set_extent((total, *shape[1:]))
    if rows is None:
        return
    if rows.dtype.kind in "UO":                 # variable-length strings: the high-level API
        f[name][n:] = rows.astype(object)
        return
    rows = np.ascontiguousarray(rows, dtype=rows.dtype)
    space = d.get_space()
    space.select_hyperslab((n, *[0] * (len(shape) - 1)), rows.shape)
    d.write(h5py.h5s.create_simple(rows.shape), space, rows)


def run_to_file(sim, path: str | Path, *, resume: bool = False,
                progress: Callable | None = None, attrs: dict | None = None,
                background: bool = False, keep_fds: tuple[int, ...] = ()):
    """Run ``sim``, saving ``path`` after every step; with ``resume`` continue the run saved
    there. ``attrs`` are added to the file's global attributes. Returns the final dataset.

    With ``background``, each step is written by a child process while the next one is
    computed (see :class:`_BackgroundWriter`; what ``thirdbody run`` does): saving then costs
    the run about 1 ms a step instead of 5-25 ms, on a machine with a core to spare. The child
    inherits the file descriptors ``keep_fds`` (a lock to hold until it is done)."""
    path = Path(path)
    blob, history, n_maps = None, [], 0
    if resume:
        if not path.exists():
            raise FileNotFoundError(f"nothing to resume: {path} does not exist")
        saved = open_results(path)
        if RESUME_VARIABLE not in saved:
            raise ValueError(f"{path} holds a finished run ({saved.attrs.get('status')}); "
                             "nothing to resume")
        if "upgraded_from_format" in saved.attrs:
            raise ValueError(f"{path} was written by an earlier thirdbody (file format "
                             f"{saved.attrs['upgraded_from_format']}): it can be read, not "
                             "resumed; run the configuration again into a new directory")
        blob, n_maps = saved_snapshot(saved)
        if STEP_HISTORY_VARIABLE in saved:    # else an earlier version's file: all anew
            history = [str(t) for t in saved[STEP_HISTORY_VARIABLE].values]

    extra = dict(attrs or {})
    writer = _StepWriter(path, extra, history, n_maps)
    if not background:
        ds = sim.run(progress=progress, checkpoint=writer, resume_from=blob)
    else:
        child = _BackgroundWriter(writer, sim, keep_fds)
        try:
            ds = sim.run(progress=progress, checkpoint=child, resume_from=blob)
        except BaseException:
            try:
                child.close()   # what was computed is saved
            except Exception:   # the run's own exception says more
                pass
            raise
        child.close()
    ds = ds.assign_attrs(extra)
    write_results(ds, path)     # whole: a compact file, in the layout xarray writes
    return ds
