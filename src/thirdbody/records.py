"""What a simulation records, in one table: every per-step variable with its dimensions, units
and long name, and the assembly of the records and maps into an :class:`xarray.Dataset`.

Dimensions: ``step``; ``interface`` = ("upper", "lower"); ``component`` = ("x", "y") for
horizontal vectors; ``quaternion_component`` = ("x", "y", "z", "w"). Maps live on ``map_step``,
``interface`` (and ``component``), ``map_y``, ``map_x``; their coordinates are the lattice cell
centres in the particle frame (m), covering every stored contact.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._version import __version__

__all__ = ["INTERFACES", "LAYER_VARIABLES", "MAP_VARIABLES", "STATES", "VARIABLES",
           "DatasetSpec", "LayerRecord", "StepMaps", "StepRecord", "Variable", "direction_sign",
           "has_maps", "layer_dataset", "map_frame", "maps_step", "orientation_label",
           "to_dataset", "union_frames"]

#: State codes stored in the results (``state`` variable, with ``flag_values``/``flag_meanings``).
STATES = ("stick", "roll_upper", "roll_lower", "rotate", "failed", "unloaded")
STATE_CODE = {name: i for i, name in enumerate(STATES)}
INTERFACES = ("upper", "lower")
COMPONENTS = ("x", "y")


@dataclass(frozen=True)
class Variable:
    """A recorded quantity: its dimensions besides ``step``, units and long name."""

    name: str
    dims: tuple[str, ...]
    units: str
    long_name: str


def _v(name: str, dims: str, units: str, long_name: str) -> Variable:
    return Variable(name, tuple(dims.split()) if dims else (), units, long_name)


#: every per-step variable (the record's fields are exactly these names)
VARIABLES: tuple[Variable, ...] = (
    _v("load_value", "", "N", "prescribed load: F_N (N) or compression ratio (1), see load_kind"),
    _v("normal_force", "", "N", "normal force F_N on each plate"),
    _v("plate_gap", "", "m", "plate separation h"),
    _v("compression", "", "1", "compression ratio (d0 - h) / d0"),
    _v("quaternion", "quaternion_component", "1",
       "orientation at the end of the step: unit quaternion (x, y, z, w), body to world"),
    _v("orientation", "component", "degree",
       "tilt vector at the end of the step: tilt angle times its horizontal axis (the paper's "
       "theta about +y is the y component)"),
    _v("tilt", "", "degree", "tilt angle of the body z axis from the vertical"),
    _v("tilt_azimuth", "", "degree", "azimuth of the tilt axis, from +x towards +y"),
    _v("yaw", "", "degree", "rotation about the body z axis before the tilt"),
    _v("rotation", "component", "degree",
       "rotation vector of the turn in this step (horizontal components)"),
    _v("rotation_angle", "", "degree", "angle turned in this step"),
    _v("state", "", "1", "what the particle did in the step"),
    _v("turned", "", "1", "the particle turned in this step"),
    _v("balanced", "", "1", "the turn ended at a balance of the couple, not inside the "
                            "friction limit"),
    _v("tangential_force", "component", "N",
       "F' = F_N (r_up - r_low) / h: force of the lower plate on the particle"),
    _v("demand_ratio", "interface", "1", "|F'| / (mu F_N) at the step's starting orientation"),
    _v("ratio", "interface", "1",
       "|F_T| / (mu F_N) at the final orientation: a magnitude, >= 0 (the state plot and the "
       "sweep summary sign it by the direction of F' against its first non-zero direction)"),
    _v("centroid", "interface component", "m", "pressure centroid (particle frame)"),
    _v("approach", "interface", "m", "approach of the plate from its first contact with the "
                                     "surface cells"),
    _v("contact_area", "interface", "m2", "contact area"),
    _v("stick_area", "interface", "m2", "stick area"),
    _v("spots", "interface", "1", "number of separate contact spots"),
    _v("position", "component", "m", "horizontal displacement of the particle centroid"),
    _v("centroid_height", "", "m", "height of the particle's centroid above the lower plate"),
    _v("slip", "interface component", "m",
       "accumulated slip of the particle over the plate while turning"),
    _v("shift", "interface component", "m",
       "rigid tangential shift of the plate in partial slip, since the last turn"),
    _v("normal_iterations", "interface", "1", "normal solver iterations"),
    _v("tangential_iterations", "interface", "1", "tangential solver CG iterations"),
    _v("normal_residual", "interface", "1", "normal solver complementarity residual"),
    _v("tangential_residual", "interface", "1", "Coulomb residual"),
    _v("force_residual", "", "1", "|F_up - F_low| / F_N from the pressure fields"),
    _v("tangential_force_residual", "", "1", "|T_up + T_low| / F_N from the traction fields"),
    _v("moment_residual", "", "1",
       "|F_N (r_up - r_low) + h T_up| / (F_N h) from the fields: tilting moment balance"),
    _v("twist_moment", "", "N m",
       "moment about z of the tractions of both plates about the centroid"),
    _v("twist_ratio", "", "1", "|twist_moment| / (max(mu) F_N a), a the contact radius"),
    _v("twist_angle", "", "degree",
       "rotation of the particle about z relative to the plates since the last turn, from "
       "balancing twist_moment (0 when it was below twist_tol)"),
    _v("turn_evaluations", "", "1", "orientations evaluated in the step"),
    _v("time_total", "", "s", "wall time of the step"),
    _v("time_normal", "", "s", "wall time in normal solves"),
    _v("time_tangential", "", "s", "wall time in tangential solves"),
    _v("time_geometry", "", "s", "wall time computing the surfaces (vertical rays)"),
)
_NAMES = tuple(v.name for v in VARIABLES)
_FLAGS = {"turned", "balanced"}
_COUNTS = {"spots", "normal_iterations", "tangential_iterations", "turn_evaluations"}

#: map variables: name -> (dimensions between interface and the map axes, units, long name)
MAP_VARIABLES: dict[str, tuple[tuple[str, ...], str, str]] = {
    "pressure": ((), "Pa", "contact pressure"),
    "traction": (("component",), "Pa", "traction of the plate on the particle"),
    "status": ((), "1", "0 open, 1 stick, 2 slip"),
}

#: coordinates of the record dimensions
COORDS = {"interface": list(INTERFACES), "component": list(COMPONENTS),
           "quaternion_component": ["x", "y", "z", "w"]}


class _Values:
    """Attribute access to ``values``: ``record.plate_gap`` reads ``record.values["plate_gap"]``
    (and pickling that does not recurse through it)."""

    def __getattr__(self, name: str) -> Any:
        values = self.__dict__.get("values")
        if values is not None and name in values:
            return values[name]
        raise AttributeError(name)

    def __getstate__(self) -> dict:
        return self.__dict__

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)


@dataclass
class StepRecord(_Values):
    """The per-step variables of :data:`VARIABLES` for one completed step.

    ``values`` maps each name to a number or, for variables with dimensions, a tuple (interface
    order upper, lower; components x, y). Attribute access reads ``values``: ``r.plate_gap``.
    """

    step: int
    load_kind: str
    values: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        missing = set(_NAMES) - set(self.values)
        extra = set(self.values) - set(_NAMES)
        if missing or extra:
            raise ValueError(f"record fields do not match the table: missing {sorted(missing)}, "
                             f"unknown {sorted(extra)}")

    def __str__(self) -> str:
        """One line for progress output (``sim.run(progress=print)``): the step, F_N (N), the
        state, the orientation and |F_T|/(μ_low F_N); the full record is ``repr``."""
        return (f"step {self.step}: F_N {self.values['normal_force']:.4g} N, "
                f"{self.values['state']}, {orientation_label(self)}, "
                f"F_T/μF_N {self.values['ratio'][1]:.3f}")



def orientation_label(record: StepRecord) -> str:
    """A short text for a record's orientation: "θ 20.00°" for a tilt about +y (the paper's
    angle), else "tilt 20.00° @ 30°" (angle and axis azimuth)."""
    x, y = record.values["orientation"]
    if abs(x) < 1e-9:
        return f"θ {y:.2f}°"
    return f"tilt {record.values['tilt']:.2f}° @ {record.values['tilt_azimuth']:.0f}°"


@dataclass
class StepMaps:
    """Fields of one step around its contacts, per interface ("upper", "lower").

    ``windows[side]`` is (i0, j0, nx, ny) on the lattice of spacing Δ; ``pressure[side]`` and
    ``status[side]`` are (ny, nx), ``traction[side]`` is (2, ny, nx).
    """

    step: int
    windows: dict[str, tuple[int, int, int, int]]
    pressure: dict[str, np.ndarray]
    traction: dict[str, np.ndarray]
    status: dict[str, np.ndarray]


def union_frames(frames) -> tuple[int, int, int, int]:
    """The smallest window (i0, j0, nx, ny) of lattice cells holding every window of
    ``frames``."""
    frames = list(frames)
    i0 = min(w[0] for w in frames)
    j0 = min(w[1] for w in frames)
    i1 = max(w[0] + w[2] for w in frames)
    j1 = max(w[1] + w[3] for w in frames)
    return i0, j0, i1 - i0, j1 - j0


def _union(maps: list[StepMaps]) -> tuple[int, int, int, int]:
    return union_frames(w for m in maps for w in m.windows.values())


def has_maps(entry) -> bool:
    """Whether a stored maps entry holds a map: a particle's :class:`StepMaps`, or a layer's
    per-particle list of them (None for a particle without one)."""
    if isinstance(entry, list | tuple):
        return any(m is not None for m in entry)
    return entry is not None


def maps_step(entry) -> int:
    """The load step of a stored maps entry that :func:`has_maps`."""
    if isinstance(entry, list | tuple):
        return next(m for m in entry if m is not None).step
    return entry.step


@dataclass(frozen=True)
class DatasetSpec:
    """What turns a run's records and maps into its results dataset, besides themselves: a
    particle's cell size, or a layer and its particles' cell sizes, and the run's inputs
    (picklable: a process writing the results elsewhere builds the same dataset)."""

    single: bool
    cell_size: float
    layer: Any
    cell_sizes: list[float]
    inputs: dict

    def build(self, records: list, maps: list, status: str,
              frame: tuple[int, int, int, int] | None = None, raw: bool = False):
        """:func:`to_dataset` (a particle) or :func:`layer_dataset` (a layer)."""
        if self.single:
            return to_dataset(records, maps, self.cell_size, self.inputs, status, frame=frame,
                              raw=raw)
        return layer_dataset(records, maps, self.layer, self.cell_sizes, self.inputs, status,
                             frame=frame, raw=raw)


def map_frame(maps: list) -> tuple[int, int, int, int]:
    """The cells (i0, j0, nx, ny) that hold every stored map window: of a particle's
    :class:`StepMaps`, or of a layer's per-step lists of them (None where not stored)."""
    flat = [m for entry in maps for m in (entry if isinstance(entry, list | tuple) else [entry])
            if m is not None]
    return _union(flat)


