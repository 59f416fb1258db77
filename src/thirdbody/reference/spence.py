"""Spence's problem: a smooth paraboloid pressed with growing load into a frictional half-space.

Set-up: an elastic half-space (or two dissimilar elastic bodies) is indented by a smooth
paraboloid (Hertzian) profile under a normal load that only grows, with Coulomb friction μ at the
interface. Because the bodies are elastically dissimilar (Dundurs' β ≠ 0), the normal pressure
drags the surface points of the softer, more compressible body radially inward relative to the
other body; friction resists that, a central stick zone r < c forms, surrounded by an annulus
c < r < a of inward slip in which the shear traction is μp, directed outward on the body. Spence
(1975) showed that the problem is self-similar: c/a stays constant during loading.

Only dimensionless ratios are returned: c/a and Dundurs' β are pure numbers.

The normal–tangential coupling acts both ways: the pressure moves the surface tangentially (that
is what creates the stick zone) and the shear traction changes the normal displacement and so the
pressure. Two references are given:

- :func:`stick_ratio` / :func:`solve`: the fully coupled problem that Spence (1975) posed and that
  CONTACT's ``spence35`` example reproduces, solved here by an axisymmetric ring-element method
  that shares nothing with the package's FFT solvers (its own kernels from closed-form disc and
  ring solutions, its own box-constrained solves). c/a depends on β/μ and on βμ.
- :func:`stick_ratio_first_order`: a closed form for the problem with the shear's effect on the
  pressure neglected (the pressure stays Hertz's). It is the limit βμ → 0 at fixed β/μ, and the
  ring-element method reproduces it when run one way (``coupled=False``), which validates that
  method.

References
----------
D. A. Spence (1975), "The Hertz contact problem with finite friction", J. Elasticity 5, 297–319.
D. A. Spence (1973), "An eigenvalue problem for elastic contact with finite friction",
Proc. Camb. Phil. Soc. 73, 249–268 (the plane version).
K. L. Johnson (1985), *Contact Mechanics*, Cambridge University Press, §5.5.
J. Dundurs (1969), "Discussion of 'Edge-bonded dissimilar orthogonal elastic wedges under normal
and shear loading'", J. Appl. Mech. 36, 650–652 (the parameter β).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import integrate
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk, ellipkm1

from .._citations import cites
from .._validate import real

__all__ = [
    "SpenceSolution",
    "beta_over_mu",
    "beta_rigid",
    "dundurs_beta",
    "solve",
    "stick_ratio",
    "stick_ratio_first_order",
]

_SPENCE = ("Spence, D. A. (1975). The Hertz contact problem with finite friction. "
           "J. Elasticity 5, 297-319.")


def dundurs_beta(G1: float, nu1: float, G2: float, nu2: float) -> float:
    """Dundurs' second parameter β of two elastic bodies, dimensionless.

    β = [(1 − 2ν₁)/G₁ − (1 − 2ν₂)/G₂] / (2[(1 − ν₁)/G₁ + (1 − ν₂)/G₂]),

    with shear moduli G in Pa (any common unit) and Poisson ratios ν in (−1, 0.5]. Body 1 is the
    one whose surface is dragged inward (β > 0 when body 1 is the softer or more compressible);
    swapping the bodies flips the sign. |β| ≤ 0.5. A rigid body has G = inf.
    """
    c1, c2 = (0.0 if G == math.inf else 1.0 / real(name, G, "(0, inf]", lambda v: v > 0.0)
              for name, G in (("G1", G1), ("G2", G2)))
    nu1 = real("nu1", nu1, "(-1, 0.5]", lambda v: -1.0 < v <= 0.5)
    nu2 = real("nu2", nu2, "(-1, 0.5]", lambda v: -1.0 < v <= 0.5)
    if c1 == 0.0 and c2 == 0.0:
        raise ValueError("at least one body must be elastic (G1 or G2 finite)")
    return ((1 - 2 * nu1) * c1 - (1 - 2 * nu2) * c2) / (2 * ((1 - nu1) * c1 + (1 - nu2) * c2))


def beta_rigid(nu: float) -> float:
    """Dundurs' β of an elastic body (Poisson ratio ν) against a rigid one: (1 − 2ν)/(2(1 − ν)).

    Dimensionless; 0.5 for ν = 0, 2/7 for ν = 0.3, 0 for an incompressible body (ν = 0.5).
    """
    nu = real("nu", nu, "(-1, 0.5]", lambda v: -1.0 < v <= 0.5)
    return (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))


def _ratio(k: float) -> float:
    """β/μ as a function of k = c/a in (0, 1): k K(√(1 − k²)) / artanh k."""
    return k * float(ellipkm1(k * k)) / math.atanh(k)


def beta_over_mu(c_over_a: float) -> float:
    """The β/μ at which the first-order stick zone is c/a, dimensionless.

    β/μ = (c/a) K(√(1 − (c/a)²)) / artanh(c/a), for c/a in (0, 1); see
    :func:`stick_ratio_first_order`.
    """
    k = real("c_over_a", c_over_a, "(0, 1)", lambda v: 0.0 < v < 1.0)
    return _ratio(k)


@cites("spence1975", _SPENCE)
def stick_ratio_first_order(beta: float, mu: float) -> float:
    """Stick-zone radius c over contact radius a in Spence's problem, to first order in βμ.

    A smooth paraboloid is pressed with monotonically growing load into a half-space (or two
    dissimilar bodies, Dundurs' parameter β) with Coulomb friction μ. The contact is a disc of
    radius a with a central stick disc of radius c; c/a is constant during loading (Spence 1975)
    and, with the pressure taken as Hertz's (the effect of the shear traction on the normal
    displacement neglected), it is the root k = c/a in (0, 1) of

        β/μ = k K(k′) / artanh k,    k′ = √(1 − k²),

    K being the complete elliptic integral of the first kind of modulus k′. The right-hand side
    falls monotonically from +∞ at k → 0 (where it behaves as ln(4/k)) to 0 at k → 1.

    Derivation (done for this module; Spence's paper gives no such closed form for the uncoupled
    problem): the load increment of a Hertz contact is a flat-punch pressure increment
    ∝ (a² − r²)^(−1/2), which pulls the surface inward by βA/r·∫p s ds (A = (1 − ν)/G). A radial
    shear q = dψ/dr moves the surface by A d/dr of the Boussinesq potential of ψ, so the
    incremental stick condition is an axisymmetric mixed problem for ψ: given on c < r < a (shear
    increment μ times the pressure increment), displacement given on r < c. With Copson's Abel
    representation ψ ↦ F(t) = ∫_t^a sψ(s)/√(s² − t²) ds, continuity of F at t = c makes the
    shear bounded, and continuity of F′ at t = c makes the shear *increment* bounded at the
    stick–slip boundary; the inner side gives F′ = β artanh(t/a), the outer side μ (t/a) K(k′),
    hence the equation.

    Parameters
    ----------
    beta : float
        Dundurs' β (dimensionless), β ≥ 0; see :func:`beta_rigid` and :func:`dundurs_beta`.
        With β < 0 swap the bodies' roles (the result depends on |β|).
    mu : float
        Coulomb friction coefficient, μ > 0.

    Returns
    -------
    float
        c/a in (0, 1]; 1 (full stick) for β = 0 and as β/μ → 0, → 0 as β/μ → ∞.

    Notes
    -----
    The fully coupled problem (:func:`stick_ratio`) depends also on βμ and has a smaller stick
    zone. For β = 0.5 (ν = 0 on a rigid indenter) and μ = 0.2986 this function gives
    c/a = 0.6233, whereas the coupled problem gives 0.50 (:func:`stick_ratio`, and CONTACT's
    ``spence35`` example). Use this function for solvers that neglect the shear's effect on the
    pressure, or as an estimate when βμ is small.
    """
    beta = real("beta", beta, "[0, inf)", lambda v: v >= 0.0)
    mu = real("mu", mu, "(0, inf)", lambda v: v > 0.0)
    rho = beta / mu
    if rho == 0.0:
        return 1.0
    k_hi = float(np.nextafter(1.0, 0.0))
    if rho <= _ratio(k_hi):
        return 1.0  # c/a closer to 1 than one ulp
    if rho > 30.0:
        # β/μ = ln(4/k) + O(k² ln k): with k < 1e−12 the correction is below round-off
        return 4.0 * math.exp(-rho)
    # β/μ ≈ ln(4/k) for small k, so k = 4 exp(−β/μ − 2) brackets the root from below
    x_lo = -math.log(k_hi)
    x_hi = rho + 2.0 - math.log(4.0)
    x = brentq(lambda x: _ratio(math.exp(-x)) - rho, x_lo, x_hi, xtol=1e-300, rtol=1e-15)
    return math.exp(-x)


# ---------------------------------------------------------------------------------------------
# The fully coupled problem, by axisymmetric ring elements
# ---------------------------------------------------------------------------------------------
# Units: compliance A = (1 − ν)/G = 1 (so E* = 2 against a rigid indenter), indenter radius R = 1,
# ring grid on 0 ≤ r ≤ 1. Only ratios leave this section.

_A_END = 0.7          # contact radius of the last stage, in units of the ring grid's radius
_MAX_PASSES = 200     # normal/tangential alternations per stage before giving up
_PASS_TOL = 1e-11     # change of p and q per pass, relative to the peak pressure


@dataclass(frozen=True)
class SpenceSolution:
    """Ring-element solution of Spence's problem; all fields dimensionless.

    Attributes
    ----------
    stick_ratio : float
        c/a, the stick-disc radius over the contact radius (each from its area), averaged over
        the second half of the stages.
    stick_ratio_spread : float
        Standard deviation of c/a over those stages: the ring granularity, not an error bound.
    centre_pressure_ratio : float
        Pressure at the centre over Hertz's peak pressure at the same load, at the last stage.
    rings, stages, passes : int
        Ring elements, load stages, and normal/tangential alternations used in all.
    coupled : bool
        Whether the shear acts back on the pressure (False: the first-order problem).
    """

    stick_ratio: float
    stick_ratio_spread: float
    centre_pressure_ratio: float
    rings: int
    stages: int
    passes: int
    coupled: bool


def _ring_shear_kernel(r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Radial displacement at radius r per unit total outward radial force on the ring s (A = 1).

    Cerruti's point solution summed round the ring: for an axisymmetric radial shear the surface
    moves by A d/dr of the Boussinesq potential of the ring, which gives
    −(E(k) − K′)/(π² max(r, s)·…) with k = min(r, s)/max(r, s); written with ellipkm1 so that the
    logarithmic singularity at r = s is evaluated without cancellation.
    """
    r, s = np.broadcast_arrays(np.asarray(r, float), np.asarray(s, float))
    lo, hi = np.minimum(r, s), np.maximum(r, s)
    m1 = (hi - lo) * (hi + lo) / hi**2  # 1 − k²
    # r < s divides by r, r > s by s: the smaller radius in both cases
    return -(ellipe(1.0 - m1) - ellipkm1(m1)) / (math.pi**2 * lo)


