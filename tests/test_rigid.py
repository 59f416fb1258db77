"""Rigid-particle criterion (paper eqs 1–5) and the tilted-ellipsoid closed forms."""

import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from thirdbody import rigid
from thirdbody.reference import rigid as reexported
from thirdbody.rigid import RigidState

lengths = st.floats(min_value=0.05, max_value=20.0)
angles = st.floats(min_value=-2 * math.pi, max_value=2 * math.pi)


def _brute_extremes(A, C, theta, n=200_001):
    """Highest/lowest points of the rotated ellipse by dense sampling of its boundary."""
    t = np.linspace(0, 2 * np.pi, n)
    x, z = A * np.cos(t), C * np.sin(t)
    xr = x * math.cos(theta) + z * math.sin(theta)
    zr = -x * math.sin(theta) + z * math.cos(theta)
    i, j = np.argmax(zr), np.argmin(zr)
    return (xr[i], zr[i]), (xr[j], zr[j])


def test_reexported_from_reference():
    assert reexported is rigid


@pytest.mark.parametrize("theta_deg", [-70, -20, 0, 15, 33.7, 90, 120, 200])
def test_contact_points_match_sampled_boundary(theta_deg):
    A, C, th = 2.0, 0.7, math.radians(theta_deg)
    (xu, zu), (xl, zl) = rigid.ellipsoid_contact_points(A, C, th)
    (bxu, bzu), (bxl, bzl) = _brute_extremes(A, C, th)
    assert zu == pytest.approx(bzu, abs=1e-9)
    assert zl == pytest.approx(bzl, abs=1e-9)
    assert xu == pytest.approx(bxu, abs=1e-4)
    assert xl == pytest.approx(bxl, abs=1e-4)


def test_rotation_is_right_handed_about_y():
    # A long axis along x (A > C) tilted by a small positive θ: its +x end dips, so the top
    # contact moves to x < 0 and the bottom one to x > 0.
    (xu, _), (xl, _) = rigid.ellipsoid_contact_points(2.0, 1.0, math.radians(10))
    assert xu < 0 < xl
    assert rigid.ellipsoid_force_ratio(2.0, 1.0, math.radians(10)) < 0


@given(lengths, lengths, angles)
def test_closed_form_xi_matches_contact_points(A, C, theta):
    up, low = rigid.ellipsoid_contact_points(A, C, theta)
    assert rigid.ellipsoid_xi(A, C, theta) == pytest.approx(rigid.xi(up, low), rel=1e-9, abs=1e-12)
    signed = rigid.ellipsoid_force_ratio(A, C, theta)
    assert signed == pytest.approx(rigid.force_ratio(up, low), rel=1e-9, abs=1e-12)
    s, c = math.sin(theta), math.cos(theta)
    quoted = (A**2 - C**2) * s * c / (A**2 * s**2 + C**2 * c**2)
    assert signed == pytest.approx(-quoted, rel=1e-12, abs=1e-15)


@given(lengths, lengths, angles)
def test_period_and_mirror(A, C, theta):
    xi = rigid.ellipsoid_xi(A, C, theta)
    # θ + π carries an absolute round-off of ~1e-16 rad, amplified by up to (A/C)² near θ = 0.
    tol = 1e-14 * max(A / C, C / A) ** 2
    assert rigid.ellipsoid_xi(A, C, theta + math.pi) == pytest.approx(xi, rel=1e-9, abs=tol)
    f = rigid.ellipsoid_force_ratio(A, C, theta)
    assert rigid.ellipsoid_force_ratio(A, C, -theta) == pytest.approx(-f, rel=1e-12, abs=1e-15)