def _place(field: np.ndarray, window: tuple[int, int, int, int],
           frame: tuple[int, int, int, int], fill: float = 0.0) -> np.ndarray:
    i0, j0, nx, ny = frame
    out = np.full((*field.shape[:-2], ny, nx), fill, dtype=field.dtype)
    wi, wj, wnx, wny = window
    out[..., wj - j0:wj - j0 + wny, wi - i0:wi - i0 + wnx] = field
    return out


def direction_sign(tangential_force: np.ndarray) -> np.ndarray:
    """+1/−1 per step: whether F' (steps, 2; N) points along its first non-zero direction of the
    run (+1) or against it (−1); +1 where F' is zero or at right angles to it.

    The state plot and the sweep summary sign ``ratio`` (a magnitude) with it, so that a run
    whose lower plate ends up pushing the other way shows a negative ratio in both."""
    f = np.asarray(tangential_force, dtype=float).reshape(-1, 2)
    norms = np.hypot(f[:, 0], f[:, 1])
    first = np.flatnonzero(norms > 0)
    if not first.size:
        return np.ones(len(f))
    sign = np.sign(f @ (f[first[0]] / norms[first[0]]))
    return np.where(sign == 0, 1.0, sign)


_STEP_ATTRS = {"units": "1", "long_name": "load step index (from 0)"}
_MAP_STEP_ATTRS = {"units": "1", "long_name": "load step index of the stored maps"}
_LOAD_KIND_ATTRS = {"units": "1", "long_name": "load control: force (load_value in N) or "
                                               "compression (load_value a ratio)"}


