"""The search for a stable orientation and the turn kinematics, on analytic couples.

Each test gives the search a couple F'(R)/F_N written in closed form (no contact solves), so the
first stable orientation along the turn is known exactly: the tests check the search lands on
it within its bisection tolerance, from the turning side."""

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from thirdbody.particle.statics import Evaluation
from thirdbody.particle.turning import TurningError, find_stable_orientation, turn_kinematics
from thirdbody.rigid import RigidState

STEP, TOL = math.radians(1.0), math.radians(0.01)


def evaluator(field, force=1.0):
    """evaluate(R) with F_N = ``force`` (N) and F'(R)/F_N = field(R); no contact fields."""
    calls = []

    def evaluate(rotation):
        calls.append(rotation)
        return Evaluation(rotation, force, 1.0, None, None,
                          force * np.asarray(field(rotation), float))

    return evaluate, calls


def theta_of(rotation):
    """Angle about +y of a rotation about y (rad)."""
    v = rotation.as_rotvec()
    assert abs(v[0]) < 1e-12 and abs(v[2]) < 1e-12
    return float(v[1])


def tilt_of(rotation):
    """Tilt angle of the body z axis from the vertical (rad)."""
    b = rotation.apply([0.0, 0.0, 1.0])
    return math.atan2(math.hypot(b[0], b[1]), b[2])


def about_y(theta_deg):
    return Rotation.from_rotvec([0.0, math.radians(theta_deg), 0.0])


def planar(fx):
    """A couple along x that depends on θ only: F'_x > 0 turns the particle towards +θ."""
    return lambda r: (fx(theta_of(r)), 0.0)


def start(evaluate, rotation):
    return evaluate(rotation)


def test_turns_to_the_friction_limit_of_a_restoring_couple():
    """F' = −sin(tilt)·(tilt direction): stable where sin(tilt) <= μ, reached from above."""
    mu = 0.3
    evaluate, calls = evaluator(lambda r: -r.apply([0.0, 0.0, 1.0])[:2])
    turn = find_stable_orientation(start(evaluate, about_y(40.0)), evaluate, mu, STEP, TOL)
    assert turn.evaluations == len(calls)              # the start included
    edge = math.asin(mu)
    assert edge - TOL <= theta_of(turn.final.rotation) <= edge
    assert turn.final.demand <= mu and not turn.balanced
    thetas = [theta_of(e.rotation) for e in turn.path]
    assert thetas[0] == pytest.approx(math.radians(40.0))
    assert all(b < a for a, b in itertools.pairwise(thetas))   # always towards 0
    assert all(e.demand > mu for e in turn.path)                          # none was stable


def test_a_stable_band_narrower_than_the_march_step_is_not_stepped_over():
    """The issue's case in closed form: F'_x = −15 θ (an ellipsoid near lying flat), μ = 0.1:
    stable for |θ| <= 0.382°, between the march points 0.5° and −0.5° from θ₀ = 7.5°."""
    mu, k = 0.1, 15.0
    evaluate, _ = evaluator(planar(lambda t: -k * t))
    for theta0 in (7.5, 7.0):
        turn = find_stable_orientation(start(evaluate, about_y(theta0)), evaluate, mu, STEP,
                                       TOL)
        edge = mu / k
        assert edge - TOL <= theta_of(turn.final.rotation) <= edge
        assert not turn.balanced


def test_without_friction_the_particle_turns_to_the_balance():
    """μ = 0: the only stable orientation is where the couple vanishes."""
    evaluate, _ = evaluator(planar(lambda t: -3.0 * math.sin(2 * (t - 0.1))))
    turn = find_stable_orientation(start(evaluate, about_y(40.0)), evaluate, 0.0, STEP, TOL)
    assert theta_of(turn.final.rotation) == pytest.approx(0.1, abs=1e-8)
    assert turn.balanced and turn.final.demand < 1e-7


