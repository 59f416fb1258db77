"""One load step of the normal and tangential contact problems solved together (coupling on).

For a pair with Dundurs' β ≠ 0 (an elastic particle with ν < 0.5 on a rigid plate) the shear
tractions move the surface normally (Cerruti, K_zx) and the pressure moves it tangentially (the
reciprocal block K_xz = −K_zx). The step is then one problem in (p, τ): the normal
complementarity with the gap g + K_zz p + K_zt τ, and Coulomb's law with history on the slip
Δs − K_tt (τ − τ⁰) − K_tz (p − p⁰).

Solver: the Panagiotopoulos process (Panagiotopoulos 1975; the default of Kalker's CONTACT, see
Vollebregt's user guide): alternate a normal solve with the current shear (its normal
displacement added to the gap) and a tangential solve with the new pressure (its increment's
tangential displacement added to the slip), each warm-started from the last pass, until neither
field changes by more than ``coupling_tol`` (relative to max p and μ max p). Why this and not a
monolithic solve: each half is a problem the existing solvers handle with their own
preconditioners, active sets and force constraints; the alternation is a contraction whose rate
is set by β and μ (the coupling blocks are β/(1 − ν)-small against the diagonal ones), and with
warm starts the later passes cost a few CG iterations each. Its rate is reported
(``coupling_passes``) and a step that does not converge raises :class:`ConvergenceError`.

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
from .normal import ConvergenceError, solve_normal
from .pair import ElasticPair
from .tangential import TangentialContact, solve_tangential

__all__ = ["solve_coupled"]

#: tolerance of the first pass's normal and tangential solves
_LOOSE = 1e-6
#: each pass solves its halves to this fraction of the last pass's change
_FORCING = 1e-3

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
        The passes stop when the pressure changed by less than ``coupling_tol`` max p and the
        traction by less than ``coupling_tol`` μ max p in the last pass.
    max_passes : int
        Budget of normal-tangential passes; exceeding it raises :class:`ConvergenceError`.
    initial : (ny, nx) array, optional
        A pressure guess for the first normal solve, Pa.

    Returns
    -------
    TangentialContact
        The step; its ``normal`` is the coupled normal solution (its displacement includes the
        shear's, its ``traction`` the shear it was solved with) and ``coupling_passes`` the
        number of passes, ``coupling_changes`` the change of each pass (its convergence).
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
    if previous is not None and previous_pressure is None \
            and previous.normal.pressure.shape == grid.shape:
        previous_pressure = previous.normal.pressure
    tau = None if previous is None else np.where(previous.normal.contact, previous.traction, 0.0)
    p_guess = initial
    tau_guess = None
    last = None
    p_last = None
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
            norm = np.hypot(*last.traction)
            with np.errstate(divide="ignore", invalid="ignore"):
                unit = last.traction / np.where(norm > 0, norm, 1.0)
            tau_guess = np.where(last.slip, mu * normal.pressure * unit, last.traction)
        step = solve_tangential(normal, mu, coupling=True, previous_pressure=previous_pressure,
                                tol=sub_tol, _initial=tau_guess, **tangential)
        if not pair.coupled:
            return replace(step, coupling_passes=1)
        p_max = float(normal.pressure.max())
        d_p = np.inf if p_last is None else float(np.abs(normal.pressure - p_last).max()) / p_max
        limit = mu * p_max
        base = np.zeros_like(step.traction) if tau is None else tau
        d_tau = float(np.abs(step.traction - base).max()) / limit if limit > 0 else 0.0
        change = max(d_p, d_tau)
        history.append(change)
        if change <= coupling_tol and sub_tol <= tol:
            return replace(step, coupling_passes=passes, coupling_changes=tuple(history))
        sub_tol = max(tol, min(sub_tol, _FORCING * change))
        if change <= coupling_tol:
            sub_tol = tol
        p_last, p_guess = normal.pressure, normal.pressure
        tau, last = step.traction, step
    rates = ", ".join(f"{h:.1e}" for h in history[-4:])
    raise ConvergenceError(
        f"normal-tangential coupling did not converge in {max_passes} passes (last changes "
        f"{rates}; coupling_tol {coupling_tol:.1e}): try smaller load steps")