def _load_value_attrs(records) -> dict:
    """units and long_name of ``load_value``: N under force control, 1 under compression
    control (a load program is one or the other)."""
    if records and all(r.load_kind == "compression" for r in records):
        return {"units": "1", "long_name": "prescribed compression ratio (d0 - h) / d0"}
    return {"units": "N", "long_name": "prescribed normal force F_N"}


def to_dataset(records: list[StepRecord], maps: list[StepMaps], cell_size: float,
               inputs: dict, status: str, attrs: dict | None = None,
               frame: tuple[int, int, int, int] | None = None, raw: bool = False):
    """Assemble the results: per-step variables along ``step`` (and their own dimensions),
    maps along ``map_step`` on the union of the stored contact windows (or on ``frame``, cells
    (i0, j0, nx, ny), which must hold them: a results file being appended to uses a frame with
    room to grow). With ``raw``, the variables as a dict name: (dims, values[, attrs]), without
    building the Dataset (a results file appending a step needs only those)."""
    import xarray as xr

    steps = np.array([r.step for r in records], dtype=int)
    data = {}
    for var in VARIABLES:
        values = [r.values[var.name] for r in records]
        attrs_v = {"units": var.units, "long_name": var.long_name}
        if var.name == "state":
            arr = np.array([STATE_CODE[v] for v in values], dtype=np.int8)
            attrs_v.update(flag_values=np.arange(len(STATES), dtype=np.int8),
                           flag_meanings=" ".join(STATES))
        else:
            shape = (len(records), *[len(COORDS[d]) for d in var.dims])
            dtype = np.int8 if var.name in _FLAGS else np.int64 if var.name in _COUNTS \
                else float
            arr = np.array(values, dtype=dtype).reshape(shape)
        data[var.name] = (("step", *var.dims), arr, attrs_v)
    data["load_kind"] = ("step", np.array([r.load_kind for r in records], dtype=str),
                         _LOAD_KIND_ATTRS)
    data["load_value"][2].update(_load_value_attrs(records))
    coords: dict[str, Any] = {"step": ("step", steps, _STEP_ATTRS)}
    used = {d for v in VARIABLES for d in v.dims}
    if maps:
        used |= {"interface", "component"}
    for d in sorted(used):
        coords[d] = (d, COORDS[d])
    if maps:
        frame = _union(maps) if frame is None else frame
        i0, j0, nx, ny = frame
        coords["map_step"] = ("map_step", np.array([m.step for m in maps], dtype=int),
                              _MAP_STEP_ATTRS)
        coords["map_x"] = ("map_x", (i0 + np.arange(nx)) * cell_size,
                           {"units": "m", "long_name": "x of the cell centre (particle frame)"})
        coords["map_y"] = ("map_y", (j0 + np.arange(ny)) * cell_size,
                           {"units": "m", "long_name": "y of the cell centre (particle frame)"})
        for name, (dims, units, long_name) in MAP_VARIABLES.items():
            stacked = np.stack([np.stack([_place(getattr(m, name)[side], m.windows[side],
                                                 frame) for side in INTERFACES])
                                for m in maps])
            data[name] = (("map_step", "interface", *dims, "map_y", "map_x"), stacked,
                          {"units": units, "long_name": long_name})
    if raw:
        return {**data, **coords}
    all_attrs = {
        "title": "thirdbody: deformable particle between two plates",
        "thirdbody_version": __version__,
        "inputs": json.dumps(inputs),
        "status": status,
        "conventions": "SI units; x, y horizontal, z up, particle frame (centroid at the "
                       "origin); orientation as a tilt vector in degrees (the paper's theta "
                       "about +y is its y component); tractions are exerted by the plate on "
                       "the particle; interface order upper, lower",
    }
    all_attrs.update(attrs or {})
    return xr.Dataset(data, coords=coords, attrs=all_attrs)


