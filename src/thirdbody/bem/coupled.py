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
rate is set by β and μ: the coupled residual falls by a roughly steady factor per pass. Four
measures keep it cheap:

* the first passes, where the fields still move a lot, run on a grid twice as coarse
  (recursively), whose pressure and shear start the fine passes; except under a growing
  normal load with no tangential load (Spence's problem, self-similar: p and τ scale with the
  contact radius a), where the previous step stretched by a/a₀ = (W/W₀)^(1/3) about each contact
  patch's centre starts them (:func:`_stretched`);
* each pass solves its halves only a hundredth below the last coupled residual (inexact
  alternation), the last one at the full tolerance;
* the slip cells of the last pass start on their new friction limit;
* the shear each normal solve sees is mixed from the last passes' (Anderson acceleration of
  depth 2, :class:`_Anderson`).

The passes and their residuals are reported (``coupling_passes``, ``coupling_changes``); a step
that does not converge raises :class:`ConvergenceError`.

The load history matters (Spence 1975): with β ≠ 0 even a growing normal load makes the surface
slip inward against friction, so a load must be applied in stages, each carrying the previous
step's tractions, as the tangential solver does.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from .._citations import cites
from ..material import Material
from .grid import Grid, coarse_grid, embed, fast_span, prolong, restrict
from .normal import ContactAtEdgeError, ConvergenceError, _kkt, solve_normal
from .operator import coupling_operator, surface_displacements
from .pair import ElasticPair
from .tangential import TangentialContact, _vector, restart_traction, solve_tangential_from

__all__ = ["solve_coupled"]

#: tolerance of the first pass's normal and tangential solves
_LOOSE = 1e-4
#: each pass solves its halves to this fraction of the last pass's change
_FORCING = 1e-2
#: grids with fewer cells than twice this across start on the finest level
_COARSEST = 32
#: the passes run on a window around the contact when that holds at most this fraction of cells
_BOX_FILL = 0.5
#: the window is the contact's bounding box widened on each side by this fraction of its size
_BOX_MARGIN = 0.1
#: or by at least this many cells (both doubled each time the contact reaches the box's edge)
_BOX_CELLS = 4

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
                  initial: np.ndarray | None = None,
                  _crop: bool = True) -> TangentialContact:
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
    history: list[float] = []
    mixing = _Anderson(_ANDERSON_DEPTH if pair.coupled else 0)
    # inexact passes: each half is solved only as accurately as the coupling is converged
    # (a hundredth of the last change), the last pass at the full tolerance
    sub_tol = max(tol, _LOOSE) if pair.coupled else tol
    boxed = None
    if pair.coupled and _crop and grid.nx * grid.ny >= (2 * _COARSEST) ** 2:
        boxed = _solve_in_box(gap, grid, pair, mu, force, approach, tangential_force, shift,
                              previous, previous_pressure, twist, twist_centre, tol,
                              coupling_tol, max_passes, initial)
    if boxed is not None:
        # the passes converged on a window around the contact: its fields on the whole window,
        # if the separation outside the box is nowhere negative; else one more pass from them
        inner, box = boxed
        whole = _on_whole_window(inner, box, gap, grid, pair, tol)
        if whole is not None:
            return whole
        p_guess = embed(inner.normal.pressure, box, grid.shape)
        tau = embed(inner.traction, box, grid.shape)
        last = (tau, embed(inner.slip, box, grid.shape))
        history = list(inner.coupling_changes)
        sub_tol = tol
    elif pair.coupled and initial is None and _normal_growth(
            previous, previous_pressure, force, tangential_force, shift, twist, mu):
        # Spence's problem: the previous step, stretched, predicts this one better than the
        # coarse passes (measured: the same fine passes or one more, without the coarse ones)
        p_guess, tau, slip_guess = _stretched(previous, (force / previous.normal.force)
                                              ** (1 / 3))
        last = (tau, slip_guess)
    elif pair.coupled and initial is None and min(grid.shape) >= _COARSEST \
            and max(grid.shape) >= 2 * _COARSEST:
        # the first passes, where the fields still move a lot, on a grid twice as coarse
        coarse = _coarse_step(gap, grid, pair, mu, force, approach, tangential_force, shift,
                              previous, previous_pressure, twist, twist_centre, tol,
                              coupling_tol, max_passes)
        p_guess = prolong(coarse.normal.pressure, grid.shape)
        tau = np.stack([prolong(t, grid.shape) for t in coarse.traction])
        # its stick/slip sets and slip directions start the first tangential solve too (instead
        # of that solver's own uncoupled coarse-to-fine start)
        last = (tau, prolong(coarse.slip.astype(float), grid.shape) > 0.5)
    for passes in range(len(history) + 1, int(max_passes) + 1):
        normal = solve_normal(gap, grid, pair, force=force, approach=approach, tol=sub_tol,
                              initial=p_guess, traction=tau)
        if last is not None:
            tau_guess = restart_traction(*last, normal, mu)
        step = solve_tangential_from(tau_guess, normal, mu, coupling=True,
                                     previous_pressure=previous_pressure, tol=sub_tol,
                                     **tangential)
        if not pair.coupled:
            return replace(step, coupling_passes=1)
        # the coupled residual: this pass's normal solve saw the shear of the last pass, so its
        # separation is off by K_zt (τ_new − τ_used), relative to the surface's displacement
        # (the normal solver's own residual scale); the tangential solve saw this pressure
        base = np.zeros_like(step.traction) if tau is None else tau
        moved = coupler.normal(step.traction - base)
        change = float(np.abs(moved).max()) \
            / max(float(np.abs(normal.displacement).max()), 1e-300)
        history.append(change)
        if change <= coupling_tol and sub_tol <= tol:
            return replace(step, coupling_passes=passes, coupling_changes=tuple(history))
        sub_tol = max(tol, min(sub_tol, _FORCING * change))
        # the residual falls by a steady factor: when the next pass should meet coupling_tol,
        # make it the last one, at the full tolerance
        rate = history[-1] / history[-2] if len(history) > 1 and history[-2] > 0 else 1.0
        # (a mixed pass is predicted to fall by _MIXED_GAIN further)
        if change * min(rate, 1.0) * (_MIXED_GAIN if mixing.mixes_next else 1.0) \
                <= coupling_tol:
            sub_tol = tol
        p_guess = normal.pressure
        tau = mixing.next(step.traction, moved, change)
        last = (step.traction, step.slip)
    rates = ", ".join(f"{h:.1e}" for h in history[-4:])
    raise ConvergenceError(
        f"normal-tangential coupling did not converge in {max_passes} passes (last changes "
        f"{rates}; coupling_tol {coupling_tol:.1e}): try smaller load steps")


