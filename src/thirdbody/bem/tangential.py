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
traction as it was, not projected on the new discs first (docs/methods/design.md §4 says why):
where the pressure fell, the projection would release a displacement K (τ⁰ − Π τ⁰) that no cell
counts as slip, so the stick cells would not follow the plate.

This module holds the step's result (:class:`TangentialContact`) and :func:`solve_tangential`,
which validates its inputs and dispatches to one function per case: full sliding, frictionless,
force control and shift control. The solvers live next door: the active set (Kalker's CONTACT
as Vollebregt 2014 solves it) in :mod:`~thirdbody.bem.active_set`, the shift search that backs
force control near full sliding in :mod:`~thirdbody.bem.shift_search`, Coulomb's discs and
residual in :mod:`~thirdbody.bem.coulomb`.

Sign conventions: traction is what the plate exerts on the particle (Pa); displacements are the
particle surface's (m), parallel to the traction that causes them; the shift is the plate's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .active_set import ActiveSet, WindowStep, solve_on_levels
from .coulomb import coulomb_residual
from .grid import fast_span
from .normal import ConvergenceError, NormalContact
from .operator import TangentialOperator, coupling_operator, tangential_operator
from .shift_search import force_by_shift

__all__ = ["FrictionLimitError", "TangentialContact", "coulomb_residual", "restart_traction",
           "solve_tangential", "solve_tangential_from"]


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
        Whether ``residual`` is within the requested ``tol``. An iterative step is accepted up
        to 10 ``tol`` (the active set stops when its inner tolerance has fallen a thousandfold
        below ``tol`` without meeting it) and then reported with ``converged`` False; beyond
        that the solver raises :class:`~thirdbody.bem.ConvergenceError`. The closed forms (full
        sliding, frictionless) iterate nothing and report True: their residual is what the
        closed form leaves (in full sliding the slip need not be parallel to μp e everywhere).
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
    search_jacobian : (2, 2) array or None
        When force control searched the shift and corrected its angle by Broyden's method:
        the last Jacobian of the straightened force and its angle against the shift's length
        (m) and angle (rad), to start the search of a repeated step (``shift_jacobian`` of
        :func:`solve_tangential_from`); else None.
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
    search_jacobian: np.ndarray | None = field(default=None, repr=False)

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


