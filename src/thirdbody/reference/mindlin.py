"""Tangential loading of a Hertzian sphere on a rigid flat with Coulomb friction.

Set-up shared by every function here: an elastic sphere (Young's modulus E, Poisson ratio ν,
radius R) is pressed on a rigid flat by a constant normal force P and a tangential force Q acts
along x. With a rigid counter-face the contact modulus is E* = E/(1−ν²) and the shear modulus
G = E/(2(1+ν)). Normal and tangential problems are uncoupled (Goodman approximation: exact for
ν = 0.5, otherwise the small coupling through (1−2ν) is neglected), so the contact radius a and
the peak pressure p₀ are those of Hertz, see :func:`thirdbody.reference.hertz.sphere`.

Units are SI (N, m, Pa). Sign convention: Q, the traction τ and the shift δ_x all carry the same
sign. τ is the shear traction transmitted through the contact in the direction of Q, and δ_x is
the tangential displacement of distant points of the sphere relative to the flat produced by it
(the tangential compliance). Q may be negative: the solution is then the mirror image.

References
----------
C. Cattaneo (1938), "Sul contatto di due corpi elastici: distribuzione locale degli sforzi",
Rend. Accad. Naz. Lincei 27, 342–348, 434–436, 474–478.
R. D. Mindlin (1949), "Compliance of elastic bodies in contact", J. Appl. Mech. 16, 259–268.
R. D. Mindlin and H. Deresiewicz (1953), "Elastic spheres in contact under varying oblique
forces", J. Appl. Mech. 20, 327–344.
K. L. Johnson (1985), *Contact Mechanics*, Cambridge University Press, §7.2 (partial slip,
loading and unloading) and §7.3 (oblique forces).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .._validate import real
from .hertz import sphere

__all__ = [
    "CattaneoMindlin",
    "MindlinDeresiewicz",
    "ProportionalLoading",
    "cattaneo_mindlin",
    "hysteresis_loop",
    "mindlin_deresiewicz_reloading",
    "mindlin_deresiewicz_unloading",
    "proportional_loading",
]

# Relative tolerance with which |Q| may exceed μP (round-off) and still count as full sliding.
_SLIDING_RTOL = 1e-12


_real = real


@dataclass(frozen=True)
class _Contact:
    """Validated material, geometry and the Hertz normal solution they imply."""

    P: float
    mu: float
    nu: float
    G: float
    a: float
    p0: float

    @property
    def compliance_scale(self) -> float:
        """3μP(2−ν)/(16Ga), the Cattaneo–Mindlin shift at the onset of sliding, m."""
        return 3.0 * self.mu * self.P * (2.0 - self.nu) / (16.0 * self.G * self.a)


def _contact(P: float, mu: float, radius: float, E: float, nu: float) -> _Contact:
    P = _real("P", P, "(0, inf)", lambda v: v > 0.0)
    mu = _real("mu", mu, "(0, inf)", lambda v: v > 0.0)
    R = _real("radius", radius, "(0, inf)", lambda v: v > 0.0)
    E = _real("E", E, "(0, inf)", lambda v: v > 0.0)
    nu = _real("nu", nu, "(-1, 0.5]", lambda v: -1.0 < v <= 0.5)
    hz = sphere(P, R, E / (1.0 - nu * nu))
    G = E / (2.0 * (1.0 + nu))
    return _Contact(P=P, mu=mu, nu=nu, G=G, a=hz.contact_radius, p0=hz.peak_pressure)


def _load_ratio(name: str, Q: float, ct: _Contact) -> float:
    """Return Q/(μP) in [−1, 1], or raise if |Q| exceeds the sliding limit μP."""
    Q = _real(name, Q, "[-mu*P, mu*P]", lambda v: True)
    limit = ct.mu * ct.P
    if abs(Q) > limit * (1.0 + _SLIDING_RTOL):
        raise ValueError(
            f"|{name}| = {abs(Q)!r} exceeds mu*P = {limit!r}: the contact slides and no static "
            f"solution exists; {name} must lie in [-mu*P, mu*P]"
        )
    return max(-1.0, min(1.0, Q / limit))


def _cm_shift(ratio: float, ct: _Contact) -> float:
    """Cattaneo–Mindlin shift for signed load ratio Q/(μP) in [−1, 1], m."""
    return math.copysign(ct.compliance_scale * (1.0 - (1.0 - abs(ratio)) ** (2.0 / 3.0)), ratio)


def _cm_stick_radius(ratio: float, ct: _Contact) -> float:
    return ct.a * (1.0 - abs(ratio)) ** (1.0 / 3.0)


def _cm_traction(r: np.ndarray, ratio: float, ct: _Contact) -> np.ndarray:
    """Cattaneo–Mindlin traction for signed load ratio Q/(μP), Pa, at radii ``r`` (m)."""
    c = _cm_stick_radius(ratio, ct)
    outer = np.sqrt(np.clip(1.0 - (r / ct.a) ** 2, 0.0, None))
    if c > 0.0:
        inner = (c / ct.a) * np.sqrt(np.clip(1.0 - (r / c) ** 2, 0.0, None))
    else:
        inner = np.zeros_like(r)
    return math.copysign(ct.mu * ct.p0, ratio) * (outer - inner)


def _as_output(values: np.ndarray) -> np.ndarray | float:
    return float(values) if values.ndim == 0 else values


@dataclass(frozen=True)
class CattaneoMindlin:
    """Partial slip of a sphere under a monotonically applied tangential force Q at constant P.

    Attributes
    ----------
    contact_radius : float
        Hertz contact radius a, m.
    stick_radius : float
        Radius c = a(1 − |Q|/(μP))^(1/3) of the central stick zone, m (0 at full sliding).
    shift : float
        Tangential shift δ_x = ±3μP(2−ν)/(16Ga)[1 − (1 − |Q|/(μP))^(2/3)], m, sign of Q.
    initial_stiffness : float
        Tangential stiffness at Q → 0, 8Ga/(2−ν), N/m.
    tangential_force, normal_force, friction_coefficient, peak_pressure : float
        Q (N), P (N), μ, and the Hertz peak pressure p₀ (Pa).
    """

    contact_radius: float
    stick_radius: float
    shift: float
    initial_stiffness: float
    tangential_force: float
    normal_force: float
    friction_coefficient: float
    peak_pressure: float

    def traction(self, r: ArrayLike) -> np.ndarray | float:
        """Shear traction τ(r), Pa, sign of Q: μp₀[√(1−r²/a²) − (c/a)√(1−r²/c²)H(c−r)].

        Zero outside the contact (r ≥ a); τ = ±μp at every r when c = 0 (full sliding).
        """
        a, c = self.contact_radius, self.stick_radius
        mu, p0 = self.friction_coefficient, self.peak_pressure
        r = np.abs(np.asarray(r, dtype=float))
        outer = np.sqrt(np.clip(1.0 - (r / a) ** 2, 0.0, None))
        inner = (c / a) * np.sqrt(np.clip(1.0 - (r / c) ** 2, 0.0, None)) if c > 0.0 else 0.0
        sign = math.copysign(1.0, self.tangential_force)
        return _as_output(sign * mu * p0 * (outer - inner))


def cattaneo_mindlin(
    Q: float, P: float, mu: float, radius: float, E: float, nu: float
) -> CattaneoMindlin:
    """Cattaneo–Mindlin partial-slip solution for a sphere on a rigid flat.

    The tangential force Q (N) is applied monotonically from zero at constant normal force P (N).
    An annulus c ≤ r ≤ a slips with |τ| = μp; the disc r < c sticks (Cattaneo 1938; Mindlin 1949;
    Johnson 1985, §7.2).

    Parameters
    ----------
    Q : float
        Tangential force, N, with |Q| ≤ μP; negative Q gives the mirror-image solution.
        |Q| = μP is full sliding (c = 0).
    P : float
        Normal force > 0, N.
    mu : float
        Coulomb friction coefficient > 0.
    radius : float
        Sphere radius R > 0, m.
    E : float
        Young's modulus of the sphere > 0, Pa (the flat is rigid).
    nu : float
        Poisson ratio of the sphere, in (−1, 0.5].

    Raises
    ------
    ValueError
        If an argument is out of range, in particular if |Q| exceeds μP.
    """
    ct = _contact(P, mu, radius, E, nu)
    ratio = _load_ratio("Q", Q, ct)
    return CattaneoMindlin(
        contact_radius=ct.a,
        stick_radius=_cm_stick_radius(ratio, ct),
        shift=_cm_shift(ratio, ct),
        initial_stiffness=8.0 * ct.G * ct.a / (2.0 - ct.nu),
        tangential_force=float(Q),
        normal_force=ct.P,
        friction_coefficient=ct.mu,
        peak_pressure=ct.p0,
    )


@dataclass(frozen=True)
class MindlinDeresiewicz:
    """State on the unloading or reloading branch of the Mindlin–Deresiewicz hysteresis loop.

    Attributes
    ----------
    contact_radius : float
        Hertz contact radius a, m.
    counter_slip_radius : float
        c′, m: the annulus c′ ≤ r ≤ a slips in the reversed direction, the disc r < c′ sticks
        (c′ = a at the turning point, c′ = c* at the opposite extreme ∓Q*).
    peak_stick_radius : float
        Stick radius c* = a(1 − Q*/(μP))^(1/3) reached at the load extreme Q*, m.
    shift : float
        Tangential shift δ_x(Q), m.
    tangential_force : float
        Current Q, N.
    peak_tangential_force : float
        Amplitude Q* ≥ 0 of the cycle, N.
    branch : str
        ``"unloading"`` (Q* → −Q*) or ``"reloading"`` (−Q* → Q*).
    """

    contact_radius: float
    counter_slip_radius: float
    peak_stick_radius: float
    shift: float
    tangential_force: float
    peak_tangential_force: float
    branch: str
    _state: _Contact = field(repr=False)

    def traction(self, r: ArrayLike) -> np.ndarray | float:
        """Shear traction τ(r), Pa, at radius r (m); zero outside the contact.

        Unloading: τ = τ_CM(Q*) − 2τ_CM((Q* − Q)/2); reloading: τ = −τ_CM(Q*) + 2τ_CM((Q* + Q)/2),
        where τ_CM(q) is the Cattaneo–Mindlin traction for a monotonic load q.
        """
        ct = self._state
        r = np.abs(np.asarray(r, dtype=float))
        limit = ct.mu * ct.P
        peak = self.peak_tangential_force / limit
        if self.branch == "unloading":
            step = (self.peak_tangential_force - self.tangential_force) / (2.0 * limit)
            tau = _cm_traction(r, peak, ct) - 2.0 * _cm_traction(r, step, ct)
        else:
            step = (self.peak_tangential_force + self.tangential_force) / (2.0 * limit)
            tau = -_cm_traction(r, peak, ct) + 2.0 * _cm_traction(r, step, ct)
        return _as_output(tau)


def _md_branch(
    branch: str, Q: float, Q_star: float, P: float, mu: float, radius: float, E: float, nu: float
) -> MindlinDeresiewicz:
    ct = _contact(P, mu, radius, E, nu)
    peak = _load_ratio("Q_star", Q_star, ct)
    if peak < 0.0:
        raise ValueError(f"Q_star must be a finite number in [0, mu*P], got {Q_star!r}")
    q = _real("Q", Q, "[-Q_star, Q_star]", lambda v: True)
    Qs = float(Q_star)
    if abs(q) > Qs * (1.0 + _SLIDING_RTOL):
        raise ValueError(
            f"Q must be a finite number in [-Q_star, Q_star] = [{-Qs!r}, {Qs!r}], got {Q!r}"
        )
    q = max(-Qs, min(Qs, q))
    limit = ct.mu * ct.P
    # The branch is the monotonic solution for the reversal (Q* ∓ Q)/2, doubled and superposed.
    step = (Qs - q) / (2.0 * limit) if branch == "unloading" else (Qs + q) / (2.0 * limit)
    step = min(step, 1.0)
    sign = 1.0 if branch == "unloading" else -1.0
    shift = sign * (_cm_shift(peak, ct) - 2.0 * _cm_shift(step, ct))
    return MindlinDeresiewicz(
        contact_radius=ct.a,
        counter_slip_radius=_cm_stick_radius(step, ct),
        peak_stick_radius=_cm_stick_radius(peak, ct),
        shift=shift,
        tangential_force=q,
        peak_tangential_force=Qs,
        branch=branch,
        _state=ct,
    )


def mindlin_deresiewicz_unloading(
    Q: float, Q_star: float, P: float, mu: float, radius: float, E: float, nu: float
) -> MindlinDeresiewicz:
    """Unloading branch: Q decreases from the peak Q* (reached monotonically from 0) to Q.

    δ(Q) = δ_CM(Q*) − 2δ_CM((Q* − Q)/2), τ = τ_CM(Q*) − 2τ_CM((Q* − Q)/2), and reverse slip
    occupies c′ ≤ r ≤ a with c′ = a(1 − (Q* − Q)/(2μP))^(1/3) (Mindlin & Deresiewicz 1953;
    Johnson 1985, §7.2). At Q = Q* this equals :func:`cattaneo_mindlin` at Q*; at Q = −Q* the
    shift is −δ_CM(Q*).

    Parameters
    ----------
    Q : float
        Current tangential force, N, in [−Q*, Q*].
    Q_star : float
        Peak tangential force, N, in [0, μP].
    P, mu, radius, E, nu
        As for :func:`cattaneo_mindlin`.

    Raises
    ------
    ValueError
        If an argument is out of range (Q* > μP, Q outside [−Q*, Q*], ...).
    """
    return _md_branch("unloading", Q, Q_star, P, mu, radius, E, nu)


def mindlin_deresiewicz_reloading(
    Q: float, Q_star: float, P: float, mu: float, radius: float, E: float, nu: float
) -> MindlinDeresiewicz:
    """Reloading branch: Q increases from −Q* (the end of unloading) back up to Q.

    The mirror image of unloading: δ(Q) = −δ_CM(Q*) + 2δ_CM((Q* + Q)/2),
    τ = −τ_CM(Q*) + 2τ_CM((Q* + Q)/2), c′ = a(1 − (Q* + Q)/(2μP))^(1/3)
    (Mindlin & Deresiewicz 1953; Johnson 1985, §7.2). At Q = Q* the loop closes on δ_CM(Q*).

    Parameters and errors are as for :func:`mindlin_deresiewicz_unloading`.
    """
    return _md_branch("reloading", Q, Q_star, P, mu, radius, E, nu)


def hysteresis_loop(
    Q_star: float, P: float, mu: float, radius: float, E: float, nu: float, n: int = 50
) -> tuple[np.ndarray, np.ndarray]:
    """Closed Mindlin–Deresiewicz loop of tangential force against shift.

    Returns ``(Q, shift)`` (N, m), each of length 2n − 1: n equally spaced points unloading from
    Q* to −Q*, then n − 1 points reloading back to Q* (the turning point −Q* is not repeated).
    The first and last points coincide: (Q*, δ_CM(Q*)).

    Raises
    ------
    ValueError
        If n < 2 or another argument is out of range.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"n must be an integer in [2, inf), got {n!r}")
    Qs = float(Q_star)
    down = np.linspace(Qs, -Qs, n)
    up = np.linspace(-Qs, Qs, n)[1:]
    shift_down = [mindlin_deresiewicz_unloading(q, Qs, P, mu, radius, E, nu).shift for q in down]
    shift_up = [mindlin_deresiewicz_reloading(q, Qs, P, mu, radius, E, nu).shift for q in up]
    return np.concatenate([down, up]), np.array(shift_down + shift_up)


