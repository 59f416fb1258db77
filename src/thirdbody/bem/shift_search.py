"""Force control by a search on the shift: the fallback of a force-controlled tangential step.

Near full sliding the stick zone is a few cells or none (with ν > 0 the slip directions fan out,
so every cell can slip while |Q| < μF_N), and the active set's force constraint has nothing left
to hold it. The step is then solved by displacement control, searching the shift increment that
transmits the prescribed force Q: along e = Q/|Q| the transmitted force F(s e)·e increases
monotonically with s (F is the gradient of a convex function of the shift), so it is bracketed
(ahead of the previous shift, or behind it when the force falls: :func:`_bracket_behind`) and
solved by Brent's method (:func:`_root`). When the contact is not symmetric that force is at an
angle to Q: the shift's length and angle are then corrected together by Broyden's method
(:func:`_broyden`), or, should that fail, one at a time (a secant step across e, then a new
root along e).

Forces in N (on the particle), shifts in m (the plate's), as in
:mod:`thirdbody.bem.tangential`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .coulomb import project_on_discs
from .normal import ConvergenceError

if TYPE_CHECKING:
    from .tangential import TangentialContact, _Step

__all__ = ["force_by_shift"]

#: Broyden steps of the shift search before it falls back on one component at a time
_BROYDEN_STEPS = 8
#: the shift search's first step past a shift that transmits too little force: the root
#: predicted from the deficit's fall as s⁻², times this margin
_BRACKET_MARGIN = 1.05
#: jumps from a guessed shift (:func:`force_by_shift`) before bracketing from scratch
_GUESS_JUMPS = 6
#: a guessed shift with a Jacobian starts with Broyden's steps (:func:`_newton`)
_GUESS_NEWTON = True


def force_by_shift(step: _Step, force: np.ndarray, failure: str,
                   solve_at: Callable[..., TangentialContact], *,
                   guess: np.ndarray | None = None,
                   start: np.ndarray | None = None,
                   jacobian: np.ndarray | None = None) -> TangentialContact:
    """The step that transmits ``force`` (2,), N, found by displacement-controlled solves
    ``solve_at(step, shift, start)`` (shift: the plate's total shift, m; start: a starting
    traction or None), each started from the last one's traction (from scratch if that
    fails). ``failure``: why force control failed, for the error raised if this fails too.
    ``guess``: a total shift (2,), m, close to the root (that of the same step under a
    slightly different pressure, e.g. the last coupled pass), and ``start`` its traction, Pa:
    the search then brackets the root around the guess, at the guess's angle, instead of
    from the full-sliding scale (falling back on that if no bracket is found there).
    ``jacobian``: that step's search's last Jacobian (``search_jacobian`` of its step): the
    search then first takes Broyden steps from the guess with it (:func:`_newton`).
    The step reports the CG iterations of all the solves, and, when the shift's angle was
    corrected by Broyden's method, its last Jacobian (``search_jacobian``)."""
    return _ShiftSearch(step, force, failure, solve_at).run(guess, start, jacobian)


