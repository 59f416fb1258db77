"""The quasi-static driver: a deformable particle squeezed between two plates, step by step.

For each load step (DESIGN.md §3, the paper's eqs 6-11):

1. Statics (:mod:`thirdbody.particle.statics`): normal contact at both plates, every spot
   included, under the step's normal force F_N (or, under gap control, the F_N that gives the
   prescribed plate gap h) at the current orientation; the pressure centroids give the force
   F' = F_N (r̄_up − r̄_low)/h the lower plate must exert for the particle to stay put.
2. If |F'| <= μ_min F_N the particle sticks: each interface solves the incremental partial-slip
   problem with its prescribed tangential force (±F'), carrying the previous step's traction.
3. Otherwise it turns (:mod:`thirdbody.particle.turning`) to the first stable orientation, about
   the horizontal axis of its couple; the tangential history restarts. With unequal μ it rolls
   about the higher-friction interface's stick zone; with equal μ it rotates about its
   centroid (:func:`thirdbody.rigid.classify`). The centroid's horizontal position and the slip
   at each plate are integrated along the turn.

Any failure inside a step (no stable orientation, a solver that does not converge, bad geometry)
ends the run as a failed step: :meth:`Simulation.run` returns the completed steps with a
``status`` saying why. All quantities are SI; angles in the results are degrees.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field

import numpy as np

from .bem import ConvergenceError, TangentialContact
from .checkpoint import restore, snapshot
from .loading import LoadProgram, LoadStep
from .orientation import Rotation, decompose
from .particle.interface import InterfaceNormal, Window
from .particle.model import Particle, Plates
from .particle.statics import Evaluation, PairStatics
from .particle.turning import find_stable_orientation, turn_kinematics
from .records import STATES, StepMaps, StepRecord, to_dataset
from .rigid import RigidState, classify

__all__ = ["STATES", "ParticleState", "Simulation", "SimulationError", "StepMaps", "StepRecord"]


class SimulationError(RuntimeError):
    """A step could not be completed (no stable orientation, a solver failure)."""


@dataclass
class ParticleState:
    """Everything one particle carries from one step to the next (what a resume needs).

    ``position`` and the slips are horizontal 2-vectors (m); ``history`` holds each interface's
    last tangential step and its window; ``force_guess`` the last normal force (N) found under
    gap control.
    """

    rotation: Rotation
    position: np.ndarray = field(default_factory=lambda: np.zeros(2))
    slip_up: np.ndarray = field(default_factory=lambda: np.zeros(2))
    slip_low: np.ndarray = field(default_factory=lambda: np.zeros(2))
    history: dict[str, tuple[Window, TangentialContact]] = field(default_factory=dict)
    force_guess: float | None = None


class Simulation:
    """A particle between two plates under a load program.

    Parameters
    ----------
    particle : Particle
    plates : Plates
    load : LoadProgram
        See :mod:`thirdbody.loading`.
    resolution : float
        Cells per particle size (the largest centroid-to-surface distance): the cell size is
        ``shape.size / resolution`` (m). Ignored if ``cell_size`` is given.
    cell_size : float, optional
        Cell size Δ, m.
    tol : float
        Tolerance of the normal and tangential solvers (dimensionless residuals).
    angle_step_deg, angle_tol_deg : float
        Turning: march step and the bisection tolerance on the final orientation, degrees.
    maps_every : int
        Store the pressure/traction/status maps every k-th step (and always the last one);
        0 stores none.
    classification : {"statics", "paper"}
        How a both-interfaces-exceeded demand is read with unequal μ
        (:func:`thirdbody.rigid.classify`).
    twist_tol : float
        Largest twisting moment about z left unbalanced, relative to max(μ) F_N a (a the contact
        radius); above it the particle's twist relative to the plates is solved for (``inf``:
        never). The tilting couple's lever arms never twist (F' is parallel to the offset of the
        pressure centroids); the tractions of non-symmetric or multi-spot contacts can.
    """

    #: fewest cells across the contact at the largest load that :meth:`preflight` accepts
    MIN_CONTACT_CELLS = 8

    def __init__(self, particle: Particle, plates: Plates, load: LoadProgram, *,
                 resolution: float = 80.0, cell_size: float | None = None,
                 tol: float = 1e-8, angle_step_deg: float = 1.0, angle_tol_deg: float = 0.01,
                 maps_every: int = 5, classification: str = "statics",
                 twist_tol: float = 1e-3) -> None:
        from ._validate import positive, real

        if not isinstance(particle, Particle):
            raise TypeError("particle must be a thirdbody.Particle")
        if not isinstance(plates, Plates):
            raise TypeError("plates must be a thirdbody.Plates")
        if not isinstance(load, LoadProgram):
            raise TypeError("load must be a load program from thirdbody.loading")
        if classification not in ("statics", "paper"):
            raise ValueError(f"classification must be 'statics' or 'paper', got "
                             f"{classification!r}")
        if isinstance(maps_every, bool) or not isinstance(maps_every, int) or maps_every < 0:
            raise ValueError(f"maps_every must be an integer >= 0, got {maps_every!r}")
        self.particle, self.plates, self.load = particle, plates, load
        shape = particle.shape
        self.cell_size = (positive("cell_size (m)", cell_size) if cell_size is not None
                          else shape.size / positive("resolution (cells per particle size)",
                                                     resolution))
        self.resolution = shape.size / self.cell_size
        self.tol = positive("tol", tol)
        self.angle_step = math.radians(positive("angle_step_deg (degrees)", angle_step_deg))
        self.angle_tol = math.radians(positive("angle_tol_deg (degrees)", angle_tol_deg))
        self.maps_every = maps_every
        self.classification = classification
        self.twist_tol = math.inf if twist_tol == math.inf else real(
            "twist_tol", twist_tol, "[0, inf]", lambda x: x >= 0)
        self.schedule: list[LoadStep] = load.schedule()
        self.d0 = shape.height(particle.orientation)
        self.statics = PairStatics(shape, particle.material, self.cell_size, self.tol)
        self.records: list[StepRecord] = []
        self.maps: list[StepMaps] = []
        self.status = "not run"

    # --- inputs, for the results file ------------------------------------------------------
    def inputs(self) -> dict:
        """The run's inputs as plain data (stored as attributes of the results)."""
        mat = self.particle.material
        return {
            "shape": repr(self.particle.shape),
            "E": mat.E, "nu": mat.nu, "orientation_deg": self.particle.orientation_deg,
            "tilt_axis_deg": self.particle.tilt_axis_deg, "yaw_deg": self.particle.yaw_deg,
            "quaternion": [float(v) for v in self.particle.orientation.as_quat()],
            "mu_up": self.plates.mu_up, "mu_low": self.plates.mu_low,
            "load": {"program": type(self.load).__name__, **asdict(self.load)},
            "cell_size": self.cell_size, "resolution": self.resolution, "tol": self.tol,
            "angle_step_deg": math.degrees(self.angle_step),
            "angle_tol_deg": math.degrees(self.angle_tol),
            "maps_every": self.maps_every, "classification": self.classification,
            "twist_tol": self.twist_tol, "d0": self.d0,
        }

    @property
    def interfaces(self):
        """The two plates' :class:`~thirdbody.particle.interface.Interface` objects."""
        return self.statics.interfaces

    # --- the physics of one step -------------------------------------------------------------
    def _stable(self, ev: Evaluation) -> bool:
        return ev.demand <= self.plates.mu_min

    def _classify(self, ev: Evaluation) -> RigidState:
        return classify(ev.demand, self.plates.mu_up, self.plates.mu_low,
                        classification=self.classification, mu_rtol=self.plates.mu_rtol)

    def _evaluate(self, rotation: Rotation, step: LoadStep, state: ParticleState) -> Evaluation:
        ev = self.statics.evaluate(rotation, step, self.d0, state.force_guess)
        if step.kind == "compression":
            state.force_guess = ev.force
        return ev

    def preflight(self) -> int:
        """Solve the largest load at the initial orientation once and check the resolution.
        Returns the contact's extent in cells.

        Raises ValueError (naming ``resolution``) when the contact at the largest load spans
        fewer than :attr:`MIN_CONTACT_CELLS` cells: the solution would not be resolved.
        Raises :class:`SimulationError` when that load cannot be solved at all.
        """
        step = max(self.schedule, key=lambda s: s.value)
        state = ParticleState(self.particle.orientation)
        try:
            ev = self._evaluate(self.particle.orientation, step, state)
        except Exception as exc:
            raise SimulationError(f"the largest load cannot be solved: {exc}") from exc
        finally:
            for i in self.interfaces.values():
                i.last = None
        extent = 0
        for sol in (ev.up, ev.low):
            c = sol.contact.contact
            rows, cols = np.flatnonzero(c.any(axis=1)), np.flatnonzero(c.any(axis=0))
            extent = max(extent, rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1)
        if extent < self.MIN_CONTACT_CELLS:
            needed = self.resolution * self.MIN_CONTACT_CELLS / max(extent, 1)
            raise ValueError(
                f"resolution (cells per particle size) {self.resolution:.4g} is too coarse: the "
                f"contact at the largest load spans {extent} cells; use at least {needed:.0f}")
        return int(extent)

    def step(self, k: int, state: ParticleState) -> tuple[StepRecord, StepMaps | None]:
        """Run load step ``k`` from ``state`` (updated in place). Raises on failure."""
        step = self.schedule[k]
        t_start = time.perf_counter()
        normal0, geometry0 = self.statics.normal_time, self.statics.geometry_time
        start_rotation = state.rotation
        ev0 = self._evaluate(state.rotation, step, state)
        kind, balanced, evaluations = RigidState.STICK, False, 1
        final = ev0
        if not self._stable(ev0):
            kind = self._classify(ev0)
            turn = find_stable_orientation(
                ev0, lambda r: self._evaluate(r, step, state), self.plates.mu_min,
                self.angle_step, self.angle_tol)
            final, balanced, evaluations = turn.final, turn.balanced, turn.evaluations
            moved = turn_kinematics([*turn.path, final], self._classify)
            state.position = state.position + moved.position
            state.slip_up = state.slip_up + moved.slip_up
            state.slip_low = state.slip_low + moved.slip_low
            state.history.clear()
            state.rotation = final.rotation
        t_tangential = time.perf_counter()
        tangential = self._tangential(final, state)
        t_tangential = time.perf_counter() - t_tangential
        record = self._record(k, step, ev0, final, kind, balanced, start_rotation, tangential,
                              state, evaluations)
        record.values.update(
            time_normal=self.statics.normal_time - normal0,
            time_geometry=self.statics.geometry_time - geometry0,
            time_tangential=t_tangential, time_total=time.perf_counter() - t_start)
        maps = None
        if self.maps_every and (k % self.maps_every == 0 or k == len(self.schedule) - 1):
            maps = _maps(k, final, tangential)
        return record, maps

    def _tangential(self, ev: Evaluation, state: ParticleState) -> dict[str, TangentialContact]:
        """Partial slip at both plates with the forces ±F'; if the tractions leave a twisting
        moment about z above ``twist_tol`` (relative to max(μ) F_N a), the particle's twist
        relative to the plates becomes an unknown, found by Illinois iterations on the total
        moment (monotone in the twist)."""
        # the plates can transmit at most μ_min F_N; only a balanced turn ends beyond it
        cap = self.plates.mu_min * ev.force
        demand = ev.demand_force
        norm = math.hypot(*demand)
        if norm > cap:
            demand = demand * (cap / norm) if norm > 0 else demand
        sides = (("low", ev.low, 1.0, self.plates.mu_low), ("up", ev.up, -1.0, self.plates.mu_up))

        def solve(twist: float | None) -> dict[str, TangentialContact]:
            out = {}
            for side, sol, sign, mu in sides:
                force = (sign * float(demand[0]) + 0.0, sign * float(demand[1]) + 0.0)
                out[side] = self.interfaces[side].solve_tangential(
                    sol, mu, force, state.history.get(side), twist=twist)
            return out

        out = solve(None)
        mu_max = max(self.plates.mu_up, self.plates.mu_low)
        radius = math.sqrt(max(ev.up.contact.area, ev.low.contact.area) / math.pi)
        scale = mu_max * ev.force * radius

        def moment(t: dict[str, TangentialContact]) -> float:
            return t["up"].moment + t["low"].moment

        m0 = moment(out)
        if scale > 0 and abs(m0) > self.twist_tol * scale:
            out = self._balance_twist(solve, out, m0, scale)
        for side, sol, _, _ in sides:
            state.history[side] = (sol.window, out[side])
        return out

    def _balance_twist(self, solve, start, m0: float, scale: float):
        """The plates' twist ω (rad) at which the moments of both plates' tractions cancel.

        The first step uses the torsional stiffness of bonded discs of the contact sizes,
        (16/3) G a³ each, an upper bound, so it falls short; the steps then grow (secant, at
        most 4x) until the moment changes sign, and Illinois iterations close the bracket. A
        twist at which the plates can no longer transmit F' (everything slips) is an overshoot:
        the step is halved."""
        G = self.particle.material.G
        stiffness = sum(16 / 3 * G * (t.normal.area / math.pi) ** 1.5 for t in start.values())
        tol = self.twist_tol * scale

        def moment_at(w: float):
            out = solve(w)
            return out["up"].moment + out["low"].moment, out

        a_w, a_m = start["up"].twist, m0
        step = -m0 / stiffness
        b_w = b_m = b_out = None
        for _ in range(60):                 # extend until the moment changes sign
            try:
                b_m, b_out = moment_at(a_w + step)
            except (ConvergenceError, ValueError):
                step *= 0.5                 # beyond what the plates can hold: overshoot
                continue
            b_w = a_w + step
            if abs(b_m) <= tol:
                return b_out
            if (b_m > 0) != (a_m > 0):
                break
            step *= min(max(a_m / (a_m - b_m), 1.0), 4.0) if a_m != b_m else 2.0
            a_w, a_m = b_w, b_m
        else:
            raise ConvergenceError("the twisting moment about z could not be balanced")
        for _ in range(40):                 # Illinois on the bracket between a and b
            w = b_w - b_m * (b_w - a_w) / (b_m - a_m)
            m, out = moment_at(w)
            if abs(m) <= tol:
                return out
            if (m > 0) != (b_m > 0):
                a_w, a_m = b_w, b_m
            else:
                a_m *= 0.5
            b_w, b_m, b_out = w, m, out
        raise ConvergenceError("the twisting moment about z could not be balanced")

    def _record(self, k: int, step: LoadStep, ev0: Evaluation, ev: Evaluation,
                kind: RigidState, balanced: bool, start_rotation: Rotation,
                tangential: dict[str, TangentialContact], state: ParticleState,
                evaluations: int) -> StepRecord:
        mu = {"up": self.plates.mu_up, "low": self.plates.mu_low}
        F, h = ev.force, ev.gap
        t = {"up": tangential["up"], "low": tangential["low"]}
        sols = {"up": ev.up, "low": ev.low}

        def ratio(side: str, demand: float) -> float:
            return demand / mu[side] if mu[side] > 0 else math.nan

        # balances recomputed from the fields
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
        tilt = decompose(ev.rotation)
        turn = (ev.rotation * start_rotation.inv()).as_rotvec()
        sides = ("up", "low")
        values = dict(
            load_value=step.value, normal_force=F, plate_gap=h,
            compression=(self.d0 - h) / self.d0,
            quaternion=tuple(float(v) for v in ev.rotation.as_quat()),
            orientation=tilt.vector_deg, tilt=tilt.angle_deg, tilt_azimuth=tilt.azimuth_deg,
            yaw=tilt.yaw_deg,
            rotation=(math.degrees(turn[0]) + 0.0, math.degrees(turn[1]) + 0.0),
            rotation_angle=math.degrees(float(np.linalg.norm(turn))),
            state=kind.value, turned=kind is not RigidState.STICK, balanced=balanced,
            tangential_force=(float(ev.demand_force[0]), float(ev.demand_force[1])),
            demand_ratio=tuple(ratio(s, ev0.demand) for s in sides),
            ratio=tuple(ratio(s, ev.demand) for s in sides),
            centroid=tuple(sols[s].centroid for s in sides),
            approach=tuple(_approach(sols[s]) for s in sides),
            contact_area=tuple(sols[s].contact.area for s in sides),
            stick_area=tuple(t[s].stick_area for s in sides),
            spots=tuple(sols[s].spots for s in sides),
            position=tuple(state.position), slip=(tuple(state.slip_up), tuple(state.slip_low)),
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
            time_total=0.0, time_normal=0.0, time_tangential=0.0, time_geometry=0.0,
        )
        return StepRecord(k, step.kind, values)

    # --- the run -------------------------------------------------------------------------
    def steps(self, state: ParticleState | None = None, start: int = 0,
              ) -> Iterator[tuple[StepRecord, StepMaps | None, ParticleState]]:
        """Run the load steps from ``start``; yields (record, maps or None, state) per step.

        Raises :class:`SimulationError` when a step cannot be completed, whatever the cause.
        """
        state = state or ParticleState(self.particle.orientation)
        for k in range(start, len(self.schedule)):
            step = self.schedule[k]
            try:
                record, maps = self.step(k, state)
            except Exception as exc:
                reason = str(exc) or type(exc).__name__
                raise SimulationError(f"step {k} ({step.kind} {step.value:.6g}): "
                                      f"{reason}") from exc
            yield record, maps, state

    def run(self, progress: Callable[[StepRecord], None] | None = None,
            checkpoint: Callable[[Simulation, ParticleState], None] | None = None,
            resume_from: bytes | None = None):
        """Run every load step and return the history as an :class:`xarray.Dataset`.

        ``progress`` is called with each completed :class:`StepRecord`; ``checkpoint`` with the
        simulation and its state after each step (to save :meth:`snapshot`). ``resume_from``
        is a snapshot: the run continues after its last completed step and ends exactly as an
        uninterrupted one. A step that cannot be completed stops the run: the dataset then
        holds the completed steps, its ``status`` attribute says why, and a warning is issued.
        """
        state, start = None, 0
        if resume_from is not None:
            state, start = self.restore(resume_from)
        else:
            self.records, self.maps = [], []
        self.status = "running"
        try:
            for record, maps, current in self.steps(state, start):
                self.records.append(record)
                if maps is not None:
                    self.maps.append(maps)
                if progress is not None:
                    progress(record)
                if checkpoint is not None:
                    checkpoint(self, current)
            self.status = "complete"
        except SimulationError as exc:
            self.status = f"failed: {exc}"
            warnings.warn(f"simulation stopped: {exc}", RuntimeWarning, stacklevel=2)
        return self.dataset()

    def snapshot(self, state: ParticleState) -> bytes:
        """Everything needed to continue after the last completed step (pickled)."""
        return snapshot(self, state)

    def restore(self, blob: bytes) -> tuple[ParticleState, int]:
        """Load a :meth:`snapshot`; returns (state, index of the next step). The snapshot must
        come from a run with the same inputs."""
        return restore(self, blob)

    def dataset(self):
        """The records and maps collected so far as an :class:`xarray.Dataset`."""
        return to_dataset(self.records, self.maps, self.cell_size, self.inputs(), self.status)


def _approach(sol: InterfaceNormal) -> float:
    """Approach (m) of the plate measured from the lowest (highest) surface cell."""
    g = sol.contact.gap
    return float(sol.contact.approach - g[np.isfinite(g)].min())


def _maps(k: int, ev: Evaluation, tangential: dict[str, TangentialContact]) -> StepMaps:
    """The fields of both interfaces on the bounding box of their contacts (one free cell
    around)."""
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
