"""Narrow phase (closest_approach) against independent computations.

* Ellipsoids in random poses, apart and overlapping: the common normal found by
  scipy.optimize.least_squares on the two parametrised surfaces (points where the normals are
  opposite and the joining segment lies along them), and for bodies apart the distance minimised
  over both surfaces by SLSQP.
* Non-convex potatoes: the result is a common normal (checked with the potato's own implicit
  function) and no vertical ray of a fine scan in the result's frame has a smaller gap.
* A tessellated ellipsoid against the analytic one (facets: agreement to the facet angle).
"""

import numpy as np
import pytest
from scipy.optimize import least_squares, minimize
from scipy.spatial.transform import Rotation

import thirdbody as tb
from thirdbody.network import Body, closest_approach, contact_frame
from thirdbody.shapes import Ellipsoid, MeshShape, Potato, Sphere, Wave

MAT = tb.Material(1e9, 0.3)


def two_bumps() -> Potato:
    """An ellipsoid (1, 0.6, 0.6) mm whose radius is modulated by 1 − 0.12 cos(2π d_x): two
    equal bumps on its upper (and lower) side at body x ≈ ±0.3 mm, 0.64 mm high, with a dip to
    0.53 mm between them. Symmetric in x, y and z, so its centroid is the wave centre."""
    return Potato((1e-3, 0.6e-3, 0.6e-3), [Wave(0.12, 2 * np.pi, 0.0, -np.pi / 2)])


def ellipsoid_point(axes, R, c, u, v):
    """World point and outward unit normal of an ellipsoid at angles (u, v)."""
    q = np.array([axes[0] * np.cos(u) * np.cos(v), axes[1] * np.sin(u) * np.cos(v),
                  axes[2] * np.sin(v)])
    normal = R @ (q / axes**2)
    return R @ q + c, normal / np.linalg.norm(normal)


def support_angles(axes, R, d):
    """Angles of the ellipsoid's support point along world direction d."""
    db = R.T @ d
    q = axes**2 * db / np.sqrt(np.sum(axes**2 * db**2))
    return np.arctan2(q[1] / axes[1], q[0] / axes[0]), np.arcsin(np.clip(q[2] / axes[2], -1, 1))


