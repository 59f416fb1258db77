"""Hertz reference solutions against FORMULAS.md numbers, limits and force balance."""

import math

import numpy as np
import pytest
from scipy import integrate
from scipy.special import ellipe, ellipk

from thirdbody.reference import hertz

E_STAR = 1.0 / (1.0 - 0.3**2)  # E = 1, ν = 0.3, rigid counter-face


def test_elliptic_reference_numbers():
    r = hertz.elliptic_from_radii(0.05, 2.0, 0.5, E_STAR)
    assert round(r.eccentricity_squared, 5) == 0.84009
    assert round(r.semi_axis_x, 5) == 0.50007
    assert round(r.semi_axis_y, 5) == 0.19997
    assert round(r.peak_pressure, 6) == 0.238734
    assert round(r.approach, 7) == 0.1025056


def test_elliptic_satisfies_classical_legendre_form():
    """The Carlson form used internally solves the textbook K, E equation."""
    A, B, W = 0.3, 2.1, 0.7
    r = hertz.elliptic(W, A, B, E_STAR)
    m = r.eccentricity_squared
    K, E = ellipk(m), ellipe(m)
    assert (E / (1 - m) - K) / (K - E) == pytest.approx(B / A, rel=1e-12)
    a3 = 3 * W * (K - E) / (2 * math.pi * E_STAR * A * m)
    assert r.semi_axis_x == pytest.approx(a3 ** (1 / 3), rel=1e-12)
    assert r.semi_axis_y == pytest.approx(r.semi_axis_x * math.sqrt(1 - m), rel=1e-12)
    assert r.approach == pytest.approx(r.peak_pressure * r.semi_axis_y * K / E_STAR, rel=1e-12)


@pytest.mark.parametrize("R", [0.01, 0.5, 3.0])
@pytest.mark.parametrize("W", [1e-3, 1.0, 250.0])
def test_sphere_limit_of_elliptic(R, W):
    s = hertz.sphere(W, R, E_STAR)
    e = hertz.elliptic_from_radii(W, R, R, E_STAR)
    assert e.eccentricity_squared == 0.0
    for got in (e.semi_axis_x, e.semi_axis_y):
        assert got == pytest.approx(s.contact_radius, rel=1e-10)
    assert e.approach == pytest.approx(s.approach, rel=1e-10)
    assert e.peak_pressure == pytest.approx(s.peak_pressure, rel=1e-10)
    # Nearly equal curvatures approach the sphere continuously.
    n = hertz.elliptic_from_radii(W, R, R * (1 + 1e-9), E_STAR)
    assert n.approach == pytest.approx(s.approach, rel=1e-8)


def test_sphere_formulas_and_displacement_control():
    s = hertz.sphere(2.0, 0.1, 3.0)
    assert s.contact_radius**3 == pytest.approx(3 * 2.0 * 0.1 / (4 * 3.0), rel=1e-14)
    assert s.approach == pytest.approx(s.contact_radius**2 / 0.1, rel=1e-14)
    d = hertz.sphere_from_approach(s.approach, 0.1, 3.0)
    assert d.normal_force == pytest.approx(2.0, rel=1e-12)
    assert d.contact_radius == pytest.approx(s.contact_radius, rel=1e-12)
    assert s.pressure(0.0) == s.peak_pressure
    assert s.pressure(s.contact_radius * 1.01) == 0.0
    assert s.pressure(np.array([0.0, 2 * s.contact_radius])).shape == (2,)


def test_sphere_force_balance():
    s = hertz.sphere(0.3, 1.5, E_STAR)
    total, _ = integrate.quad(
        lambda r: 2 * math.pi * r * s.pressure(r), 0, s.contact_radius, epsabs=0, epsrel=1e-13
    )
    assert total == pytest.approx(0.3, rel=1e-8)


@pytest.mark.parametrize(("A", "B"), [(0.25, 1.0), (1.0, 0.25), (0.7, 0.7), (1.0, 30.0)])
def test_elliptic_force_balance(A, B):
    W = 0.05
    r = hertz.elliptic(W, A, B, E_STAR)
    ax, ay = r.semi_axis_x, r.semi_axis_y

    def strip(x):
        half = ay * math.sqrt(max(0.0, 1 - (x / ax) ** 2))
        val, _ = integrate.quad(lambda y: r.pressure(x, y), -half, half, epsabs=0, epsrel=1e-13)
        return val

    total, _ = integrate.quad(strip, -ax, ax, epsabs=0, epsrel=1e-12, limit=200)
    assert total == pytest.approx(W, rel=1e-8)


def test_swap_exchanges_axes():
    r1 = hertz.elliptic(0.05, 0.25, 1.0, E_STAR)
    r2 = hertz.elliptic(0.05, 1.0, 0.25, E_STAR)
    assert r1.semi_axis_x > r1.semi_axis_y
    assert r2.semi_axis_x == pytest.approx(r1.semi_axis_y, rel=1e-14)
    assert r2.semi_axis_y == pytest.approx(r1.semi_axis_x, rel=1e-14)
    assert r2.approach == pytest.approx(r1.approach, rel=1e-14)
    assert r2.peak_pressure == pytest.approx(r1.peak_pressure, rel=1e-14)
    x, y = 0.1, 0.05
    assert r2.pressure(y, x) == pytest.approx(r1.pressure(x, y), rel=1e-13)


def test_slender_contact_is_solved():
    r = hertz.elliptic(1.0, 1.0, 1e10, 1.0)
    m = r.eccentricity_squared
    assert 0.0 < 1.0 - m < 1e-10
    assert r.semi_axis_x > r.semi_axis_y > 0


def test_pressure_shape():
    r = hertz.elliptic(0.05, 0.25, 1.0, E_STAR)
    assert r.pressure(0.0, 0.0) == r.peak_pressure
    assert r.pressure(r.semi_axis_x, 0.0) == 0.0
    assert r.pressure(0.0, 1.01 * r.semi_axis_y) == 0.0
    xs = np.linspace(-1, 1, 5)[:, None]
    ys = np.linspace(-1, 1, 3)[None, :]
    assert r.pressure(xs, ys).shape == (5, 3)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, "x", None])
def test_invalid_inputs_raise(bad):
    with pytest.raises(ValueError, match="force"):
        hertz.sphere(bad, 1.0, 1.0)
    with pytest.raises(ValueError, match="radius"):
        hertz.sphere(1.0, bad, 1.0)
    with pytest.raises(ValueError, match="E_star"):
        hertz.sphere(1.0, 1.0, bad)
    with pytest.raises(ValueError, match="approach"):
        hertz.sphere_from_approach(bad, 1.0, 1.0)
    with pytest.raises(ValueError, match="A must"):
        hertz.elliptic(1.0, bad, 1.0, 1.0)
    with pytest.raises(ValueError, match="B must"):
        hertz.elliptic(1.0, 1.0, bad, 1.0)
    with pytest.raises(ValueError, match="R_y"):
        hertz.elliptic_from_radii(1.0, 1.0, bad, 1.0)
