"""Hertz solutions for frictionless, non-conforming elastic contact.

All quantities are SI: forces in N, lengths in m, moduli and pressures in Pa.
``E_star`` is the contact (plane-strain) modulus. For an elastic body of Young's modulus E and
Poisson ratio ν pressed against a rigid plate it is E* = E/(1−ν²); for two elastic bodies
1/E* = (1−ν₁²)/E₁ + (1−ν₂²)/E₂.

Sign conventions: the pressure p ≥ 0 is compressive; the approach δ > 0 is the mutual approach of
distant points of the two bodies (the indentation depth when the counter-face is rigid).

References
----------
H. Hertz (1882), "Über die Berührung fester elastischer Körper", J. reine angew. Math. 92,
156–171.
K. L. Johnson (1985), *Contact Mechanics*, Cambridge University Press, ch. 3–4 (§3.4 sphere,
§4.2 general profiles).
B. C. Carlson (1979), "Computing elliptic integrals by duplication", Numer. Math. 33, 1–16
(the symmetric integrals R_F, R_D used to evaluate K and K − E without cancellation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq
from scipy.special import elliprd, elliprf

from .._validate import positive

__all__ = [
    "HertzEllipse",
    "HertzSphere",
    "elliptic",
    "elliptic_from_radii",
    "sphere",
    "sphere_from_approach",
]


_positive = positive


@dataclass(frozen=True)
class HertzSphere:
    """Hertz contact of a sphere (or any axisymmetric paraboloid z = r²/(2R)) on a flat.

    Attributes
    ----------
    contact_radius : float
        Radius a of the circular contact, m.
    approach : float
        Mutual approach δ of distant points, m (positive when pressed together).
    peak_pressure : float
        Central pressure p₀, Pa (compressive positive).
    normal_force : float
        Normal force W, N.
    radius : float
        Effective radius of curvature R, m.
    """

    contact_radius: float
    approach: float
    peak_pressure: float
    normal_force: float
    radius: float

    def pressure(self, r: ArrayLike) -> np.ndarray | float:
        """Pressure p(r) = p₀√(1 − r²/a²) in Pa at radial distance ``r`` (m); zero for r ≥ a.

        Accepts a scalar or an array of radii (negative values are treated as |r|).
        """
        r = np.asarray(r, dtype=float)
        rho2 = (r / self.contact_radius) ** 2
        p = self.peak_pressure * np.sqrt(np.clip(1.0 - rho2, 0.0, None))
        return float(p) if p.ndim == 0 else p


@dataclass(frozen=True)
class HertzEllipse:
    """Hertz contact of a body with gap A x² + B y² on a flat: an elliptic contact area.

    Attributes
    ----------
    semi_axis_x : float
        Semi-axis of the contact ellipse along x, m.
    semi_axis_y : float
        Semi-axis of the contact ellipse along y, m.
    approach : float
        Mutual approach δ of distant points, m.
    peak_pressure : float
        Central pressure p₀ = 3W/(2π a_x a_y), Pa.
    eccentricity_squared : float
        e² = 1 − (minor/major)², dimensionless, in [0, 1).
    normal_force : float
        Normal force W, N.
    """

    semi_axis_x: float
    semi_axis_y: float
    approach: float
    peak_pressure: float
    eccentricity_squared: float
    normal_force: float

    def pressure(self, x: ArrayLike, y: ArrayLike) -> np.ndarray | float:
        """Pressure p = p₀√(1 − x²/a_x² − y²/a_y²) in Pa at (x, y) (m); zero outside the ellipse.

        ``x`` and ``y`` broadcast against each other.
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        rho2 = (x / self.semi_axis_x) ** 2 + (y / self.semi_axis_y) ** 2
        p = self.peak_pressure * np.sqrt(np.clip(1.0 - rho2, 0.0, None))
        return float(p) if p.ndim == 0 else p


def sphere(force: float, radius: float, E_star: float) -> HertzSphere:
    """Hertz solution for a sphere of radius ``radius`` (m) pressed by ``force`` (N) on a flat.

    a³ = 3WR/(4E*), δ = a²/R, p₀ = 3W/(2πa²) (Hertz 1882; Johnson 1985, §3.4 and §4.2).

    Parameters
    ----------
    force : float
        Normal force W > 0, N.
    radius : float
        Effective radius R > 0, m (1/R = 1/R₁ + 1/R₂ for two spheres).
    E_star : float
        Contact modulus E* > 0, Pa.

    Raises
    ------
    ValueError
        If an argument is not a finite positive number.
    """
    W = _positive("force", force)
    R = _positive("radius", radius)
    Es = _positive("E_star", E_star)
    a = (3.0 * W * R / (4.0 * Es)) ** (1.0 / 3.0)
    return HertzSphere(
        contact_radius=a,
        approach=a * a / R,
        peak_pressure=3.0 * W / (2.0 * math.pi * a * a),
        normal_force=W,
        radius=R,
    )