def common_normal(axa, Ra, ca, axb, Rb, cb):
    """(normal a->b, signed separation, point on a, point on b) by least squares."""
    d = (cb - ca) / np.linalg.norm(cb - ca)

    def residual(x):
        pa, na = ellipsoid_point(axa, Ra, ca, x[0], x[1])
        pb, nb = ellipsoid_point(axb, Rb, cb, x[2], x[3])
        return np.concatenate([na + nb, pb - pa - x[4] * na])

    x0 = [*support_angles(axa, Ra, d), *support_angles(axb, Rb, -d), 0.0]
    sol = least_squares(residual, x0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.abs(sol.fun).max() < 1e-12
    pa, na = ellipsoid_point(axa, Ra, ca, *sol.x[:2])
    pb, _ = ellipsoid_point(axb, Rb, cb, *sol.x[2:4])
    return na, sol.x[4], pa, pb


def distance(axa, Ra, ca, axb, Rb, cb, start):
    """Shortest distance between the two surfaces, SLSQP over both angle pairs."""
    def f(x):
        pa, _ = ellipsoid_point(axa, Ra, ca, x[0], x[1])
        pb, _ = ellipsoid_point(axb, Rb, cb, x[2], x[3])
        return float(np.sum((pb - pa) ** 2))

    sol = minimize(f, start, method="SLSQP", options={"ftol": 1e-20, "maxiter": 500})
    return np.sqrt(sol.fun)


def random_pair(rng, gap_range=(-0.05, 0.05)):
    axa, axb = rng.uniform(0.5, 1.5, 3), rng.uniform(0.5, 1.5, 3)
    Ra, Rb = Rotation.random(random_state=rng), Rotation.random(random_state=rng)
    ca = rng.normal(size=3)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    # support heights along d: the bodies touch at distance ha + hb along d if d is the normal
    ha = np.sqrt(np.sum(axa**2 * Ra.inv().apply(d) ** 2))
    hb = np.sqrt(np.sum(axb**2 * Rb.inv().apply(d) ** 2))
    cb = ca + d * (ha + hb + rng.uniform(*gap_range))
    return (axa, Ra, ca), (axb, Rb, cb)


def assert_closest(found, n, sep, pa, pb):
    """``found`` is the independent reference's common normal, separation and closest points
    (normal and points to 1e-9, separation to 1e-12; sizes ~1)."""
    np.testing.assert_allclose(found.normal, n, atol=1e-9)
    assert found.separation == pytest.approx(sep, abs=1e-12)
    np.testing.assert_allclose(found.point_a, pa, atol=1e-9)
    np.testing.assert_allclose(found.point_b, pb, atol=1e-9)


@pytest.mark.parametrize("seed", range(40))
def test_ellipsoids_against_least_squares(seed):
    """Measured over 40 poses: normal within 6e-11, separation within 2e-15, points within
    6e-11 (sizes ~1)."""
    (axa, Ra, ca), (axb, Rb, cb) = random_pair(np.random.default_rng(seed))
    a = Body(Ellipsoid(axa), MAT, Ra, ca)
    b = Body(Ellipsoid(axb), MAT, Rb, cb)
    found = closest_approach(a, b)
    n, sep, pa, pb = common_normal(axa, Ra.as_matrix(), ca, axb, Rb.as_matrix(), cb)
    assert found.converged
    # Newton's method on the surfaces' quadratic models: 6 or 7 iterations on these poses (12
    # with the gap's terms dropped from the model)
    assert found.iterations <= 8
    assert_closest(found, n, sep, pa, pb)
    np.testing.assert_allclose(found.point_b - found.point_a, found.separation * found.normal,
                               atol=1e-12)
    np.testing.assert_allclose(found.midpoint, 0.5 * (pa + pb), atol=1e-9)
    if sep > 0:     # apart: the separation is the distance between the bodies
        start = [*support_angles(axa, Ra.as_matrix(), n), *support_angles(axb, Rb.as_matrix(), -n)]
        assert found.separation == pytest.approx(
            distance(axa, Ra.as_matrix(), ca, axb, Rb.as_matrix(), cb, start), abs=1e-7)


@pytest.mark.parametrize("normal", [(0.48, -0.36, 0.8), (0.7, 0.7, 0.1414), (-0.1, 0.2, -0.97)])
def test_spheres_along_oblique_and_near_horizontal_normals(normal):
    n = np.asarray(normal) / np.linalg.norm(normal)
    a = Body(Sphere(1e-3), MAT, Rotation.random(random_state=3), (1e-3, -2e-3, 5e-4))
    b = Body(Sphere(2.5e-3), MAT, Rotation.random(random_state=4), a.centre + n * 3.49e-3)
    found = closest_approach(a, b)
    np.testing.assert_allclose(found.normal, n, atol=1e-12)
    assert found.separation == pytest.approx(-1e-5, abs=1e-15)
    np.testing.assert_allclose(found.point_a, a.centre + 1e-3 * n, atol=1e-15)
    np.testing.assert_allclose(found.point_b, b.centre - 2.5e-3 * n, atol=1e-15)
    # exchanging the bodies flips the normal
    back = closest_approach(b, a)
    np.testing.assert_allclose(back.normal, -n, atol=1e-12)
    assert back.separation == pytest.approx(found.separation, abs=1e-15)


def vertical_gap_min(a, b, frame, origin, half_width, n_rays):
    """Smallest vertical gap on a square scan in a frame, straight from Shape.surfaces."""
    s = np.linspace(-half_width, half_width, n_rays)
    X, Y = np.meshgrid(s, s)
    out = []
    for body in (a, b):
        c = frame.apply(body.centre - origin)
        lo, up = body.shape.surfaces(frame * body.rotation, X - c[0], Y - c[1])
        out.append((lo + c[2], up + c[2]))
    gap = out[1][0] - out[0][1]
    return float(np.nanmin(gap))


def implicit_normal(shape, body, point, h=1e-9):
    """Outward unit normal from the potato's implicit function (central differences)."""
    q = body.rotation.inv().apply(point - body.centre)
    grad = np.array([(shape.implicit(q + e) - shape.implicit(q - e)) / (2 * h)
                     for e in np.eye(3) * h])
    n = body.rotation.apply(grad)
    return n / np.linalg.norm(n)


@pytest.mark.parametrize("seed", range(4))
def test_potatoes_common_normal_and_deepest_minimum(seed):
    rng = np.random.default_rng(100 + seed)
    shape_a = Potato((1.0e-3, 0.8e-3, 0.7e-3), seed=4, amplitude=0.1, wavenumber_range=(4, 8))
    shape_b = Potato((0.8e-3, 0.7e-3, 0.5e-3), seed=int(rng.integers(1000)), amplitude=0.08)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    a = Body(shape_a, MAT, Rotation.random(random_state=rng), (0, 0, 0))
    frame = contact_frame(d)
    # place b where the vertical gap along d is about 1 % of the size (a scan of the test's own)
    b = Body(shape_b, MAT, Rotation.random(random_state=rng), d * 1.6e-3)
    g = vertical_gap_min(a, b, frame, 0.5 * b.centre, 1e-3, 81)
    b = b.moved(centre=b.centre - d * (g - 1e-5))
    found = closest_approach(a, b)
    assert found.converged
    # a common normal: both surfaces' own normals are ±n at the points on them
    assert shape_a.implicit(a.rotation.inv().apply(found.point_a - a.centre)) == \
        pytest.approx(0, abs=1e-11)
    assert shape_b.implicit(b.rotation.inv().apply(found.point_b - b.centre)) == \
        pytest.approx(0, abs=1e-11)
    np.testing.assert_allclose(implicit_normal(shape_a, a, found.point_a), found.normal,
                               atol=1e-8)
    np.testing.assert_allclose(implicit_normal(shape_b, b, found.point_b), -found.normal,
                               atol=1e-8)
    # the deepest: no ray of a fine scan in the found frame has a smaller gap
    scan = vertical_gap_min(a, b, found.frame, found.midpoint, 8e-4, 161)
    assert scan >= found.separation - 1e-12
    assert found.separation < 2e-5


def test_the_deeper_of_two_minima_is_found_from_a_misleading_start():
    """A body with two bumps under a sphere placed 20 µm off centre: the bump on its side is
    3 µm closer. Started from a normal tilted towards the other bump, the local search ends on
    that one (4.40e-5 m apart); the rescan in its frame finds the deeper (4.10e-5 m). The whole
    pair is turned by a random rotation."""
    R = Rotation.random(random_state=11)
    shift = np.array([1e-3, -2e-3, 0.5e-3])
    a = Body(two_bumps(), MAT, R, shift)
    b = Body(Sphere(4e-3), MAT, R, R.apply([2e-5, 0, 4.67055e-3]) + shift)
    plain = closest_approach(a, b)
    misled = closest_approach(a, b, normal=R.apply([0.6, 0.0, 1.0]))
    assert plain.separation == pytest.approx(4.100e-5, rel=1e-3)
    assert misled.separation == pytest.approx(plain.separation, abs=1e-15)
    np.testing.assert_allclose(misled.point_a, plain.point_a, atol=1e-12)
    assert R.inv().apply(plain.point_a - shift)[0] > 0     # the bump on the sphere's side


@pytest.mark.parametrize("seed", range(6))
def test_a_start_near_the_contact_finds_the_same_closest_points(seed):
    """Started at a point 1 % of the size off the reference midpoint, with a normal 0.01 rad off
    (the cluster solver's warm start from the last pass), the search skips the scan and ends on
    the least-squares common normal within the tolerances of the scan's start, in at most 4
    iterations (measured 3 to 4; 6 to 7 from the scan)."""
    rng = np.random.default_rng(100 + seed)
    (axa, Ra, ca), (axb, Rb, cb) = random_pair(rng)
    a = Body(Ellipsoid(axa), MAT, Ra, ca)
    b = Body(Ellipsoid(axb), MAT, Rb, cb)
    n, sep, pa, pb = common_normal(axa, Ra.as_matrix(), ca, axb, Rb.as_matrix(), cb)
    guess = n + 0.01 * np.cross(n, rng.normal(size=3) / np.sqrt(3))
    near = 0.5 * (pa + pb) + 0.01 * min(axa.max(), axb.max()) * rng.normal(size=3) / np.sqrt(3)
    found = closest_approach(a, b, normal=guess, near=near)
    assert found.converged
    assert found.iterations <= 4
    assert_closest(found, n, sep, pa, pb)


def test_a_start_near_the_shallower_of_two_minima_still_finds_the_deeper():
    """The two bumps of test_the_deeper_of_two_minima_is_found_from_a_misleading_start, started
    at the closest points on the shallower bump: a non-convex body is rescanned after the local
    search, which finds the deeper one."""
    R = Rotation.random(random_state=11)
    shift = np.array([1e-3, -2e-3, 0.5e-3])
    a = Body(two_bumps(), MAT, R, shift)
    b = Body(Sphere(4e-3), MAT, R, R.apply([2e-5, 0, 4.67055e-3]) + shift)
    plain = closest_approach(a, b)
    # the shallower minimum: the misleading start's local search alone (no rescan)
    shallow = closest_approach(a, b, normal=R.apply([0.6, 0.0, 1.0]),
                               near=R.apply([-3e-4, 0.0, 0.64e-3]) + shift)
    assert plain.separation == pytest.approx(4.100e-5, rel=1e-3)
    assert shallow.separation == pytest.approx(plain.separation, abs=1e-15)
    np.testing.assert_allclose(shallow.point_a, plain.point_a, atol=1e-12)


def test_mesh_against_the_ellipsoid_it_tessellates():
    """Facets of ~4e-5 m on semi-axes of 1e-3 m: the normal within 1e-2 rad of the analytic
    one (measured 5e-3), the separation within 1e-6 m (measured 5e-7)."""
    rng = np.random.default_rng(7)
    ellipsoid = Ellipsoid((1.0e-3, 0.7e-3, 0.5e-3))
    mesh = MeshShape.from_shape(ellipsoid, subdivisions=5)
    (_, Ra, ca), (_, Rb, cb) = random_pair(rng, (1e-4, 1e-4))
    ca, cb = ca * 1e-3, ca * 1e-3 + (cb - ca) * 0.8e-3
    exact = closest_approach(Body(ellipsoid, MAT, Ra, ca), Body(ellipsoid, MAT, Rb, cb))
    faceted = closest_approach(Body(ellipsoid, MAT, Ra, ca), Body(mesh, MAT, Rb, cb))
    np.testing.assert_allclose(faceted.normal, exact.normal, atol=1e-2)
    assert faceted.separation == pytest.approx(exact.separation, abs=1e-6)


def test_far_apart_gives_none_and_bad_input_raises():
    a = Body(Sphere(1.0), MAT)
    assert closest_approach(a, Body(Sphere(1.0), MAT, centre=(0, 0, 2.01))) is None
    assert closest_approach(a, Body(Sphere(1.0), MAT, centre=(0, 0, 2.0))).separation == \
        pytest.approx(0.0, abs=1e-15)
    with pytest.raises(TypeError, match="Body"):
        closest_approach(a, Sphere(1.0))
    with pytest.raises(ValueError, match="tol"):
        closest_approach(a, a, tol=0)
