"""Spence's problem: a smooth paraboloid pressed with growing load into a frictional half-space.

Set-up: an elastic half-space (or two dissimilar elastic bodies) is indented by a smooth
paraboloid (Hertzian) profile under a normal load that only grows, with Coulomb friction μ at the
interface. Because the bodies are elastically dissimilar (Dundurs' β ≠ 0), the normal pressure
drags the surface points of the softer, more compressible body radially inward relative to the
other body; friction resists that, a central stick zone r < c forms, surrounded by an annulus
c < r < a of inward slip in which the shear traction is μp, directed outward on the body. Spence
(1975) showed that the problem is self-similar: c/a stays constant during loading.

Only dimensionless ratios are returned: c/a and Dundurs' β are pure numbers.

Which problem is solved here: the normal–tangential coupling acts both ways. The pressure moves
the surface tangentially (that is what creates the stick zone) and the shear traction changes the
normal displacement and so the pressure. :func:`stick_ratio` neglects the second effect (the
pressure is Hertz's, the "Goodman approximation" also used in :mod:`thirdbody.reference.mindlin`);
then c/a depends on β/μ alone. That is exact to first order in βμ. The fully coupled problem, which
Spence (1975) solved, depends on β/μ and on βμ separately; see the Notes of :func:`stick_ratio` for
how far apart the two are.

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

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipkm1

from .._citations import cites
from .._validate import real

__all__ = ["beta_over_mu", "beta_rigid", "dundurs_beta", "stick_ratio"]

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
    """The inverse of :func:`stick_ratio`: the β/μ at which the stick zone is c/a, dimensionless.

    β/μ = (c/a) K(√(1 − (c/a)²)) / artanh(c/a), for c/a in (0, 1); see :func:`stick_ratio`.
    """
    k = real("c_over_a", c_over_a, "(0, 1)", lambda v: 0.0 < v < 1.0)
    return _ratio(k)


@cites("spence1975", _SPENCE)
def stick_ratio(beta: float, mu: float) -> float:
    """Stick-zone radius c as a fraction of the contact radius a in Spence's problem (uncoupled).

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
    The fully coupled problem depends also on βμ and has a smaller stick zone. For β = 0.5
    (ν = 0 on a rigid indenter) and μ = 0.2986 this function gives c/a = 0.6233, whereas
    CONTACT's ``spence35`` example (Vollebregt, CONTACT user guide, fully coupled, citing Spence
    1975) and an axisymmetric ring-element solution of the coupled problem give c/a ≈ 0.50; the
    same ring-element solution without coupling gives 0.625. At fixed β/μ = 1.674 the coupled c/a
    rises to 0.59 for βμ = 0.037 and 0.62 for βμ = 0.006. Use this function for solvers that
    neglect the shear's effect on the pressure, or as a first-order estimate when βμ is small.
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