# --- layers ------------------------------------------------------------------------------------
#: per-step variables of a layer (along ``step`` only)
LAYER_VARIABLES: tuple[Variable, ...] = (
    _v("load_value", "", "N", "prescribed load: F_N (N) or compression ratio (1), see load_kind"),
    _v("total_force", "", "N", "total normal force F_N on each plate"),
    _v("plate_gap", "", "m", "plate separation h (force-weighted mean over the loaded "
                             "particles)"),
    _v("compression", "", "1", "compression ratio (d0 - h) / d0, d0 the tallest particle's "
                               "height"),
    _v("loaded", "", "1", "number of particles the plates press"),
    _v("fraction_stick", "", "1", "fraction of the loaded particles that stuck"),
    _v("fraction_roll", "", "1", "fraction of the loaded particles that rolled (about either "
                                 "plate)"),
    _v("fraction_rotate", "", "1", "fraction of the loaded particles that rotated about their "
                                   "centroid"),
    _v("plate_force", "component", "N",
       "net tangential force of the particles on the upper plate (minus that on the lower)"),
    _v("plate_moment", "component", "N m",
       "tilting moment of the particles' forces on the upper plate, about the origin on the "
       "lower plate"),
    _v("share_error", "", "1", "largest error of a particle's share of F_N accepted by the "
                               "load sharing in the step (converged: <= 1e-7)"),
    _v("time_total", "", "s", "wall time of the step"),
)
#: record variables that belong to the layer, not to a particle
_LAYER_ONLY = {"load_value", "plate_gap", "compression", "time_total"}