def _disc_normal(b: float, r: np.ndarray) -> np.ndarray:
    """Normal displacement at r under unit uniform pressure on the disc of radius b (A = 1).

    Johnson (1985) eqs 3.36–3.37 with (1 − ν²)/E = A/2: (2b/π) E(r/b) inside,
    (2r/π) [E(b/r) − (1 − b²/r²) K(b/r)] outside (K, E of parameter m = k²).
    """
    r = np.asarray(r, float)
    out = np.empty_like(r)
    inside = r <= b
    out[inside] = 2.0 * b / math.pi * ellipe((r[inside] / b) ** 2)
    ro = r[~inside]
    m = (b / ro) ** 2
    out[~inside] = 2.0 * ro / math.pi * (ellipe(m) - (1.0 - m) * ellipk(m))
    return out


def _ring_matrices(n: int, beta: float) -> tuple[np.ndarray, ...]:
    """Edges, centres, areas and the four influence matrices of n rings of width 1/n.

    Collocation at ring centres r_i, piecewise-constant p and q (outward radial shear on the
    particle). N: normal displacement (into the body) per unit pressure; T: radial displacement
    per unit shear; C: normal displacement per unit shear, −β ∫_r^∞ q ds; D: radial displacement
    per unit pressure, −(β/r) ∫_0^r p s ds (the pressure pulls the surface inward). The last two
    are Johnson (1985) eqs 3.91a–b, rearranged for A = 1.
    """
    h = 1.0 / n
    e = np.arange(n + 1) * h
    rm = 0.5 * (e[:-1] + e[1:])
    area = math.pi * (e[1:] ** 2 - e[:-1] ** 2)
    discs = np.stack([_disc_normal(b, rm) if b > 0 else np.zeros(n) for b in e], axis=1)
    N = np.diff(discs, axis=1)
    # T: 24-point Gauss–Legendre over each ring, adaptive quadrature round the log singularity
    x, w = np.polynomial.legendre.leggauss(24)
    s = e[:-1, None] + 0.5 * h * (x[None, :] + 1.0)                       # (n, 24)
    T = 0.5 * h * np.einsum("ijk,k->ij", 2 * math.pi * s[None] * _ring_shear_kernel(
        rm[:, None, None], s[None]), w)
    for i, r in enumerate(rm):
        for j in range(max(0, i - 1), min(n, i + 2)):
            T[i, j] = integrate.quad(
                lambda t, r=r: 2 * math.pi * t * float(_ring_shear_kernel(r, t)), e[j], e[j + 1],
                points=[r] if j == i else None, limit=200)[0]
    C = -beta * np.clip(e[None, 1:] - np.maximum(e[None, :-1], rm[:, None]), 0.0, None)
    D = -beta / rm[:, None] * np.clip(
        np.minimum(e[None, 1:], rm[:, None]) ** 2 - e[None, :-1] ** 2, 0.0, None) / 2.0
    return e, rm, area, N, T, C, D


