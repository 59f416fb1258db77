"""What a simulation records, in one table: every per-step variable with its dimensions, units
and long name, and the assembly of the records and maps into an :class:`xarray.Dataset`.

Dimensions: ``step``; ``interface`` = ("upper", "lower"); ``component`` = ("x", "y") for
horizontal vectors; ``quaternion_component`` = ("x", "y", "z", "w"). Maps live on ``map_step``,
``interface`` (and ``component``), ``map_y``, ``map_x``; their coordinates are the lattice cell
centres in the particle frame (m), covering every stored contact.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._version import __version__

__all__ = ["INTERFACES", "MAP_VARIABLES", "STATES", "VARIABLES", "StepMaps", "StepRecord",
           "Variable", "orientation_label", "to_dataset"]

#: State codes stored in the results (``state`` variable, with ``flag_values``/``flag_meanings``).
STATES = ("stick", "roll_upper", "roll_lower", "rotate", "failed")
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
    _v("load_value", "", "N or 1", "prescribed load: F_N (N) or compression ratio (1)"),
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
    _v("ratio", "interface", "1", "F_T / (mu F_N) at the final orientation"),
    _v("centroid", "interface component", "m", "pressure centroid (particle frame)"),
    _v("approach", "interface", "m", "approach of the plate from its first contact with the "
                                     "surface cells"),
    _v("contact_area", "interface", "m2", "contact area"),
    _v("stick_area", "interface", "m2", "stick area"),
    _v("spots", "interface", "1", "number of separate contact spots"),
    _v("position", "component", "m", "horizontal displacement of the particle centroid"),
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


@dataclass
class StepRecord:
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

    def __getattr__(self, name: str) -> Any:
        values = self.__dict__.get("values")
        if values is not None and name in values:
            return values[name]
        raise AttributeError(name)

    def __getstate__(self) -> dict:
        return self.__dict__

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)


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


def _union(maps: list[StepMaps]) -> tuple[int, int, int, int]:
    i0 = min(w[0] for m in maps for w in m.windows.values())
    j0 = min(w[1] for m in maps for w in m.windows.values())
    i1 = max(w[0] + w[2] for m in maps for w in m.windows.values())
    j1 = max(w[1] + w[3] for m in maps for w in m.windows.values())
    return i0, j0, i1 - i0, j1 - j0


def _place(field: np.ndarray, window: tuple[int, int, int, int],
           frame: tuple[int, int, int, int], fill: float = 0.0) -> np.ndarray:
    i0, j0, nx, ny = frame
    out = np.full((*field.shape[:-2], ny, nx), fill, dtype=field.dtype)
    wi, wj, wnx, wny = window
    out[..., wj - j0:wj - j0 + wny, wi - i0:wi - i0 + wnx] = field
    return out


def to_dataset(records: list[StepRecord], maps: list[StepMaps], cell_size: float,
               inputs: dict, status: str, attrs: dict | None = None):
    """Assemble the results: per-step variables along ``step`` (and their own dimensions),
    maps along ``map_step`` on the union of the stored contact windows."""
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
                         {"long_name": "load control: force or compression"})
    coords: dict[str, Any] = {"step": ("step", steps, {"long_name": "load step index"})}
    used = {d for v in VARIABLES for d in v.dims}
    if maps:
        used |= {"interface", "component"}
    for d in sorted(used):
        coords[d] = (d, COORDS[d])
    if maps:
        frame = _union(maps)
        i0, j0, nx, ny = frame
        coords["map_step"] = ("map_step", np.array([m.step for m in maps], dtype=int),
                              {"long_name": "load step of the stored maps"})
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
