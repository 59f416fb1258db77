"""Spence's frictional Hertz indentation: c/a coupled and to first order; Dundurs' β."""

import itertools
import math

import numpy as np
import pytest
from scipy import integrate

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
    assert spence.stick_ratio_first_order(0.0, 0.3) == 1.0
    assert spence.stick_ratio_first_order(1e-3, 1.0) == 1.0
    assert 0.99 < spence.stick_ratio_first_order(0.5, 1.0) < 1.0
    assert spence.stick_ratio_first_order(20.0, 1.0) < 1e-8
    # small c/a: β/μ = ln(4a/c) + O((c/a)² ln(c/a))
    for rho in (12.0, 20.0, 29.0, 31.0, 60.0):
        assert spence.stick_ratio_first_order(rho, 1.0) == pytest.approx(
            4 * math.exp(-rho), rel=1e-8, abs=0)
    # c/a → 1 as β/μ → 0: 1 − c/a ≈ 2 exp(−π μ/β)
    k = spence.stick_ratio_first_order(0.2, 1.0)
    assert 1 - k == pytest.approx(2 * math.exp(-math.pi / 0.2), rel=0.05)


def test_depends_on_ratio_only_and_decreases():
    rhos = np.geomspace(0.15, 25.0, 40)
    ks = [spence.stick_ratio_first_order(r, 1.0) for r in rhos]
    assert all(a > b for a, b in itertools.pairwise(ks))
    for r, k in zip(rhos[::7], ks[::7], strict=True):
        assert spence.stick_ratio_first_order(0.5, 0.5 / r) == pytest.approx(k, rel=1e-12)
        # near c/a = 1 the inverse is ill-conditioned (β/μ ∝ 1/ln(1 − c/a))
        assert spence.beta_over_mu(k) == pytest.approx(r, rel=1e-12 / (1 - k))


def test_contact_example_parameters():
    # β = 0.5 (ν = 0 against a rigid indenter), μ = 0.2986: CONTACT's spence35 example. Its 0.5 is
    # the fully coupled value; the first-order ratio is larger.
    k = spence.stick_ratio_first_order(spence.beta_rigid(0.0), 0.2986)
    assert k == pytest.approx(0.62331, abs=2e-5)


@pytest.mark.parametrize(("beta", "mu"), [(0.5, 0.2986), (0.25, 0.4), (0.4, 0.12)])
def test_equation_by_quadrature(beta, mu):
    """Both sides of the stick-boundary condition F_in′(c) = F_out′(c), by direct quadrature.

    F_in(t) = β ∫₀^{π/2} (1 − √(1 − t² sin²θ))/sin θ dθ is the Abel transform of the pressure's
    radial pull that the stick zone must cancel; F_out′(t) = μ t ∫_t^1 ds/(√(s² − t²)√(1 − s²))
    comes from the slip annulus (a = 1). The closed forms (β artanh t, μ t K) are not used.
    """
    c = spence.stick_ratio_first_order(beta, mu)

    def F_in(t):
        f = lambda th: (1 - math.sqrt(1 - (t * math.sin(th)) ** 2)) / math.sin(th)  # noqa: E731
        return beta * integrate.quad(f, 0, math.pi / 2, epsabs=0, epsrel=1e-13)[0]

    d = 1e-5
    inner = (F_in(c + d) - F_in(c - d)) / (2 * d)
    # s = √(c² + (1 − c²) sin²φ) removes both endpoint singularities
    g = lambda ph: 1 / math.sqrt(c * c + (1 - c * c) * math.sin(ph) ** 2)  # noqa: E731
    outer = mu * c * integrate.quad(g, 0, math.pi / 2, epsabs=0, epsrel=1e-13)[0]
    assert inner == pytest.approx(outer, rel=1e-7)


def test_ring_shear_kernel_is_cerruti_summed_round_the_ring():
    """The ring kernel against Cerruti's point solution integrated round the ring, for two ν.

    u_i = Q_j/(2πG) [(1 − ν) δ_ij/ρ + ν x_i x_j/ρ³] (Johnson 1985, eq. 3.86a) with G = 1 − ν so
    that A = (1 − ν)/G = 1; the ν-term integrates to zero round the ring.
    """
    for nu in (0.0, 0.3):
        G = 1.0 - nu
        for r, s in ((0.3, 0.7), (0.7, 0.3), (0.5, 0.52), (0.9, 0.1)):
            def integrand(th, r=r, s=s, nu=nu, G=G):
                rho = math.sqrt(r * r + s * s - 2 * r * s * math.cos(th))
                radial = (1 - nu) * math.cos(th) / rho
                radial += nu * (r - s * math.cos(th)) * (r * math.cos(th) - s) / rho**3
                return radial / (2 * math.pi * G) / (2 * math.pi)
            direct = integrate.quad(integrand, 0, 2 * math.pi, epsabs=0, epsrel=1e-12,
                                    limit=200)[0]
            assert spence._ring_shear_kernel(r, s) == pytest.approx(direct, rel=1e-9), (nu, r, s)