class _ShiftSearch:
    """The state of one search: the solves made so far and their iterations."""

    def __init__(self, step: _Step, force: np.ndarray, failure: str,
                 solve_at: Callable[..., TangentialContact]) -> None:
        self.step, self.Q, self.failure, self.solve_at = step, force, failure, solve_at
        self.q = float(np.hypot(*force))
        self.e = force / self.q
        self.e_perp = np.array([-self.e[1], self.e[0]])
        self.cap = step.cap
        self.ftol = max(step.tol, 1e-12) * self.q
        self.iterations = 0
        self.warm: np.ndarray | None = None
        #: every solve: (s, s_perp, step)
        self.points: list[tuple[float, float, TangentialContact]] = []

    def solve(self, s: float, s_perp: float) -> TangentialContact:
        """The step at the shift increment s e + s_perp e_perp."""
        shift = self.step.prev_shift + s * self.e + s_perp * self.e_perp
        try:
            t = self.solve_at(self.step, shift, self.warm)
        except ConvergenceError:
            if self.warm is None:
                raise
            t = self.solve_at(self.step, shift, None)
        self.warm = t.traction
        self.iterations += t.iterations
        self.points.append((s, s_perp, t))
        return t

    def along(self, t: TangentialContact) -> float:
        """F·e − q, N: zero at the root along e."""
        return float(t.force @ self.e) - self.q

    def mismatch(self, t: TangentialContact) -> np.ndarray:
        # the force's magnitude as (μF_N − q)^½ / (μF_N − |F|)^½ − 1 and its angle to e: both
        # zero at the root and nearly linear in the shift near full sliding, the first in the
        # shift's length (see _root), the second in its angle; F·e would mix the two (the
        # angle lowers it to second order, as much as the last 1e-4 of the length does)
        q, cap = self.q, self.cap
        f = float(np.hypot(*t.force))
        h = _straightened(f, q, cap) if cap > q else f - q
        return np.array([h, float(np.arctan2(t.force @ self.e_perp, t.force @ self.e))])

    def met(self, t: TangentialContact) -> bool:
        return float(np.abs(t.force - self.Q).max()) <= self.ftol

    def run(self, guess: np.ndarray | None = None, start: np.ndarray | None = None,
            jacobian: np.ndarray | None = None) -> TangentialContact:
        e, e_perp, q, cap, ftol = self.e, self.e_perp, self.q, self.cap, self.ftol
        solve, along = self.solve, self.along
        s_perp = 0.0
        bracket = None
        if guess is not None:
            ds = np.asarray(guess, dtype=float) - self.step.prev_shift
            s_guess = float(ds @ e)
            if s_guess > 0 and jacobian is not None and _GUESS_NEWTON:
                # the repeated step's Jacobian: Broyden's steps from its shift
                self.warm = start
                t = solve(s_guess, float(ds @ e_perp))
                found = t if self.met(t) else _newton(
                    solve, self.mismatch, np.array([s_guess, float(ds @ e_perp) / s_guess]),
                    t, np.asarray(jacobian, dtype=float), self.met)
                if found is not None:
                    t, J = (found, jacobian) if found is t else found
                    return replace(t, iterations=self.iterations, search_jacobian=J)
            if s_guess > 0:
                # the root of a nearby step: its angle, and a bracket a small stride around it
                s_perp = float(ds @ e_perp)
                self.warm = start
                bracket = self._bracket_from(s_guess, s_perp)
            if bracket is None:
                s_perp = 0.0
        lo, f_lo, hi, f_hi, t_hi = self._bracket(s_perp) if bracket is None else bracket
        for _ in range(10):                     # corrections of the shift's angle
            best = _root(solve, along, lo, f_lo, hi, f_hi, t_hi, s_perp, ftol, q, cap)
            if best is None:
                break
            perp = float(best.force @ e_perp)
            if self.step.scalar or abs(perp) <= ftol:
                return replace(best, iterations=self.iterations)
            s_best = float((best.shift - self.step.prev_shift) @ e)
            probe = solve(s_best, s_perp + 1e-3 * s_best)
            # both components at once: Broyden's method from the Jacobian of the solves at hand
            met = _broyden(solve, self.mismatch, np.array([s_best, s_perp]), best, probe,
                           1e-3 * s_best, self.points, self.met)
            if met is not None:
                return replace(met[0], iterations=self.iterations, search_jacobian=met[1])
            # else one component at a time: a secant step across e, then the root along e again
            slope = (float(probe.force @ e_perp) - perp) / (1e-3 * s_best)
            if slope == 0:
                break
            s_perp -= perp / slope
            bracket = self._bracket_near(s_best, s_perp)
            if bracket is None:
                break
            lo, f_lo, hi, f_hi, t_hi = bracket
        raise ConvergenceError(f"{self.failure}; the shift search did not converge either")

    def _bracket(self, s_perp: float):
        """(lo, f_lo, hi, f_hi, step at hi): a bracket of the root along e, f = F·e − q."""
        step, e, q = self.step, self.e, self.q
        normal, mu = step.normal, step.mu
        solve, along = self.solve, self.along
        # scale: the shift of full sliding along e (all cells slip once the plate has moved past
        # the furthest surface point)
        tau_full = mu * normal.pressure * e[:, None, None]
        tau_full[:, ~normal.contact] = 0.0
        tau0 = project_on_discs(np.where(normal.contact, step.tau0, 0.0), mu * normal.pressure)
        du = step.K(tau_full - tau0)
        s_hi = max(float((du * e[:, None, None]).sum(axis=0)[normal.contact].max()), 1e-300)
        lo = 0.0
        hi, t_hi = s_hi, solve(s_hi, s_perp)
        f_hi = along(t_hi)
        for jump in range(60):
            if f_hi >= 0:
                break
            lo, f_lo = hi, f_hi
            hi *= _bracket_factor(f_hi, q, self.cap, jump)
            t_hi = solve(hi, s_perp)
            f_hi = along(t_hi)
        else:
            raise ConvergenceError(f"{self.failure}; no shift transmits the force")
        if lo == 0.0:
            # at no shift increment: the force of the previous traction on the new discs, an
            # estimate (the step's reference is that traction as it was); solved when it is not
            # below q
            f_lo = -q + float(step.force_of(tau0) @ e)
            if f_lo >= 0:
                t_zero = solve(0.0, s_perp)
                f_lo = along(t_zero)
                if f_lo >= 0:
                    lo, f_lo, hi, f_hi, t_hi = _bracket_behind(solve, along, t_zero, f_lo, s_hi,
                                                               s_perp, self.failure)
        return lo, f_lo, hi, f_hi, t_hi

    def _bracket_from(self, s: float, s_perp: float):
        """A bracket along e from a guessed shift increment ``s`` > 0 (the root of a nearby
        step) at ``s_perp``, by the jumps of :func:`_bracket_factor`: forwards while the
        force falls short, backwards (the same model, inverted) while it exceeds the target.
        None if no sign change within a few jumps (the caller then brackets from scratch)."""
        solve, along, q, cap = self.solve, self.along, self.q, self.cap
        t = solve(s, s_perp)
        f = along(t)
        if abs(f) <= self.ftol:
            return s, f, s, f, t
        h = _straightened(q + f, q, cap) if cap > q + f else None
        previous = None
        for _ in range(_GUESS_JUMPS):
            # the straightened force h is nearly linear in s (:func:`_root`): the first jump
            # goes to the root of the line through s = 0 (h = -1 there if the deficit falls
            # like s⁻²), the next ones twice as far as the secant's root
            if h is None:
                far = 0.5 * s
            elif previous is None or previous[1] == h:
                far = s / (h + 1.0)
            else:
                s_old, h_old = previous
                far = s - 2.0 * h * (s - s_old) / (h - h_old)
            if not far > 0:
                far = 0.5 * s
            if (far - s) * f > 0 or far == s:     # the jump must go towards the root
                far = s * (1.0 + 1e-3 if f < 0 else 1.0 - 1e-3)
            t_far = solve(far, s_perp)
            f_far = along(t_far)
            if abs(f_far) <= self.ftol:
                return far, f_far, far, f_far, t_far
            if (f_far < 0) != (f < 0):
                (lo, f_lo, _), (hi, f_hi, t_hi) = sorted([(s, f, t), (far, f_far, t_far)],
                                                         key=lambda x: x[1])
                return lo, f_lo, hi, f_hi, t_hi
            previous = (s, h)
            s, f, t = far, f_far, t_far
            h = _straightened(q + f, q, cap) if cap > q + f else None
        return None

    def _bracket_near(self, s_best: float, s_perp: float):
        """A new bracket along e near the last root ``s_best`` at the corrected ``s_perp``: a
        small step out, doubling; None if the force does not change sign."""
        solve, along = self.solve, self.along
        t_mid = solve(s_best, s_perp)
        f_mid = along(t_mid)
        stride = 0.02 * abs(s_best) * (1.0 if f_mid < 0 else -1.0)
        far, t_far = s_best + stride, None
        for _ in range(40):
            t_far = solve(far, s_perp)
            if (along(t_far) < 0) != (f_mid < 0):
                break
            stride *= 2.0
            far = s_best + stride
        (lo, f_lo, _), (hi, f_hi, t_hi) = sorted(
            [(s_best, f_mid, t_mid), (far, along(t_far), t_far)], key=lambda x: x[1])
        if f_lo > 0 or f_hi < 0:
            return None
        return lo, f_lo, hi, f_hi, t_hi


