"""What a step records, and the results dataset built from the records.

Every variable is declared once, in :mod:`thirdbody.schema`; this module computes the values
(:func:`particle_record` from a particle's solves, :func:`unloaded_record` for a particle the
plates do not press, :meth:`LayerRecord.from_particles` for the plates' totals) and assembles
them, with the maps, into one dataset form (:meth:`DatasetSpec.build`): a single particle is a
layer of one, with a ``particle`` dimension of size 1. :func:`particle_view` gives one particle's
variables without that dimension, maps on their metre coordinates.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import schema
from ._version import __version__
from .particle.interface import surface_approach
from .rigid import RigidState
from .schema import INTERFACES, SLIDING, STATES

#: the states that count as rolling (``fraction_roll``)
ROLLING = ("roll_upper", "roll_lower", "roll")

__all__ = ["INTERFACES", "STATES", "DatasetSpec", "LayerRecord", "StepMaps", "StepRecord",
           "direction_sign", "has_maps", "map_frame", "maps_step", "orientation_label",
           "particle_record", "particle_view", "step_maps", "union_frames", "unloaded_record"]


def _particle_names() -> set[str]:
    """The per-particle variables a :class:`StepRecord` holds (not derived from the others;
    ``load_share`` is the layer's to set)."""
    return {v.name for v in schema.by_kind("particle")
            if v.derive is None and v.name != "load_share"}


class _Values:
    """Attribute access to ``values``: ``record.state`` reads ``record.values["state"]`` (and
    pickling that does not recurse through it)."""

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
    """One particle's per-step variables (:mod:`thirdbody.schema`, kind "particle").

    ``values`` maps each name to a number or, for variables with dimensions, a tuple (interface
    order upper, lower; components x, y). ``gap`` is the plate gap (m) the particle was solved
    at (its own, within the load sharing's tolerance of the layer's). Attribute access reads
    ``values``: ``r.state``.
    """

    step: int
    load_kind: str
    values: dict[str, Any] = field(default_factory=dict)
    gap: float = math.nan

    def __post_init__(self) -> None:
        names = _particle_names()
        missing = names - set(self.values)
        extra = set(self.values) - names - {v.name for v in schema.by_kind("particle")}
        if missing or extra:
            raise ValueError(f"record fields do not match the schema: missing "
                             f"{sorted(missing)}, unknown {sorted(extra)}")

    def __str__(self) -> str:
        """One line for progress output: the step, F_N (N), the state, the orientation and
        |F_T|/(μ_low F_N); the full record is ``repr``."""
        return (f"step {self.step}: F_N {self.values['normal_force']:.4g} N, "
                f"{self.values['state']}, {orientation_label(self)}, "
                f"F_T/μF_N {self.values['ratio'][1]:.3f}")


def orientation_label(record: StepRecord) -> str:
    """A short text for a record's orientation: "θ 20.00°" for a tilt about +y (the paper's
    angle), else "tilt 20.00° @ 30°" (angle and axis azimuth)."""
    if isinstance(record, LayerRecord):
        record = record.particles[0]
    x, y = record.values["orientation"]
    if abs(x) < 1e-9:
        return f"θ {y:.2f}°"
    return f"tilt {record.values['tilt']:.2f}° @ {record.values['tilt_azimuth']:.0f}°"


# --- computing the values ----------------------------------------------------------------------
def _pose(rotation) -> dict:
    from .orientation import decompose

    tilt = decompose(rotation)
    return dict(quaternion=tuple(float(v) for v in rotation.as_quat()),
                orientation=tilt.vector_deg, tilt=tilt.angle_deg,
                tilt_azimuth=tilt.azimuth_deg, yaw=tilt.yaw_deg)


def _turn(rotation, start_rotation) -> dict:
    turn = (rotation * start_rotation.inv()).as_rotvec()
    return dict(rotation=(math.degrees(turn[0]) + 0.0, math.degrees(turn[1]) + 0.0),
                rotation_angle=math.degrees(float(np.linalg.norm(turn))))


def particle_record(k: int, step, plates, ev0, ev, kind: RigidState, balanced: bool,
                    start_rotation, tangential: dict, state, evaluations: int) -> StepRecord:
    """A loaded particle's variables in step ``k`` (``step``: the load step), with the balances
    recomputed from the fields.

    ``ev0``, ``ev``: its normal equilibria at the step's start and end (:class:`Evaluation`);
    ``kind``: what it did; ``tangential``: its tangential steps ("up", "low"); ``state``: its
    :class:`~thirdbody.state.ParticleState` after the step; ``evaluations``: the
    orientations evaluated."""
    mu = {"up": plates.mu_up, "low": plates.mu_low}
    F, h = ev.force, ev.gap
    t = {"up": tangential["up"], "low": tangential["low"]}
    sols = {"up": ev.up, "low": ev.low}

    def ratio(side: str, demand: float) -> float:
        return demand / mu[side] if mu[side] > 0 else math.nan

    force, first, twist = {}, {}, 0.0
    for side, sol in sols.items():
        X, Y = sol.contact.grid.mesh()
        dA = sol.contact.grid.cell_area
        p = sol.contact.pressure
        force[side] = float(p.sum() * dA)
        first[side] = np.array([(p * X).sum(), (p * Y).sum()]) * dA
        tau = t[side].traction
        twist += float((X * tau[1] - Y * tau[0]).sum() * dA)
    T_up, T_low = t["up"].force, t["low"].force
    offset = first["up"] / force["up"] - first["low"] / force["low"]
    moment = F * offset + h * T_up
    radius = math.sqrt(max(s.contact.area for s in sols.values()) / math.pi)
    mu_max = max(mu.values())
    sides = ("up", "low")
    values = dict(
        normal_force=F, plate_normal_force=(F, F), **_pose(ev.rotation),
        **_turn(ev.rotation, start_rotation),
        state=kind.value, turned=kind is not RigidState.STICK, balanced=balanced,
        tangential_force=(float(ev.demand_force[0]), float(ev.demand_force[1])),
        demand_ratio=tuple(ratio(s, ev0.demand) for s in sides),
        ratio=tuple(ratio(s, ev.demand) for s in sides),
        centroid=tuple(sols[s].centroid for s in sides),
        approach=tuple(surface_approach(sols[s]) for s in sides),
        contact_area=tuple(sols[s].contact.area for s in sides),
        stick_area=tuple(t[s].stick_area for s in sides),
        spots=tuple(sols[s].spots for s in sides),
        position=tuple(state.position), centroid_height=-ev.low.plate,
        slip=(tuple(state.slip_up), tuple(state.slip_low)),
        shift=tuple(tuple(float(v) for v in t[s].shift) for s in sides),
        normal_iterations=tuple(sols[s].contact.iterations for s in sides),
        tangential_iterations=tuple(t[s].iterations for s in sides),
        normal_residual=tuple(sols[s].contact.residual for s in sides),
        tangential_residual=tuple(t[s].residual for s in sides),
        force_residual=abs(force["up"] - force["low"]) / F,
        tangential_force_residual=float(np.hypot(*(T_up + T_low))) / F,
        moment_residual=float(np.hypot(*moment)) / (F * h),
        twist_moment=twist,
        twist_ratio=abs(twist) / (mu_max * F * radius) if mu_max > 0 else 0.0,
        twist_angle=-math.degrees(t["up"].twist) + 0.0,
        turn_evaluations=evaluations,
        time_normal=0.0, time_tangential=0.0, time_geometry=0.0,
        translation=schema.VARIABLES["translation"].blank(),      # a network run's
    )
    return StepRecord(k, step.kind, values, gap=h)


def unloaded_record(k: int, step, gap: float, state, start_rotation, turned: bool,
                    lowest: float) -> StepRecord:
    """The record of a particle the plates do not press (shorter than the gap ``gap``, m): the
    schema's blanks (no force, no contact, NaN where a quantity is undefined) and its pose.
    ``turned``: it turned in the step before it lost its load (from ``start_rotation``);
    ``lowest``: the height of its lowest point in the particle frame (m)."""
    values = {name: schema.VARIABLES[name].blank() for name in _particle_names()}
    values.update(**_pose(state.rotation), **_turn(state.rotation, start_rotation),
                  turned=turned, position=tuple(state.position), centroid_height=-lowest,
                  slip=(tuple(state.slip_up), tuple(state.slip_low)))
    return StepRecord(k, step.kind, values, gap=gap)


@dataclass
class LayerRecord(_Values):
    """One completed step: each particle's :class:`StepRecord` (layer order) and the step's
    variables (:mod:`thirdbody.schema`, kind "step"). ``error`` is set when the step ended with
    two particles touching. For a run of one particle, attribute access also reads the
    particle's variables: ``r.state``, ``r.ratio``."""

    step: int
    load_kind: str
    particles: list[StepRecord]
    values: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    #: a network run's contacts in the step (rows of the ``contact`` table, each a dict of the
    #: schema's kind "contact" variables); None for the layer model without particle contacts
    contacts: list[dict] | None = None

    def __getattr__(self, name: str) -> Any:
        values = self.__dict__.get("values")
        if values is not None and name in values:
            return values[name]
        particles = self.__dict__.get("particles")
        if particles is not None and len(particles) == 1 and name in particles[0].values:
            return particles[0].values[name]
        raise AttributeError(name)

    def __str__(self) -> str:
        """One line for progress output: for one particle its line (:class:`StepRecord`);
        else the step, the total F_N (N), how many particles are loaded and what fractions of
        them stick, roll and rotate."""
        if len(self.particles) == 1:
            return str(self.particles[0])
        v = self.values
        return (f"step {self.step}: F_N {v['total_force']:.4g} N, {v['loaded']} loaded: "
                f"{v['fraction_stick']:.0%} stick, {v['fraction_roll']:.0%} roll, "
                f"{v['fraction_rotate']:.0%} rotate")

    @classmethod
    def from_particles(cls, k: int, step, gap: float, d0: float, records: list[StepRecord],
                       layer, time_total: float, share_error: float = 0.0) -> LayerRecord:
        """The step's variables from its particles' records (``gap``, ``d0``: m; the wall time
        of the step, s; the largest share error accepted by the load sharing); sets each
        particle's ``load_share`` and its derived variables."""
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
            terms.append((fx, fy, py * F - r.gap * fy, r.gap * fx - px * F))
        fx, fy, mx, my = (math.fsum(t[c] for t in terms) for c in range(4))
        for r in records:
            r.values["load_share"] = r.normal_force / total if total > 0 else 0.0
        values = dict(
            load_value=step.value, load_kind=step.kind, total_force=total, plate_gap=gap,
            compression=(d0 - gap) / d0, loaded=len(loaded),
            fraction_stick=sum(r.state == "stick" for r in loaded) / n,
            fraction_roll=sum(r.state in ROLLING for r in loaded) / n,
            fraction_rotate=sum(r.state == "rotate" for r in loaded) / n,
            fraction_slide=sum(r.state in SLIDING for r in loaded) / n,
            plate_force=(float(fx), float(fy)), plate_moment=(float(mx), float(my)),
            share_error=share_error, time_total=time_total)
        for var in schema.by_kind("step"):          # the network's, for this model: blank
            if var.derive is None and var.name not in values:
                values[var.name] = var.blank()
        for var in schema.VARIABLES.values():
            if var.derive is None:
                continue
            if var.kind == "particle":
                for r in records:
                    r.values[var.name] = var.derive(r.values)
            elif var.kind == "step":
                values[var.name] = var.derive(values)
        return cls(k, step.kind, records, values)


# --- maps --------------------------------------------------------------------------------------
@dataclass
class StepMaps:
    """Fields of one particle in one step around its contacts, per interface ("upper",
    "lower").

    ``windows[side]`` is (i0, j0, nx, ny) on the particle's lattice of spacing Δ (cell indices
    from its centroid); ``pressure[side]`` and ``status[side]`` are (ny, nx), ``traction[side]``
    is (2, ny, nx).
    """

    step: int
    windows: dict[str, tuple[int, int, int, int]]
    pressure: dict[str, np.ndarray]
    traction: dict[str, np.ndarray]
    status: dict[str, np.ndarray]


def step_maps(k: int, ev, tangential: dict) -> StepMaps:
    """A loaded particle's fields at both plates in step ``k`` (``ev``: its normal equilibrium,
    ``tangential``: its tangential steps "up", "low") on the bounding box of their contacts,
    one free cell around."""
    windows, pressure, traction, status = {}, {}, {}, {}
    for side, sol, t in (("upper", ev.up, tangential["up"]), ("lower", ev.low, tangential["low"])):
        c = sol.contact.contact
        rows, cols = np.flatnonzero(c.any(axis=1)), np.flatnonzero(c.any(axis=0))
        j0, j1 = max(rows[0] - 1, 0), min(rows[-1] + 2, c.shape[0])
        i0, i1 = max(cols[0] - 1, 0), min(cols[-1] + 2, c.shape[1])
        w = sol.window
        windows[side] = (w.i0 + int(i0), w.j0 + int(j0), int(i1 - i0), int(j1 - j0))
        pressure[side] = sol.contact.pressure[j0:j1, i0:i1].copy()
        traction[side] = t.traction[:, j0:j1, i0:i1].copy()
        status[side] = np.where(t.stick, 1, np.where(t.slip, 2, 0)).astype(np.int8)[j0:j1,
                                                                                     i0:i1]
    return StepMaps(k, windows, pressure, traction, status)


def union_frames(frames) -> tuple[int, int, int, int]:
    """The smallest window (i0, j0, nx, ny) of lattice cells holding every window of
    ``frames``."""
    frames = list(frames)
    i0 = min(w[0] for w in frames)
    j0 = min(w[1] for w in frames)
    i1 = max(w[0] + w[2] for w in frames)
    j1 = max(w[1] + w[3] for w in frames)
    return i0, j0, i1 - i0, j1 - j0


def has_maps(entry) -> bool:
    """Whether a stored maps entry (a step's per-particle list of :class:`StepMaps`, None for a
    particle without one) holds a map."""
    if isinstance(entry, list | tuple):
        return any(m is not None for m in entry)
    return entry is not None


def maps_step(entry) -> int:
    """The load step of a stored maps entry that :func:`has_maps`."""
    if isinstance(entry, list | tuple):
        return next(m for m in entry if m is not None).step
    return entry.step


def map_frame(maps: list) -> tuple[int, int, int, int]:
    """The cells (i0, j0, nx, ny) that hold every stored map window of the per-step lists of
    :class:`StepMaps` (None where not stored)."""
    flat = [m for entry in maps for m in (entry if isinstance(entry, list | tuple) else [entry])
            if m is not None]
    return union_frames(w for m in flat for w in m.windows.values())


def _place(values: np.ndarray, window: tuple[int, int, int, int],
           frame: tuple[int, int, int, int], fill: float = 0.0) -> np.ndarray:
    i0, j0, nx, ny = frame
    out = np.full((*values.shape[:-2], ny, nx), fill, dtype=values.dtype)
    wi, wj, wnx, wny = window
    out[..., wj - j0:wj - j0 + wny, wi - i0:wi - i0 + wnx] = values
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


# --- the dataset -------------------------------------------------------------------------------
def _load_value_attrs(records) -> dict:
    """units and long_name of ``load_value``: N under force control, 1 under compression
    control (a load program is one or the other)."""
    if records and all(r.load_kind == "compression" for r in records):
        return {"units": "1", "long_name": "prescribed compression ratio (d0 - h) / d0"}
    return {"units": "N", "long_name": "prescribed normal force F_N"}


def _events(records: list[LayerRecord]) -> dict[str, list]:
    """The event table of the records (:func:`_events_from_arrays`)."""
    return _events_from_arrays(
        [r.step for r in records], [[p.state for p in r.particles] for r in records],
        [[p.turned for p in r.particles] for r in records],
        [[p.normal_force for p in r.particles] for r in records],
        [[p.rotation_angle for p in r.particles] for r in records])


def _events_from_arrays(steps, states, turned, normal_force, rotation_angle) -> dict[str, list]:
    """The event table, one row per event, in step then particle order: a particle is loaded
    or unloaded (compared with the step before; at step 0 every loaded particle is), or turns
    (the state in which it turned, with the angle; ``rolled_off`` if it turned until it lost
    its load). Arguments per step (and particle): step index, state names, turned, normal
    force (N), angle turned (degree)."""
    rows = []
    previous = None
    for k, step in enumerate(steps):
        for i, state in enumerate(states[k]):
            loaded = state != "unloaded"
            was = previous[i] if previous is not None else False
            if loaded != was:
                rows.append((int(step), i, "loaded" if loaded else "unloaded",
                             float(normal_force[k][i])))
            if turned[k][i]:
                rows.append((int(step), i, state if loaded else "rolled_off",
                             float(rotation_angle[k][i])))
        previous = [s != "unloaded" for s in states[k]]
    names = ("event_step", "event_particle", "event_kind", "event_value")
    return {name: [row[c] for row in rows] for c, name in enumerate(names)}


@dataclass(frozen=True)
class DatasetSpec:
    """What turns a run's records and maps into its results dataset, besides themselves: the
    layer, its particles' cell sizes (m) and the run's inputs (picklable: a process writing
    the results elsewhere builds the same dataset)."""

    layer: Any
    cell_sizes: list[float]
    inputs: dict

    def build(self, records: list[LayerRecord], maps: list, status: str,
              frame: tuple[int, int, int, int] | None = None, raw: bool = False,
              attrs: dict | None = None):
        """The results: the step's variables along ``step``, each particle's along (``step``,
        ``particle``), maps along (``map_step``, ``particle``) on each particle's lattice
        (``map_i``, ``map_j``: cell indices from its centroid; ``map_x``, ``map_y``: the cell
        centres in m, particle frame), on the union of the stored windows or on ``frame``
        (cells (i0, j0, nx, ny), which must hold them: a results file being appended to uses a
        frame with room to grow). With ``raw``, the variables as a dict name: (dims, values,
        attrs), without building the Dataset (a results file appending a step needs only
        those)."""
        import xarray as xr

        layer, n = self.layer, len(self.layer)
        lead = {"step": (len(records),), "particle": (len(records), n)}
        data: dict[str, Any] = {}
        for var in schema.VARIABLES.values():
            if var.kind == "step":
                values = [r.values[var.name] for r in records]
            elif var.kind == "particle":
                values = [p.values[var.name] for r in records for p in r.particles]
            else:
                continue
            data[var.name] = (var.dims, var.array(values, lead[var.kind]), var.attrs)
        data["load_value"][2].update(_load_value_attrs(records))
        for name, values in _events(records).items():
            var = schema.VARIABLES[name]
            data[name] = (var.dims, var.array(values, (len(values),)), var.attrs)
        network = [r for r in records if getattr(r, "contacts", None) is not None]
        if network:
            rows = [row for r in network for row in r.contacts]
            for var in schema.by_kind("contact"):
                data[var.name] = (var.dims, var.array([row[var.name] for row in rows],
                                                      (len(rows),)), var.attrs)
        static = {"x0": layer.positions[:, 0], "y0": layer.positions[:, 1],
                  "size": [p.particle.shape.size for p in layer],
                  "cell_size": self.cell_sizes,
                  "shape": [repr(p.particle.shape) for p in layer]}
        for name, values in static.items():
            var = schema.VARIABLES[name]
            data[name] = (var.dims, var.array(list(values), (n,)), var.attrs)
        coords: dict[str, Any] = {
            "step": ("step", np.array([r.step for r in records], dtype=int),
                     _dim_attrs("step")),
            "particle": ("particle", np.arange(n), _dim_attrs("particle")),
        }
        for d in ("interface", "component", "quaternion_component", "xyz"):
            coords[d] = (d, list(schema.DIMENSIONS[d].labels), _dim_attrs(d))
        stored = [(maps_step(m_list), m_list) for m_list in maps if has_maps(m_list)]
        if stored:
            self._maps(stored, map_frame(maps) if frame is None else frame, data, coords)
        if raw:
            return {**data, **coords}
        all_attrs = {
            "title": "thirdbody: deformable particles between two plates",
            "thirdbody_version": __version__,
            "thirdbody_format": schema.FORMAT_VERSION,
            "inputs": json.dumps(self.inputs),
            "status": status,
            "conventions": "SI units; x, y horizontal, z up; per-particle vectors in the "
                           "particle's frame (centroid at the origin) unless stated; orientation "
                           "as a tilt vector in degrees (the paper's theta about +y is its y "
                           "component); tractions are exerted by the plate on the particle; "
                           "interface order upper, lower; unloaded particles have state "
                           "'unloaded' and NaN where a quantity is undefined",
        }
        all_attrs.update(attrs or {})
        return xr.Dataset(data, coords=coords, attrs=all_attrs)

    def _maps(self, stored: list, frame: tuple[int, int, int, int], data: dict,
              coords: dict) -> None:
        i0, j0, nx, ny = frame
        cells = np.asarray(self.cell_sizes, dtype=float)
        coords["map_step"] = ("map_step", np.array([s for s, _ in stored], dtype=int),
                              _dim_attrs("map_step"))
        coords["map_i"] = ("map_i", i0 + np.arange(nx), _dim_attrs("map_i"))
        coords["map_j"] = ("map_j", j0 + np.arange(ny), _dim_attrs("map_j"))
        coords["map_x"] = (("particle", "map_i"), cells[:, None] * (i0 + np.arange(nx)),
                           {"units": "m", "long_name": "x of the cell centre (particle frame)"})
        coords["map_y"] = (("particle", "map_j"), cells[:, None] * (j0 + np.arange(ny)),
                           {"units": "m", "long_name": "y of the cell centre (particle frame)"})
        for name in ("pressure", "traction", "status"):
            var = schema.VARIABLES[name]
            blank = np.full((len(INTERFACES), *([2] if "component" in var.dims else []), ny, nx),
                            var.fill, dtype=var.dtype)
            stacked = np.stack([
                np.stack([blank if m is None else
                          np.stack([_place(getattr(m, name)[side], m.windows[side], frame)
                                    for side in INTERFACES])
                          for m in m_list])
                for _, m_list in stored])
            data[name] = (var.dims, stacked, var.attrs)


def _dim_attrs(name: str) -> dict:
    d = schema.DIMENSIONS[name]
    return {"long_name": d.long_name, **({"units": d.units} if d.units else {})}


def particle_view(ds, particle: int = 0):
    """One particle's results without the ``particle`` dimension (what the one-particle figures
    read): the step's and the particle's variables, its maps on the metre coordinates
    ``map_x``, ``map_y`` (particle frame) as their dimensions, and its static variables."""
    view = ds.isel(particle=particle)
    if "map_i" in view.dims:
        view = view.swap_dims({"map_i": "map_x", "map_j": "map_y"})
    return view
