"""The quasi-static driver: a deformable particle squeezed between two plates, step by step.

For each load step (DESIGN.md §3, the paper's eqs 6-11):

1. Normal contact at both interfaces under the step's normal force F_N (or, under gap control,
   the F_N that gives the prescribed plate gap h), at the current orientation θ.
2. The pressure centroids x̄_up, x̄_low give the couple M_p = F_N (x̄_up − x̄_low) (eq 8) and the
   tangential force the particle needs to stay put, F'_x = M_p / h (eq 9); F'_x is the force of
   the lower plate on the particle (the upper plate's is −F'_x), so that M_p + h·F_T,up = 0.
3. If |F'| <= μ_min F_N the particle sticks: each interface solves the incremental partial-slip
   problem with its prescribed tangential force, carrying the previous step's traction.
4. Otherwise it turns in the sense of M_p (θ marched by ``angle_step_deg``, then bisected to
   ``angle_tol_deg``) to the first orientation where it sticks again; the tangential history is
   reset after a turn. With unequal μ it rolls about the higher-friction interface's stick zone;
   with equal μ it rotates about its centroid (:func:`thirdbody.rigid.classify`). The particle's
   horizontal position and the slip at each interface are integrated along the turn. If no
   stable orientation exists within a full turn the step is marked failed and the run stops.

All quantities are SI; orientation is reported in degrees. The result is an
:class:`xarray.Dataset` (see :func:`Simulation.run`).
"""

from __future__ import annotations

import itertools
import json
import math
import pickle
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field

import numpy as np

from ._version import __version__
from .bem import ContactAtEdgeError, ConvergenceError, TangentialContact
from .loading import LoadProgram, LoadStep
from .particle.interface import Interface, InterfaceNormal, Window, remap
from .particle.model import Particle, Plates
from .rigid import RigidState, classify

__all__ = ["STATES", "Simulation", "SimulationError", "StepMaps", "StepRecord"]

#: State codes stored in the results (``state`` variable, with ``flag_values``/``flag_meanings``).
STATES = ("stick", "roll_upper", "roll_lower", "rotate", "failed")
_STATE_CODE = {name: i for i, name in enumerate(STATES)}


class SimulationError(RuntimeError):
    """A step could not be completed (no stable orientation, a solver failure)."""


@dataclass
class StepRecord:
    """Scalars of one completed load step (SI units; angles in degrees)."""

    step: int
    load_kind: str
    load_value: float
    normal_force: float
    plate_gap: float
    compression: float
    orientation: float
    rotation: float
    state: str
    turned: bool
    tangential_force_x: float
    tangential_force_y: float
    demand_ratio_up: float
    demand_ratio_low: float
    ratio_up: float
    ratio_low: float
    centroid_x_up: float
    centroid_x_low: float
    centroid_y_up: float
    centroid_y_low: float
    approach_up: float
    approach_low: float
    contact_area_up: float
    contact_area_low: float
    stick_area_up: float
    stick_area_low: float
    position_x: float
    slip_up: float
    slip_low: float
    shift_up: float
    shift_low: float
    normal_iterations_up: int
    normal_iterations_low: int
    tangential_iterations_up: int
    tangential_iterations_low: int
    normal_residual_up: float
    normal_residual_low: float
    tangential_residual_up: float
    tangential_residual_low: float
    force_residual: float
    tangential_force_residual: float
    moment_residual: float
    turn_evaluations: int
    time_total: float
    time_normal: float
    time_tangential: float
    time_geometry: float


