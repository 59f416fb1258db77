"""Turning: the first stable orientation along the way the couple turns the particle, and the
kinematics of the turn (pure functions of the evaluated orientations).

The particle is massless, so a turn runs to completion inside its load step (see
docs/methods/design.md §3). It turns about the horizontal axis ``e_z × F'/|F'|`` of its current
couple, recomputed at every orientation the search visits; each leg is a rotation about a fixed
axis. It stops at the first orientation that is *stable*:

* inside the friction limit, ``|F'| <= μ_min F_N`` (it sticks there), or
* at a *balance*: the couple along the leg changes sign (the particle would turn back), and at
  the zero crossing the couple's remaining part, across the leg, is within what the bracket
  resolves. With μ = 0 this is the only way to stop: the orientation where F' = 0;
* where it loses its load (``evaluate`` returns :meth:`Evaluation.unloaded`: in a layer, the
  other particles hold the plates above it): the couple vanishes with the load, so it stops
  at the last orientation where it touches (a balance, to the bisection tolerance).

The search marches in legs of ``step`` (rad) and brackets every event between march points:

* the couple reverses (its component along the leg, ``F'·F̂'_start``, is <= 0 at the end), or the
  particle sticks at the end: bisect the leg to ``tol`` for the first orientation that is stable
  or reversed, then, if it is only reversed, find the zero crossing (Illinois method) and
  check it;
* the demand |F'|/F_N has a local minimum between march points that comes within twice its
  depth of μ_min (a narrow stable band between two unstable samples): search it with golden
  sections and, if a stable orientation is found, bisect back to the first one.

Kinematics: on each leg from a to b (rotation vector φ n, horizontal) a material point at
height z moves horizontally by ``φ (z − z_P)(n_y, −n_x)`` about a pivot at height z_P: the lower
plate (rolling about the lower contact's stick zone), the upper plate, or the centroid
(rotation). Heights are averaged over the two ends of the leg (trapezoidal rule).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..orientation import turned
from ..rigid import RigidState, classify
from .compliance import Compliance, share_while_turning
from .model import Plates
from .statics import Evaluation

__all__ = ["Increments", "Turn", "TurnSettings", "TurningError", "find_stable_orientation",
           "turn_kinematics", "turn_particle"]

_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))


class TurningError(RuntimeError):
    """No stable orientation exists along the turn (the particle would turn for ever)."""


@dataclass(frozen=True)
class Turn:
    """The outcome of a turn.

    Attributes
    ----------
    final : Evaluation
        The first stable orientation.
    path : tuple[Evaluation, ...]
        The orientations passed on the way, in order, from the start (first) to the last one
        before ``final``; consecutive entries are joined by a rotation about the earlier one's
        axis.
    evaluations : int
        Orientations evaluated (the start included).
    balanced : bool
        The turn ended at a balance of the couple rather than inside the friction limit.
    lost_load : bool
        It ended because the particle lost its load just beyond ``final`` (``balanced`` too).
    """

    final: Evaluation
    path: tuple[Evaluation, ...]
    evaluations: int
    balanced: bool
    lost_load: bool = False


class _Search:
    def __init__(self, evaluate: Callable, mu_min: float, tol: float) -> None:
        self.evaluate_rotation = evaluate
        self.mu_min, self.tol = mu_min, tol
        self.count = 0
        self.lost_load = False

    def at(self, origin: Evaluation, t: float) -> Evaluation:
        """The orientation ``t`` (rad) along the leg that starts at ``origin``."""
        self.count += 1
        return self.evaluate_rotation(turned(origin.rotation, origin.axis, t))

    def stable(self, ev: Evaluation) -> bool:
        """Inside the friction limit, or unloaded (no couple)."""
        return ev.demand <= self.mu_min

    def stops(self, ev: Evaluation, origin: Evaluation) -> bool:
        return self.stable(ev) or ev.drive(origin) <= 0.0

    def settle(self, origin: Evaluation, t_end: float, end: Evaluation,
               ) -> tuple[Evaluation | None, list[Evaluation], bool]:
        """On the leg from ``origin`` (not stable) to ``end`` at ``t_end`` (stable or
        reversed), the first stable orientation. Returns (final or None, orientations passed,
        balanced); None means the couple reversed at an unstable orientation from which the
        particle turns on about a new axis: the last orientation passed is that one."""
        passed: list[Evaluation] = []
        lo_t, lo, hi_t, hi = 0.0, origin, t_end, end
        while hi_t - lo_t > self.tol:
            t = 0.5 * (lo_t + hi_t)
            mid = self.at(origin, t)
            if self.stops(mid, origin):
                hi_t, hi = t, mid
            else:
                lo_t, lo = t, mid
                passed.append(mid)
        if hi.force == 0:
            # the particle lost its load (in a layer: the others took it) and the couple with
            # it: it stops where it last touched, to within the tolerance
            if passed and passed[-1] is lo:
                passed.pop()
            self.lost_load = True
            return lo, passed, True
        if self.stable(hi):
            return hi, passed, False
        # reversed, not stable: the couple along the leg crosses zero in (lo, hi)
        _, zero = self._zero(origin, lo_t, lo, hi_t, hi)
        if self.stable(zero):
            return zero, passed, False
        # resolved within the bracket: the couple across the leg is no larger than the change
        # of F' over the bracket
        across = abs(float(zero.demand_force @ origin.axis)) / zero.force
        resolution = float(np.hypot(*(hi.demand_force - lo.demand_force))) / zero.force
        if across <= resolution + 1e-12 * max(zero.demand, 1.0):
            return zero, passed, True
        passed.append(zero)
        return None, passed, False

    def _zero(self, origin: Evaluation, a_t: float, a: Evaluation, b_t: float,
              b: Evaluation) -> tuple[float, Evaluation]:
        """Illinois iterations on the couple along the leg, f(t) = F'(t)·F̂'_origin / F_N,
        from the bracket f(a) > 0 >= f(b), to 1e-3 of the bisection tolerance."""
        fa, fb = a.drive(origin), b.drive(origin)
        best_t, best = (b_t, b)
        side = 0
        for _ in range(40):
            if b_t - a_t <= 1e-3 * self.tol or fb == 0.0:
                break
            t = b_t - fb * (b_t - a_t) / (fb - fa) if fa != fb else 0.5 * (a_t + b_t)
            if not a_t < t < b_t:
                t = 0.5 * (a_t + b_t)
            ev = self.at(origin, t)
            f = ev.drive(origin)
            best_t, best = t, ev
            if self.stable(ev):
                return t, ev
            if f > 0:
                a_t, a, fa = t, ev, f
                if side == 1:
                    fb *= 0.5
                side = 1
            else:
                b_t, b, fb = t, ev, f
                if side == -1:
                    fa *= 0.5
                side = -1
            if abs(f) <= 1e-12:
                break
        return best_t, best

    def dip(self, prev: Evaluation, a: Evaluation,
            step: float) -> tuple[Evaluation, float, Evaluation] | None:
        """Golden-section search of the demand over the two march legs prev -> a and a -> (the
        next march point), each ``step`` long, for a stable orientation; returns (origin of its
        leg, its position on that leg, the stable orientation) or None."""
        t_prev = step

        def point(s: float) -> tuple[Evaluation, float]:
            return (prev, s) if s < t_prev else (a, s - t_prev)

        def value(s: float) -> Evaluation:
            origin, t = point(s)
            return self.at(origin, t) if t > 0 else origin

        lo, hi = 0.0, 2.0 * step
        x1, x2 = lo + _GOLDEN * (hi - lo), hi - _GOLDEN * (hi - lo)
        e1, e2 = value(x1), value(x2)
        while hi - lo > self.tol:
            for x, e in ((x1, e1), (x2, e2)):
                if self.stable(e):
                    origin, t = point(x)
                    return origin, t, e
            if e1.demand <= e2.demand:
                hi, x2, e2 = x2, x1, e1
                x1 = lo + _GOLDEN * (hi - lo)
                e1 = value(x1)
            else:
                lo, x1, e1 = x1, x2, e2
                x2 = hi - _GOLDEN * (hi - lo)
                e2 = value(x2)
        return None


def find_stable_orientation(start: Evaluation, evaluate: Callable[..., Evaluation],
                            mu_min: float, step: float, tol: float,
                            max_turn: float = 2.0 * math.pi) -> Turn:
    """March from ``start`` (not stable) to the first stable orientation (module docstring).

    Parameters
    ----------
    start : Evaluation
        The unstable orientation the turn starts from.
    evaluate : callable
        ``evaluate(rotation) -> Evaluation`` at the step's load.
    mu_min : float
        min(μ_up, μ_low): the particle sticks when |F'| <= μ_min F_N.
    step, tol : float
        March leg and bisection tolerance, rad.
    max_turn : float
        Give up (:class:`TurningError`) after turning this far, rad.
    """
    search = _Search(evaluate, mu_min, tol)
    search.count = 1
    path: list[Evaluation] = [start]
    marched = False                     # path[-2] -> path[-1] is a full march leg
    a = start
    travelled = 0.0
    while True:
        if travelled >= max_turn * (1.0 - 1e-12):      # rounding of the summed legs
            raise TurningError(
                f"no stable orientation within {math.degrees(max_turn):.0f}° of turning: the "
                f"couple stays above the friction limit (|F'|/F_N = {a.demand:.4g} > "
                f"μ = {mu_min:.4g}) and never reverses")
        b = search.at(a, step)
        travelled += step
        origin, t_end, end = a, step, b
        if not search.stops(b, a):
            found = None
            if marched and _dip_suspected(path[-2], a, b, mu_min):
                found = search.dip(path[-2], a, step)
            if found is None:
                path.append(b)
                marched = True
                a = b
                continue
            origin, t_end, end = found
            if origin is not a:
                path.pop()          # the stable band lies before a: the particle never got there
        final, passed, balanced = search.settle(origin, t_end, end)
        path.extend(passed)
        if final is not None:
            return Turn(final, tuple(path), search.count, balanced, search.lost_load)
        a = path[-1]                # turned back at an unstable balance: on about a new axis
        marched = False


def _dip_suspected(prev: Evaluation, a: Evaluation, b: Evaluation, mu_min: float) -> bool:
    """The demand has a local minimum at ``a`` that comes within twice its depth of μ_min."""
    if not (a.demand <= prev.demand and a.demand <= b.demand):
        return False
    depth = min(prev.demand, b.demand) - a.demand
    return a.demand - mu_min < 2.0 * depth


@dataclass(frozen=True)
class Increments:
    """Horizontal displacements (m, 2-vectors) accumulated along a turn: the centroid's, and
    the particle's slip over the upper and the lower plate."""

    position: np.ndarray
    slip_up: np.ndarray
    slip_low: np.ndarray