@dataclass(frozen=True)
class ProportionalLoading:
    """Sphere loaded from zero along a fixed direction, Q = κP with |κ| ≤ μ: no slip anywhere.

    Attributes
    ----------
    contact_radius : float
        Hertz contact radius a, m.
    shift : float
        δ_x = 3κP(2−ν)/(16Ga), m: 1.5× the initial Cattaneo compliance (2−ν)/(8Ga) times Q.
    tangential_force, normal_force, ratio, peak_pressure : float
        Q = κP (N), P (N), κ, and the Hertz peak pressure p₀ (Pa).
    """

    contact_radius: float
    shift: float
    tangential_force: float
    normal_force: float
    ratio: float
    peak_pressure: float

    def traction(self, r: ArrayLike) -> np.ndarray | float:
        """Shear traction τ(r) = κ·p(r), Pa, at radius r (m); zero outside the contact."""
        r = np.abs(np.asarray(r, dtype=float))
        p = self.peak_pressure * np.sqrt(np.clip(1.0 - (r / self.contact_radius) ** 2, 0.0, None))
        return _as_output(self.ratio * p)


def proportional_loading(
    kappa: float, P: float, mu: float, radius: float, E: float, nu: float
) -> ProportionalLoading:
    """Oblique loading from zero with a constant ratio Q/P = κ (Mindlin & Deresiewicz 1953).

    Each load increment enlarges the contact; as long as |dQ| ≤ μ dP the increments add
    traction in the same flat-punch form as the pressure increments, so nothing slips, τ = κp and
    δ_x = 3κP(2−ν)/(16Ga) (Johnson 1985, §7.3). This history dependence is why the shift is 1.5×
    what the initial Cattaneo stiffness 8Ga/(2−ν) would give for the same Q.

    Parameters
    ----------
    kappa : float
        Ratio Q/P, with |κ| ≤ μ (|κ| = μ is the limiting case τ = ±μp with no slip yet).
    P, mu, radius, E, nu
        As for :func:`cattaneo_mindlin`; P is the final normal force, N.

    Raises
    ------
    ValueError
        If |κ| > μ or another argument is out of range.
    """
    ct = _contact(P, mu, radius, E, nu)
    k = _real("kappa", kappa, "[-mu, mu]", lambda v: True)
    if abs(k) > ct.mu:
        raise ValueError(
            f"|kappa| = {abs(k)!r} exceeds mu = {ct.mu!r}: the contact slides; "
            "kappa must lie in [-mu, mu]"
        )
    return ProportionalLoading(
        contact_radius=ct.a,
        shift=3.0 * k * ct.P * (2.0 - ct.nu) / (16.0 * ct.G * ct.a),
        tangential_force=k * ct.P,
        normal_force=ct.P,
        ratio=k,
        peak_pressure=ct.p0,
    )