@pytest.mark.parametrize("theta0, centre_deg", [(0.0, 3.3), (-4.0, 3.3), (-4.0, 2.7)])
def test_a_dip_of_the_couple_between_march_points_is_found(theta0, centre_deg):
    """F'_x = 0.5 − 0.45 exp(−((θ − θ_d)/0.5°)²), μ = 0.1: never reverses, and the only stable
    orientations, |θ − θ_d| <= 0.172°, lie between two march points: after the local minimum of
    the samples (θ_d = 3.3°) or before it (2.7°: the particle never reaches the 3° sample).
    From θ₀ = −4° the dip is met after a longer march."""
    mu, centre, width = 0.1, math.radians(centre_deg), math.radians(0.5)
    evaluate, calls = evaluator(planar(
        lambda t: 0.5 - 0.45 * math.exp(-(((t - centre) / width) ** 2))))
    turn = find_stable_orientation(start(evaluate, about_y(theta0)), evaluate, mu, STEP, TOL)
    assert turn.evaluations == len(calls)
    edge = centre - width * math.sqrt(math.log(0.45 / 0.4))
    assert edge <= theta_of(turn.final.rotation) <= edge + TOL
    assert turn.final.demand <= mu
    thetas = [theta_of(e.rotation) for e in turn.path]
    assert max(thetas) < edge                      # the path ends before the band


def test_the_turn_axis_follows_a_couple_that_is_not_along_the_tilt():
    """F' = −R_z(30°)·(tilt direction)·sin(tilt): the axis is recomputed at every orientation
    and the path leaves the plane of the first turn; it still stops at the first orientation
    with sin(tilt) <= μ, within the bisection tolerance."""
    mu, twist = 0.25, Rotation.from_rotvec([0.0, 0.0, math.radians(30.0)])
    evaluate, _ = evaluator(lambda r: -twist.apply(r.apply([0.0, 0.0, 1.0]) * [1, 1, 0])[:2])
    turn = find_stable_orientation(start(evaluate, Rotation.from_rotvec([0.3, 0.6, 0.0])),
                                   evaluate, mu, STEP, TOL)
    edge = math.asin(mu)
    assert edge - 1.01 * TOL <= tilt_of(turn.final.rotation) <= edge
    axes = [e.axis for e in turn.path]
    assert min(float(a @ axes[0]) for a in axes) < math.cos(math.radians(5))   # it curved
    for a, b in zip(turn.path, turn.path[1:], strict=False):
        step = (b.rotation * a.rotation.inv()).as_rotvec()
        assert abs(step[2]) < 1e-12                 # every leg about a horizontal axis


def test_a_couple_that_never_weakens_is_refused():
    """A full turn of 1° legs (360 of them, plus the start) without a stable orientation."""
    evaluate, calls = evaluator(lambda r: (0.5, 0.0))
    with pytest.raises(TurningError, match="no stable orientation within 360°"):
        find_stable_orientation(start(evaluate, about_y(0.0)), evaluate, 0.3, STEP, TOL)
    assert len(calls) == 361


def test_a_couple_exactly_at_the_friction_limit_sticks():
    """|F'| = μ F_N counts as stick (the particle turns only if the demand exceeds μ, eq 10):
    F'_x = 0.3 + 5 (θ₁ − θ) below θ₁ = 2.5° and exactly 0.3 from there on."""
    mu, theta1 = 0.3, math.radians(2.5)
    evaluate, _ = evaluator(planar(lambda t: mu + 5.0 * max(theta1 - t, 0.0)))
    turn = find_stable_orientation(start(evaluate, about_y(0.0)), evaluate, mu, STEP, TOL)
    assert theta1 <= theta_of(turn.final.rotation) <= theta1 + TOL
    assert turn.final.demand == mu


def test_a_stable_band_narrower_than_the_bisection_tolerance_is_its_zero():
    """F'_x = −15 (θ − 0.123°) with μ = 1e-5: stable only within 4e-5° of 0.123°, far less
    than the 0.01° bisection tolerance; the bisection ends on a reversed, unstable orientation
    and the zero of the couple (found by the Illinois method) is stable: it sticks there, no
    balance."""
    mu, k, zero = 1e-5, 15.0, math.radians(0.123)
    evaluate, _ = evaluator(planar(lambda t: -k * (t - zero)))
    turn = find_stable_orientation(start(evaluate, about_y(7.5)), evaluate, mu, STEP, TOL)
    assert abs(theta_of(turn.final.rotation) - zero) <= mu / k
    assert turn.final.demand <= mu and not turn.balanced


def test_without_friction_a_twisted_couple_is_followed_to_its_balance():
    """μ = 0 and F' = −R_z(30°)·(tilt direction)·sin(tilt): the couple along each leg vanishes
    where the part across it does not, so the search turns on about new axes from each zero
    until the couple vanishes altogether, upright."""
    twist = Rotation.from_rotvec([0.0, 0.0, math.radians(30.0)])
    evaluate, _ = evaluator(lambda r: -twist.apply(r.apply([0.0, 0.0, 1.0]) * [1, 1, 0])[:2],
                            force=3.0)
    turn = find_stable_orientation(start(evaluate, Rotation.from_rotvec([0.3, 0.6, 0.0])),
                                   evaluate, 0.0, STEP, TOL)
    # balanced to what the last bracket resolves: within the bisection tolerance of upright
    assert tilt_of(turn.final.rotation) < TOL and turn.balanced
    for a, b in zip(turn.path, turn.path[1:], strict=False):
        step = (b.rotation * a.rotation.inv()).as_rotvec()
        assert abs(step[2]) < 1e-12