@dataclass
class LayerRecord(_Values):
    """One completed step of a layer: the per-particle :class:`StepRecord` objects (layer
    order) and the layer's variables (:data:`LAYER_VARIABLES`). ``error`` is set when the step
    ended with two particles touching."""

    step: int
    load_kind: str
    particles: list[StepRecord]
    values: dict[str, Any] = field(default_factory=dict)
    error: str | None = None

    def __str__(self) -> str:
        """One line for progress output: the step, the total F_N (N), how many particles are
        loaded and what fractions of them stick, roll and rotate."""
        v = self.values
        return (f"step {self.step}: F_N {v['total_force']:.4g} N, {v['loaded']} loaded: "
                f"{v['fraction_stick']:.0%} stick, {v['fraction_roll']:.0%} roll, "
                f"{v['fraction_rotate']:.0%} rotate")


    @classmethod
    def from_particles(cls, k: int, step, gap: float, d0: float, records: list[StepRecord],
                       layer, time_total: float, share_error: float = 0.0) -> LayerRecord:
        """The layer's variables from its particles' records (``gap``, ``d0``: m; the wall
        time of the step, s; the largest share error accepted by the load sharing)."""
        total = math.fsum(r.normal_force for r in records)
        loaded = [r for r in records if r.state != "unloaded"]
        n = max(len(loaded), 1)
        terms = []                      # (F'_x, F'_y, M_x, M_y) of each loaded particle
        for r, placed in zip(records, layer, strict=True):
            if r.state == "unloaded":
                continue
            F, (fx, fy) = r.normal_force, r.tangential_force
            px = placed.xy[0] + r.position[0] + r.centroid[0][0]
            py = placed.xy[1] + r.position[1] + r.centroid[0][1]
            terms.append((fx, fy, py * F - r.plate_gap * fy, r.plate_gap * fx - px * F))
        fx, fy, mx, my = (math.fsum(t[c] for t in terms) for c in range(4))
        force, moment = (fx, fy), (mx, my)
        values = dict(
            load_value=step.value, total_force=total, plate_gap=gap,
            compression=(d0 - gap) / d0, loaded=len(loaded),
            fraction_stick=sum(r.state == "stick" for r in loaded) / n,
            fraction_roll=sum(r.state in ("roll_upper", "roll_lower") for r in loaded) / n,
            fraction_rotate=sum(r.state == "rotate" for r in loaded) / n,
            plate_force=tuple(float(v) for v in force),
            plate_moment=tuple(float(v) for v in moment), share_error=share_error,
            time_total=time_total)
        return cls(k, step.kind, records, values)


