"""Spence's frictional Hertz indentation: stick-zone ratio c/a (uncoupled) and Dundurs' β."""

import itertools
import math

import numpy as np
import pytest
from scipy import integrate
from scipy.linalg import cholesky, solve_triangular
from scipy.optimize import lsq_linear
from scipy.special import ellipe, ellipkm1

from thirdbody.reference import spence


def test_beta_rigid_values():
    assert spence.beta_rigid(0.0) == 0.5
    assert spence.beta_rigid(0.5) == 0.0
    assert spence.beta_rigid(0.3) == pytest.approx(2 / 7, rel=1e-15)


def test_dundurs_beta_two_bodies():
    # a rigid partner reduces to beta_rigid; swapping the bodies flips the sign; like bodies: 0
    assert spence.dundurs_beta(80e9, 0.3, math.inf, 0.2) == pytest.approx(spence.beta_rigid(0.3))
    b = spence.dundurs_beta(1.0, 0.1, 3.0, 0.4)
    assert spence.dundurs_beta(3.0, 0.4, 1.0, 0.1) == pytest.approx(-b)
    # by hand: [(0.8/1 - 0.2/3)] / (2 [0.9/1 + 0.6/3]) = (11/15) / 2.2
    assert b == pytest.approx((11 / 15) / 2.2, rel=1e-14)
    assert spence.dundurs_beta(5.0, 0.25, 5.0, 0.25) == 0.0
    with pytest.raises(ValueError, match="G1"):
        spence.dundurs_beta(-1.0, 0.3, 1.0, 0.3)


def test_limits():
    # no coupling: full stick; weak coupling: stick almost everywhere; strong: stick shrinks to 0
    assert spence.stick_ratio(0.0, 0.3) == 1.0
    assert spence.stick_ratio(1e-3, 1.0) == 1.0
    assert 0.99 < spence.stick_ratio(0.5, 1.0) < 1.0
    assert spence.stick_ratio(20.0, 1.0) < 1e-8
    # small c/a: β/μ = ln(4a/c) + O((c/a)² ln(c/a))
    for rho in (12.0, 20.0, 29.0, 31.0, 60.0):
        assert spence.stick_ratio(rho, 1.0) == pytest.approx(4 * math.exp(-rho), rel=1e-8, abs=0)
    # c/a → 1 as β/μ → 0: 1 − c/a ≈ 2 exp(−π μ/β)
    k = spence.stick_ratio(0.2, 1.0)
    assert 1 - k == pytest.approx(2 * math.exp(-math.pi / 0.2), rel=0.05)


def test_depends_on_ratio_only_and_decreases():
    rhos = np.geomspace(0.15, 25.0, 40)
    ks = [spence.stick_ratio(r, 1.0) for r in rhos]
    assert all(a > b for a, b in itertools.pairwise(ks))
    for r, k in zip(rhos[::7], ks[::7], strict=True):
        assert spence.stick_ratio(0.5, 0.5 / r) == pytest.approx(k, rel=1e-12)
        # near c/a = 1 the inverse is ill-conditioned (β/μ ∝ 1/ln(1 − c/a))
        assert spence.beta_over_mu(k) == pytest.approx(r, rel=1e-12 / (1 - k))


def test_contact_example_parameters():
    # β = 0.5 (ν = 0 against a rigid indenter), μ = 0.2986: CONTACT's spence35 example. Its 0.5 is
    # the fully coupled value; the uncoupled ratio is larger (ring-element solution: 0.625 ± 0.004).
    assert spence.stick_ratio(spence.beta_rigid(0.0), 0.2986) == pytest.approx(0.62331, abs=2e-5)


