"""Rigid particle between two parallel plates: the point-contact criterion (paper eqs 1–5).

Conventions (docs/methods/design.md §2): x horizontal in the plane of rotation, y the axis of
rotation, z up. The orientation θ is a rotation about +y by the right-hand rule, in radians here
(names ending in ``_deg`` would be degrees). A vector (x, z) rotated by θ becomes
(x cosθ + z sinθ, −x sinθ + z cosθ); seen with x to the right and z up, +y points into the
page, so a positive θ turns the particle clockwise in that picture.

Statics of a massless rigid particle touching the upper plate at (x_up, z_up) and the lower plate
at (x_low, z_low). Forces on the particle: the upper plate pushes with (T_up, −F_N), the lower
plate with (T_low, +F_N). The y-moment of a force (F_x, F_z) at (x, z) is z·F_x − x·F_z, so

- the normal forces form the couple M_p = F_N (x_up − x_low),
- horizontal equilibrium gives T_low = −T_up, and the tangential couple is T_up·h with
  h = z_up − z_low the plate separation,
- moment balance gives T_up = −M_p/h. The signed ratio returned by :func:`force_ratio` is
  F'_x/F_N = M_p/(F_N h) = (x_up − x_low)/h (eq 9 in the rigid limit); F'_x is the tangential
  force the *lower* plate exerts on the particle (equivalently the one the particle exerts on
  the upper plate); the upper plate exerts −F'_x. Its magnitude is ξ of eq 3.

References: the third-body particle paper that defines this project (eqs 1–5); the Coulomb
friction limit |T| ≤ μF_N at each contact.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq

from ._validate import real

__all__ = [
    "RigidState",
    "classify",
    "ellipsoid_contact_points",
    "ellipsoid_equilibrium_angle",
    "ellipsoid_force_ratio",
    "ellipsoid_gap",
    "ellipsoid_max_xi",
    "ellipsoid_max_xi_angle",
    "ellipsoid_xi",
    "force_ratio",
    "xi",
]

FloatOrArray = float | np.ndarray


_real = real


def _point(name: str, point: Sequence[float]) -> tuple[float, float]:
    """Return (x, z) from a point given as (x, z) or (x, y, z)."""
    arr = np.asarray(point, dtype=float)
    if arr.shape not in {(2,), (3,)} or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite point (x, z) or (x, y, z), got {point!r}")
    return float(arr[0]), float(arr[-1])


def force_ratio(upper_point: Sequence[float], lower_point: Sequence[float]) -> float:
    """Signed F'_x/F_N = (x_up − x_low)/(z_up − z_low) for point contacts (dimensionless).

    Points are (x, z) or (x, y, z) in m. See the module docstring for the sign: a positive value
    means the lower plate must push the particle towards +x (and the upper plate towards −x)
    to keep it from turning; it equals M_p/(F_N h).

    Raises
    ------
    ValueError
        If a point is malformed or the upper point is not above the lower one.
    """
    x1, z1 = _point("upper_point", upper_point)
    x2, z2 = _point("lower_point", lower_point)
    if not z1 > z2:
        raise ValueError(
            f"upper_point must lie above lower_point (z_up > z_low), got z_up={z1!r}, z_low={z2!r}"
        )
    return (x1 - x2) / (z1 - z2)


def xi(upper_point: Sequence[float], lower_point: Sequence[float]) -> float:
    """ξ = |x_up − x_low|/(z_up − z_low), eq 3: the friction coefficient needed to stick.

    Points are (x, z) or (x, y, z) in m; ξ is dimensionless and ≥ 0.

    Raises
    ------
    ValueError
        If a point is malformed or z_up ≤ z_low.
    """
    return abs(force_ratio(upper_point, lower_point))


class RigidState(enum.Enum):
    """State of a rigid particle between the plates (eqs 4–5).

    - ``STICK``: both contacts stick, no motion.
    - ``ROLL_UPPER``: rolling about the upper contact: the upper contact sticks (it is the
      instantaneous pivot) and the lower contact slides.
    - ``ROLL_LOWER``: rolling about the lower contact: the lower contact sticks, the upper slides.
    - ``ROTATE``: both contacts slide; the particle rotates about its centroid.
    """

    STICK = "stick"
    ROLL_UPPER = "roll_upper"
    ROLL_LOWER = "roll_lower"
    ROTATE = "rotate"


def classify(
    xi: float,
    mu_up: float,
    mu_low: float,
    *,
    classification: str = "statics",
    mu_rtol: float = 1e-9,
) -> RigidState:
    """Classify the state of a rigid particle from ξ (eq 3) and the friction coefficients.

    A contact can stick iff ξ ≤ μ at that contact (equality counts as stick). Then (eq 4):

    ==================  ==================  =====================================
    upper (ξ ≤ μ_up)    lower (ξ ≤ μ_low)   state
    ==================  ==================  =====================================
    sticks              sticks              ``STICK``
    sticks              slides              ``ROLL_UPPER`` (μ_up ≥ ξ > μ_low)
    slides              sticks              ``ROLL_LOWER`` (μ_low ≥ ξ > μ_up)
    slides              slides              see below
    ==================  ==================  =====================================

    Both exceeded: with ``classification="paper"`` the result is ``ROTATE`` (eq 4 literally).
    With the default ``"statics"``, ``ROTATE`` only when μ_up and μ_low are equal within
    ``mu_rtol`` (eq 5). For unequal μ, horizontal equilibrium (eq 1) makes both contacts carry the
    same |T| ≤ min(μ_up, μ_low)·F_N, so only the lower-friction contact slides and the particle
    rolls about the higher-friction one (``ROLL_UPPER`` if μ_up > μ_low, else ``ROLL_LOWER``).

    Parameters
    ----------
    xi : float
        ξ ≥ 0 (dimensionless).
    mu_up, mu_low : float
        Friction coefficients ≥ 0 at the upper and lower plates.
    classification : {"statics", "paper"}
        How to resolve the both-exceeded row for unequal μ.
    mu_rtol : float
        Relative tolerance under which μ_up and μ_low count as equal (``"statics"`` only).

    Raises
    ------
    ValueError
        If an argument is out of range or ``classification`` is unknown.
    """
    x = _real("xi", xi, "[0, inf)", lambda v: v >= 0.0)
    mu1 = _real("mu_up", mu_up, "[0, inf)", lambda v: v >= 0.0)
    mu2 = _real("mu_low", mu_low, "[0, inf)", lambda v: v >= 0.0)
    rtol = _real("mu_rtol", mu_rtol, "[0, inf)", lambda v: v >= 0.0)
    if classification not in {"statics", "paper"}:
        raise ValueError(
            f"classification must be one of 'statics', 'paper', got {classification!r}"
        )
    up_sticks = x <= mu1
    low_sticks = x <= mu2
    if up_sticks and low_sticks:
        return RigidState.STICK
    if up_sticks:
        return RigidState.ROLL_UPPER
    if low_sticks:
        return RigidState.ROLL_LOWER
    if classification == "paper" or math.isclose(mu1, mu2, rel_tol=rtol, abs_tol=0.0):
        return RigidState.ROTATE
    return RigidState.ROLL_UPPER if mu1 > mu2 else RigidState.ROLL_LOWER


def _semi_axes(A: float, C: float) -> tuple[float, float]:
    return (
        _real("A", A, "(0, inf)", lambda v: v > 0.0),
        _real("C", C, "(0, inf)", lambda v: v > 0.0),
    )


def _out(values: np.ndarray) -> FloatOrArray:
    return float(values) if np.ndim(values) == 0 else values


def ellipsoid_contact_points(
    A: float, C: float, theta: ArrayLike
) -> tuple[tuple[FloatOrArray, FloatOrArray], tuple[FloatOrArray, FloatOrArray]]:
    """Highest and lowest points of the tilted ellipse x²/A² + z²/C² = 1 (centre at the origin).

    The ellipse (the xz-section of an ellipsoid with semi-axes A along x and C along z, m) is
    rotated by ``theta`` (rad, right-handed about +y). For an ellipse pᵀMp = 1 the extreme point
    along a unit direction n is ±M⁻¹n/√(nᵀM⁻¹n); here M⁻¹ = R diag(A², C²) Rᵀ and n = (0, 1):

        x_up = (C² − A²) sinθ cosθ / S,   z_up = S,   S = √(A² sin²θ + C² cos²θ),

    and the lowest point is the reflection (−x_up, −z_up).

    Returns
    -------
    ((x_up, z_up), (x_low, z_low))
        In m; arrays if ``theta`` is an array.

    Raises
    ------
    ValueError
        If A or C is not a finite positive number.
    """
    A, C = _semi_axes(A, C)
    th = np.asarray(theta, dtype=float)
    s, c = np.sin(th), np.cos(th)
    half_gap = np.sqrt(A * A * s * s + C * C * c * c)
    x_up = (C * C - A * A) * s * c / half_gap
    return (_out(x_up), _out(half_gap)), (_out(-x_up), _out(-half_gap))


def ellipsoid_gap(A: float, C: float, theta: ArrayLike) -> FloatOrArray:
    """Plate separation h(θ) = z_up − z_low = 2√(A² sin²θ + C² cos²θ) (m) of the tilted ellipse.

    Useful for the turning direction: dh/dθ = x_low − x_up, so the normal couple
    M_p = F_N(x_up − x_low) = −F_N dh/dθ always turns the particle towards smaller h.
    """
    A, C = _semi_axes(A, C)
    th = np.asarray(theta, dtype=float)
    return _out(2.0 * np.sqrt(A * A * np.sin(th) ** 2 + C * C * np.cos(th) ** 2))


def ellipsoid_force_ratio(A: float, C: float, theta: ArrayLike) -> FloatOrArray:
    """Signed F'_x/F_N = (x_up − x_low)/(z_up − z_low) for the tilted ellipse (dimensionless).

        F'_x/F_N = (C² − A²) sinθ cosθ / (A² sin²θ + C² cos²θ) = −ξ_formula(θ),

    where ξ_formula = (A² − C²) sinθ cosθ/(A² sin²θ + C² cos²θ) is the expression usually quoted
    for ξ. For A > C and 0 < θ < 90° the ratio is negative: the +x end of the long axis has
    dipped, the upper contact is at x < 0 and the lower at x > 0. Sign convention as in
    :func:`force_ratio`; θ in rad about +y. The ratio has the sign of the normal couple M_p, and
    hence of the direction in which θ changes if the particle turns.
    """
    A, C = _semi_axes(A, C)
    th = np.asarray(theta, dtype=float)
    s, c = np.sin(th), np.cos(th)
    return _out((C * C - A * A) * s * c / (A * A * s * s + C * C * c * c))


def ellipsoid_xi(A: float, C: float, theta: ArrayLike) -> FloatOrArray:
    """ξ(θ) = |(A² − C²) sinθ cosθ| / (A² sin²θ + C² cos²θ) ≥ 0 for the tilted ellipsoid.

    Equal to :func:`xi` of :func:`ellipsoid_contact_points`; zero at θ = 0 and 90°, period 180°.
    A, C in m (semi-axes along x and z before rotation), θ in rad.
    """
    return _out(np.abs(ellipsoid_force_ratio(A, C, theta)))


def ellipsoid_max_xi(A: float, C: float) -> float:
    """Largest ξ over all orientations, |A² − C²|/(2AC), reached at tanθ = C/A."""
    A, C = _semi_axes(A, C)
    return abs(A * A - C * C) / (2.0 * A * C)


def ellipsoid_max_xi_angle(A: float, C: float) -> float:
    """Orientation θ = atan(C/A) in (0, π/2) (rad) where ξ is largest (also θ + kπ and −θ)."""
    A, C = _semi_axes(A, C)
    return math.atan2(C, A)


def ellipsoid_equilibrium_angle(
    A: float, C: float, theta0: float, mu: float, mu_low: float | None = None
) -> float:
    """Orientation (rad) at which a rigid tilted ellipsoid, started at θ0, comes to rest.

    If ξ(θ0) ≤ μ the particle sticks and θ0 is returned. Otherwise it turns in the direction of
    the unbalanced moment until ξ(θ) = μ, and that θ is returned (the first crossing along the
    path, found with brentq).

    Turning direction. The moment on the particle is the normal couple M_p = F_N(x_up − x_low)
    plus the friction couple T_up·h, which at the sliding limit has magnitude μF_N h < |M_p| and
    the opposite sign, so θ moves with the sign of M_p, i.e. of :func:`ellipsoid_force_ratio`.
    Since dh/dθ = x_low − x_up (see :func:`ellipsoid_gap`), M_p dθ = −F_N dh: the normal couple
    turns the particle so that the plate gap h *decreases* (virtual work of the plates), towards
    the nearest orientation with the long axis horizontal (θ = kπ if A > C, π/2 + kπ if A < C).
    It does not always reduce |x_up − x_low|: from beyond the angle of maximum ξ the lever arm
    first grows. The returned angle lies strictly between θ0 and that flat orientation, on the
    side of it where ξ falls monotonically (for μ = 0 it is the flat orientation itself).

    Parameters
    ----------
    A, C : float
        Semi-axes along x and z before rotation, m.
    theta0 : float
        Initial orientation, rad (right-handed about +y).
    mu : float
        Friction coefficient ≥ 0 at both plates, or μ_up when ``mu_low`` is given.
    mu_low : float, optional
        Friction coefficient at the lower plate. With unequal coefficients the particle rolls
        until the smaller one can hold it, so min(μ_up, μ_low) is used. A rigid particle's
        orientation does not depend on whether it rolls or rotates.

    Raises
    ------
    ValueError
        If an argument is out of range.
    """
    A, C = _semi_axes(A, C)
    th0 = _real("theta0", theta0, "(-inf, inf)", lambda v: True)
    mu_eff = _real("mu", mu, "[0, inf)", lambda v: v >= 0.0)
    if mu_low is not None:
        mu_eff = min(mu_eff, _real("mu_low", mu_low, "[0, inf)", lambda v: v >= 0.0))
    if ellipsoid_xi(A, C, th0) <= mu_eff:
        return th0
    direction = math.copysign(1.0, ellipsoid_force_ratio(A, C, th0))
    flat0 = 0.0 if A > C else 0.5 * math.pi
    k = (th0 - flat0) / math.pi
    flat = flat0 + math.pi * (math.floor(k) if direction < 0 else math.ceil(k))

    def residual(t: float) -> float:
        return float(ellipsoid_xi(A, C, t)) - mu_eff

    # ξ − μ > 0 at θ0, ≤ 0 at the flat orientation, and has a single root in between. ξ at the
    # flat orientation is zero up to round-off; if μ is below that, the flat orientation is it.
    if residual(flat) >= 0.0:
        return flat
    lo, hi = (flat, th0) if flat < th0 else (th0, flat)
    return float(brentq(residual, lo, hi, xtol=1e-15, rtol=4.0 * np.finfo(float).eps))