def turn_kinematics(nodes: Sequence[Evaluation],
                    classify: Callable[[Evaluation], RigidState]) -> Increments:
    """Integrate the kinematics over consecutive orientations (module docstring).

    ``classify`` gives the state on the leg that starts at an orientation: ``ROLL_LOWER``
    pivots about the lower plate, ``ROLL_UPPER`` about the upper plate, ``ROTATE`` about the
    centroid.
    """
    position, slip_up, slip_low = np.zeros(2), np.zeros(2), np.zeros(2)
    for a, b in itertools.pairwise(nodes):
        phi = (b.rotation * a.rotation.inv()).as_rotvec()
        sweep = np.array([phi[1], -phi[0]])     # φ (n_y, −n_x)
        kind = classify(a)
        top = 0.5 * (a.up.plate + b.up.plate)
        bottom = 0.5 * (a.low.plate + b.low.plate)
        if kind is RigidState.ROLL_LOWER:
            pivot = bottom
        elif kind is RigidState.ROLL_UPPER:
            pivot = top
        else:
            pivot = 0.0
        position += sweep * (0.0 - pivot)
        slip_up += sweep * (top - pivot)
        slip_low += sweep * (bottom - pivot)
    return Increments(position, slip_up, slip_low)


# --- a particle's turn in a load step ----------------------------------------------------------
@dataclass(frozen=True)
class TurnSettings:
    """What a turn needs besides the particle (picklable, for worker processes): the plates,
    how a both-exceeded demand is read (:func:`thirdbody.rigid.classify`), the march step and
    the bisection tolerance (rad), and d₀ (m, the gap at first contact, for gap control)."""

    plates: Plates
    classification: str
    angle_step: float
    angle_tol: float
    d0: float

    def classify(self, ev: Evaluation) -> RigidState:
        return classify(ev.demand, self.plates.mu_up, self.plates.mu_low,
                        classification=self.classification, mu_rtol=self.plates.mu_rtol)