def _array(var: Variable, values: list, lead: tuple[int, ...]) -> tuple[np.ndarray, dict]:
    attrs_v = {"units": var.units, "long_name": var.long_name}
    if var.name == "state":
        arr = np.array([STATE_CODE[v] for v in values], dtype=np.int8).reshape(lead)
        attrs_v.update(flag_values=np.arange(len(STATES), dtype=np.int8),
                       flag_meanings=" ".join(STATES))
        return arr, attrs_v
    shape = (*lead, *[len(COORDS[d]) for d in var.dims])
    dtype = np.int8 if var.name in _FLAGS else np.int64 if var.name in _COUNTS | {"loaded"} \
        else float
    return np.array(values, dtype=dtype).reshape(shape), attrs_v


#: what the events table records
EVENTS = ("loaded", "unloaded", "roll_upper", "roll_lower", "rotate", "rolled_off")


def _events(records: list[LayerRecord]) -> list[tuple[str, np.ndarray, dict]]:
    """The events table, one row per event, in step then particle order: a particle is loaded
    or unloaded (compared with the step before; at step 0 every loaded particle is), or turns
    (the state in which it turned, with the angle; ``rolled_off`` if it turned until it lost
    its load)."""
    rows = []
    previous = None
    for r in records:
        for i, p in enumerate(r.particles):
            loaded = p.state != "unloaded"
            was = previous[i] if previous is not None else False
            if loaded != was:
                rows.append((r.step, i, "loaded" if loaded else "unloaded", p.normal_force))
            if p.turned:
                rows.append((r.step, i, p.state if loaded else "rolled_off", p.rotation_angle))
        previous = [p.state != "unloaded" for p in r.particles]
    return [
        ("event_step", np.array([row[0] for row in rows], dtype=np.int64),
         {"long_name": "load step of the event"}),
        ("event_particle", np.array([row[1] for row in rows], dtype=np.int64),
         {"long_name": "particle of the event"}),
        ("event_kind", np.array([row[2] for row in rows], dtype=str),
         {"long_name": "one of " + ", ".join(EVENTS)}),
        ("event_value", np.array([row[3] for row in rows], dtype=float),
         {"units": "N or degree", "long_name": "the normal force when loaded or unloaded "
                                                "(N); the angle turned (degree)"}),
    ]