#: depth of the Anderson acceleration of the passes (0: plain alternation)
_ANDERSON_DEPTH = 2
#: a pass whose shear is mixed is predicted to reduce the coupled residual by this much more
#: than the last pass did, when deciding to solve it at the full tolerance. 1: as an unmixed
#: pass. Smaller values end some steps a pass earlier, but just below coupling_tol instead of
#: the decade below it where the last pass usually lands (docs/performance.md, coupled step)
_MIXED_GAIN = 1.0


@cites("walker_ni2011", "Walker, H. F. & Ni, P. (2011). Anderson acceleration for fixed-point "
       "iterations. SIAM J. Numer. Anal. 49, 1715-1735.")
class _Anderson:
    """Anderson acceleration (Walker & Ni 2011, type II, depth m) of the passes' fixed point
    τ -> G(τ), G: a normal solve with τ then a tangential solve with that pressure. The
    residual is f = K_zt (G(τ) - τ) (the normal displacement the coupled residual measures);
    the next shear is G(τ_k) - Σ γ_j (G(τ_{j+1}) - G(τ_j)) with γ minimising
    |f_k - Σ γ_j (f_{j+1} - f_j)| over the last m differences. The mixed shear only enters the
    next normal solve; the tangential solve starts from the unmixed one. The history is
    dropped when the coupled residual grows. Not restarted when the contact or slip set
    changes: the sets change between the first passes, so such a restart mixes only the last
    pass (measured: no pass saved)."""

    def __init__(self, depth: int) -> None:
        self.depth = depth
        self.g: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.change = np.inf

    @property
    def mixes_next(self) -> bool:
        """Whether the next call mixes (it will hold at least two passes)."""
        return self.depth > 0 and len(self.f) >= 1

    def next(self, g: np.ndarray, f: np.ndarray, change: float) -> np.ndarray:
        """The shear (2, ny, nx), Pa, for the next normal solve, from this pass's tangential
        solution ``g`` and residual ``f`` (m) of coupled size ``change``."""
        if self.depth < 1:
            return g
        if change > self.change:
            self.g, self.f = [], []
        self.change = change
        self.g = [*self.g, g][-self.depth - 1:]
        self.f = [*self.f, f.ravel()][-self.depth - 1:]
        if len(self.f) < 2:
            return g
        dF = np.stack([b - a for a, b in zip(self.f[:-1], self.f[1:], strict=True)], axis=1)
        gamma = np.linalg.lstsq(dF, self.f[-1], rcond=None)[0]
        out = g.copy()
        for k, c in enumerate(gamma):
            out -= c * (self.g[k + 1] - self.g[k])
        return out


