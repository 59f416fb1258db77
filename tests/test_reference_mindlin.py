"""Cattaneo–Mindlin, Mindlin–Deresiewicz and proportional loading reference solutions."""

import itertools
import math

import numpy as np
import pytest
from scipy import integrate

from thirdbody.reference import hertz, mindlin

P, MU, R, E, NU = 2.0, 0.4, 0.01, 210.0, 0.3  # O(1) magnitudes keep quadrature tolerances clear
LIMIT = MU * P


def _force(traction, a, kinks=()):
    """∫τ dA over the disc r < a; ``kinks`` are the slip-zone radii where τ has a √ edge."""
    edges = [0.0, *sorted(k for k in kinks if 0 < k < a), a]
    total = 0.0
    for lo, hi in itertools.pairwise(edges):
        val, _ = integrate.quad(
            lambda r: 2 * math.pi * r * traction(r), lo, hi, epsabs=0, epsrel=1e-13, limit=200
        )
        total += val
    return total


@pytest.mark.parametrize(
    ("ratio", "c_over_a"), [(0.25, 0.9086), (0.5, 0.7937), (0.75, 0.6300), (0.9, 0.4642)]
)
def test_stick_radius_reference_numbers(ratio, c_over_a):
    s = mindlin.cattaneo_mindlin(ratio * LIMIT, P, MU, R, E, NU)
    assert round(s.stick_radius / s.contact_radius, 4) == c_over_a


def test_contact_is_hertz():
    s = mindlin.cattaneo_mindlin(0.3 * LIMIT, P, MU, R, E, NU)
    h = hertz.sphere(P, R, E / (1 - NU**2))
    assert s.contact_radius == h.contact_radius
    assert s.peak_pressure == h.peak_pressure


@pytest.mark.parametrize("ratio", [-0.9, -0.3, 0.0, 0.25, 0.5, 0.75, 1.0])
def test_traction_integrates_to_Q(ratio):
    Q = ratio * LIMIT
    s = mindlin.cattaneo_mindlin(Q, P, MU, R, E, NU)
    total = _force(s.traction, s.contact_radius, [s.stick_radius])
    assert total == pytest.approx(Q, rel=1e-8, abs=1e-12 * LIMIT)


def test_traction_bounded_by_friction_and_sliding_in_annulus():
    s = mindlin.cattaneo_mindlin(0.6 * LIMIT, P, MU, R, E, NU)
    h = hertz.sphere(P, R, E / (1 - NU**2))
    r = np.linspace(0, 1.2 * s.contact_radius, 301)
    tau, p = s.traction(r), h.pressure(r)
    assert np.all(tau <= MU * p * (1 + 1e-12) + 1e-300)
    slip = (r > s.stick_radius) & (r < s.contact_radius)
    np.testing.assert_allclose(tau[slip], MU * p[slip], rtol=1e-12)
    assert np.all(tau[r >= s.contact_radius] == 0.0)


def test_initial_slope_is_inverse_initial_stiffness():
    s = mindlin.cattaneo_mindlin(0.0, P, MU, R, E, NU)
    dQ = 1e-7 * LIMIT
    slope = mindlin.cattaneo_mindlin(dQ, P, MU, R, E, NU).shift / dQ
    assert slope == pytest.approx(1 / s.initial_stiffness, rel=1e-6)
    G = E / (2 * (1 + NU))
    assert s.initial_stiffness == pytest.approx(8 * G * s.contact_radius / (2 - NU), rel=1e-14)


def test_negative_Q_is_mirror_image():
    pos = mindlin.cattaneo_mindlin(0.4 * LIMIT, P, MU, R, E, NU)
    neg = mindlin.cattaneo_mindlin(-0.4 * LIMIT, P, MU, R, E, NU)
    assert neg.shift == -pos.shift
    assert neg.stick_radius == pos.stick_radius
    r = np.linspace(0, pos.contact_radius, 7)
    np.testing.assert_array_equal(neg.traction(r), -pos.traction(r))


def test_full_sliding():
    s = mindlin.cattaneo_mindlin(LIMIT, P, MU, R, E, NU)
    assert s.stick_radius == 0.0
    h = hertz.sphere(P, R, E / (1 - NU**2))
    r = np.linspace(0, s.contact_radius, 50)
    np.testing.assert_allclose(s.traction(r), MU * h.pressure(r), rtol=1e-14)
    G = E / (2 * (1 + NU))
    assert s.shift == pytest.approx(3 * LIMIT * (2 - NU) / (16 * G * s.contact_radius))


@pytest.mark.parametrize("Q", [1.0001 * LIMIT, -1.5 * LIMIT])
def test_Q_beyond_friction_limit_raises(Q):
    with pytest.raises(ValueError, match="exceeds mu\\*P"):
        mindlin.cattaneo_mindlin(Q, P, MU, R, E, NU)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"P": 0.0}, "P"),
        ({"mu": -0.1}, "mu"),
        ({"radius": math.nan}, "radius"),
        ({"E": -1.0}, "E"),
        ({"nu": 0.6}, "nu"),
        ({"nu": -1.0}, "nu"),
    ],
)
def test_invalid_inputs_raise(kwargs, name):
    args = {"Q": 0.1 * LIMIT, "P": P, "mu": MU, "radius": R, "E": E, "nu": NU} | kwargs
    with pytest.raises(ValueError, match=rf"^{name} must"):
        mindlin.cattaneo_mindlin(**args)


# Mindlin–Deresiewicz

Q_STAR = 0.7 * LIMIT