def _box_lcp(A: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             x: np.ndarray) -> np.ndarray:
    """Solve the box complementarity problem of the collocation equations A x = b.

    Find lower ≤ x ≤ upper with r = A x − b zero where x is strictly inside, r ≥ 0 where
    x = lower and r ≤ 0 where x = upper, by a primal–dual active set (semi-smooth Newton) started
    from x. The matrix is not symmetrised: collocation at ring centres is not reciprocal near the
    axis, and a symmetrised system moves the centre pressure by 3 % at any ring count.
    """
    scale = 1.0 / np.diag(A)
    state = None
    for _ in range(4 * len(b) + 20):
        y = x - scale * (A @ x - b)
        at_lo, at_hi = y <= lower, y >= upper
        key = (at_lo.tobytes(), at_hi.tobytes())
        if key == state:
            return x
        state = key
        free = ~(at_lo | at_hi)
        x = np.where(at_lo, lower, np.where(at_hi, upper, 0.0))
        if free.any():
            rest = b[free] - A[free] @ np.where(free, 0.0, x)
            x[free] = np.linalg.solve(A[np.ix_(free, free)], rest)
    raise RuntimeError("Spence ring elements: the active set did not settle")


@cites("spence1975", _SPENCE)
def solve(beta: float, mu: float, *, rings: int = 200, stages: int = 320,
          coupled: bool = True) -> SpenceSolution:
    """Spence's problem, fully coupled, by axisymmetric ring elements under a staged load.

    A rigid paraboloid indents an elastic half-space (Dundurs' β against the indenter, Coulomb
    friction μ) under a growing indentation applied in ``stages`` equal steps of contact radius.
    Each stage alternates a normal solve (pressure ≥ 0, shear frozen) and a tangential solve
    (|q| ≤ μp, radial displacement of stuck rings frozen at the previous stage) until p and q
    change by less than 1e-11 of the peak pressure. Both solves are convex box-constrained
    complementarity problems, solved by a primal–dual active set.

    Discretisation (β = 0.5, μ = 0.2986; rings/stages → c/a one way, c/a coupled, centre
    pressure over Hertz's coupled):

    ========  =======  ======  =====
    50/80     0.6211   0.5035  1.309
    100/160   0.6220   0.5013  1.312
    200/320   0.6227   0.5008  1.313
    400/640   0.6230   0.5004  1.314
    ========  =======  ======  =====

    One way it converges to the closed form 0.6233 (:func:`stick_ratio_first_order`); coupled,
    to CONTACT's c/a = 0.5 and centre pressure 1.31 × Hertz (``spence35``; its 225 of 921
    sticking elements give √(225/921) = 0.494).

    Parameters
    ----------
    beta : float
        Dundurs' β in [0, 0.5]; see :func:`beta_rigid`.
    mu : float
        Coulomb friction coefficient, > 0.
    rings : int
        Ring elements on the grid's radius (≥ 20); the last contact covers 70 % of them.
    stages : int
        Load stages (≥ 10). Fewer stages remember less of the loading history.
    coupled : bool
        False drops the shear's effect on the pressure (the first-order problem).

    Returns
    -------
    SpenceSolution
        Dimensionless c/a, its spread over the stages, and the centre pressure over Hertz's.

    Raises
    ------
    RuntimeError
        If a stage's alternation does not converge in 200 passes.
    """
    beta = real("beta", beta, "[0, 0.5]", lambda v: 0.0 <= v <= 0.5)
    mu = real("mu", mu, "(0, inf)", lambda v: 0.0 < v < math.inf)
    if isinstance(rings, bool) or not isinstance(rings, int) or rings < 20:
        raise ValueError(f"rings must be an integer >= 20, got {rings!r}")
    if isinstance(stages, bool) or not isinstance(stages, int) or stages < 10:
        raise ValueError(f"stages must be an integer >= 10, got {stages!r}")
    _, rm, area, N, T, C, D = _ring_matrices(rings, beta)
    if not coupled:
        C = np.zeros_like(C)
    p = q = u_prev = np.zeros(rings)
    zero, inf = np.zeros(rings), np.full(rings, np.inf)
    ratios, passes = [], 0
    for k in range(1, stages + 1):
        delta = (_A_END * k / stages) ** 2            # Hertz: a² = Rδ with R = 1
        for _ in range(_MAX_PASSES):
            passes += 1
            p_new = _box_lcp(N, delta - rm**2 / 2 - C @ q, zero, inf, p)
            q_new = _box_lcp(T, u_prev - D @ p_new, -mu * p_new, mu * p_new, q)
            peak = p_new.max()
            change = max(np.abs(p_new - p).max(), np.abs(q_new - q).max())
            p, q = p_new, q_new
            if peak == 0.0 or change <= _PASS_TOL * peak:
                break
        else:
            raise RuntimeError(f"Spence ring elements: stage {k} did not converge in "
                               f"{_MAX_PASSES} passes (change {change / peak:.2e})")
        u_prev = T @ q + D @ p
        if 2 * k > stages:
            contact = p > 0.0
            stick = contact & (np.abs(q) < mu * p * (1.0 - 1e-9))
            ratios.append(math.sqrt(area[stick].sum() / area[contact].sum()))
    force = float(area @ p)
    a_hertz = (3.0 * force / 8.0) ** (1.0 / 3.0)      # E* = 2, R = 1
    p_hertz = 3.0 * force / (2.0 * math.pi * a_hertz**2)
    return SpenceSolution(float(np.mean(ratios)), float(np.std(ratios)), float(p[0] / p_hertz),
                          rings, stages, passes, coupled)


def stick_ratio(beta: float, mu: float, *, rings: int = 200, stages: int = 320) -> float:
    """Stick-zone radius over contact radius, c/a, of Spence's fully coupled problem.

    Dimensionless; see :func:`solve` for the method and its discretisation error (≈ 1e-3 at the
    defaults, which take ~2 s). For β = 0.5, μ = 0.2986 it gives 0.501, CONTACT's value for its
    ``spence35`` example being 0.5.
    """
    return solve(beta, mu, rings=rings, stages=stages).stick_ratio