def _straightened(force: float, q: float, cap: float) -> float:
    """The force transmitted along e (N) as (μF_N − q)^½ / (μF_N − force)^½ − 1: zero at the
    target q, increasing with the force, and nearly linear in the shift near full sliding, where
    the deficit μF_N − force falls as 1/(s − s₀)² (``cap`` = μF_N > q)."""
    return float(np.sqrt((cap - q) / max(cap - force, 1e-300))) - 1.0


def _broyden(solve, mismatch, x: np.ndarray, t, probe, h: float, points, met):
    """The shift s e + s_perp e_perp where the force F meets Q in both components, from a root
    along e (``t`` at x = (s, s_perp): F·e = |Q|, F·e_perp ≠ 0): Broyden's method (1965) on
    ``mismatch``, two functions of the force that vanish at Q and are nearly linear in the
    shift's length s and angle s_perp / s, the unknowns here. Its first Jacobian costs no
    solve beyond ``probe`` (at x + (0, h)): the secants to it and to the nearest other solve
    on the same line (the root search's iterates). ``met`` says when the force is met. Returns
    (the step, the Jacobian of its Broyden step), or None (a step that raised the mismatch
    tenfold, a shift along e that would change sign, or ``_BROYDEN_STEPS`` spent: the caller
    then corrects one component at a time).

    Broyden, C. G. (1965). A class of methods for solving nonlinear simultaneous equations.
    Math. Comp. 19, 577-593."""
    def polar(s: float, s_perp: float) -> np.ndarray:
        return np.array([s, s_perp / s])

    # (not the root itself, which may come back a rounding away from x)
    line = [(s, step) for s, sp, step in points
            if sp == x[1] and abs(s - x[0]) > 1e-6 * abs(x[0])]
    if not line or h == 0 or x[0] == 0:
        return None
    s2, t2 = min(line, key=lambda p: abs(p[0] - x[0]))
    if s2 * x[0] <= 0:          # the angle s_perp / s is defined on one side of s = 0
        return None
    y, r = polar(*x), mismatch(t)
    steps = np.column_stack([polar(s2, x[1]) - y, polar(x[0], x[1] + h) - y])
    changes = np.column_stack([mismatch(t2) - r, mismatch(probe) - r])
    try:
        J = changes @ np.linalg.inv(steps)
    except np.linalg.LinAlgError:
        return None
    return _newton(solve, mismatch, y, t, J, met)


