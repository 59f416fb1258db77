"""One load step of the normal and tangential contact problems solved together (coupling on).

For a pair with Dundurs' β ≠ 0 (an elastic particle with ν < 0.5 on a rigid plate) the shear
tractions move the surface normally (Cerruti, K_zx) and the pressure moves it tangentially (the
reciprocal block K_xz = −K_zx). The step is then one problem in (p, τ): the normal
complementarity with the gap g + K_zz p + K_zt τ, and Coulomb's law with history on the slip
Δs − K_tt (τ − τ⁰) − K_tz (p − p⁰).

Solver: the Panagiotopoulos process (Panagiotopoulos 1975; the default of Kalker's CONTACT, see
Vollebregt's user guide): alternate a normal solve with the current shear (its normal
displacement added to the gap) and a tangential solve with the new pressure (its increment's
tangential displacement added to the slip), until the coupled residual (the separation error
left by the shear the normal solve did not see) is below ``coupling_tol``. Why this and not a
monolithic solve: each half is a problem the existing solvers handle with their own
preconditioners, active sets and force constraints, and the alternation is a contraction whose
rate is set by β and μ: the coupled residual falls ~10x per pass (measured 3.4e-5, 2.3e-6,
1.9e-7, 1.5e-8 on a Cattaneo step at ν = 0.3, μ = 0.3). Three measures keep it cheap:

* the first passes, where the fields still move a lot, run on a grid twice as coarse
  (recursively), whose pressure and shear start the fine passes;
* each pass solves its halves only a hundredth below the last coupled residual (inexact
  alternation), the last one at the full tolerance;
* the slip cells of the last pass start on their new friction limit.

The passes and their residuals are reported (``coupling_passes``, ``coupling_changes``); a step
that does not converge raises :class:`ConvergenceError`.

The load history matters (Spence 1975): with β ≠ 0 even a growing normal load makes the surface
slip inward against friction, so a load must be applied in stages, each carrying the previous
step's tractions, as the tangential solver does.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._citations import cites
from ..material import Material
from .grid import Grid
from .normal import ConvergenceError, _prolong, _restrict, solve_normal
from .operator import coupling_operator
from .pair import ElasticPair
from .tangential import TangentialContact, solve_tangential

__all__ = ["solve_coupled"]

#: tolerance of the first pass's normal and tangential solves
_LOOSE = 1e-4
#: each pass solves its halves to this fraction of the last pass's change
_FORCING = 1e-2
#: grids with fewer cells than twice this across start on the finest level
_COARSEST = 32

_PANAGIOTOPOULOS = ("Panagiotopoulos, P. D. (1975). A nonlinear programming approach to the "
                    "unilateral contact- and friction-boundary value problem in the theory of "
                    "elasticity. Ing.-Arch. 44, 421-432; as used in Kalker's CONTACT (Vollebregt, "
                    "User guide for CONTACT, 2020).")


@cites("panagiotopoulos1975", _PANAGIOTOPOULOS)
def solve_coupled(gap: np.ndarray, grid: Grid, pair: ElasticPair | Material, mu: float, *,
                  force: float | None = None, approach: float | None = None,
                  tangential_force=None, shift=None,
                  previous: TangentialContact | None = None,
                  previous_pressure: np.ndarray | None = None,
                  twist: float | None = None,
                  twist_centre: tuple[float, float] = (0.0, 0.0),
                  tol: float = 1e-8, coupling_tol: float = 1e-6,
                  max_passes: int = 60,
                  initial: np.ndarray | None = None) -> TangentialContact:
    """Solve one load step with normal-tangential coupling.

    Parameters
    ----------
    gap, grid, force, approach, tol
        The normal problem, as in :func:`~thirdbody.bem.solve_normal` (force in N, approach in m).
    pair : ElasticPair or Material
        The pair's elastic constants (a Material: the particle against a rigid plate).
    mu : float
        Friction coefficient (>= 0).
    tangential_force, shift
        The tangential load of the step, as ``force``/``shift`` of
        :func:`~thirdbody.bem.solve_tangential` (N or m; exactly one).
    previous : TangentialContact, optional
        The last converged step on this grid: its traction is the history, its pressure the
        reference of the pressure increment (unless ``previous_pressure`` is given).
    previous_pressure : (ny, nx) array, optional
        The previous step's pressure on this grid, Pa (default: ``previous.normal.pressure``,
        or zero: the whole normal load is applied in this one stage).
    twist, twist_centre
        As in :func:`~thirdbody.bem.solve_tangential`.
    coupling_tol : float
        The passes stop when the coupled residual is below it: the last normal solve saw the
        shear of the pass before, so its separation is off by K_zt (τ_k − τ_{k−1}); that error,
        relative to the largest surface displacement (the normal solver's residual scale).
        The tangential half is always solved with the final pressure.
    max_passes : int
        Budget of normal-tangential passes; exceeding it raises :class:`ConvergenceError`.
    initial : (ny, nx) array, optional
        A pressure guess for the first normal solve, Pa.

    Returns
    -------
    TangentialContact
        The step; its ``normal`` is the coupled normal solution (its displacement includes the
        shear's, its ``traction`` the shear it was solved with) and ``coupling_passes`` the
        number of passes, ``coupling_changes`` the coupled residual after each (its
        convergence).
        When the pair's β is 0 this is one uncoupled normal and tangential
        solve, bit for bit.
    """
    if not coupling_tol > 0:
        raise ValueError(f"coupling_tol must be > 0, got {coupling_tol!r}")
    if int(max_passes) < 1:
        raise ValueError(f"max_passes must be >= 1, got {max_passes!r}")
    pair = pair if isinstance(pair, ElasticPair) else ElasticPair.rigid_plate(pair)
    tangential = {"force": tangential_force, "shift": shift, "previous": previous,
                  "twist": twist, "twist_centre": twist_centre}
    tau = None if previous is None else np.where(previous.normal.contact, previous.traction, 0.0)
    p_guess = initial
    tau_guess = None
    last = None                 # (traction, slip set) of the last pass
    coupler = coupling_operator(grid.shape, grid.spacing, pair.coupling_modulus) \
        if pair.coupled else None
    if pair.coupled and initial is None and min(grid.shape) >= 2 * _COARSEST:
        # the first passes, where the fields still move a lot, on a grid twice as coarse
        coarse = _coarse_step(gap, grid, pair, mu, force, approach, tangential_force, shift,
                              previous, previous_pressure, twist, twist_centre, tol,
                              coupling_tol, max_passes)
        p_guess = _prolong(coarse.normal.pressure, grid.shape)
        tau = np.stack([_prolong(t, grid.shape) for t in coarse.traction])
    history: list[float] = []
    # inexact passes: each half is solved only as accurately as the coupling is converged
    # (a hundredth of the last change), the last pass at the full tolerance
    sub_tol = max(tol, _LOOSE) if pair.coupled else tol
    for passes in range(1, int(max_passes) + 1):
        normal = solve_normal(gap, grid, pair, force=force, approach=approach, tol=sub_tol,
                              initial=p_guess, traction=tau)
        if last is not None:
            # the last pass's slip cells start on their new friction limit, in their direction
            # (on the old limit most would count as sticking and the active set would start over)
            traction, slipping = last
            norm = np.hypot(*traction)
            with np.errstate(divide="ignore", invalid="ignore"):
                unit = traction / np.where(norm > 0, norm, 1.0)
            tau_guess = np.where(slipping & normal.contact, mu * normal.pressure * unit,
                                 np.where(normal.contact, traction, 0.0))
        step = solve_tangential(normal, mu, coupling=True, previous_pressure=previous_pressure,
                                tol=sub_tol, _initial=tau_guess, **tangential)
        if not pair.coupled:
            return replace(step, coupling_passes=1)
        # the coupled residual: this pass's normal solve saw the shear of the last pass, so its
        # separation is off by K_zt (τ_new − τ_used), relative to the surface's displacement
        # (the normal solver's own residual scale); the tangential solve saw this pressure
        base = np.zeros_like(step.traction) if tau is None else tau
        change = float(np.abs(coupler.normal(step.traction - base)).max()) \
            / max(float(np.abs(normal.displacement).max()), 1e-300)
        history.append(change)
        if change <= coupling_tol and sub_tol <= tol:
            return replace(step, coupling_passes=passes, coupling_changes=tuple(history))
        sub_tol = max(tol, min(sub_tol, _FORCING * change))
        # the residual falls by a steady factor: when the next pass should meet coupling_tol,
        # make it the last one, at the full tolerance
        rate = history[-1] / history[-2] if len(history) > 1 and history[-2] > 0 else 1.0
        if change * min(rate, 1.0) <= coupling_tol:
            sub_tol = tol
        p_guess = normal.pressure
        tau, last = step.traction, (step.traction, step.slip)
    rates = ", ".join(f"{h:.1e}" for h in history[-4:])
    raise ConvergenceError(
        f"normal-tangential coupling did not converge in {max_passes} passes (last changes "
        f"{rates}; coupling_tol {coupling_tol:.1e}): try smaller load steps")


def _coarse_step(gap, grid, pair, mu, force, approach, tangential_force, shift, previous,
                 previous_pressure, twist, twist_centre, tol, coupling_tol, max_passes):
    """The step on a grid of cells twice as large (2x2 averages of the gap, the history's
    traction and pressure), converged loosely: its fields start the fine passes."""
    nx, ny = grid.n
    dx, dy = grid.spacing
    cx, cy = grid.center
    c_nx, c_ny = (nx + 1) // 2, (ny + 1) // 2
    coarse = Grid((c_nx, c_ny), (2 * dx, 2 * dy),
                  center=(cx + (c_nx - nx / 2) * dx, cy + (c_ny - ny / 2) * dy))
    c_previous = c_pressure = None
    if previous_pressure is not None:
        c_pressure = _restrict(previous_pressure)
    if previous is not None:
        normal = previous.normal
        c_normal = replace(normal, pressure=_restrict(normal.pressure), grid=coarse,
                           contact=_restrict(normal.contact.astype(float)) > 0)
        c_previous = replace(previous, traction=np.stack([_restrict(t)
                                                          for t in previous.traction]),
                             normal=c_normal)
    return solve_coupled(_restrict(gap), coarse, pair, mu, force=force, approach=approach,
                         tangential_force=tangential_force, shift=shift, previous=c_previous,
                         previous_pressure=c_pressure, twist=twist, twist_centre=twist_centre,
                         tol=max(tol, 1e-6), coupling_tol=max(coupling_tol, 1e-4),
                         max_passes=max_passes)