def turn_particle(settings: TurnSettings, member, ev: Evaluation, particle, step,
                  others: list[Compliance] | None, twins: int = 1):
    """Turn one particle from ``ev`` to its first stable orientation (or until it loses its
    load) and integrate its kinematics: at its share under force control (``others``: the
    other particles' compliance, held; None for a particle alone), at the plate gap under gap
    control. ``member`` is the particle's :class:`~thirdbody.particle.member.Member`,
    ``particle`` its :class:`~thirdbody.state.ParticleState`, updated in place; ``twins``:
    the number of identical particles turning alike with it (its share F_i then follows from
    ``twins`` · F_i + Σ others = F_N).

    Returns (the particle's state, the :class:`Turn` without its path, the wall time of its
    normal solves and of its geometry, s): what a worker process sends back."""
    m, s = member, particle
    m.bind(s.warm)
    normal0, geometry0 = m.statics.normal_time, m.statics.geometry_time
    if step.kind == "compression":
        h = settings.d0 * (1.0 - step.value)

        def evaluate(r):
            if m.reach(r) <= h:             # turned off the plates: it stops where it touched
                return Evaluation.unloaded(r)
            return m.at_gap(r, h, s)
    elif others is None:
        total = ev.force

        def evaluate(r):
            return m.at_force(r, total)
    else:
        guess = [ev.force]

        def evaluate(r):
            out = share_while_turning(m, r, step.value, others, guess[0], twins)
            if out.force > 0:
                guess[0] = out.force
            return out
    turn = find_stable_orientation(ev, evaluate, settings.plates.mu_min, settings.angle_step,
                                   settings.angle_tol)
    kinematics = turn_kinematics([*turn.path, turn.final], settings.classify)
    s.position = s.position + kinematics.position
    s.slip_up = s.slip_up + kinematics.slip_up
    s.slip_low = s.slip_low + kinematics.slip_low
    s.history.clear()
    s.rotation = turn.final.rotation
    m.restart_points(turn.final)        # the search ended elsewhere: model the final one
    times = (m.statics.normal_time - normal0, m.statics.geometry_time - geometry0)
    return s, replace(turn, path=()), times     # the path is integrated: do not ship it back


def turn_task(task: tuple):
    """:func:`turn_particle` of a tuple of its arguments (for ``Executor.map``)."""
    return turn_particle(*task)