def sphere_from_approach(approach: float, radius: float, E_star: float) -> HertzSphere:
    """Hertz sphere under displacement control: given the approach δ (m), find W and the rest.

    a = √(δR), W = 4E*a³/(3R) = (4/3)E*R^½δ^(3/2) (Hertz 1882; Johnson 1985, §4.2).

    Raises
    ------
    ValueError
        If an argument is not a finite positive number.
    """
    d = _positive("approach", approach)
    R = _positive("radius", radius)
    Es = _positive("E_star", E_star)
    a = math.sqrt(d * R)
    W = 4.0 * Es * a**3 / (3.0 * R)
    return sphere(W, R, Es)


def _axis_ratio_squared(curvature_ratio: float) -> float:
    """Solve the Hertz eccentricity equation for s = (b/a)² = 1 − e², given λ = B/A ≥ 1.

    The classical relation λ = [E/(1−e²) − K]/(K − E), with K, E the complete elliptic integrals
    of parameter m = e², is evaluated in the equivalent Carlson form λ = R_D(0, 1, s)/R_D(0, s, 1),
    using K − E = (m/3)R_D(0, s, 1) and E/s − K = (m/3)R_D(0, 1, s). This has no 0/0 at the
    sphere limit (s = 1 gives λ = 1 exactly) and keeps full precision for very slender contacts.
    The ratio increases monotonically as s decreases, so a bracketing root find in ln s is robust.
    """
    if curvature_ratio == 1.0:
        return 1.0
    target = math.log(curvature_ratio)

    def residual(t: float) -> float:
        s = math.exp(t)
        return math.log(float(elliprd(0.0, 1.0, s)) / float(elliprd(0.0, s, 1.0))) - target

    lo = -1.0
    while residual(lo) <= 0.0:
        lo *= 2.0
        if lo < -690.0:
            raise ValueError(
                f"curvature ratio B/A = {curvature_ratio!r} is too extreme to solve "
                "(allowed range: below about 1e290)"
            )
    t = brentq(residual, lo, 0.0, xtol=1e-15, rtol=4.0 * np.finfo(float).eps, maxiter=200)
    return math.exp(t)


def elliptic(force: float, A: float, B: float, E_star: float) -> HertzEllipse:
    """Hertz solution for the gap h(x, y) = A x² + B y² (A, B > 0, in 1/m) under force W (N).

    With A ≤ B the contact ellipse has its major semi-axis a along x and minor b along y
    (and the reverse if A > B; the result always reports ``semi_axis_x`` along x). With
    e² = 1 − b²/a² and K, E the complete elliptic integrals of parameter e²:

    - B/A = [E/(1−e²) − K]/(K − E)  (curvatures ordered so that B/A ≥ 1),
    - a³ = 3W(K − E)/(2πE*·A·e²), b = a√(1 − e²),
    - p₀ = 3W/(2πab), δ = p₀·b·K/E*.

    A == B reproduces :func:`sphere` with R = 1/(2A) (no division by zero: see
    ``_axis_ratio_squared`` for the cancellation-free form). References: Hertz (1882);
    Johnson (1985), §4.2.

    Parameters
    ----------
    force : float
        Normal force W > 0, N.
    A, B : float
        Curvature coefficients of the gap along x and y, 1/m (A = 1/(2R_x), B = 1/(2R_y)).
    E_star : float
        Contact modulus E* > 0, Pa.

    Raises
    ------
    ValueError
        If an argument is not a finite positive number.
    """
    W = _positive("force", force)
    A = _positive("A", A)
    B = _positive("B", B)
    Es = _positive("E_star", E_star)
    c_small, c_large = (A, B) if A <= B else (B, A)
    s = _axis_ratio_squared(c_large / c_small)
    # (K − E)/e² = R_D(0, s, 1)/3, so a³ = W·R_D(0, s, 1)/(2π E* A_small).
    major = (W * float(elliprd(0.0, s, 1.0)) / (2.0 * math.pi * Es * c_small)) ** (1.0 / 3.0)
    minor = major * math.sqrt(s)
    p0 = 3.0 * W / (2.0 * math.pi * major * minor)
    K = float(elliprf(0.0, s, 1.0))
    delta = p0 * minor * K / Es
    ax, ay = (major, minor) if A <= B else (minor, major)
    return HertzEllipse(
        semi_axis_x=ax,
        semi_axis_y=ay,
        approach=delta,
        peak_pressure=p0,
        eccentricity_squared=1.0 - s,
        normal_force=W,
    )


def elliptic_from_radii(force: float, R_x: float, R_y: float, E_star: float) -> HertzEllipse:
    """Hertz elliptic contact for principal radii of relative curvature R_x, R_y (m).

    Same as :func:`elliptic` with A = 1/(2R_x), B = 1/(2R_y). An upright ellipsoid with
    semi-axes (A, B, C), C vertical, touches a plate with R_x = A²/C and R_y = B²/C.

    Raises
    ------
    ValueError
        If an argument is not a finite positive number.
    """
    Rx = _positive("R_x", R_x)
    Ry = _positive("R_y", R_y)
    return elliptic(force, 1.0 / (2.0 * Rx), 1.0 / (2.0 * Ry), E_star)