def layer_dataset(records: list[LayerRecord], maps: list[list[StepMaps | None]], layer,
                  cell_sizes: list[float], inputs: dict, status: str,
                  attrs: dict | None = None, frame: tuple[int, int, int, int] | None = None,
                  raw: bool = False):
    """Assemble a layer's results: layer variables along ``step``, per-particle variables along
    (``step``, ``particle``), maps along (``map_step``, ``particle``) on a lattice of each
    particle's own cells (``map_i``, ``map_j``: cell indices from its centroid; x = ``x0`` +
    ``position`` + ``map_i`` · ``cell_size``; the union of the stored windows, or ``frame``
    as in :func:`to_dataset`; ``raw`` as there)."""
    import xarray as xr

    n = len(layer)
    steps = np.array([r.step for r in records], dtype=int)
    data: dict[str, Any] = {}
    for var in LAYER_VARIABLES:
        arr, a = _array(var, [r.values[var.name] for r in records], (len(records),))
        data[var.name] = (("step", *var.dims), arr, a)
    for var in VARIABLES:
        if var.name in _LAYER_ONLY:
            continue
        values = [p.values[var.name] for r in records for p in r.particles]
        arr, a = _array(var, values, (len(records), n))
        data[var.name] = (("step", "particle", *var.dims), arr, a)
    F = np.array([[p.normal_force for p in r.particles] for r in records]).reshape(-1, n)
    totals = np.array([[r.values["total_force"]] for r in records]).reshape(-1, 1)
    data["load_share"] = (("step", "particle"),
                          np.divide(F, totals, out=np.zeros_like(F), where=totals > 0),
                          {"units": "1", "long_name": "the particle's share of F_N"})
    data["load_kind"] = ("step", np.array([r.load_kind for r in records], dtype=str),
                         _LOAD_KIND_ATTRS)
    data["load_value"][2].update(_load_value_attrs(records))
    for name, values, attrs_e in _events(records):
        data[name] = ("event", values, attrs_e)
    pos = layer.positions
    data["x0"] = ("particle", pos[:, 0], {"units": "m", "long_name": "initial centroid x"})
    data["y0"] = ("particle", pos[:, 1], {"units": "m", "long_name": "initial centroid y"})
    data["size"] = ("particle", np.array([p.particle.shape.size for p in layer]),
                    {"units": "m", "long_name": "particle size: largest centroid-to-surface "
                                                "distance"})
    data["cell_size"] = ("particle", np.array(cell_sizes, dtype=float),
                         {"units": "m", "long_name": "the particle's BEM cell size"})
    data["shape"] = ("particle", np.array([repr(p.particle.shape) for p in layer], dtype=str),
                     {"long_name": "shape"})
    coords: dict[str, Any] = {
        "step": ("step", steps, _STEP_ATTRS),
        "particle": ("particle", np.arange(n), {"long_name": "particle index (layer order)"}),
    }
    for d in ("interface", "component", "quaternion_component"):
        coords[d] = (d, COORDS[d])
    stored = [(maps_step(m_list), m_list) for m_list in maps if has_maps(m_list)]
    if stored:
        i0, j0, nx, ny = map_frame(maps) if frame is None else frame
        coords["map_step"] = ("map_step", np.array([s for s, _ in stored], dtype=int),
                              _MAP_STEP_ATTRS)
        coords["map_i"] = ("map_i", i0 + np.arange(nx),
                           {"long_name": "cell index along x from the particle's centroid"})
        coords["map_j"] = ("map_j", j0 + np.arange(ny),
                           {"long_name": "cell index along y from the particle's centroid"})
        for name, (dims, units, long_name) in MAP_VARIABLES.items():
            blank = np.zeros((len(INTERFACES), *([2] if dims else []), ny, nx),
                             dtype=np.int8 if name == "status" else float)
            stacked = np.stack([
                np.stack([blank if m is None else
                          np.stack([_place(getattr(m, name)[side], m.windows[side],
                                           (i0, j0, nx, ny)) for side in INTERFACES])
                          for m in m_list])
                for _, m_list in stored])
            data[name] = (("map_step", "particle", "interface", *dims, "map_j", "map_i"),
                          stacked, {"units": units, "long_name": long_name})
    if raw:
        return {**data, **coords}
    all_attrs = {
        "title": "thirdbody: a layer of deformable particles between two plates",
        "thirdbody_version": __version__,
        "inputs": json.dumps(inputs),
        "status": status,
        "conventions": "SI units; x, y horizontal, z up; per-particle vectors in the particle's "
                       "frame (centroid at the origin) unless stated; orientation as a tilt "
                       "vector in degrees; tractions are exerted by the plate on the particle; "
                       "interface order upper, lower; unloaded particles have state 'unloaded' "
                       "and NaN where a quantity is undefined",
    }
    all_attrs.update(attrs or {})
    return xr.Dataset(data, coords=coords, attrs=all_attrs)