def test_disc_displacement_is_boussinesq_by_quadrature():
    """Uniform unit pressure on a disc of radius b with E* = 2: Boussinesq's 1/(πE*ρ) kernel
    integrated over the disc in polar coordinates about the point (ρ dρ cancels the 1/ρ)."""
    b = 0.6
    for r in (0.0, 0.25, 0.59, 0.8, 1.7):
        def chord(phi, r=r):
            # distance from the point (r, 0) to the disc's edge along the direction phi
            c = r * math.cos(phi)
            disc = c * c - (r * r - b * b)
            if disc < 0:
                return 0.0, 0.0
            return max(-c - math.sqrt(disc), 0.0), max(-c + math.sqrt(disc), 0.0)
        # ∫∫ (1/ρ) ρ dρ dφ = ∫ (ρ_out − ρ_in) dφ; u = (1/(π E*)) × that with E* = 2
        pts = None if r < b else [math.pi - math.asin(b / r), math.pi + math.asin(b / r)]
        length = integrate.quad(lambda f: chord(f)[1] - chord(f)[0], 0, 2 * math.pi,
                                points=pts, epsabs=0, epsrel=1e-11, limit=200)[0]
        assert float(spence._disc_normal(b, np.array([r]))[0]) == pytest.approx(
            length / (2 * math.pi), rel=1e-8), r


def test_ring_elements_one_way_converge_to_the_closed_form():
    """Two independent derivations of the first-order problem agree: the ring-element solution
    with the shear's effect on the pressure switched off tends to the closed form as the rings
    and stages refine, and its pressure is Hertz's."""
    exact = spence.stick_ratio_first_order(0.5, 0.2986)
    errors = []
    for rings, stages in ((50, 80), (100, 160), (200, 320)):
        sol = spence.solve(0.5, 0.2986, rings=rings, stages=stages, coupled=False)
        errors.append(abs(sol.stick_ratio - exact))
        assert sol.centre_pressure_ratio == pytest.approx(1.0, abs=2e-3)
        assert not sol.coupled
    assert errors[2] < errors[0] and errors[2] < 1e-3, errors


def test_coupled_solution_is_contacts_spence35():
    """β = 0.5, μ = 0.2986: CONTACT's user guide gives c/a = 0.5 and a centre pressure 1.31 ×
    Hertz's; the first-order value (0.6233) is far from it."""
    sol = spence.solve(0.5, 0.2986)
    assert sol.stick_ratio == pytest.approx(0.5, abs=0.005)
    assert sol.centre_pressure_ratio == pytest.approx(1.31, abs=0.01)
    assert sol.coupled and sol.rings == 200 and sol.stages == 320
    assert spence.stick_ratio(0.5, 0.2986, rings=100, stages=160) == pytest.approx(
        sol.stick_ratio, abs=0.005)


def test_coupled_tends_to_first_order_as_beta_mu_vanishes():
    """At fixed β/μ the coupled c/a rises towards the first-order value as βμ → 0."""
    rho = 0.5 / 0.2986
    first = spence.stick_ratio_first_order(rho, 1.0)
    coupled = [spence.stick_ratio(beta, beta / rho, rings=100, stages=160)
               for beta in (0.5, 0.25, 0.1)]
    assert coupled[0] < coupled[1] < coupled[2] < first + 0.005
    assert abs(coupled[2] - first) < 0.3 * abs(coupled[0] - first)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"beta": 0.6, "mu": 0.3}, "beta"), ({"beta": 0.5, "mu": 0.0}, "mu"),
    ({"beta": 0.5, "mu": 0.3, "rings": 10}, "rings"),
    ({"beta": 0.5, "mu": 0.3, "stages": 2.5}, "stages")])
def test_solve_checks_its_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        spence.solve(**kwargs)