@given(lengths, lengths, angles)
def test_gap_derivative_is_minus_lever_arm(A, C, theta):
    """dh/dθ = x_low − x_up: the normal couple M_p = −F_N dh/dθ turns the particle to lower h."""
    eps = 1e-6
    dh = (rigid.ellipsoid_gap(A, C, theta + eps) - rigid.ellipsoid_gap(A, C, theta - eps)) / (
        2 * eps
    )
    (xu, zu), (xl, zl) = rigid.ellipsoid_contact_points(A, C, theta)
    assert dh == pytest.approx(xl - xu, rel=1e-6, abs=1e-7 * max(A, C))
    assert rigid.ellipsoid_gap(A, C, theta) == pytest.approx(zu - zl, rel=1e-14)


@given(lengths, lengths)
def test_maximum_at_tan_theta_c_over_a(A, C):
    th = rigid.ellipsoid_max_xi_angle(A, C)
    assert math.tan(th) == pytest.approx(C / A, rel=1e-12)
    assert rigid.ellipsoid_xi(A, C, th) == pytest.approx(rigid.ellipsoid_max_xi(A, C), rel=1e-9)
    grid = np.linspace(-math.pi, math.pi, 2001)
    assert np.max(rigid.ellipsoid_xi(A, C, grid)) <= rigid.ellipsoid_max_xi(A, C) * (1 + 1e-12)


def test_max_xi_value():
    assert rigid.ellipsoid_max_xi(2.0, 1.0) == pytest.approx(3.0 / 4.0)
    assert rigid.ellipsoid_max_xi(1.0, 2.0) == pytest.approx(3.0 / 4.0)


@pytest.mark.parametrize(("A", "C"), [(2.0, 1.0), (1.0, 3.0), (1.0, 1.0)])
def test_xi_zero_when_axis_aligned(A, C):
    assert rigid.ellipsoid_xi(A, C, 0.0) == 0.0
    assert rigid.ellipsoid_xi(A, C, math.pi / 2) == pytest.approx(0.0, abs=1e-15)


def test_array_input():
    th = np.linspace(0, math.pi, 5)
    assert rigid.ellipsoid_xi(2.0, 1.0, th).shape == (5,)
    (xu, zu), _ = rigid.ellipsoid_contact_points(2.0, 1.0, th)
    assert xu.shape == zu.shape == (5,)


def test_xi_of_points():
    assert rigid.xi((1.0, 2.0), (0.0, 0.0)) == 0.5
    assert rigid.xi((0.0, 5.0, 2.0), (1.0, -3.0, 0.0)) == 0.5
    assert rigid.force_ratio((0.0, 2.0), (1.0, 0.0)) == -0.5
    with pytest.raises(ValueError, match="upper_point must lie above"):
        rigid.xi((0.0, 0.0), (0.0, 0.0))
    with pytest.raises(ValueError, match="lower_point"):
        rigid.xi((0.0, 1.0), (0.0, math.nan))
    with pytest.raises(ValueError, match="upper_point"):
        rigid.xi((0.0, 1.0, 2.0, 3.0), (0.0, 0.0))


# Eq 4 (μ_up = μ1, μ_low = μ2) and eq 5 (equal μ); equality counts as stick.
EQ4 = [
    (0.2, 0.3, 0.4, RigidState.STICK),
    (0.3, 0.3, 0.4, RigidState.STICK),
    (0.3, 0.4, 0.2, RigidState.ROLL_UPPER),  # μ_up > ξ > μ_low: upper sticks, lower slides
    (0.3, 0.2, 0.4, RigidState.ROLL_LOWER),  # μ_low > ξ > μ_up
    (0.4, 0.3, 0.3, RigidState.ROTATE),  # eq 5, μ < ξ
    (0.3, 0.3, 0.3, RigidState.STICK),  # eq 5, μ = ξ
    (0.1, 0.3, 0.3, RigidState.STICK),  # eq 5, μ > ξ
    (0.0, 0.0, 0.0, RigidState.STICK),
]


@pytest.mark.parametrize(("xi", "mu_up", "mu_low", "state"), EQ4)
def test_classify_table(xi, mu_up, mu_low, state):
    assert rigid.classify(xi, mu_up, mu_low) is state
    assert rigid.classify(xi, mu_up, mu_low, classification="paper") is state


