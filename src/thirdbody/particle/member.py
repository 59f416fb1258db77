"""One particle of a layer between the plates: its statics on its own lattice, its tangential
solves with their history, and what a step records about it.

The driver (:mod:`thirdbody.simulation`) owns the load: it decides each particle's normal force
(its share of F_N, or the force at the common plate gap) and when a particle turns; a
:class:`Member` does the per-particle physics. All quantities are SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..bem import ContactAtEdgeError, ConvergenceError, TangentialContact
from ..loading import LoadStep
from ..orientation import Rotation, decompose, key
from ..records import StepMaps, StepRecord
from ..rigid import RigidState
from .interface import InterfaceNormal, Window
from .model import Particle, Plates
from .statics import Evaluation, PairStatics
from .surface import LOWER, UPPER

__all__ = ["Compliance", "Member", "ParticleState", "step_maps"]


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


@dataclass(frozen=True)
class Compliance:
    """A particle's normal force against the plate gap at one orientation, modelled from its
    last solves there: ``points`` (force N, plate gap m, total approach m), ``reach`` the plate
    gap at first contact (m, from the scan), the material's E* (Pa) and the shape's size (m)."""

    points: tuple[tuple[float, float, float], ...]
    reach: float
    E_star: float
    size: float

    def force_at(self, gap: float) -> float:
        """The normal force (N) at plate gap ``gap`` (m): F^(2/3) linear in the gap (Hertz),
        through the last two solves when their forces differ by more than 0.1 % (a secant);
        otherwise through the last solve with the Hertz stiffness of its approach,
        F ∝ (δ + h₁ − h)^(3/2), δ the total approach measured from the lowest surface cells (a
        Newton step, free of the solver's noise); with no solve, Hertz for a radius ``size``
        from the scanned height."""
        pts = self.points
        if len(pts) == 2 and abs(pts[0][0] - pts[1][0]) > 1e-3 * pts[1][0] \
                and pts[0][1] != pts[1][1]:
            (F0, h0, _), (F1, h1, _) = pts
            slope = (F1 ** (2 / 3) - F0 ** (2 / 3)) / (h1 - h0)
            if slope < 0:
                value = F1 ** (2 / 3) + slope * (gap - h1)
                return value**1.5 if value > 0 else 0.0
        if pts and pts[-1][2] > 0 and pts[-1][0] > 0:
            F1, h1, d1 = pts[-1]
            value = (d1 + h1 - gap) / d1
            return F1 * value**1.5 if value > 0 else 0.0
        delta = self.reach - gap
        return (4.0 / 3.0 * self.E_star * math.sqrt(self.size) * (delta / 2) ** 1.5
                if delta > 0 else 0.0)


class Member:
    """One particle: its :class:`~thirdbody.particle.statics.PairStatics` on a lattice of cell
    size ``cell_size`` (m), and the solves of a step.

    ``points`` keeps (normal force N, plate gap m, total approach m) of the last two solves at
    the current orientation: the layer's force balance models each particle's compliance with them.
    """

    def __init__(self, particle: Particle, plates: Plates, cell_size: float, tol: float,
                 twist_tol: float, coupling: bool = False) -> None:
        self.particle, self.plates = particle, plates
        self.cell_size, self.tol, self.twist_tol = cell_size, tol, twist_tol
        self.statics = PairStatics(particle.shape, particle.material, cell_size, tol,
                                   coupling=coupling)
        self.coupling = self.statics.coupling
        #: (orientation key, tangential history) the coupled evaluations load from: the
        #: particle's state at the start of the step (:meth:`begin_step`)
        self.shear_history: tuple[tuple | None, dict] = (None, {})
        if self.coupling:
            self.statics.shear_solver = self._shear
        self.d0 = particle.shape.height(particle.orientation)
        self.points: list[tuple[float, float]] = []
        self._points_key: tuple | None = None

    @property
    def interfaces(self):
        return self.statics.interfaces

    # --- normal equilibrium --------------------------------------------------------------------
    def reach(self, rotation: Rotation) -> float:
        """Plate gap (m) at which both plates first touch the particle at ``rotation``."""
        s = self.statics.surfaces(rotation)
        return s.reference[UPPER] - s.reference[LOWER]

    def lowest(self, rotation: Rotation) -> float:
        """Height (m, particle frame) of the particle's lowest point at ``rotation``."""
        return self.statics.surfaces(rotation).reference[LOWER]

    def _note(self, ev: Evaluation) -> Evaluation:
        k = key(ev.rotation)
        if k != self._points_key:
            self._points_key, self.points = k, []
        point = (ev.force, ev.gap, _approach(ev.up) + _approach(ev.low))
        if self.points and abs(self.points[-1][0] - ev.force) <= 1e-12 * ev.force:
            # the same force again: keep the older point, so that the secant survives
            self.points = [*self.points[:-1], point]
        else:
            self.points = [*self.points[-1:], point]
        return ev

    def restart_points(self, ev: Evaluation) -> None:
        """Model the compliance at ``ev``'s orientation from ``ev`` alone."""
        self._points_key, self.points = None, []
        self._note(ev)

    def at_force(self, rotation: Rotation, force: float) -> Evaluation:
        """The normal equilibrium under ``force`` (N) on each plate."""
        return self._note(self.statics.at_force(rotation, force))

    def at_gap(self, rotation: Rotation, gap: float, state: ParticleState) -> Evaluation:
        """The normal equilibrium at the plate gap ``gap`` (m); warm-starts from (and updates)
        the state's last force."""
        ev = self._note(self.statics.at_gap(rotation, gap, state.force_guess))
        state.force_guess = ev.force
        return ev

    def compliance(self, rotation: Rotation) -> Compliance:
        """The model of this particle's normal force against the plate gap at ``rotation``
        (a plain, picklable snapshot)."""
        pts = self.points if key(rotation) == self._points_key else []
        return Compliance(tuple(pts), self.reach(rotation), self.particle.material.E_star,
                          self.particle.shape.size)

    def force_at(self, rotation: Rotation, gap: float) -> float:
        """The modelled normal force (N) at plate gap ``gap`` (m): :meth:`Compliance.force_at`
        of :meth:`compliance`."""
        return self.compliance(rotation).force_at(gap)

    # --- tangential ----------------------------------------------------------------------------
    def begin_step(self, state: ParticleState) -> None:
        """Coupled evaluations in this step load from ``state``'s tangential history (at its
        orientation; elsewhere the contact is new and loads from zero)."""
        self.shear_history = (key(state.rotation), state.history)

    def _sides(self, ev: Evaluation):
        """(side, interface normal, sign of F', μ) of both plates, and F' capped at
        μ_min F_N (the plates can transmit no more; only a balanced turn ends beyond it)."""
        cap = self.plates.mu_min * ev.force
        demand = ev.demand_force
        norm = math.hypot(*demand)
        if norm > cap:
            demand = demand * (cap / norm) if norm > 0 else demand
        sides = (("low", ev.low, 1.0, self.plates.mu_low), ("up", ev.up, -1.0, self.plates.mu_up))
        return sides, demand

    def _solve_sides(self, ev: Evaluation, history: dict, twist: float | None,
                     warm: dict | None = None) -> dict[str, TangentialContact]:
        sides, demand = self._sides(ev)
        out = {}
        for side, sol, sign, mu in sides:
            force = (sign * float(demand[0]) + 0.0, sign * float(demand[1]) + 0.0)
            # the last coupled pass's step (if any) starts this one
            out[side] = self.interfaces[side].solve_tangential(
                sol, mu, force, history.get(side), twist=twist, coupling=self.coupling,
                restart=warm.get(side) if warm else None)
        return out

    def _shear(self, ev: Evaluation,
               warm: dict | None = None) -> dict[str, TangentialContact]:
        """The tangential steps a coupled evaluation is solved with (no history written);
        ``warm``: {side: (window, step)} of the last pass, to start from."""
        orientation, history = self.shear_history
        return self._solve_sides(ev, history if orientation == key(ev.rotation) else {}, None,
                                 warm)

    def tangential(self, ev: Evaluation, state: ParticleState) -> dict[str, TangentialContact]:
        """Partial slip at both plates with the forces ±F'; if the tractions leave a twisting
        moment about z above ``twist_tol`` (relative to max(μ) F_N a), the particle's twist
        relative to the plates becomes an unknown, found by Illinois iterations on the total
        moment (monotone in the twist)."""
        sides, _ = self._sides(ev)

        def solve(twist: float | None) -> dict[str, TangentialContact]:
            return self._solve_sides(ev, state.history, twist)

        # a coupled evaluation already solved them, with this history (or none, after a turn)
        out = dict(ev.shear) if ev.shear is not None else solve(None)
        mu_max = max(self.plates.mu_up, self.plates.mu_low)
        radius = math.sqrt(max(ev.up.contact.area, ev.low.contact.area) / math.pi)
        scale = mu_max * ev.force * radius
        m0 = out["up"].moment + out["low"].moment
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
            except (ConvergenceError, ContactAtEdgeError, ValueError):
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

    # --- records -------------------------------------------------------------------------------
    def record(self, k: int, step: LoadStep, d0: float, ev0: Evaluation, ev: Evaluation,
               kind: RigidState, balanced: bool, start_rotation: Rotation,
               tangential: dict[str, TangentialContact], state: ParticleState,
               evaluations: int) -> StepRecord:
        """The step's variables for this particle (``d0``: the plate gap at first contact of
        the layer, m, for the compression ratio), with the balances recomputed from the
        fields."""
        mu = {"up": self.plates.mu_up, "low": self.plates.mu_low}
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
        turn = (ev.rotation * start_rotation.inv()).as_rotvec()
        sides = ("up", "low")
        values = dict(
            load_value=step.value, normal_force=F, plate_gap=h, compression=(d0 - h) / d0,
            **_pose(ev.rotation),
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
            time_total=0.0, time_normal=0.0, time_tangential=0.0, time_geometry=0.0,
        )
        return StepRecord(k, step.kind, values)

    def unloaded_record(self, k: int, step: LoadStep, d0: float, gap: float,
                        state: ParticleState, start_rotation: Rotation,
                        turned: bool) -> StepRecord:
        """The record of a particle the plates do not press (shorter than the gap ``gap``, m):
        no force, no contact (NaN where a quantity is undefined). ``turned``: it turned in the
        step before it lost its load (from ``start_rotation``)."""
        nan, nan2 = math.nan, (math.nan, math.nan)
        turn = (state.rotation * start_rotation.inv()).as_rotvec()
        values = dict(
            load_value=step.value, normal_force=0.0, plate_gap=gap, compression=(d0 - gap) / d0,
            **_pose(state.rotation),
            rotation=(math.degrees(turn[0]) + 0.0, math.degrees(turn[1]) + 0.0),
            rotation_angle=math.degrees(float(np.linalg.norm(turn))),
            state="unloaded", turned=turned, balanced=False, tangential_force=(0.0, 0.0),
            demand_ratio=nan2, ratio=nan2, centroid=(nan2, nan2), approach=nan2,
            contact_area=(0.0, 0.0), stick_area=(0.0, 0.0), spots=(0, 0),
            position=tuple(state.position), centroid_height=-self.lowest(state.rotation),
            slip=(tuple(state.slip_up), tuple(state.slip_low)),
            shift=((0.0, 0.0), (0.0, 0.0)), normal_iterations=(0, 0),
            tangential_iterations=(0, 0), normal_residual=nan2, tangential_residual=nan2,
            force_residual=nan, tangential_force_residual=nan, moment_residual=nan,
            twist_moment=0.0, twist_ratio=0.0, twist_angle=0.0, turn_evaluations=0,
            time_total=0.0, time_normal=0.0, time_tangential=0.0, time_geometry=0.0,
        )
        return StepRecord(k, step.kind, values)


def _pose(rotation: Rotation) -> dict:
    tilt = decompose(rotation)
    return dict(quaternion=tuple(float(v) for v in rotation.as_quat()),
                orientation=tilt.vector_deg, tilt=tilt.angle_deg,
                tilt_azimuth=tilt.azimuth_deg, yaw=tilt.yaw_deg)


def _approach(sol: InterfaceNormal) -> float:
    """Approach (m) of the plate measured from the lowest (highest) surface cell."""
    g = sol.contact.gap
    return float(sol.contact.approach - g[np.isfinite(g)].min())


def step_maps(k: int, ev: Evaluation, tangential: dict[str, TangentialContact]) -> StepMaps:
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