@pytest.mark.parametrize(("beta", "mu"), [(0.5, 0.2986), (0.25, 0.4), (0.4, 0.12)])
def test_equation_by_quadrature(beta, mu):
    """Both sides of the stick-boundary condition F_in′(c) = F_out′(c), by direct quadrature.

    F_in(t) = β ∫₀^{π/2} (1 − √(1 − t² sin²θ))/sin θ dθ is the Abel transform of the pressure's
    radial pull that the stick zone must cancel; F_out′(t) = μ t ∫_t^1 ds/(√(s² − t²)√(1 − s²))
    comes from the slip annulus (a = 1). The closed forms (β artanh t, μ t K) are not used.
    """
    c = spence.stick_ratio(beta, mu)

    def F_in(t):
        f = lambda th: (1 - math.sqrt(1 - (t * math.sin(th)) ** 2)) / math.sin(th)  # noqa: E731
        return beta * integrate.quad(f, 0, math.pi / 2, epsabs=0, epsrel=1e-13)[0]

    d = 1e-5
    inner = (F_in(c + d) - F_in(c - d)) / (2 * d)
    # s = √(c² + (1 − c²) sin²φ) removes both endpoint singularities
    g = lambda ph: 1 / math.sqrt(c * c + (1 - c * c) * math.sin(ph) ** 2)  # noqa: E731
    outer = mu * c * integrate.quad(g, 0, math.pi / 2, epsabs=0, epsrel=1e-13)[0]
    assert inner == pytest.approx(outer, rel=1e-7)


def _ring_kernel(r, s):
    """Radial displacement at r per unit total outward radial ring force at s, A = (1−ν)/G = 1.

    Boussinesq potential of the uniform disc, differentiated in r (Cerruti's point solution
    integrated round the ring gives the same, independent of ν once scaled by 1 − ν).
    """
    if r < s:
        m1 = (s - r) * (s + r) / s**2
        return -(ellipe(1 - m1) - ellipkm1(m1)) / (math.pi**2 * r)
    m1 = (r - s) * (r + s) / r**2
    return -(ellipe(1 - m1) - ellipkm1(m1)) / (math.pi**2 * s)


def test_incremental_ring_elements():
    """Independent route: load a ring-element model in many small steps and read off c/a.

    Hertz pressure (E* = 2, R = 1), piecewise-constant radial shear on rings of width h, stick
    memory of the radial displacement between steps, Coulomb bounds solved as a box-constrained
    least-squares problem. The shear meets μp smoothly at r = c, so reading the stick edge off
    |q| < μp over-estimates c by one to two rings (0.667, 0.653, 0.639 for 36, 72, 144 rings in
    contact; the exact root is 0.6233): the root must lie within 2.5 rings below the estimate.
    """
    beta, mu, n, a_end = 0.5, 0.2986, 48, 0.75
    h = 1.0 / n
    edges = np.arange(n + 1) * h
    rm = 0.5 * (edges[:-1] + edges[1:])
    T = np.empty((n, n))
    for i, r in enumerate(rm):
        for j in range(n):
            pts = [r] if edges[j] < r < edges[j + 1] else None
            T[i, j] = integrate.quad(lambda s, r=r: 2 * math.pi * s * _ring_kernel(r, s),
                                     edges[j], edges[j + 1], points=pts, limit=100)[0]
    area = math.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    M = area[:, None] * T
    L = cholesky(0.5 * (M + M.T), lower=True)
    ur_prev = np.zeros(n)
    for a in a_end * np.arange(1, 121) / 120:
        p0 = 4 * a / math.pi
        p = p0 * np.sqrt(np.clip(1 - (rm / a) ** 2, 0, None))
        inside = p0 * a * a / 3 * (1 - np.clip(1 - (rm / a) ** 2, 0, None) ** 1.5)
        ur_p = -beta * inside / rm  # inward pull of the pressure
        rhs = -solve_triangular(L, area * (ur_p - ur_prev), lower=True)
        q = lsq_linear(L.T, rhs, bounds=(-mu * p - 1e-300, mu * p + 1e-300), method="bvls",
                       tol=1e-13).x
        ur_prev = T @ q + ur_p
    stick = (p > 0) & (np.abs(q) < mu * p * (1 - 1e-6))
    c = (np.nonzero(stick)[0].max() + 1) * h
    k = spence.stick_ratio(beta, mu)
    assert c / a_end - 2.5 * h / a_end <= k <= c / a_end