def test_a_near_miss_dip_is_searched_and_the_march_goes_on():
    """A dip down to 0.12 (μ = 0.1) between march points is suspected and searched, holds no
    stable orientation, and the particle turns on to where the couple falls below μ for good
    (θ > 10°)."""
    mu, centre, width = 0.1, math.radians(3.3), math.radians(0.5)
    evaluate, _ = evaluator(planar(
        lambda t: 0.5 - 0.38 * math.exp(-(((t - centre) / width) ** 2))
        - 0.45 * (t > math.radians(10.0))))
    turn = find_stable_orientation(start(evaluate, about_y(0.0)), evaluate, mu, STEP, TOL)
    assert math.radians(10.0) <= theta_of(turn.final.rotation) <= math.radians(10.0) + TOL
    thetas = [theta_of(e.rotation) for e in turn.path]
    assert thetas == sorted(thetas) and len(thetas) >= 10


def test_the_couple_along_a_turn_is_scaled_by_the_normal_force():
    """drive = F'·(unit F' of the reference)/F_N (dimensionless)."""
    ref = Evaluation(about_y(0.0), 2.0, 1.0, None, None, np.array([3.0, 4.0]))
    other = Evaluation(about_y(0.0), 4.0, 1.0, None, None, np.array([1.0, 2.0]))
    assert other.drive(ref) == pytest.approx((0.6 * 1.0 + 0.8 * 2.0) / 4.0, rel=1e-15)
    np.testing.assert_allclose(ref.axis, [-0.8, 0.6])
    assert ref.demand == pytest.approx(2.5)


def node(theta_deg, top, bottom):
    """A fake evaluation at θ about y with the plates at heights ``top`` and ``bottom``."""
    return SimpleNamespace(rotation=about_y(theta_deg), up=SimpleNamespace(plate=top),
                           low=SimpleNamespace(plate=bottom))


@pytest.mark.parametrize("kind, position, up, low", [
    (RigidState.ROTATE, 0.0, 1.0, -1.0),        # pivot at the centroid
    (RigidState.ROLL_LOWER, 1.0, 2.0, 0.0),     # pivot on the lower plate
    (RigidState.ROLL_UPPER, -1.0, 0.0, -2.0),   # pivot on the upper plate
])
def test_kinematics_of_a_turn_about_y(kind, position, up, low):
    """Plates at z = ±S: turning by Δθ about +y moves a point at height z by Δθ (z − z_P)
    along x (in units of Δθ·S here)."""
    S, total = 2e-4, math.radians(-6.0)
    nodes = [node(t, S, -S) for t in np.linspace(0.0, -6.0, 7)]
    moved = turn_kinematics(nodes, lambda ev: kind)
    np.testing.assert_allclose(moved.position, [position * total * S, 0.0], atol=1e-18)
    np.testing.assert_allclose(moved.slip_up, [up * total * S, 0.0], atol=1e-18)
    np.testing.assert_allclose(moved.slip_low, [low * total * S, 0.0], atol=1e-18)


def test_kinematics_about_an_oblique_axis_turn_the_displacements_with_it():
    """The same turn about the horizontal axis at azimuth φ: the displacements are those of
    the turn about y, turned by φ − 90° about z."""
    S, angle, phi = 3e-4, math.radians(5.0), math.radians(35.0)
    axis = np.array([math.cos(phi), math.sin(phi), 0.0])
    nodes = [SimpleNamespace(rotation=Rotation.from_rotvec(axis * t),
                             up=SimpleNamespace(plate=S), low=SimpleNamespace(plate=-S))
             for t in np.linspace(0.0, angle, 4)]
    moved = turn_kinematics(nodes, lambda ev: RigidState.ROLL_LOWER)
    direction = np.array([axis[1], -axis[0]])        # e.g. +x for a turn about +y
    np.testing.assert_allclose(moved.position, direction * angle * S, rtol=1e-12)
    np.testing.assert_allclose(moved.slip_up, direction * angle * 2 * S, rtol=1e-12)
    np.testing.assert_allclose(moved.slip_low, 0.0, atol=1e-20)