def _newton(solve, mismatch, y: np.ndarray, t, J: np.ndarray, met):
    """Broyden's steps on ``mismatch`` from the step ``t`` at y = (s, s_perp / s) with the
    Jacobian ``J`` (2x2, of the mismatch against y): (step, last Jacobian) once ``met``, or
    None (see :func:`_broyden`)."""
    r = mismatch(t)
    start = float(np.abs(r).max())
    for _ in range(_BROYDEN_STEPS):
        try:
            dy = -np.linalg.solve(J, r)
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(dy).all() or (y[0] + dy[0]) * y[0] <= 0:
            return None
        t_new = solve(float(y[0] + dy[0]), float((y[0] + dy[0]) * (y[1] + dy[1])))
        if met(t_new):
            return t_new, J
        r_new = mismatch(t_new)
        if np.abs(r_new).max() > 10 * start:
            return None
        J = J + np.outer(r_new - r - J @ dy, dy) / float(dy @ dy)
        y, r = y + dy, r_new
    return None


def _bracket_factor(f: float, q: float, cap: float, jump: int) -> float:
    """How far to move the shift (a factor on it) after a solve that transmits too little force
    (f = F·e − q < 0) to bracket the root. Near full sliding the deficit μF_N − F·e falls like
    1/(s − s₀)² with s₀ >= 0 (see :func:`_root`), or faster, so s (deficit / (μF_N − q))^½,
    the root if s₀ were 0, is at or beyond it: a bracket usually with one solve, where
    doubling the shift takes several. Later jumps at least double the shift, so a force that
    bends over differently is still bracketed."""
    factor = 2.0
    if cap > q:
        factor = _BRACKET_MARGIN / (_straightened(q + f, q, cap) + 1.0)
        if jump > 0:
            factor = max(factor, 2.0)
    return max(factor, 1.0 + 1e-3)