def test_unloading_starts_on_loading_curve():
    load = mindlin.cattaneo_mindlin(Q_STAR, P, MU, R, E, NU)
    un = mindlin.mindlin_deresiewicz_unloading(Q_STAR, Q_STAR, P, MU, R, E, NU)
    assert un.shift == pytest.approx(load.shift, rel=1e-14)
    assert un.counter_slip_radius == un.contact_radius
    assert un.peak_stick_radius == pytest.approx(load.stick_radius, rel=1e-14)
    r = np.linspace(0, load.contact_radius, 9)
    np.testing.assert_allclose(un.traction(r), load.traction(r), rtol=1e-13, atol=0)


def test_unloading_to_minus_Q_star_mirrors_loading():
    load = mindlin.cattaneo_mindlin(Q_STAR, P, MU, R, E, NU)
    un = mindlin.mindlin_deresiewicz_unloading(-Q_STAR, Q_STAR, P, MU, R, E, NU)
    assert un.shift == pytest.approx(-load.shift, rel=1e-13)
    assert un.counter_slip_radius == pytest.approx(load.stick_radius, rel=1e-13)
    r = np.linspace(0, load.contact_radius, 9)
    np.testing.assert_allclose(un.traction(r), -load.traction(r), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("Q", [0.6 * Q_STAR, 0.0, -0.5 * Q_STAR])
def test_unloading_traction_balance_and_bound(Q):
    un = mindlin.mindlin_deresiewicz_unloading(Q, Q_STAR, P, MU, R, E, NU)
    kinks = [un.counter_slip_radius, un.peak_stick_radius]
    assert _force(un.traction, un.contact_radius, kinks) == pytest.approx(Q, rel=1e-8, abs=1e-12)
    c1 = (1 - (Q_STAR - Q) / (2 * LIMIT)) ** (1 / 3)
    assert un.counter_slip_radius / un.contact_radius == pytest.approx(c1, rel=1e-14)
    h = hertz.sphere(P, R, E / (1 - NU**2))
    r = np.linspace(0, un.contact_radius, 401)
    tau, p = un.traction(r), h.pressure(r)
    assert np.all(np.abs(tau) <= MU * p * (1 + 1e-12) + 1e-15)
    reverse = r > un.counter_slip_radius
    np.testing.assert_allclose(tau[reverse], -MU * p[reverse], rtol=1e-10, atol=1e-15)


def test_reloading_is_mirror_of_unloading():
    for Q in np.linspace(-Q_STAR, Q_STAR, 7):
        un = mindlin.mindlin_deresiewicz_unloading(-Q, Q_STAR, P, MU, R, E, NU)
        re = mindlin.mindlin_deresiewicz_reloading(Q, Q_STAR, P, MU, R, E, NU)
        assert re.shift == pytest.approx(-un.shift, rel=1e-13, abs=1e-18)
        assert re.traction(0.3 * re.contact_radius) == pytest.approx(
            -un.traction(0.3 * un.contact_radius), rel=1e-12, abs=1e-15
        )


def test_hysteresis_loop_closes_and_dissipates():
    Q, d = mindlin.hysteresis_loop(Q_STAR, P, MU, R, E, NU, n=41)
    assert Q.shape == d.shape == (81,)
    load = mindlin.cattaneo_mindlin(Q_STAR, P, MU, R, E, NU)
    assert Q[0] == Q[-1] == Q_STAR
    assert d[0] == pytest.approx(load.shift, rel=1e-14)
    assert d[-1] == pytest.approx(load.shift, rel=1e-13)
    assert d[40] == pytest.approx(-load.shift, rel=1e-13)
    # Unloading branch lies above reloading at every Q: a loop with positive area.
    Q_up, d_up = Q[41:], d[41:]
    d_down_at_up = np.interp(Q_up, Q[:41][::-1], d[:41][::-1])
    assert np.all(d_down_at_up[:-1] > d_up[:-1])
    area = -np.trapezoid(d, Q)  # ∮ Q dδ > 0 for the dissipated work, traversed clockwise
    assert area > 0


def test_md_invalid_inputs_raise():
    with pytest.raises(ValueError, match="Q must"):
        mindlin.mindlin_deresiewicz_unloading(1.1 * Q_STAR, Q_STAR, P, MU, R, E, NU)
    with pytest.raises(ValueError, match="Q_star"):
        mindlin.mindlin_deresiewicz_unloading(0.0, 1.1 * LIMIT, P, MU, R, E, NU)
    with pytest.raises(ValueError, match="Q_star"):
        mindlin.mindlin_deresiewicz_reloading(0.0, -0.1, P, MU, R, E, NU)
    with pytest.raises(ValueError, match=r"^n must"):
        mindlin.hysteresis_loop(Q_STAR, P, MU, R, E, NU, n=1)


# Proportional loading


def test_proportional_shift_is_one_and_a_half_initial_compliance():
    kappa = 0.6 * MU
    s = mindlin.proportional_loading(kappa, P, MU, R, E, NU)
    cm = mindlin.cattaneo_mindlin(0.0, P, MU, R, E, NU)
    assert s.tangential_force == pytest.approx(kappa * P)
    assert s.shift == pytest.approx(1.5 * s.tangential_force / cm.initial_stiffness, rel=1e-14)


def test_proportional_traction_is_kappa_p_and_balances():
    kappa = -0.3 * MU
    s = mindlin.proportional_loading(kappa, P, MU, R, E, NU)
    h = hertz.sphere(P, R, E / (1 - NU**2))
    r = np.linspace(0, 1.1 * h.contact_radius, 23)
    np.testing.assert_allclose(s.traction(r), kappa * h.pressure(r), rtol=1e-14)
    assert _force(s.traction, s.contact_radius) == pytest.approx(kappa * P, rel=1e-8)


def test_proportional_beyond_mu_raises():
    with pytest.raises(ValueError, match="kappa"):
        mindlin.proportional_loading(1.01 * MU, P, MU, R, E, NU)