def solve_tangential(normal: NormalContact, mu: float, *,
                     force: ArrayLike | float | None = None,
                     shift: ArrayLike | float | None = None,
                     previous: TangentialContact | None = None, tol: float = 1e-8,
                     scalar: bool = False, max_outer: int = 60, max_iter: int = 500,
                     twist: float | None = None,
                     twist_centre: tuple[float, float] = (0.0, 0.0),
                     coupling: bool = False, previous_pressure: np.ndarray | None = None,
                     callback: Callable[[ActiveSet], None] | None = None,
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
    callback : callable, optional
        Called as ``callback(solver)`` after each outer pass of every active-set solve (on
        each level of the coarse-to-fine cascade, and in each solve of the shift search), with
        the :class:`~thirdbody.bem.active_set.ActiveSet`; its ``last_pass``
        (:class:`~thirdbody.bem.active_set.OuterPass`) says what the pass did. For tracing:
        ``callback=lambda s: print(s.last_pass)``.

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
    The cases, each in its own function: full sliding (|force| = μF_N, a closed form),
    frictionless (μ = 0 and no force), force control (the active set with the force
    constraint; near full sliding, where it can fail, the shift search of
    :mod:`~thirdbody.bem.shift_search`) and shift control (the active set).

    Without coupling (Goodman's approximation) the tangential tractions do not change the
    pressure and the pressure does not move the surface tangentially: exact for ν = 0.5
    against a rigid plate. :func:`thirdbody.bem.solve_coupled` alternates the two problems.
    """
    step, force, shift = _validated(
        normal, mu, force=force, shift=shift, previous=previous, tol=tol, scalar=scalar,
        max_outer=max_outer, max_iter=max_iter, twist=twist, twist_centre=twist_centre,
        coupling=coupling, previous_pressure=previous_pressure, callback=callback)
    return _dispatch(step, force, shift, start=None)


#: the keyword arguments of :func:`solve_tangential` and their defaults
_OPTIONS = dict(solve_tangential.__kwdefaults__)


def solve_tangential_from(start: np.ndarray | None, normal: NormalContact, mu: float, *,
                          shift_guess: ArrayLike | None = None, search_first: bool = False,
                          shift_jacobian: np.ndarray | None = None,
                          **options: Any) -> TangentialContact:
    """:func:`solve_tangential` (``options``: its keyword arguments) with the iteration
    started from the traction ``start`` (2, ny, nx), Pa, instead of the coarse-to-fine
    cascade: its cells on the friction limit start slipping in its direction. For solvers that
    repeat a step under a slightly different pressure (the coupled passes of
    :func:`~thirdbody.bem.solve_coupled`, a particle's coupled evaluations), with ``start``
    from :func:`restart_traction`. None: as :func:`solve_tangential`. ``shift_guess``: the
    plate's total shift (2,), m, of that repeated step; under force control, should the
    active set fail (near full sliding), the shift search starts there instead of from
    scratch (:func:`~thirdbody.bem.shift_search.force_by_shift`). ``search_first`` (with a
    ``shift_guess``): go to that search without trying the active set's force control first,
    for a step whose repeated one had no stick cell left (force control, which needs one to
    carry the force, fails there after several outer passes). ``shift_jacobian``: that
    step's ``search_jacobian``, with which the search from the guess starts by Broyden's
    steps. The start, the guess, ``search_first`` and the Jacobian change the iteration, not
    what is accepted: the same checks apply."""
    step, force, shift = _validated(normal, mu, **{**_OPTIONS, **options})
    guess = None if shift_guess is None else _vector(shift_guess, "shift_guess")
    return _dispatch(step, force, shift, start, guess, search_first and guess is not None,
                     shift_jacobian)


def _dispatch(step: _Step, force: np.ndarray | None, shift: np.ndarray | None,
              start: np.ndarray | None, guess: np.ndarray | None = None,
              search_first: bool = False,
              jacobian: np.ndarray | None = None) -> TangentialContact:
    """The case the load makes of the step, solved: ``force`` (2,), N, or the total ``shift``
    (2,), m; ``guess``: a total shift (2,), m, near the one the force needs; ``search_first``:
    force control by the shift search alone; ``jacobian``: the guess's search Jacobian."""
    if force is None:
        return _shift_control(step, shift, start)
    q = float(np.hypot(*force))
    if q >= step.cap * (1 - 1e-12) and q > 0:
        return _full_sliding(step, force / q)
    if step.cap == 0:
        return _frictionless(step)
    return _force_control(step, force, start, guess, search_first, jacobian)


@dataclass(frozen=True)
class _Step:
    """One step as :func:`_validated` made it, without its load: what every case needs (and
    each solve of the shift search, which differ only in the shift)."""

    normal: NormalContact
    mu: float
    #: the previous traction as it was (the reference of the displacement increment), Pa
    tau0: np.ndarray
    #: the previous step's shift, m
    prev_shift: np.ndarray
    twist: float
    twist_centre: tuple[float, float]
    #: rigid displacement increment of the plate on top of the uniform shift (twist; with
    #: coupling also the pressure increment's tangential displacement, opposite), m, or None
    rigid: np.ndarray | None
    #: tangential displacement of the whole pressure (coupling), m, or None
    coupled: np.ndarray | None
    K: TangentialOperator
    tol: float
    scalar: bool
    max_outer: int
    max_iter: int
    callback: Callable[[ActiveSet], None] | None

    @property
    def k0(self) -> float:
        """Self-compliance K_xx(0), m/Pa."""
        return self.K.self_terms[0]

    @property
    def cap(self) -> float:
        """The friction limit μF_N, N."""
        return self.mu * self.normal.force

    def force_of(self, traction: np.ndarray) -> np.ndarray:
        """Total force Σ τ ΔA (2,), N, of a (2, ny, nx) traction in Pa."""
        return traction.reshape(2, -1).sum(axis=1) * self.normal.grid.cell_area


def _vector(value, name: str) -> np.ndarray:
    """A finite scalar (x component) or 2-vector as a (2,) float array."""
    a = np.zeros(2)
    v = np.atleast_1d(np.asarray(value, dtype=float))
    if v.size not in (1, 2) or not np.isfinite(v).all():
        raise ValueError(f"{name} must be a finite scalar or 2-vector, got {v!r}")
    a[: v.size] = v
    return a


def _validated(normal: NormalContact, mu: float, *, force, shift, previous, tol, scalar,
               max_outer, max_iter, twist, twist_centre, coupling, previous_pressure,
               callback) -> tuple[_Step, np.ndarray | None, np.ndarray | None]:
    """Check the inputs of :func:`solve_tangential` and gather the step: (step, force (2,) in N
    or None, total shift (2,) in m or None)."""
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu (friction coefficient) must be a finite number >= 0, got {mu!r}")
    if (force is None) == (shift is None):
        raise ValueError("give exactly one of force (N) and shift (m)")
    grid, mat = normal.grid, normal.pair
    p = normal.pressure
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
    coupled = None
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
    step = _Step(normal, mu, tau0, prev_shift, twist, centre, rigid, coupled, K, tol, scalar,
                 max_outer, max_iter, callback)
    if force is not None:
        Q = _vector(force, "force")
        if scalar and Q[1] != 0:
            raise ValueError("scalar=True solves x-loading only: force must have F_y = 0")
        Qn = float(np.hypot(*Q))
        cap = step.cap
        if Qn > cap * (1 + 1e-12):
            raise FrictionLimitError(
                f"tangential force {Qn:.6g} N exceeds the friction limit mu*F_N = {cap:.6g} N "
                f"(mu = {mu}, F_N = {normal.force:.6g} N): the contact slides")
        return step, Q, None
    total = _vector(shift, "shift")
    if scalar and (total - prev_shift)[1] != 0:
        raise ValueError("scalar=True solves x-loading only: shift must have s_y = 0")
    return step, None, total


# --- the cases -------------------------------------------------------------------------------
def _full_sliding(step: _Step, e: np.ndarray) -> TangentialContact:
    """|force| = μF_N along the unit vector ``e``: τ = μp e everywhere in contact. The shift is
    the smallest one consistent with every cell slipping along e: the plate has moved at least
    as far as the furthest surface point."""
    normal, rigid = step.normal, step.rigid
    tau = step.mu * normal.pressure * e[:, None, None]
    tau[:, ~normal.contact] = 0.0
    du = step.K(tau - step.tau0)
    if rigid is not None:
        du = du - rigid
    along = (du * e[:, None, None]).sum(axis=0)[normal.contact].max()
    return _finish(step, tau, e * along, 0, 1.0, full=True, rigid=rigid)


def _frictionless(step: _Step) -> TangentialContact:
    """μ = 0 and no force: no traction anywhere, every cell free to slip; the plate's shift is
    undefined, so it does not move."""
    return _finish(step, np.zeros_like(step.tau0), np.zeros(2), 0, step.tol, full=True)


def _force_control(step: _Step, force: np.ndarray, start: np.ndarray | None = None,
                   guess: np.ndarray | None = None, search_first: bool = False,
                   jacobian: np.ndarray | None = None) -> TangentialContact:
    """0 < |force| < μF_N: the active set with the force constraint, its answer's force checked
    from the tractions like Coulomb's law (the active set holds it to round-off); if either
    fails (typically close to full sliding, where the stick zone is a few cells or none), the
    shift search (from the total shift ``guess``, m, when given). ``search_first``: the shift
    search without the active set's attempt; ``jacobian``: the search's first Jacobian."""
    if search_first:
        return force_by_shift(step, force, "tangential solver: the shift search from the "
                              "repeated step's shift failed", _shift_control, guess=guess,
                              start=start, jacobian=jacobian)
    t, failure = _by_active_set(step, force=force, start=start)
    if t is not None:
        if np.abs(t.force - force).max() <= max(step.tol, 1e-12) * step.cap:
            return t
        failure = (f"tangential solver: force ({t.force[0]:.6g}, {t.force[1]:.6g}) N "
                   f"misses the prescribed ({force[0]:.6g}, {force[1]:.6g}) N")
    return force_by_shift(step, force, failure, _shift_control, guess=guess, start=start,
                          jacobian=jacobian)


def _shift_control(step: _Step, shift: np.ndarray,
                   start: np.ndarray | None = None) -> TangentialContact:
    """The plate's total shift prescribed (2,), m: the active set."""
    t, failure = _by_active_set(step, shift=shift - step.prev_shift, start=start)
    if t is None:
        raise ConvergenceError(failure)
    return t


def _by_active_set(step: _Step, *, force: np.ndarray | None = None,
                   shift: np.ndarray | None = None,
                   start: np.ndarray | None = None) -> tuple[TangentialContact | None, str]:
    """The step by the active set (:func:`~thirdbody.bem.active_set.solve_on_levels`) on the
    bounding box of the contact (tractions vanish outside it), with the prescribed ``force``
    (N) or ``shift`` increment (m), checked by :func:`_finish`: (step, "") or (None, why)."""
    normal, grid, K = step.normal, step.normal.grid, step.K
    contact = normal.contact
    rows = np.flatnonzero(contact.any(axis=1))
    cols = np.flatnonzero(contact.any(axis=0))
    if rows.size == 0:
        raise ValueError("the normal solution has no contact")
    box = (fast_span(rows[0], rows[-1] + 1, grid.ny), fast_span(cols[0], cols[-1] + 1, grid.nx))
    cells = (slice(None), *box)
    rigid_box = None if step.rigid is None else step.rigid[cells]
    outside = step.tau0.copy()
    outside[cells] = 0.0
    if outside.any():
        # the previous traction outside the box (where the contact was lost) drops to zero: the
        # displacement that releases on the box counts like a motion of the plate
        released = K(outside)[cells]
        rigid_box = released if rigid_box is None else rigid_box + released
    limit = step.mu * normal.pressure
    window = WindowStep(grid.spacing, step.tau0[cells], limit[box], contact[box], force=force,
                        shift=shift, rigid=rigid_box)
    out = solve_on_levels(window, normal.pair.G, normal.pair.nu, step.tol,
                          start=None if start is None else start[cells], scalar=step.scalar,
                          max_outer=step.max_outer, max_inner=step.max_iter,
                          callback=step.callback)
    if out is None:
        return None, ("tangential solver did not converge (stick/slip set or slip directions "
                      "kept changing); try a smaller load increment")
    ncomp = out.traction.shape[0]
    tau = np.zeros((2, *grid.shape))
    tau[(slice(ncomp), *box)] = out.traction
    ds = np.zeros(2)
    ds[:ncomp] = out.shift
    if shift is not None:
        ds = shift
    try:
        return _finish(step, tau, ds, out.iterations, step.tol, rigid=step.rigid,
                       scalar=step.scalar), ""
    except ConvergenceError as exc:
        return None, str(exc)


def _finish(step: _Step, tau: np.ndarray, ds: np.ndarray, iterations: int, tol: float, *,
            full: bool = False, rigid: np.ndarray | None = None,
            scalar: bool = False) -> TangentialContact:
    """The step with traction ``tau`` (Pa) and shift increment ``ds`` (m), its slip and
    Coulomb residual recomputed from the tractions; raises :class:`ConvergenceError` if that
    residual is above 10 ``tol``. ``full``: a closed form (full sliding, frictionless)."""
    normal, mu, K = step.normal, step.mu, step.K
    contact = normal.contact
    limit = mu * normal.pressure
    du = K(tau - step.tau0)
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
    residual = coulomb_residual(np.where(contact, tau, 0.0), w, normal.pressure, mu, step.k0)
    if not residual <= max(tol, 1e-14) * 10:
        raise ConvergenceError(f"tangential solver: Coulomb residual {residual:.3e} above "
                               f"tol {tol:.1e}")
    displacement = K(tau) if step.coupled is None else K(tau) + step.coupled
    return TangentialContact(
        traction=tau, displacement=displacement, shift=step.prev_shift + ds,
        force=step.force_of(tau), stick=stick, slip=slip,
        slip_increment=w, mu=float(mu), normal=normal, iterations=iterations,
        residual=residual, converged=bool(full or residual <= tol),
        full_sliding=bool(full or not stick.any()),
        twist=step.twist, twist_centre=step.twist_centre)