def test_classify_both_exceeded_unequal_mu():
    # The paper's eq 4 says rotation; statics (eq 1: equal |T| at both contacts) says the
    # lower-friction contact slides and the particle rolls about the other one.
    assert rigid.classify(0.5, 0.2, 0.4, classification="paper") is RigidState.ROTATE
    assert rigid.classify(0.5, 0.2, 0.4) is RigidState.ROLL_LOWER
    assert rigid.classify(0.5, 0.4, 0.2) is RigidState.ROLL_UPPER
    assert rigid.classify(0.5, 0.3, 0.3 * (1 + 1e-12)) is RigidState.ROTATE
    assert [s.value for s in RigidState] == ["stick", "roll_upper", "roll_lower", "rotate"]


@pytest.mark.parametrize(
    ("args", "kwargs", "name"),
    [
        ((-0.1, 0.3, 0.3), {}, "xi"),
        ((0.1, math.nan, 0.3), {}, "mu_up"),
        ((0.1, 0.3, -1.0), {}, "mu_low"),
        ((0.1, 0.3, 0.3), {"classification": "x"}, "classif"),
    ],
)
def test_classify_invalid(args, kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name}"):
        rigid.classify(*args, **kwargs)


# Equilibrium angle


@given(
    st.floats(min_value=1.2, max_value=6.0),
    st.floats(min_value=-math.pi, max_value=math.pi),
    st.one_of(st.just(0.0), st.floats(min_value=1e-6, max_value=0.8)),
)
@example(aspect=2.0, theta0=math.pi, mu=0.0)        # found by hypothesis in CI
def test_equilibrium_angle(aspect, theta0, mu):
    for A, C in ((aspect, 1.0), (1.0, aspect)):
        th = rigid.ellipsoid_equilibrium_angle(A, C, theta0, mu)
        xi0 = rigid.ellipsoid_xi(A, C, theta0)
        if xi0 <= mu:
            assert th == theta0
            continue
        if xi0 <= mu + 1e-12:
            # at the limit to rounding (ξ(π) is 1e-16 with μ = 0; for A < C that is the
            # unstable upright balance): staying or turning either way is right, as long as
            # it ends in equilibrium
            assert rigid.ellipsoid_xi(A, C, th) <= mu + 1e-9
            continue
        assert rigid.ellipsoid_xi(A, C, th) == pytest.approx(mu, abs=1e-9)
        # It turned in the direction of the normal couple, i.e. of the signed force ratio ...
        direction = math.copysign(1.0, rigid.ellipsoid_force_ratio(A, C, theta0))
        assert (th - theta0) * direction > 0
        # ... towards the nearest orientation with the long axis horizontal (minimum gap),
        flat = (
            round(theta0 / math.pi) * math.pi
            if A > C
            else ((math.floor(theta0 / math.pi) + 0.5) * math.pi)
        )
        assert (flat - theta0) * direction > 0
        lo, hi = sorted((theta0, flat))
        if mu == 0.0:
            assert th == flat  # only the flat orientation has ξ = 0 on the way
        else:
            assert lo < th < hi
        assert rigid.ellipsoid_gap(A, C, th) <= rigid.ellipsoid_gap(A, C, theta0)
        # ... and no earlier orientation on the way could hold it.
        path = np.linspace(theta0, th, 200)[:-1]
        assert np.all(rigid.ellipsoid_xi(A, C, path) > mu - 1e-9)