def _normal_growth(previous, previous_pressure, force, tangential_force, shift, twist,
                   mu: float) -> bool:
    """Whether the step only raises the normal force on a step that carried no tangential
    load: force control with W >= W₀ of ``previous`` (whose pressure is the reference), no
    tangential force before (below 10⁻⁶ μW₀) nor now (below 10⁻⁶ μW), or the previous shift
    kept, and no twist."""
    if previous is None or previous_pressure is not None or force is None \
            or twist is not None or previous.twist != 0:
        return False
    w0 = float(previous.normal.force)
    if not (0 < w0 <= force) or np.hypot(*previous.force) > 1e-6 * mu * w0:
        return False
    if tangential_force is not None:
        return bool(np.hypot(*_vector(tangential_force, "tangential_force"))
                    <= 1e-6 * mu * force)
    return bool(np.array_equal(_vector(shift, "shift"), previous.shift))


def _stretched(previous: TangentialContact, s: float):
    """The previous step's pressure and shear (Pa) and slip set, each contact patch stretched
    by ``s`` about its pressure centroid and scaled by ``s``: Spence's fields under a growing
    normal load on a Hertzian patch (self-similar, p and τ proportional to the contact radius,
    which grows by ``s`` = (W/W₀)^(1/3)). Bilinear interpolation; the slip set nearest."""
    p0 = previous.normal.pressure
    contact = previous.normal.contact
    fields = np.concatenate([p0[None], np.where(contact, previous.traction, 0.0),
                             previous.slip[None].astype(float)])
    out = np.zeros_like(fields)
    labels, _ = ndimage.label(contact)
    ny, nx = p0.shape
    for k, box in enumerate(ndimage.find_objects(labels), start=1):
        if box is None:
            continue
        mine = labels == k
        weight = p0[box] * mine[box]
        if not weight.sum() > 0:
            continue
        iy, ix = np.mgrid[box[0], box[1]]
        cy, cx = (weight * iy).sum() / weight.sum(), (weight * ix).sum() / weight.sum()
        # the patch grows by (s - 1) of its size: map the cells of the widened box back
        span = []
        for sl, n in zip(box, (ny, nx), strict=True):
            grow = int(np.ceil((s - 1) * (sl.stop - sl.start))) + 2
            span.append(slice(max(sl.start - grow, 0), min(sl.stop + grow, n)))
        jy, jx = np.mgrid[span[0], span[1]].astype(float)
        coords = np.array([cy + (jy - cy) / s, cx + (jx - cx) / s])
        for f, field in enumerate(fields):
            out[f][span[0], span[1]] += ndimage.map_coordinates(
                field * mine, coords, order=0 if f == 3 else 1, mode="constant")
    return s * out[0], s * out[1:3], out[3] > 0.5


def _solve_in_box(gap, grid, pair, mu, force, approach, tangential_force, shift, previous,
                  previous_pressure, twist, twist_centre, tol, coupling_tol, max_passes,
                  initial):
    """The coupled passes on a window around the contact, or None when that window would hold
    more than ``_BOX_FILL`` of the cells. Every operator of a pass then works on that window
    (its FFTs are those of the window's size) instead of the whole one; the tractions vanish
    outside the contact, so the influence between the cells inside is the same. The window is
    the bounding box of an uncoupled contact estimate (solved loosely on a grid twice as
    coarse) and of the history's pressure and traction, widened by ``_BOX_MARGIN`` of its size
    (at least ``_BOX_CELLS``); it is widened further when the contact reaches its edge. What
    the window cannot see, a contact outside it, the caller checks on the whole window
    (:func:`_on_whole_window`). Returns (step on the window, box)."""
    mask = _contact_estimate(gap, grid, pair, force, approach)
    if mask is None:
        return None
    if previous is not None:
        mask |= (previous.normal.pressure > 0) | (previous.traction != 0).any(axis=0)
    for field in (previous_pressure, initial):
        if field is not None:
            mask |= np.asarray(field) != 0
    widen, last = 1, None
    while True:
        box = _box_around(mask, _BOX_CELLS * widen, _BOX_MARGIN * widen)
        ny, nx = grid.shape
        if (box[0].stop - box[0].start) * (box[1].stop - box[1].start) > _BOX_FILL * nx * ny \
                or box == last:
            return None         # too large, or it cannot grow: the whole window decides
        last = box
        sub = Grid((box[1].stop - box[1].start, box[0].stop - box[0].start), grid.spacing,
                   center=(float(grid.x[box[1]].mean()), float(grid.y[box[0]].mean())))
        try:
            inner = solve_coupled(
                gap[box], sub, pair, mu, force=force, approach=approach,
                tangential_force=tangential_force, shift=shift,
                previous=None if previous is None else _crop_step(previous, box, sub),
                previous_pressure=None if previous_pressure is None
                else np.asarray(previous_pressure)[box],
                twist=twist, twist_centre=twist_centre, tol=tol, coupling_tol=coupling_tol,
                max_passes=max_passes, initial=None if initial is None else initial[box],
                _crop=False)
        except ContactAtEdgeError:
            widen *= 2
            continue
        return inner, box


