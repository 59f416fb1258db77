"""Influence coefficients against numerical quadrature of the point solutions, and parities."""

import numpy as np
import pytest
from scipy import integrate

from thirdbody.bem import influence

HALF_X, HALF_Y = 0.5, 0.7
G, NU = 0.8, 0.3
E_STAR = 2 * G / (1 - NU)

# Boussinesq and Cerruti point solutions at the surface (Johnson 1985, eqs 3.19, 3.86a):
# offsets (X, Y) from the source, unit force.
POINT = {
    "zz": lambda X, Y: (1 - NU) / (2 * np.pi * G * np.hypot(X, Y)),
    "xx": lambda X, Y: ((1 - NU) / np.hypot(X, Y) + NU * X**2 / np.hypot(X, Y) ** 3)
    / (2 * np.pi * G),
    "yy": lambda X, Y: ((1 - NU) / np.hypot(X, Y) + NU * Y**2 / np.hypot(X, Y) ** 3)
    / (2 * np.pi * G),
    "xy": lambda X, Y: NU * X * Y / np.hypot(X, Y) ** 3 / (2 * np.pi * G),
    "zx": lambda X, Y: (1 - 2 * NU) * X / (X**2 + Y**2) / (4 * np.pi * G),
    "zy": lambda X, Y: (1 - 2 * NU) * Y / (X**2 + Y**2) / (4 * np.pi * G),
}


def closed_form(name, x, y):
    kxx, kxy, kyy = influence.tangential(x, y, HALF_X, HALF_Y, G, NU)
    return {
        "zz": influence.normal(x, y, HALF_X, HALF_Y, E_STAR),
        "xx": kxx, "yy": kyy, "xy": kxy,
        "zx": influence.coupling(x, y, HALF_X, HALF_Y, G, NU),
        # the operator's K_zy: H_x with the roles of x and y exchanged
        "zy": (1 - 2 * NU) * influence.coupling_integral(y, x, HALF_Y, HALF_X) / (4 * np.pi * G),
    }[name]


def quadrature(name, x, y):
    f = POINT[name]
    return integrate.dblquad(lambda t, s: f(x - s, y - t), -HALF_X, HALF_X, -HALF_Y, HALF_Y,
                             epsabs=0, epsrel=1e-13)[0]


FIELD_POINTS = [(2.3, 1.1), (0.5, 3.0), (-4.0, 0.3), (1.7, -2.2), (0.2, 1.9), (-3.1, -5.4)]


@pytest.mark.parametrize("name", sorted(POINT))
@pytest.mark.parametrize("point", FIELD_POINTS)
def test_coefficients_match_quadrature(name, point):
    exact = quadrature(name, *point)
    assert closed_form(name, *point) == pytest.approx(exact, rel=1e-10, abs=1e-14)


def test_self_terms_of_a_square_cell():
    h = 0.37
    c = np.log(1 + np.sqrt(2))
    assert influence.normal(0.0, 0.0, h / 2, h / 2, E_STAR) == pytest.approx(
        4 * h * c / (np.pi * E_STAR), rel=1e-14)
    kxx, kxy, kyy = influence.tangential(0.0, 0.0, h / 2, h / 2, G, NU)
    assert kxx == pytest.approx((2 - NU) * h * c / (np.pi * G), rel=1e-14)
    assert kyy == pytest.approx(kxx, rel=1e-14)
    assert kxy == 0.0


def test_values_on_cell_edge_lines_are_finite_and_continuous():
    # k, l, m or n = 0 exactly: the logarithms of the textbook form read 0/0 here
    for x, y in [(HALF_X, 0.0), (0.0, HALF_Y), (HALF_X, HALF_Y), (3 * HALF_X, HALF_Y)]:
        for name in POINT:
            v = closed_form(name, x, y)
            near = closed_form(name, x + 1e-9, y + 1e-9)
            assert np.isfinite(v)
            assert v == pytest.approx(near, rel=1e-6, abs=1e-8)


def test_parities():
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=(2, 50)) * 3
    for name, (px, py) in {"zz": (1, 1), "xx": (1, 1), "yy": (1, 1), "xy": (-1, -1),
                           "zx": (-1, 1)}.items():
        v = closed_form(name, x, y)
        np.testing.assert_allclose(closed_form(name, -x, y), px * v, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(closed_form(name, x, -y), py * v, rtol=1e-12, atol=1e-15)


def test_operator_is_the_exact_linear_convolution():
    from thirdbody.bem import normal_operator, tangential_operator

    rng = np.random.default_rng(0)
    ny, nx, dx, dy = 6, 9, 0.3, 0.5
    p = rng.random((ny, nx))
    t = rng.random((2, ny, nx))
    X, Y = np.meshgrid(np.arange(nx) * dx, np.arange(ny) * dy)
    u = np.zeros((ny, nx))
    ut = np.zeros((2, ny, nx))
    for j in range(ny):
        for i in range(nx):
            u += p[j, i] * influence.normal(X - i * dx, Y - j * dy, dx / 2, dy / 2, E_STAR)
            kxx, kxy, kyy = influence.tangential(X - i * dx, Y - j * dy, dx / 2, dy / 2, G, NU)
            ut[0] += kxx * t[0, j, i] + kxy * t[1, j, i]
            ut[1] += kxy * t[0, j, i] + kyy * t[1, j, i]
    np.testing.assert_allclose(normal_operator((ny, nx), (dx, dy), E_STAR)(p), u, rtol=1e-12)
    np.testing.assert_allclose(tangential_operator((ny, nx), (dx, dy), G, NU)(t), ut,
                               rtol=1e-12, atol=1e-14 * np.abs(ut).max())


def test_the_operator_caches_are_bounded_by_count_and_bytes(monkeypatch):
    """Operators are kept by their arguments, least recently used dropped first, within a count
    and a byte budget (the arrays of a 40 x 40 normal operator: its padded spectrum, counted
    here from the array sizes independently of the cache's own count)."""
    from thirdbody.bem import operator as op

    cache = op._Cache(op.NormalOperator)
    one = cache((40, 40), (1e-6, 1e-6), 1e9)
    size = sum(v.nbytes for v in vars(one).values() if isinstance(v, np.ndarray))
    assert size > 0 and cache.nbytes >= size
    assert cache((40, 40), (1e-6, 1e-6), 1e9) is one                     # a hit
    monkeypatch.setattr(op, "_OPERATOR_BYTES", 2.5 * cache.nbytes)       # room for two
    two = cache((40, 40), (2e-6, 2e-6), 1e9)
    cache((40, 40), (1e-6, 1e-6), 1e9)                                   # one used last
    cache((40, 40), (3e-6, 3e-6), 1e9)                                   # evicts two
    assert len(cache.items) == 2 and cache.nbytes <= op._OPERATOR_BYTES
    assert cache((40, 40), (1e-6, 1e-6), 1e9) is one
    assert cache((40, 40), (2e-6, 2e-6), 1e9) is not two                 # rebuilt
    monkeypatch.setattr(op, "_OPERATORS", 1)                             # count bound
    cache((40, 40), (4e-6, 4e-6), 1e9)
    assert len(cache.items) == 1
    monkeypatch.setattr(op, "_OPERATOR_BYTES", 1)                        # too large to keep
    big = cache((40, 40), (5e-6, 5e-6), 1e9)
    assert big is not cache((40, 40), (5e-6, 5e-6), 1e9)
