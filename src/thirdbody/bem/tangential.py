"""Incremental partial-slip (Coulomb) tangential contact of a rigid plate on the particle.

One load step: given the normal solution (pressure p, contact set) and the previous converged
traction τ⁰, the plate makes a rigid tangential shift increment Δs (m, 2-vector). The particle's
surface moves by Δu = K (τ - τ⁰) (Cerruti influence coefficients, x-y coupling through ν,
Goodman approximation: no normal-tangential coupling, exact for ν = 0.5). Coulomb's law with
history (the paper's eq 7, with the friction disc |τ| <= μp rather than a box per component):

* stick cells (|τ| < μp): Δu = Δs, the surface follows the plate;
* slip cells: |τ| = μp and τ points along the relative slip w = Δs - Δu of the plate over the
  particle (the plate drags the particle along).

Equivalently τ minimises ½ (τ-τ⁰)ᵀ K (τ-τ⁰) - Δs·Σ(τ-τ⁰)ΔA over the discs; with a prescribed
force Q the constraint Σ τ ΔA = Q replaces Δs, which becomes its multiplier. τ⁰ is the previous
traction as it was, not projected on the new discs first (DESIGN.md §4 projects it): where the
pressure fell, the projection would release a displacement K (τ⁰ − Π τ⁰) that no cell counts as
slip, so the stick cells would not follow the plate (measured: off by 78-93 % of the step's
displacement when the normal load drops to 0.8 or 0.3 of its value).

Solver: an active-set method in the spirit of Kalker's CONTACT (Vollebregt 2014): with the slip
cells and their slip directions fixed, the stick tractions solve a linear symmetric positive
definite problem, handled by conjugate gradients preconditioned with the inverse of the
half-space's 2x2 lattice symbol (:func:`~thirdbody.bem.operator.cerruti_symbol`); an outer loop
moves cells between stick and slip and updates slip directions.
Slip cells keep one degree of freedom in the CG, a rotation on their disc, with the Newton
curvature |w|/(μp); three measures keep the iteration counts low at ν > 0:

* the rotation dofs are scaled by (k₀/(k₀ + |w|/(μp)))^½ around the Fourier preconditioner;
* the preconditioner is the free half-space's symbol, not the inverse of the zero-padded
  kernel's spectrum (cut off at the window, wrong at the contact's own wavelengths): on the
  Cattaneo benchmark at 512² it takes 33 CG iterations at ν = 0.5 and 30 at ν = 0.3, where the
  inverse of a kernel padded by half the box took 164 and 263;
* a coarse-to-fine cascade gives the finest grid its starting stick/slip sets and directions,
  and while the sets still change each CG solve only reduces its residual tenfold.

Sign conventions: traction is what the plate exerts on the particle (Pa); displacements are the
particle surface's (m), parallel to the traction that causes them; the shift is the plate's.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .active_set import WindowStep, solve_on_levels
from .coulomb import coulomb_residual, project_on_discs
from .grid import fast_span
from .normal import ConvergenceError, NormalContact
from .operator import coupling_operator, tangential_operator

__all__ = ["FrictionLimitError", "TangentialContact", "coulomb_residual", "restart_traction",
           "solve_tangential"]


class FrictionLimitError(ValueError):
    """A prescribed tangential force exceeds what friction can transmit, μ·F_N."""


@dataclass(frozen=True)
class TangentialContact:
    """One converged incremental tangential step.

    Attributes
    ----------
    traction : (2, ny, nx) array
        (τ_x, τ_y) exerted by the plate on the particle, Pa; zero outside the contact.
    displacement : (2, ny, nx) array
        Tangential elastic displacement of the particle surface, m (total, from zero traction).
    shift : (2,) array
        Rigid tangential displacement of the plate, m, accumulated over the steps.
    force : (2,) array
        Total tangential force Σ τ ΔA, N.
    stick, slip : (ny, nx) bool arrays
        Stick and slip cells (both inside the contact).
    slip_increment : (2, ny, nx) array
        Relative slip of the plate over the particle in this step, Δs - Δu (m), zero in stick.
    mu : float
    normal : NormalContact
        The normal solution this step was solved on.
    iterations : int
        Conjugate-gradient iterations (all outer passes).
    residual : float
        Coulomb complementarity residual max_i |τ_i - Π_i(τ_i + w_i/k₀)| / (μ max p), with Π_i
        the projection on the friction disc and k₀ the self-compliance: zero iff every cell
        obeys stick or slip exactly.
    converged : bool
    full_sliding : bool
        Every contact cell slides (|τ| = μp everywhere).
    twist : float
        Rigid rotation of the plate about the vertical axis through ``twist_centre``, rad,
        accumulated over the steps like ``shift`` (positive counter-clockwise seen from +z).
    twist_centre : (float, float)
        The point (m) the twist turns about.
    coupling_passes : int
        Normal-tangential passes of :func:`~thirdbody.bem.solve_coupled` (0: solved uncoupled).
    coupling_changes : tuple of float
        The relative change of the pressure or traction in each of those passes.
    """

    traction: np.ndarray
    displacement: np.ndarray
    shift: np.ndarray
    force: np.ndarray
    stick: np.ndarray
    slip: np.ndarray
    slip_increment: np.ndarray
    mu: float
    normal: NormalContact = field(repr=False)
    iterations: int
    residual: float
    converged: bool
    full_sliding: bool
    methods: tuple[str, ...] = ("kalker_tangcg", "lattice_symbol", "love1929", "dcfft")
    twist: float = 0.0
    twist_centre: tuple[float, float] = (0.0, 0.0)
    coupling_passes: int = 0
    coupling_changes: tuple[float, ...] = ()

    @property
    def stick_area(self) -> float:
        """Area of the stick zone, m²."""
        return float(self.stick.sum()) * self.normal.grid.cell_area

    @property
    def moment(self) -> float:
        """Moment about the vertical axis through ``twist_centre`` of the tractions, N m
        (positive counter-clockwise seen from +z): Σ ((x − x_c) τ_y − (y − y_c) τ_x) ΔA."""
        X, Y = self.normal.grid.mesh()
        xc, yc = self.twist_centre
        return float(((X - xc) * self.traction[1] - (Y - yc) * self.traction[0]).sum()
                     * self.normal.grid.cell_area)


def restart_traction(traction: np.ndarray, slipping: np.ndarray, normal: NormalContact,
                     mu: float) -> np.ndarray:
    """A start for a tangential solve close to a solved one (the same load under a slightly
    different pressure, e.g. the next coupled pass): the old slip cells on their new friction
    limit μp in their old direction (on the old limit most would count as sticking and the active
    set would start over), the other contact cells with their old traction, Pa (2, ny, nx)."""
    norm = np.hypot(*traction)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = traction / np.where(norm > 0, norm, 1.0)
    return np.where(slipping & normal.contact, mu * normal.pressure * unit,
                    np.where(normal.contact, traction, 0.0))


def solve_tangential(normal: NormalContact, mu: float, *, force=None, shift=None,
                     previous: TangentialContact | None = None, tol: float = 1e-8,
                     scalar: bool = False, max_outer: int = 60,
                     max_iter: int = 500, twist: float | None = None,
                     twist_centre: tuple[float, float] = (0.0, 0.0),
                     coupling: bool = False, previous_pressure: np.ndarray | None = None,
                     _initial: np.ndarray | None = None,
                     ) -> TangentialContact:
    """Solve one incremental partial-slip step on top of a normal contact solution.

    Parameters
    ----------
    normal : NormalContact
        The current normal solution (pressure, contact set, grid, material).
    mu : float
        Coulomb friction coefficient (>= 0).
    force : (2,) array_like or float, optional
        Prescribed total tangential force (F_x, F_y) on the particle, N; a scalar means F_x.
        Must not exceed μ·F_N in magnitude (:class:`FrictionLimitError`); equal to it means full
        sliding.
    shift : (2,) array_like or float, optional
        Prescribed total rigid tangential displacement of the plate, m (scalar: x). Exactly one of
        ``force`` and ``shift``.
    previous : TangentialContact, optional
        The last converged step. Its traction τ⁰ is the reference of the displacement increment
        Δu = K (τ − τ⁰) as it was, also where it exceeds the new friction limit or the contact
        was lost (there the released displacement counts as slip, eq. 7); the iteration starts
        from τ⁰ projected on the new friction discs, new contact cells from zero traction.
        Without it the step starts from zero traction and zero shift.
    tol : float
        Tolerance on the Coulomb residual (see :class:`TangentialContact`).
    scalar : bool
        Solve for τ_x only with a box |τ_x| <= μp (the classical scalar approximation that ignores
        u_y); default False: the full x-y coupled problem with the friction disc.
    twist : float, optional
        Prescribed total rotation of the plate about the vertical axis through
        ``twist_centre`` (m), rad, counter-clockwise seen from +z; default: the previous
        step's (no increment). Its increment moves the plate by Δω (−(y − y_c), x − x_c) on
        top of the uniform shift; the moment it needs is :attr:`TangentialContact.moment`.
        In full sliding the tractions stay μp along the force and the twist enters only the
        slip increment.
    coupling : bool
        Normal-tangential coupling: the pressure's change since the previous step moves the
        surface tangentially, Δu = -(K_zx, K_zy) * (p − p_prev) (reciprocal to Cerruti's normal
        displacement; zero when the pair's Dundurs β is 0), and that displacement enters the
        slip like the plate's. Default False: Goodman's approximation.
    previous_pressure : (ny, nx) array, optional
        With ``coupling``: the previous step's pressure on this grid, Pa (default:
        ``previous.normal.pressure``, or zero without ``previous``: the normal load was applied
        in this step).

    Raises
    ------
    ConvergenceError
        No step was found whose Coulomb residual, recomputed from the tractions, is within
        10 ``tol``, or (force control) whose force, summed from the tractions, is the
        prescribed one within ``tol`` μF_N. A wrong answer is never returned.
    FrictionLimitError
        |force| > μF_N.

    Notes
    -----
    Without coupling (Goodman's approximation) the tangential tractions do not change the
    pressure and the pressure does not move the surface tangentially: exact for ν = 0.5
    against a rigid plate. :func:`thirdbody.bem.solve_coupled` alternates the two problems.
    """
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu (friction coefficient) must be a finite number >= 0, got {mu!r}")
    if (force is None) == (shift is None):
        raise ValueError("give exactly one of force (N) and shift (m)")
    grid, mat = normal.grid, normal.pair

    def vec(v, name):
        a = np.zeros(2)
        v = np.atleast_1d(np.asarray(v, dtype=float))
        if v.size not in (1, 2) or not np.isfinite(v).all():
            raise ValueError(f"{name} must be a finite scalar or 2-vector, got {v!r}")
        a[: v.size] = v
        return a

    p = normal.pressure
    contact = normal.contact
    limit = mu * p
    FN = normal.force
    prev_shift = np.zeros(2)
    prev_twist = 0.0
    tau0 = np.zeros((2, *grid.shape))
    if previous is not None:
        if previous.traction.shape != tau0.shape:
            raise ValueError("previous step was solved on a different grid")
        prev_shift = np.asarray(previous.shift, dtype=float)
        prev_twist = float(previous.twist)
        # the increment's displacement is measured from the previous traction as it was, also
        # where it exceeds the new friction limit or the contact was lost: projecting it first
        # would move the surface by K (τ⁰ − Π τ⁰) without counting that as slip, and stick
        # cells would not follow the plate (eq. 7)
        tau0 = np.asarray(previous.traction, dtype=float)
    twist = prev_twist if twist is None else float(twist)
    if not np.isfinite(twist):
        raise ValueError(f"twist must be a finite angle in rad, got {twist!r}")
    centre = (float(twist_centre[0]), float(twist_centre[1]))
    rigid = None
    if twist != prev_twist:
        if scalar:
            raise ValueError("scalar=True solves x-loading only: no twist")
        X, Y = grid.mesh()
        rigid = (twist - prev_twist) * np.stack([-(Y - centre[1]), X - centre[0]])
    coupled = None          # tangential displacement of the whole pressure (with coupling)
    if coupling and mat.coupled:
        if scalar:
            raise ValueError("scalar=True ignores u_y: no normal-tangential coupling")
        if previous_pressure is None:
            same = previous is not None and previous.normal.pressure.shape == grid.shape
            previous_pressure = previous.normal.pressure if same else np.zeros(grid.shape)
        previous_pressure = np.asarray(previous_pressure, dtype=float)
        if previous_pressure.shape != grid.shape:
            raise ValueError(f"previous_pressure has shape {previous_pressure.shape}, expected "
                             f"{grid.shape}")
        C = coupling_operator(grid.shape, grid.spacing, mat.coupling_modulus)
        coupled = C.tangential(p)
        # the pressure increment moves the surface like a rigid motion of the plate the other way
        pressure_slip = -C.tangential(p - previous_pressure)
        rigid = pressure_slip if rigid is None else rigid + pressure_slip
    K = tangential_operator(grid.shape, grid.spacing, mat.G, mat.nu)
    k0 = K.self_terms[0]
    spin = {"twist": twist, "twist_centre": centre}
    couple = {"coupling": coupling, "previous_pressure": previous_pressure}

    if force is not None:
        Q = vec(force, "force")
        if scalar and Q[1] != 0:
            raise ValueError("scalar=True solves x-loading only: force must have F_y = 0")
        Qn = float(np.hypot(*Q))
        cap = mu * FN
        if Qn > cap * (1 + 1e-12):
            raise FrictionLimitError(
                f"tangential force {Qn:.6g} N exceeds the friction limit mu*F_N = {cap:.6g} N "
                f"(mu = {mu}, F_N = {FN:.6g} N): the contact slides")
        if Qn >= cap * (1 - 1e-12) and Qn > 0:
            return replace(_full_sliding(normal, mu, Q / Qn, tau0, prev_shift, K, rigid,
                                         coupled), **spin)
        if cap == 0:
            # frictionless (μ = 0) and no force: no traction anywhere, every cell free to slip;
            # the plate's shift is undefined, so it does not move
            return _finish(normal, mu, np.zeros_like(tau0), tau0, np.zeros(2), prev_shift, K,
                           k0, 0, tol, full=True, spin=spin, coupled=coupled)
        ds_prescribed = None
    else:
        ds_prescribed = vec(shift, "shift") - prev_shift
        if scalar and ds_prescribed[1] != 0:
            raise ValueError("scalar=True solves x-loading only: shift must have s_y = 0")
        Q = None

    # work on the bounding box of the contact: tractions vanish outside it
    rows = np.flatnonzero(contact.any(axis=1))
    cols = np.flatnonzero(contact.any(axis=0))
    if rows.size == 0:
        raise ValueError("the normal solution has no contact")
    box = (fast_span(rows[0], rows[-1] + 1, grid.ny), fast_span(cols[0], cols[-1] + 1, grid.nx))
    cells = (slice(None), *box)
    rigid_box = None if rigid is None else rigid[cells]
    outside = tau0.copy()
    outside[cells] = 0.0
    if outside.any():
        # the previous traction outside the box (where the contact was lost) drops to zero: the
        # displacement that releases on the box counts like a motion of the plate
        released = K(outside)[cells]
        rigid_box = released if rigid_box is None else rigid_box + released
    window = WindowStep(grid.spacing, tau0[cells], limit[box], contact[box], force=Q,
                        shift=ds_prescribed, rigid=rigid_box)
    out = solve_on_levels(window, mat.G, mat.nu, tol,
                          start=None if _initial is None else _initial[cells], scalar=scalar,
                          max_outer=max_outer, max_inner=max_iter)
    failure = ("tangential solver did not converge (stick/slip set or slip directions kept "
               "changing); try a smaller load increment")
    if out is not None:
        tau_b, ds, iterations = out.traction, out.shift, out.iterations
        ncomp = tau_b.shape[0]
        tau = np.zeros((2, *grid.shape))
        tau[(slice(ncomp), *box)] = tau_b
        dsv = np.zeros(2)
        dsv[:ncomp] = ds
        if ds_prescribed is not None:
            dsv = ds_prescribed
        try:
            t = _finish(normal, mu, tau, tau0, dsv, prev_shift, K, k0, iterations, tol,
                        rigid=rigid, spin=spin, coupled=coupled, scalar=scalar)
        except ConvergenceError as exc:
            failure = str(exc)
        else:
            # the force too is checked from the tractions, as Coulomb's law is (the active set
            # holds it to round-off); a miss goes on to the shift search below
            if Q is None or np.abs(t.force - Q).max() <= max(tol, 1e-12) * cap:
                return t
            failure = (f"tangential solver: force ({t.force[0]:.6g}, {t.force[1]:.6g}) N "
                       f"misses the prescribed ({Q[0]:.6g}, {Q[1]:.6g}) N")
    if Q is None:
        raise ConvergenceError(failure)
    # force control failed: typically close to full sliding, where the stick zone is a few
    # cells or none (with ν > 0 the slip directions fan out, so every cell can slip while
    # |Q| < μF_N); find the shift that transmits Q with displacement-controlled solves
    return _force_by_shift(normal, mu, Q, previous, prev_shift, tol, scalar, max_outer,
                           max_iter, failure, spin, couple)


def _force_by_shift(normal, mu, Q, previous, prev_shift, tol, scalar, max_outer, max_iter,
                    failure, spin, couple):
    """Force control by root finding on the shift increment: along e = Q/|Q| the transmitted
    force F(s e)·e increases monotonically with s (F is the gradient of a convex function of
    the shift), so it is bracketed (ahead of the previous shift, or behind it when the force
    falls: :func:`_bracket_behind`) and solved by Brent's method (:func:`_root`). When the
    contact is not symmetric that force is at an angle to Q: the shift's length and angle are
    then corrected together by Broyden's method (:func:`_broyden`), or, should that fail, one
    at a time (a secant step across e, then a new root along e)."""
    q = float(np.hypot(*Q))
    e = Q / q
    e_perp = np.array([-e[1], e[0]])
    iterations = 0
    warm: list[np.ndarray | None] = [None]
    points: list[tuple[float, float, TangentialContact]] = []     # every solve: (s, s_perp, step)

    def solve(s: float, s_perp: float) -> TangentialContact:
        nonlocal iterations
        shift = prev_shift + s * e + s_perp * e_perp
        try:
            t = solve_tangential(normal, mu, shift=shift, previous=previous, tol=tol,
                                 scalar=scalar, max_outer=max_outer, max_iter=max_iter,
                                 _initial=warm[0], **spin, **couple)
        except ConvergenceError:
            if warm[0] is None:
                raise
            t = solve_tangential(normal, mu, shift=shift, previous=previous, tol=tol,
                                 scalar=scalar, max_outer=max_outer, max_iter=max_iter,
                                 **spin, **couple)
        warm[0] = t.traction
        iterations += t.iterations
        points.append((s, s_perp, t))
        return t

    def along(t: TangentialContact) -> float:
        return float(t.force @ e) - q

    def mismatch(t: TangentialContact) -> np.ndarray:
        # the force's magnitude as (μF_N − q)^½ / (μF_N − |F|)^½ − 1 and its angle to e: both
        # zero at the root and nearly linear in the shift near full sliding, the first in the
        # shift's length (see _root), the second in its angle; F·e would mix the two (the
        # angle lowers it to second order, as much as the last 1e-4 of the length does)
        f = float(np.hypot(*t.force))
        h = _straightened(f, q, cap) if cap > q else f - q
        return np.array([h, float(np.arctan2(t.force @ e_perp, t.force @ e))])

    # scale: the shift of full sliding along e (all cells slip once the plate has moved past
    # the furthest surface point)
    K = tangential_operator(normal.grid.shape, normal.grid.spacing, normal.pair.G,
                            normal.pair.nu)
    tau_full = mu * normal.pressure * e[:, None, None]
    tau_full[:, ~normal.contact] = 0.0
    tau0 = np.zeros_like(tau_full)
    if previous is not None:
        tau0 = project_on_discs(np.where(normal.contact, previous.traction, 0.0),
                                mu * normal.pressure)
    du = K(tau_full - tau0)
    s_hi = max(float((du * e[:, None, None]).sum(axis=0)[normal.contact].max()), 1e-300)
    s_perp = 0.0
    lo = 0.0
    hi, t_hi = s_hi, solve(s_hi, s_perp)
    f_hi = along(t_hi)
    cap = mu * normal.force
    for jump in range(60):
        if f_hi >= 0:
            break
        lo, f_lo = hi, f_hi
        hi *= _bracket_factor(f_hi, q, cap, jump)
        t_hi = solve(hi, s_perp)
        f_hi = along(t_hi)
    else:
        raise ConvergenceError(f"{failure}; no shift transmits the force")
    ftol = max(tol, 1e-12) * q
    if lo == 0.0:
        # at no shift increment: the force of the previous traction on the new discs, an estimate
        # (the step's reference is that traction as it was); solved when it is not below q
        f_lo = -q + float(_force_of(tau0, normal) @ e)
        if f_lo >= 0:
            t_zero = solve(0.0, s_perp)
            f_lo = along(t_zero)
            if f_lo >= 0:
                lo, f_lo, hi, f_hi, t_hi = _bracket_behind(solve, along, t_zero, f_lo, s_hi,
                                                           s_perp, failure)
    for _ in range(10):                     # corrections of the shift's angle
        best = _root(solve, along, lo, f_lo, hi, f_hi, t_hi, s_perp, ftol, q, cap)
        if best is None:
            break
        perp = float(best.force @ e_perp)
        if scalar or abs(perp) <= ftol:
            return replace(best, iterations=iterations)
        s_best = float((best.shift - prev_shift) @ e)
        probe = solve(s_best, s_perp + 1e-3 * s_best)
        # both components at once: Broyden's method from the Jacobian of the solves at hand
        met = _broyden(solve, mismatch, np.array([s_best, s_perp]), best, probe,
                       1e-3 * s_best, points, lambda t: float(np.abs(t.force - Q).max()) <= ftol)
        if met is not None:
            return replace(met, iterations=iterations)
        # else one component at a time: a secant step across e, then the root along e again
        slope = (float(probe.force @ e_perp) - perp) / (1e-3 * s_best)
        if slope == 0:
            break
        s_perp -= perp / slope
        # re-bracket the force along e near the last root: a small step out, doubling
        t_mid = solve(s_best, s_perp)
        f_mid = along(t_mid)
        step = 0.02 * abs(s_best) * (1.0 if f_mid < 0 else -1.0)
        far, t_far = s_best + step, None
        for _ in range(40):
            t_far = solve(far, s_perp)
            if (along(t_far) < 0) != (f_mid < 0):
                break
            step *= 2.0
            far = s_best + step
        (lo, f_lo, _), (hi, f_hi, t_hi) = sorted(
            [(s_best, f_mid, t_mid), (far, along(t_far), t_far)], key=lambda x: x[1])
        if f_lo > 0 or f_hi < 0:
            break
    raise ConvergenceError(f"{failure}; the shift search did not converge either")


def _straightened(force: float, q: float, cap: float) -> float:
    """The force transmitted along e (N) as (μF_N − q)^½ / (μF_N − force)^½ − 1: zero at the
    target q, increasing with the force, and nearly linear in the shift near full sliding, where
    the deficit μF_N − force falls as 1/(s − s₀)² (``cap`` = μF_N > q)."""
    return float(np.sqrt((cap - q) / max(cap - force, 1e-300))) - 1.0


#: Broyden steps of the shift search before it falls back on one component at a time
_BROYDEN_STEPS = 8


def _broyden(solve, mismatch, x: np.ndarray, t, probe, h: float, points, met):
    """The shift s e + s_perp e_perp where the force F meets Q in both components, from a root
    along e (``t`` at x = (s, s_perp): F·e = |Q|, F·e_perp ≠ 0): Broyden's method (1965) on
    ``mismatch``, two functions of the force that vanish at Q and are nearly linear in the
    shift's length s and angle s_perp / s, the unknowns here. Its first Jacobian costs no
    solve beyond ``probe`` (at x + (0, h)): the secants to it and to the nearest other solve
    on the same line (the root search's iterates). ``met`` says when the force is met. Returns
    the step, or None (a step that raised the mismatch tenfold, a shift along e that would
    change sign, or ``_BROYDEN_STEPS`` spent: the caller then corrects one component at a
    time).

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
    start = float(np.abs(r).max())
    steps = np.column_stack([polar(s2, x[1]) - y, polar(x[0], x[1] + h) - y])
    changes = np.column_stack([mismatch(t2) - r, mismatch(probe) - r])
    try:
        J = changes @ np.linalg.inv(steps)
    except np.linalg.LinAlgError:
        return None
    for _ in range(_BROYDEN_STEPS):
        try:
            dy = -np.linalg.solve(J, r)
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(dy).all() or (y[0] + dy[0]) * y[0] <= 0:
            return None
        t_new = solve(float(y[0] + dy[0]), float((y[0] + dy[0]) * (y[1] + dy[1])))
        if met(t_new):
            return t_new
        r_new = mismatch(t_new)
        if np.abs(r_new).max() > 10 * start:
            return None
        J = J + np.outer(r_new - r - J @ dy, dy) / float(dy @ dy)
        y, r = y + dy, r_new
    return None


#: the shift search's first step past a shift that transmits too little force: the root
#: predicted from the deficit's fall as s⁻², times this margin
_BRACKET_MARGIN = 1.05


def _bracket_factor(f: float, q: float, cap: float, jump: int) -> float:
    """How far to move the shift (a factor on it) after a solve that transmits too little force
    (f = F·e − q < 0) to bracket the root. Near full sliding the deficit μF_N − F·e falls like
    1/(s − s₀)² with s₀ >= 0 (see :func:`_root`; measured local exponents 3.5 down to 2.0 on
    the coupled Fig. 3 run), so s (deficit / (μF_N − q))^½, the root if s₀ were 0, is at or
    beyond it: a bracket with one solve where doubling took 1-5. Later jumps at least double
    the shift, so a force that bends over differently is still bracketed."""
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
    (μF_N − q)^½ / (μF_N − F·e)^½ − 1, which is then a straight line through the root: one
    or two solves inside the bracket (the Illinois method on (s, f) took 8-11 solves, Brent on
    log s against log(μF_N − F·e) 3). Returns the step, or None if the bracket holds no root
    to ftol."""
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


def _force_of(traction: np.ndarray, normal: NormalContact) -> np.ndarray:
    return traction.reshape(2, -1).sum(axis=1) * normal.grid.cell_area


def _finish(normal, mu, tau, tau0, ds, prev_shift, K, k0, iterations, tol, full=False,
            rigid=None, spin=None, coupled=None, scalar=False):
    contact = normal.contact
    limit = mu * normal.pressure
    du = K(tau - tau0)
    w = ds[:, None, None] - du
    if rigid is not None:
        w = w + rigid
    w[:, ~contact] = 0.0
    if scalar:
        w[1] = 0.0          # the scalar approximation ignores u_y (and so the slip along y)
    norm_tau = np.hypot(tau[0], tau[1])
    slip = contact & (norm_tau >= limit * (1 - 1e-9))
    stick = contact & ~slip
    w[:, contact & (limit <= 0)] = 0.0
    residual = coulomb_residual(np.where(contact, tau, 0.0), w, normal.pressure, mu, k0)
    if not residual <= max(tol, 1e-14) * 10:
        raise ConvergenceError(f"tangential solver: Coulomb residual {residual:.3e} above "
                               f"tol {tol:.1e}")
    displacement = K(tau) if coupled is None else K(tau) + coupled
    return TangentialContact(
        traction=tau, displacement=displacement, shift=prev_shift + ds,
        force=_force_of(tau, normal), stick=stick, slip=slip,
        slip_increment=w, mu=float(mu), normal=normal, iterations=iterations,
        residual=residual, converged=True, full_sliding=bool(full or not stick.any()),
        **(spin or {}))


def _full_sliding(normal, mu, e, tau0, prev_shift, K, rigid=None, coupled=None):
    """τ = μp e everywhere in contact. The shift is the smallest one consistent with every cell
    slipping along e: the plate has moved at least as far as the furthest surface point."""
    tau = mu * normal.pressure * e[:, None, None]
    tau[:, ~normal.contact] = 0.0
    du = K(tau - tau0)
    if rigid is not None:
        du = du - rigid
    along = (du * e[:, None, None]).sum(axis=0)[normal.contact].max()
    ds = e * along
    return _finish(normal, mu, tau, tau0, ds, prev_shift, K, K.self_terms[0], 0, 1.0, full=True,
                   rigid=rigid, coupled=coupled)
