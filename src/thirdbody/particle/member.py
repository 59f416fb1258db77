"""One particle of a layer between the plates: its statics on its own lattice and its tangential
solves with their history (physics only: what a step records is :mod:`thirdbody.records`).

The driver (:mod:`thirdbody.simulation`) owns the load: it decides each particle's normal force
(its share of F_N, or the force at the common plate gap) and when a particle turns; a
:class:`Member` does the per-particle physics. All quantities are SI.
"""

from __future__ import annotations

import math

from ..bem import ContactAtEdgeError, ConvergenceError, TangentialContact
from ..orientation import Rotation, key
from ..state import ParticleState, WarmStart
from .compliance import Compliance
from .interface import surface_approach
from .model import Particle, Plates
from .statics import Evaluation, PairStatics
from .surface import LOWER, UPPER

__all__ = ["Member"]


class Member:
    """One particle: its :class:`~thirdbody.particle.statics.PairStatics` on a lattice of cell
    size ``cell_size`` (m), and the solves of a step.

    Its solvers start from a :class:`~thirdbody.state.WarmStart` that belongs to the particle's
    state (:meth:`bind`): the last normal solve of each plate, and ``points``, (normal force N,
    plate gap m, total approach m) of the last two solves at the current orientation, with
    which the layer's force balance models the particle's compliance.
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
        self.bind(WarmStart())

    @property
    def interfaces(self):
        return self.statics.interfaces

    def bind(self, warm: WarmStart) -> None:
        """Start the solves from, and record them in, ``warm`` (a particle state's)."""
        self.warm = warm
        for interface in self.interfaces.values():
            interface.warm = warm

    @property
    def points(self) -> list[tuple[float, float, float]]:
        return self.warm.points

    @points.setter
    def points(self, value: list) -> None:
        self.warm.points = value

    @property
    def _points_key(self) -> tuple | None:
        return self.warm.points_key

    @_points_key.setter
    def _points_key(self, value: tuple | None) -> None:
        self.warm.points_key = value

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
        point = (ev.force, ev.gap, surface_approach(ev.up) + surface_approach(ev.low))
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
        """Solve from ``state``: its warm starts (:meth:`bind`), and for coupled evaluations its
        tangential history (at its orientation; elsewhere the contact is new and loads from
        zero)."""
        self.bind(state.warm)
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
                     warm: dict | None = None,
                     tol: float | None = None) -> dict[str, TangentialContact]:
        sides, demand = self._sides(ev)
        out = {}
        for side, sol, sign, mu in sides:
            force = (sign * float(demand[0]) + 0.0, sign * float(demand[1]) + 0.0)
            # the last coupled pass's step (if any) starts this one
            out[side] = self.interfaces[side].solve_tangential(
                sol, mu, force, history.get(side), twist=twist, coupling=self.coupling,
                restart=warm.get(side) if warm else None, tol=tol)
        return out

    def _shear(self, ev: Evaluation, warm: dict | None = None,
               tol: float | None = None) -> dict[str, TangentialContact]:
        """The tangential steps a coupled evaluation is solved with (no history written);
        ``warm``: {side: (window, step)} of the last pass, to start from."""
        orientation, history = self.shear_history
        return self._solve_sides(ev, history if orientation == key(ev.rotation) else {}, None,
                                 warm, tol)

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