#: units and long names of the per-step variables
VARIABLES: dict[str, tuple[str, str]] = {
    "load_value": ("N or 1", "prescribed load: F_N (N) or compression ratio (1)"),
    "normal_force": ("N", "normal force F_N on each plate"),
    "plate_gap": ("m", "plate separation h"),
    "compression": ("1", "compression ratio (d0 - h) / d0"),
    "orientation": ("degree", "orientation theta about +y at the end of the step"),
    "rotation": ("degree", "rotation during the step"),
    "state": ("1", "what the particle did in the step"),
    "turned": ("1", "the particle turned in this step"),
    "tangential_force_x": ("N", "F'_x = M_p / h: x force of the lower plate on the particle"),
    "tangential_force_y": ("N", "F'_y: y force of the lower plate on the particle"),
    "demand_ratio_up": ("1", "|F'| / (mu_up F_N) at the step's starting orientation"),
    "demand_ratio_low": ("1", "|F'| / (mu_low F_N) at the step's starting orientation"),
    "ratio_up": ("1", "F_T / (mu_up F_N) at the final orientation"),
    "ratio_low": ("1", "F_T / (mu_low F_N) at the final orientation"),
    "centroid_x_up": ("m", "pressure centroid x at the upper interface (particle frame)"),
    "centroid_x_low": ("m", "pressure centroid x at the lower interface (particle frame)"),
    "centroid_y_up": ("m", "pressure centroid y at the upper interface (particle frame)"),
    "centroid_y_low": ("m", "pressure centroid y at the lower interface (particle frame)"),
    "approach_up": ("m", "normal approach of the upper plate"),
    "approach_low": ("m", "normal approach of the lower plate"),
    "contact_area_up": ("m2", "contact area, upper interface"),
    "contact_area_low": ("m2", "contact area, lower interface"),
    "stick_area_up": ("m2", "stick area, upper interface"),
    "stick_area_low": ("m2", "stick area, lower interface"),
    "position_x": ("m", "horizontal displacement of the particle centroid"),
    "slip_up": ("m", "accumulated slip of the particle over the upper plate while turning"),
    "slip_low": ("m", "accumulated slip of the particle over the lower plate while turning"),
    "shift_up": ("m", "rigid tangential shift (partial slip) of the upper plate, since the last "
                      "turn"),
    "shift_low": ("m", "rigid tangential shift (partial slip) of the lower plate, since the last "
                       "turn"),
    "normal_iterations_up": ("1", "normal solver iterations, upper"),
    "normal_iterations_low": ("1", "normal solver iterations, lower"),
    "tangential_iterations_up": ("1", "tangential solver CG iterations, upper"),
    "tangential_iterations_low": ("1", "tangential solver CG iterations, lower"),
    "normal_residual_up": ("1", "normal solver complementarity residual, upper"),
    "normal_residual_low": ("1", "normal solver complementarity residual, lower"),
    "tangential_residual_up": ("1", "Coulomb residual, upper"),
    "tangential_residual_low": ("1", "Coulomb residual, lower"),
    "force_residual": ("1", "|F_up - F_low| / F_N from the pressure fields"),
    "tangential_force_residual": ("1", "|T_up + T_low| / F_N from the traction fields"),
    "moment_residual": ("1", "|M_p + h T_up,x| / (F_N h) from the fields"),
    "turn_evaluations": ("1", "orientations evaluated while turning"),
    "time_total": ("s", "wall time of the step"),
    "time_normal": ("s", "wall time in normal solves"),
    "time_tangential": ("s", "wall time in tangential solves"),
    "time_geometry": ("s", "wall time computing gaps from the shape"),
}

MAP_VARIABLES: dict[str, tuple[str, str]] = {
    "pressure": ("Pa", "contact pressure"),
    "traction_x": ("Pa", "x traction of the plate on the particle"),
    "traction_y": ("Pa", "y traction of the plate on the particle"),
    "status": ("1", "0 open, 1 stick, 2 slip"),
}


@dataclass
class StepMaps:
    """Fields of one step on fixed-size map windows, one per interface ("up", "low")."""

    step: int
    fields: dict[str, np.ndarray]        # f"{name}_{side}" -> (m, m)
    centers: dict[str, tuple[float, float]]
    cropped: dict[str, bool]


@dataclass
class _Evaluation:
    theta: float
    force: float
    gap: float
    up: InterfaceNormal
    low: InterfaceNormal
    fx: float
    fy: float

    @property
    def demand(self) -> float:
        return math.hypot(self.fx, self.fy) / self.force