def test_equilibrium_angle_example_and_unequal_mu():
    A, C, mu = 2.0, 1.0, 0.3
    th0 = math.radians(30)  # ξ(30°) ≈ 0.74 > 0.3
    th = rigid.ellipsoid_equilibrium_angle(A, C, th0, mu)
    assert 0 < th < th0
    # tanθ = t solves 3t/(4t² + 1) = 0.3 on the branch below the maximum (t < 1/2)
    t = (3 - math.sqrt(9 - 4 * 1.2 * 0.3)) / (2 * 1.2)
    assert th == pytest.approx(math.atan(t), rel=1e-12)
    assert rigid.ellipsoid_equilibrium_angle(A, C, th0, 0.5, mu_low=0.3) == th
    assert rigid.ellipsoid_equilibrium_angle(A, C, th0, 0.3, mu_low=0.5) == th
    assert rigid.ellipsoid_equilibrium_angle(A, C, -th0, mu) == pytest.approx(-th, rel=1e-12)
    assert rigid.ellipsoid_equilibrium_angle(1.0, 1.0, th0, 0.0) == th0
    assert rigid.ellipsoid_equilibrium_angle(A, C, th0, 0.0) == pytest.approx(0.0, abs=1e-12)


def test_ellipsoid_invalid():
    with pytest.raises(ValueError, match=r"^A must"):
        rigid.ellipsoid_xi(0.0, 1.0, 0.1)
    with pytest.raises(ValueError, match=r"^C must"):
        rigid.ellipsoid_contact_points(1.0, -1.0, 0.1)
    with pytest.raises(ValueError, match=r"^mu must"):
        rigid.ellipsoid_equilibrium_angle(2.0, 1.0, 0.5, -0.1)
    with pytest.raises(ValueError, match=r"^theta0"):
        rigid.ellipsoid_equilibrium_angle(2.0, 1.0, math.inf, 0.1)


def test_classify_tolerance_and_range_boundaries():
    """μ_rtol decides when unequal coefficients count as equal (rotation) and may be 0; the
    allowed ranges include their closed ends (ξ = 0, μ = 0) and messages give the range."""
    assert rigid.classify(0.5, 0.3, 0.3001, mu_rtol=1e-3) is RigidState.ROTATE
    assert rigid.classify(0.5, 0.3, 0.3001) is RigidState.ROLL_LOWER
    assert rigid.classify(0.5, 0.3001, 0.3, mu_rtol=0.0) is RigidState.ROLL_UPPER
    assert rigid.classify(0.0, 0.0, 0.0) is RigidState.STICK
    with pytest.raises(ValueError, match=r"mu_rtol must be a finite number in \[0, inf\)"):
        rigid.classify(0.1, 0.3, 0.3, mu_rtol=-1.0)
    with pytest.raises(ValueError, match=r"xi must be a finite number in \[0, inf\)"):
        rigid.classify(-0.1, 0.3, 0.3)


def test_ellipsoid_helpers_take_scalars_to_floats_and_refuse_flat_ellipses():
    assert type(rigid.ellipsoid_xi(2.0, 1.0, 0.3)) is float
    assert type(rigid.ellipsoid_gap(2.0, 1.0, 1)) is float
    assert rigid.ellipsoid_force_ratio(2.0, 1.0, 0) == 0.0
    (x_up, z_up), _ = rigid.ellipsoid_contact_points(2.0, 1.0, 1)
    assert type(x_up) is float and z_up > 0
    with pytest.raises(ValueError, match=r"^C must be a finite number in \(0, inf\)"):
        rigid.ellipsoid_xi(1.0, 0.0, 0.1)
    with pytest.raises(ValueError, match=r"^A must be a finite number in \(0, inf\)"):
        rigid.ellipsoid_gap(-1.0, 1.0, 0.1)
    # a frictionless lower plate is allowed: the particle turns flat
    assert rigid.ellipsoid_equilibrium_angle(2.0, 1.0, 0.5, 0.3, mu_low=0.0) == \
        pytest.approx(0.0, abs=1e-12)
    assert rigid.force_ratio((0.1, 0.0, 1.0), (0.0, 0.0, 0.0)) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="upper_point must lie above lower_point"):
        rigid.force_ratio((0.0, 0.0), (0.0, 1.0))
    with pytest.raises(ValueError, match=r"^lower_point must be a finite point"):
        rigid.force_ratio((0.0, 1.0), (0.0, math.nan))