def _contact_estimate(gap, grid: Grid, pair: ElasticPair, force, approach) -> np.ndarray | None:
    """Where the contact will be, roughly: the uncoupled contact solved loosely on a grid twice
    as coarse, on this grid's cells (None: the coarse solve failed; the whole window decides)."""
    try:
        estimate = solve_normal(restrict(gap), coarse_grid(grid), pair, force=force,
                                approach=approach, tol=1e-4)
    except (ContactAtEdgeError, ConvergenceError, ValueError):
        return None         # ValueError: an approach that misses the coarse gap
    return prolong(estimate.contact.astype(float), grid.shape) > 0


def _on_whole_window(inner: TangentialContact, box, gap: np.ndarray, grid: Grid,
                     pair: ElasticPair, tol: float) -> TangentialContact | None:
    """The step solved on a box, on the whole window: the displacements of its tractions
    everywhere, and the normal complementarity checked on every cell (None if it fails: a
    contact outside the box)."""
    normal = inner.normal
    p = embed(normal.pressure, box, grid.shape)
    tau = embed(inner.traction, box, grid.shape)
    used = np.zeros_like(tau) if normal.traction is None \
        else embed(normal.traction, box, grid.shape)
    u, u_shear, u_t = surface_displacements(grid.shape, grid.spacing, pair, p, tau, used)
    u_z = u + u_shear
    g = np.asarray(gap, dtype=float)
    contact = embed(normal.contact, box, grid.shape)
    s = np.where(np.isfinite(g), g + u_z - normal.approach, np.inf)
    residual = _kkt(s, contact, float(u.max()))
    if not residual < tol:
        return None
    whole = replace(normal, pressure=p, displacement=u_z, contact=contact, gap=gap, grid=grid,
                    traction=None if normal.traction is None else used, residual=residual,
                    converged=True)         # residual < tol, checked above
    return replace(inner, traction=tau, displacement=u_t,
                   stick=embed(inner.stick, box, grid.shape),
                   slip=embed(inner.slip, box, grid.shape),
                   slip_increment=embed(inner.slip_increment, box, grid.shape), normal=whole)


def _box_around(mask: np.ndarray, cells: int, fraction: float) -> tuple[slice, slice]:
    """The bounding box of ``mask`` widened on each side by ``fraction`` of its size or at least
    ``cells`` cells, then to a fast FFT length."""
    box = []
    for axis, n in enumerate(mask.shape):
        hits = np.flatnonzero(mask.any(axis=1 - axis))
        margin = max(cells, int(np.ceil(fraction * (hits[-1] + 1 - hits[0]))))
        box.append(fast_span(max(int(hits[0]) - margin, 0),
                              min(int(hits[-1]) + 1 + margin, n), n))
    return box[0], box[1]


def _crop_step(step: TangentialContact, box, grid: Grid) -> TangentialContact:
    """A converged step restricted to a window (its fields on the box's cells)."""
    cells = (..., *box)
    normal = step.normal
    c_normal = replace(normal, pressure=normal.pressure[cells],
                       displacement=normal.displacement[cells], contact=normal.contact[cells],
                       gap=np.asarray(normal.gap)[cells], grid=grid,
                       traction=None if normal.traction is None else normal.traction[cells])
    return replace(step, traction=step.traction[cells], displacement=step.displacement[cells],
                   stick=step.stick[cells], slip=step.slip[cells],
                   slip_increment=step.slip_increment[cells], normal=c_normal)


def _coarse_step(gap, grid, pair, mu, force, approach, tangential_force, shift, previous,
                 previous_pressure, twist, twist_centre, tol, coupling_tol, max_passes):
    """The step on a grid of cells twice as large (2x2 averages of the gap, the history's
    traction and pressure), converged loosely: its fields start the fine passes."""
    coarse = coarse_grid(grid)
    c_previous = c_pressure = None
    if previous_pressure is not None:
        c_pressure = restrict(previous_pressure)
    if previous is not None:
        normal = previous.normal
        c_normal = replace(normal, pressure=restrict(normal.pressure), grid=coarse,
                           contact=restrict(normal.contact.astype(float)) > 0)
        c_previous = replace(previous, traction=np.stack([restrict(t)
                                                          for t in previous.traction]),
                             normal=c_normal)
    return solve_coupled(restrict(gap), coarse, pair, mu, force=force, approach=approach,
                         tangential_force=tangential_force, shift=shift, previous=c_previous,
                         previous_pressure=c_pressure, twist=twist, twist_centre=twist_centre,
                         tol=max(tol, 1e-6), coupling_tol=max(coupling_tol, 1e-4),
                         max_passes=max_passes, _crop=False)