@dataclass
class _State:
    """Everything carried from one step to the next (what a resume needs)."""

    theta: float
    position_x: float = 0.0
    slip_up: float = 0.0
    slip_low: float = 0.0
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
    map_cells : int, optional
        Size of the stored maps, cells across; default: 1.25 x the largest contact at the
        maximum load and initial orientation (found by a trial solve), at least 32.
    classification : {"statics", "paper"}
        How a both-interfaces-exceeded demand is read with unequal μ
        (:func:`thirdbody.rigid.classify`).
    """

    def __init__(self, particle: Particle, plates: Plates, load: LoadProgram, *,
                 resolution: float = 200.0, cell_size: float | None = None,
                 tol: float = 1e-8, angle_step_deg: float = 1.0, angle_tol_deg: float = 0.01,
                 maps_every: int = 1, map_cells: int | None = None,
                 classification: str = "statics", min_cells: int = 32) -> None:
        from ._validate import positive

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
        self.min_cells = int(min_cells)
        self.map_cells = map_cells
        self.schedule: list[LoadStep] = load.schedule()
        self.d0 = shape.height(particle.orientation)
        self.interfaces = {
            "up": Interface("upper", shape, particle.material, self.cell_size, self.min_cells,
                            tol),
            "low": Interface("lower", shape, particle.material, self.cell_size, self.min_cells,
                             tol),
        }
        self.records: list[StepRecord] = []
        self.maps: list[StepMaps] = []
        self.status = "not run"
        self._timers = {"normal": 0.0, "tangential": 0.0}

    # --- inputs, for the results file ------------------------------------------------------
    def inputs(self) -> dict:
        """The run's inputs as plain data (stored as attributes of the results)."""
        mat = self.particle.material
        return {
            "shape": repr(self.particle.shape),
            "E": mat.E, "nu": mat.nu, "orientation_deg": self.particle.orientation_deg,
            "mu_up": self.plates.mu_up, "mu_low": self.plates.mu_low,
            "load": {"program": type(self.load).__name__, **asdict(self.load)},
            "cell_size": self.cell_size, "resolution": self.resolution, "tol": self.tol,
            "angle_step_deg": math.degrees(self.angle_step),
            "angle_tol_deg": math.degrees(self.angle_tol),
            "maps_every": self.maps_every, "classification": self.classification,
            "d0": self.d0,
        }

    # --- one orientation ---------------------------------------------------------------------
    def _evaluate(self, theta: float, step: LoadStep, state: _State) -> _Evaluation:
        start = time.perf_counter()
        geometry = sum(i.geometry_time for i in self.interfaces.values())
        if step.kind == "force":
            force = step.value
            up = self.interfaces["up"].solve_normal(theta, force=force)
            low = self.interfaces["low"].solve_normal(theta, force=force)
        else:
            force, up, low = self._solve_gap(theta, self.d0 * (1 - step.value), state)
        h = self.particle.shape.height(theta) - up.contact.approach - low.contact.approach
        if not h > 0:
            raise SimulationError(f"the plates met (gap h = {h:.3g} m): load too large for the "
                                  "half-space approximation")
        fx = force * (up.centroid[0] - low.centroid[0]) / h
        fy = force * (up.centroid[1] - low.centroid[1]) / h
        geometry = sum(i.geometry_time for i in self.interfaces.values()) - geometry
        self._timers["normal"] += time.perf_counter() - start - geometry
        return _Evaluation(theta, force, h, up, low, fx, fy)

    def _solve_gap(self, theta: float, h_target: float, state: _State):
        """F_N (N) such that the plate gap is ``h_target`` (m) at orientation ``theta``."""
        height = self.particle.shape.height(theta)
        target = height - h_target           # total approach δ_up + δ_low, m
        if not target > 0:
            raise SimulationError(f"prescribed plate gap {h_target:.6g} m does not touch the "
                                  f"particle (height {height:.6g} m at this orientation)")
        mat = self.particle.material
        # Hertz-like first guess: δ_total ≈ 2 (9 F² / (16 E*² R))^(1/3) with R ~ size
        F = state.force_guess or (target / 2) ** 1.5 * 4 / 3 * mat.E_star * \
            math.sqrt(self.particle.shape.size)
        points: list[tuple[float, float]] = []
        for _ in range(40):
            up = self.interfaces["up"].solve_normal(theta, force=F)
            low = self.interfaces["low"].solve_normal(theta, force=F)
            total = up.contact.approach + low.contact.approach
            if abs(total - target) <= 1e-7 * target:
                state.force_guess = F
                return F, up, low
            points.append((math.log(F), math.log(total)))
            if len(points) >= 2 and points[-1][1] != points[-2][1]:
                (x0, y0), (x1, y1) = points[-2:]
                slope = (y1 - y0) / (x1 - x0)
                slope = min(max(slope, 0.2), 2.0)
            else:
                slope = 2.0 / 3.0
            F = math.exp(points[-1][0] + (math.log(target) - points[-1][1]) / slope)
        raise SimulationError(f"could not find the normal force for the plate gap "
                              f"{h_target:.6g} m")

    def _stick(self, ev: _Evaluation) -> bool:
        return math.hypot(ev.fx, ev.fy) <= self.plates.mu_min * ev.force

    def _classify(self, ev: _Evaluation) -> RigidState:
        return classify(ev.demand, self.plates.mu_up, self.plates.mu_low,
                        classification=self.classification, mu_rtol=self.plates.mu_rtol)

    # --- turning -----------------------------------------------------------------------------
    def _turn(self, ev0: _Evaluation, step: LoadStep, state: _State):
        """March then bisect to the first orientation that sticks. Returns (final evaluation,
        evaluations along the way in order of progress, number of evaluations)."""
        sense = 1.0 if ev0.fx > 0 else -1.0      # M_p > 0 turns the particle about +y
        path = [ev0]
        a = ev0
        travelled = 0.0
        while True:
            theta = a.theta + sense * self.angle_step
            b = self._evaluate(theta, step, state)
            travelled += self.angle_step
            if self._stick(b):
                break
            if (b.fx > 0) != (a.fx > 0):
                raise SimulationError(
                    f"no stable orientation: the moment changes sign between "
                    f"{math.degrees(a.theta):.3f} and {math.degrees(b.theta):.3f} deg without "
                    "a sticking orientation (a jump of the contact between spots); try a "
                    "smaller angle_step_deg")
            path.append(b)
            a = b
            if travelled >= 2 * math.pi:
                raise SimulationError("no stable orientation within a full turn: the particle "
                                      "would turn for ever at this load")
        evaluations = len(path)
        while abs(b.theta - a.theta) > self.angle_tol:
            mid = self._evaluate(0.5 * (a.theta + b.theta), step, state)
            evaluations += 1
            if self._stick(mid):
                b = mid
            else:
                path.append(mid)
                a = mid
        return b, path, evaluations

    def _integrate(self, path: list[_Evaluation], final: _Evaluation, state: _State) -> None:
        """Particle position and interface slips along a turn (pivot per turning state)."""
        shape = self.particle.shape
        nodes = [*path, final]
        for a, b in itertools.pairwise(nodes):
            d = b.theta - a.theta
            z_top = shape.highest_point(a.theta)[2] - a.up.contact.approach
            z_bottom = shape.lowest_point(a.theta)[2] + a.low.contact.approach
            kind = self._classify(a)
            if kind is RigidState.ROLL_LOWER:
                pivot = z_bottom
            elif kind is RigidState.ROLL_UPPER:
                pivot = z_top
            else:                               # rotation about the centroid
                pivot = 0.0
            state.position_x += -d * pivot
            state.slip_up += d * (z_top - pivot)
            state.slip_low += d * (z_bottom - pivot)

    # --- the run -------------------------------------------------------------------------
    #: fewest cells across the contact at the largest load that :meth:`preflight` accepts
    MIN_CONTACT_CELLS = 8

    def preflight(self) -> int:
        """Solve the largest load at the initial orientation once: sets the map size and
        checks the resolution. Returns the contact's extent in cells.

        Raises ValueError (naming ``resolution``) when the contact at the largest load spans
        fewer than :attr:`MIN_CONTACT_CELLS` cells: the solution would not be resolved.
        Raises :class:`SimulationError` when that load cannot be solved at all.
        """
        step = max(self.schedule, key=lambda s: s.value)
        state = _State(theta=self.particle.orientation)
        try:
            ev = self._evaluate(self.particle.orientation, step, state)
        except (ConvergenceError, ContactAtEdgeError) as exc:
            raise SimulationError(f"the largest load cannot be solved: {exc}") from exc
        finally:
            for i in self.interfaces.values():
                i.last = None
        extent = 0
        for sol in (ev.up, ev.low):
            c = sol.contact.contact
            rows, cols = np.flatnonzero(c.any(axis=1)), np.flatnonzero(c.any(axis=0))
            extent = max(extent, rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1)
        if self.map_cells is None:
            self.map_cells = max(32, math.ceil(1.25 * extent / 16) * 16)
        if extent < self.MIN_CONTACT_CELLS:
            needed = self.resolution * self.MIN_CONTACT_CELLS / max(extent, 1)
            raise ValueError(
                f"resolution (cells per particle size) {self.resolution:.4g} is too coarse: the "
                f"contact at the largest load spans {extent} cells; use at least {needed:.0f}")
        return int(extent)

    def steps(self, state: _State | None = None, start: int = 0,
              ) -> Iterator[tuple[StepRecord, StepMaps | None, _State]]:
        """Run the load steps from ``start``; yields (record, maps or None, state) per step.

        Raises :class:`SimulationError` when a step cannot be completed.
        """
        if self.map_cells is None and self.maps_every:
            try:
                self.preflight()
            except ValueError:
                pass                        # coarse but allowed from Python; the CLI refuses
            except SimulationError:
                self.map_cells = 64         # the step that cannot be solved will say why
        state = state or _State(theta=self.particle.orientation)
        n_steps = len(self.schedule)
        for k in range(start, n_steps):
            step = self.schedule[k]
            t_start = time.perf_counter()
            geometry0 = sum(i.geometry_time for i in self.interfaces.values())
            self._timers = {"normal": 0.0, "tangential": 0.0}
            try:
                ev0 = self._evaluate(state.theta, step, state)
                kind = RigidState.STICK if self._stick(ev0) else self._classify(ev0)
                evaluations = 1
                if kind is RigidState.STICK:
                    final = ev0
                else:
                    final, path, evaluations = self._turn(ev0, step, state)
                    self._integrate(path, final, state)
                    state.history.clear()
                tangential = self._tangential(final, state)
            except (ConvergenceError, ContactAtEdgeError, SimulationError) as exc:
                raise SimulationError(f"step {k} ({step.kind} {step.value:.6g}): {exc}") from exc
            rotation = math.degrees(final.theta - state.theta)
            state.theta = final.theta
            record = self._record(k, step, ev0, final, kind, rotation, tangential, state,
                                  evaluations)
            record.time_geometry = sum(i.geometry_time for i in self.interfaces.values()) \
                - geometry0
            record.time_total = time.perf_counter() - t_start
            maps = None
            if self.maps_every and (k % self.maps_every == 0 or k == n_steps - 1):
                maps = self._maps(k, final, tangential)
            yield record, maps, state

    def _tangential(self, ev: _Evaluation, state: _State) -> dict[str, TangentialContact]:
        start = time.perf_counter()
        out = {}
        for side, sol, sign, mu in (("low", ev.low, 1.0, self.plates.mu_low),
                                    ("up", ev.up, -1.0, self.plates.mu_up)):
            force = (sign * ev.fx, sign * ev.fy)
            if mu == 0 and ev.fx == ev.fy == 0:
                force = (0.0, 0.0)
            t = self.interfaces[side].solve_tangential(sol, mu, force, state.history.get(side))
            state.history[side] = (sol.window, t)
            out[side] = t
        self._timers["tangential"] += time.perf_counter() - start
        return out

    def _record(self, k, step, ev0, ev, kind, rotation, tangential, state, evaluations):
        mu_up, mu_low = self.plates.mu_up, self.plates.mu_low
        F = ev.force
        t_up, t_low = tangential["up"], tangential["low"]

        def ratio(mu: float, demand: float) -> float:
            return demand / mu if mu > 0 else (0.0 if demand == 0 else math.inf)

        def moment(sol: InterfaceNormal) -> tuple[float, float]:
            grid = sol.contact.grid
            X, _ = grid.mesh()
            p = sol.contact.pressure
            return float(p.sum() * grid.cell_area), float((p * X).sum() * grid.cell_area)

        f_up, m_up = moment(ev.up)
        f_low, m_low = moment(ev.low)
        T_up, T_low = t_up.force, t_low.force
        demand0 = ev0.demand
        demand = ev.demand
        return StepRecord(
            step=k, load_kind=step.kind, load_value=step.value, normal_force=F,
            plate_gap=ev.gap, compression=(self.d0 - ev.gap) / self.d0,
            orientation=math.degrees(ev.theta), rotation=rotation, state=kind.value,
            turned=kind is not RigidState.STICK,
            tangential_force_x=ev.fx, tangential_force_y=ev.fy,
            demand_ratio_up=ratio(mu_up, demand0), demand_ratio_low=ratio(mu_low, demand0),
            ratio_up=ratio(mu_up, demand), ratio_low=ratio(mu_low, demand),
            centroid_x_up=ev.up.centroid[0], centroid_x_low=ev.low.centroid[0],
            centroid_y_up=ev.up.centroid[1], centroid_y_low=ev.low.centroid[1],
            approach_up=ev.up.contact.approach, approach_low=ev.low.contact.approach,
            contact_area_up=ev.up.contact.area, contact_area_low=ev.low.contact.area,
            stick_area_up=t_up.stick_area, stick_area_low=t_low.stick_area,
            position_x=state.position_x, slip_up=state.slip_up, slip_low=state.slip_low,
            shift_up=float(t_up.shift[0]), shift_low=float(t_low.shift[0]),
            normal_iterations_up=ev.up.contact.iterations,
            normal_iterations_low=ev.low.contact.iterations,
            tangential_iterations_up=t_up.iterations, tangential_iterations_low=t_low.iterations,
            normal_residual_up=ev.up.contact.residual,
            normal_residual_low=ev.low.contact.residual,
            tangential_residual_up=t_up.residual, tangential_residual_low=t_low.residual,
            force_residual=abs(f_up - f_low) / F,
            tangential_force_residual=float(np.hypot(*(T_up + T_low))) / F,
            moment_residual=abs(m_up - m_low + ev.gap * T_up[0]) / (F * ev.gap),
            turn_evaluations=evaluations, time_total=0.0,
            time_normal=self._timers["normal"], time_tangential=self._timers["tangential"],
            time_geometry=0.0,
        )

    def _maps(self, k: int, ev: _Evaluation, tangential: dict[str, TangentialContact],
              ) -> StepMaps:
        m = int(self.map_cells)
        fields, centers, cropped = {}, {}, {}
        for side, sol in (("up", ev.up), ("low", ev.low)):
            t = tangential[side]
            c = sol.contact.contact
            rows, cols = np.flatnonzero(c.any(axis=1)), np.flatnonzero(c.any(axis=0))
            w = sol.window
            ci = w.i0 + (cols[0] + cols[-1] + 1) // 2
            cj = w.j0 + (rows[0] + rows[-1] + 1) // 2
            target = Window(ci - m // 2, cj - m // 2, m, m)
            status = np.where(t.stick, 1, np.where(t.slip, 2, 0)).astype(np.int8)
            fields[f"pressure_{side}"] = remap(sol.contact.pressure, w, target)
            fields[f"traction_x_{side}"] = remap(t.traction[0], w, target)
            fields[f"traction_y_{side}"] = remap(t.traction[1], w, target)
            fields[f"status_{side}"] = remap(status.astype(float), w, target).astype(np.int8)
            grid = target.grid(self.cell_size)
            centers[side] = grid.center
            cropped[side] = bool(np.count_nonzero(fields[f"status_{side}"]) < c.sum())
        return StepMaps(k, fields, centers, cropped)

    def run(self, progress: Callable[[StepRecord], None] | None = None,
            checkpoint: Callable[[Simulation, _State], None] | None = None,
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

    def snapshot(self, state: _State) -> bytes:
        """Everything needed to continue after the last completed step (pickled)."""
        return pickle.dumps({
            "inputs": self.inputs(), "state": state, "records": self.records, "maps": self.maps,
            "map_cells": self.map_cells,
            "interfaces": {k: (i.cells, i.last) for k, i in self.interfaces.items()},
        })

    def restore(self, blob: bytes) -> tuple[_State, int]:
        """Load a :meth:`snapshot`; returns (state, index of the next step). The snapshot must
        come from a run with the same inputs."""
        data = pickle.loads(blob)
        if data["inputs"] != self.inputs():
            raise ValueError("cannot resume: the results were made with different inputs")
        self.records, self.maps = list(data["records"]), list(data["maps"])
        self.map_cells = data["map_cells"]
        for k, (cells, last) in data["interfaces"].items():
            self.interfaces[k].cells, self.interfaces[k].last = cells, last
        return data["state"], len(self.records)

    def dataset(self):
        """The records and maps collected so far as an :class:`xarray.Dataset`."""
        return to_dataset(self.records, self.maps, self.cell_size, self.inputs(), self.status)


def to_dataset(records: list[StepRecord], maps: list[StepMaps], cell_size: float,
               inputs: dict, status: str):
    """Assemble the results: per-step scalars along ``step``, maps along ``map_step``."""
    import xarray as xr

    steps = np.array([r.step for r in records], dtype=int)
    data = {}
    for name, (units, long_name) in VARIABLES.items():
        values = [getattr(r, name) for r in records]
        if name == "state":
            arr = np.array([_STATE_CODE[v] for v in values], dtype=np.int8)
            attrs = {"units": units, "long_name": long_name,
                     "flag_values": np.arange(len(STATES), dtype=np.int8),
                     "flag_meanings": " ".join(STATES)}
        else:
            arr = np.array(values)
            if arr.dtype == bool:
                arr = arr.astype(np.int8)
            attrs = {"units": units, "long_name": long_name}
        data[name] = ("step", arr, attrs)
    data["load_kind"] = ("step", np.array([r.load_kind for r in records], dtype=str),
                         {"long_name": "load control: force or compression"})
    coords = {"step": ("step", steps, {"long_name": "load step index"})}
    if maps:
        m = next(iter(maps[0].fields.values())).shape[0]
        offset = (np.arange(m) - (m - 1) / 2) * cell_size
        coords["map_step"] = ("map_step", np.array([mp.step for mp in maps], dtype=int),
                              {"long_name": "load step of the stored maps"})
        coords["map_x"] = ("map_x", offset, {"units": "m", "long_name":
                                             "x offset from the map centre"})
        coords["map_y"] = ("map_y", offset, {"units": "m", "long_name":
                                             "y offset from the map centre"})
        for side, where in (("up", "upper"), ("low", "lower")):
            for name, (units, long_name) in MAP_VARIABLES.items():
                key = f"{name}_{side}"
                data[key] = (("map_step", "map_y", "map_x"),
                             np.stack([mp.fields[key] for mp in maps]),
                             {"units": units, "long_name": f"{long_name}, {where} interface"})
            for axis, i in (("x", 0), ("y", 1)):
                data[f"map_center_{axis}_{side}"] = (
                    "map_step", np.array([mp.centers[side][i] for mp in maps]),
                    {"units": "m", "long_name": f"map centre {axis}, {where} interface "
                                                "(particle frame)"})
            data[f"map_cropped_{side}"] = (
                "map_step", np.array([mp.cropped[side] for mp in maps], dtype=np.int8),
                {"units": "1", "long_name": f"contact extends beyond the map, {where}"})
    attrs = {
        "title": "thirdbody: deformable particle between two plates",
        "thirdbody_version": __version__,
        "inputs": json.dumps(inputs),
        "status": status,
        "conventions": "SI units; x in the plane of rotation, y the rotation axis, z up; "
                       "orientation about +y (right-hand rule) in degrees; tractions are "
                       "exerted by the plate on the particle",
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)