def _bracket_behind(solve, along, t_zero, f_zero: float, scale: float, s_perp: float,
                    failure: str):
    """A bracket [lo, hi] <= 0 of the shift increment along e when the force already exceeds
    the target with no increment (f_zero = F·e − q >= 0 at s = 0: the force falls, e.g. a
    particle at its friction limit unloads, and the plate moves back). The force falls slowly
    while every cell keeps slipping, then fast once cells stick, so the secant through the last
    two solves, extended to f = 0, lies beyond the root: each step goes there (at least twice
    as far), starting from -``scale``. Returns (lo, f_lo, hi, f_hi, step at hi)."""
    hi, f_hi, t_hi = 0.0, f_zero, t_zero
    lo = -scale
    for _ in range(60):
        t_lo = solve(lo, s_perp)
        f_lo = along(t_lo)
        if f_lo < 0:
            return lo, f_lo, hi, f_hi, t_hi
        reach = 2.0 * lo
        if f_hi > f_lo:
            reach = min(reach, lo - 1.5 * f_lo * (hi - lo) / (f_hi - f_lo))
        hi, f_hi, t_hi, lo = lo, f_lo, t_lo, reach
    raise ConvergenceError(f"{failure}; no shift transmits the force")


class _ForceMet(Exception):
    """Raised inside the root search once the force is met, to stop it there."""


def _root(solve, along, lo: float, f_lo: float, hi: float, f_hi: float, t_hi, s_perp: float,
          ftol: float, q: float, cap: float):
    """The shift along the force that transmits it, in the bracket [lo, hi] (f_lo < 0 < f_hi,
    f = F·e − q): Brent's method (scipy's brentq), stopped as soon as |f| <= ftol. Near full
    sliding every cell slips at an angle ~ b_i / (s − s_i) to e, so the deficit μF_N − F·e
    (``cap`` − F·e) falls like 1/(s − s₀)²; the search runs on s against
    (μF_N − q)^½ / (μF_N − F·e)^½ − 1, which is then a straight line through the root, so
    the root is found in few solves inside the bracket (fewer than the Illinois method on
    (s, f) or Brent on log s against log(μF_N − F·e)). Returns the step, or None if the
    bracket holds no root to ftol."""
    from scipy.optimize import brentq

    if abs(f_hi) <= ftol:
        return t_hi
    if not f_lo < 0 < f_hi:
        return None
    model = cap > q and f_hi < cap - q       # the deficit μF_N − F·e stays positive

    def value(f: float) -> float:
        # increasing with f, zero at the root, linear in s where the deficit goes as 1/(s − s₀)²
        return _straightened(q + f, q, cap) if model else f

    known = {lo: value(f_lo), hi: value(f_hi)}          # the bracket's ends, solved already
    best = [t_hi, abs(f_hi)]

    def g(x: float) -> float:
        if x in known:
            return known[x]
        t = solve(x, s_perp)
        f = along(t)
        if abs(f) < best[1]:
            best[:] = [t, abs(f)]
        if abs(f) <= ftol:
            raise _ForceMet
        return value(f)

    try:
        brentq(g, lo, hi, xtol=1e-300, rtol=1e-13, maxiter=100)
    except _ForceMet:
        return best[0]
    except RuntimeError:        # brentq's iteration budget
        return None
    return best[0] if best[1] <= ftol else None
