"""Tests of thirdbody.shapes: vertical ray geometry of spheres, ellipsoids, potatoes and meshes.

Lengths in metres; particles of millimetre size, so "1e-12·size" tolerances are ~1e-15 m.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thirdbody.shapes import (
    MAX_TOTAL_AMPLITUDE,
    Ellipsoid,
    MeshShape,
    Potato,
    Shape,
    Sphere,
    Wave,
    rotate_to_body,
    rotate_to_world,
)

MM = 1e-3
A, B, C = 3.0 * MM, 2.0 * MM, 1.0 * MM


def grid(half: float, n: int = 81) -> tuple[np.ndarray, np.ndarray]:
    x = np.linspace(-half, half, n)
    return np.meshgrid(x, x, indexing="ij")


def exact_upright_gap(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Gap of the upright ellipsoid (A, B, C): C(1 − √(1 − s)) written without cancellation."""
    s = (x / A) ** 2 + (y / B) ** 2
    with np.errstate(invalid="ignore"):
        g = C * s / (1.0 + np.sqrt(1.0 - s))
    return np.where(s <= 1.0, g, np.inf)


@pytest.fixture(scope="module")
def potato() -> Potato:
    return Potato((2.0 * MM, 1.5 * MM, 1.2 * MM), seed=7)


# --- conventions --------------------------------------------------------------------------------


def test_rotation_convention() -> None:
    # A body point on +x turns down (towards −z) for θ > 0: rotation about +y, right-hand rule.
    assert np.allclose(rotate_to_world([1.0, 0.0, 0.0], np.pi / 2), [0.0, 0.0, -1.0], atol=1e-15)
    assert np.allclose(rotate_to_world([0.0, 0.0, 1.0], np.pi / 2), [1.0, 0.0, 0.0], atol=1e-15)
    p = np.random.default_rng(0).normal(size=(10, 3))
    assert np.allclose(rotate_to_body(rotate_to_world(p, 0.7), 0.7), p, atol=1e-14)


def test_shapes_package_imports_no_solver() -> None:
    import thirdbody.shapes as pkg

    for path in Path(pkg.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                if name.startswith("thirdbody"):
                    # geometry only: the shapes and the orientation helpers, nothing above
                    assert name.startswith(("thirdbody.shapes", "thirdbody.orientation")), \
                        (path.name, name)


# --- ellipsoid and sphere -----------------------------------------------------------------------


def test_upright_ellipsoid_apex_is_the_osculating_paraboloid() -> None:
    e = Ellipsoid((A, B, C))
    rx, ry = A * A / C, B * B / C
    phi = 0.7
    errors = []
    for r in (2e-4, 1e-4, 5e-5, 2.5e-5):
        x, y = r * np.cos(phi), r * np.sin(phi)
        paraboloid = x * x / (2 * rx) + y * y / (2 * ry)
        errors.append(float(e.gap_lower(0.0, x, y)) - paraboloid)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(np.abs(ratios - 16.0) < 0.2), ratios  # the error is O(r⁴)


def test_upright_ellipsoid_gaps_match_closed_form() -> None:
    e = Ellipsoid((A, B, C))
    x, y = grid(1.1 * A, 101)
    y = y * (B / A)
    exact = exact_upright_gap(x, y)
    for gap in (e.gap_lower(0.0, x, y), e.gap_upper(0.0, x, y)):
        fin = np.isfinite(exact)
        assert np.array_equal(np.isfinite(gap), fin)
        np.testing.assert_allclose(gap[fin], exact[fin], rtol=0, atol=1e-12 * e.size)
    # Near the apex the gap is accurate relative to itself (no cancellation).
    for r in (1e-9 * MM, 1e-6 * MM, 1e-3 * MM):
        np.testing.assert_allclose(e.gap_lower(0.0, r, 0.0), exact_upright_gap(r, 0.0), rtol=1e-14)


def test_sphere_height_and_gap() -> None:
    R = 1.5 * MM
    s = Sphere(R)
    x, y = grid(1.2 * R)
    rho2 = x * x + y * y
    with np.errstate(invalid="ignore"):
        exact = np.where(rho2 <= R * R, rho2 / (R + np.sqrt(R * R - rho2)), np.inf)
    for theta in np.linspace(-3.0, 3.0, 7):
        assert s.height(theta) == pytest.approx(2 * R, rel=1e-15)
        np.testing.assert_allclose(s.lowest_point(theta), [0, 0, -R], atol=1e-15 * R)
        for gap in (s.gap_lower(theta, x, y), s.gap_upper(theta, x, y)):
            fin = np.isfinite(exact)
            assert np.array_equal(np.isfinite(gap), fin)
            np.testing.assert_allclose(gap[fin], exact[fin], rtol=0, atol=1e-12 * R)


@settings(max_examples=40, deadline=None)
@given(
    theta=st.floats(-2 * np.pi, 2 * np.pi),
    axes=st.tuples(*[st.floats(0.2 * MM, 5 * MM)] * 3),
)
def test_tilted_ellipsoid_closed_forms(theta: float, axes: tuple[float, float, float]) -> None:
    a, _, c = axes
    e = Ellipsoid(axes)
    s, co = np.sin(theta), np.cos(theta)
    h = np.sqrt(a * a * s * s + c * c * co * co)
    assert e.height(theta) == pytest.approx(2 * h, rel=1e-14)
    low = np.array([s * co * (a * a - c * c) / h, 0.0, -h])
    np.testing.assert_allclose(e.lowest_point(theta), low, rtol=0, atol=1e-14 * e.size)
    np.testing.assert_allclose(e.highest_point(theta), -low, rtol=0, atol=1e-14 * e.size)
    # The lowest point lies on the surface with a horizontal tangent plane: zero gap there.
    assert e.gap_lower(theta, low[0], 0.0) <= 1e-14 * e.size
    assert np.isfinite(e.gap_lower(theta, low[0], 0.0))
    x, y = grid(1.05 * e.size, 41)
    z_low, z_up = e.surfaces(theta, x, y)
    hit = np.isfinite(z_low)
    assert np.array_equal(hit, np.isfinite(z_up))
    assert np.all(z_low[hit] <= z_up[hit])
    assert np.all(z_low[hit] >= low[2] - 1e-14 * e.size)
    for z in (z_low, z_up):
        pts = rotate_to_body(np.stack([x[hit], y[hit], z[hit]], axis=-1), theta)
        assert np.max(np.abs(e.implicit(pts))) < 1e-10
    # Consistency with the generic (surfaces-based) gaps of the base class.
    for mine, generic in ((e.gap_lower, Shape.gap_lower), (e.gap_upper, Shape.gap_upper)):
        g1, g2 = mine(theta, x, y), generic(e, theta, x, y)
        fin = np.isfinite(g1)
        assert np.array_equal(fin, np.isfinite(g2))
        np.testing.assert_allclose(g1[fin], g2[fin], rtol=0, atol=1e-12 * e.size)


def test_ellipsoid_periodicity_and_misses() -> None:
    e = Ellipsoid((A, B, C))
    x, y = grid(1.2 * A, 61)
    for theta in (0.0, 0.4, 1.3):
        ref = e.surfaces(theta, x, y)
        # Rays grazing the silhouette are ill-conditioned (the crossing moves like √ of the
        # rounding): compare the rays with a chord longer than 1e-3 of the size.
        solid = ref[1] - ref[0] > 1e-3 * e.size
        for other in (theta + 2 * np.pi, theta + np.pi, theta - np.pi):
            for z0, z1 in zip(ref, e.surfaces(other, x, y), strict=True):
                assert np.array_equal(np.isnan(z0[solid]), np.isnan(z1[solid]))
                np.testing.assert_allclose(z1[solid], z0[solid], rtol=0, atol=1e-12 * e.size)
    # Rays beyond the silhouette miss: NaN surfaces, infinite gaps.
    far = np.array([1.01 * A, 5 * A, -1.01 * A])
    for xs, ys in ((far, 0.0 * far), (0.0 * far, far * (B / A))):
        z_low, z_up = e.surfaces(0.0, xs, ys)
        assert np.all(np.isnan(z_low)) and np.all(np.isnan(z_up))
        assert np.all(np.isposinf(e.gap_lower(0.0, xs, ys)))
        assert np.all(np.isposinf(e.gap_upper(0.0, xs, ys)))


def test_input_validation() -> None:
    with pytest.raises(ValueError, match="semi_axes"):
        Ellipsoid((1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="semi_axes"):
        Sphere(0.0)


# --- potato -------------------------------------------------------------------------------------


def test_potato_reproducible_from_seed(potato: Potato) -> None:
    same = Potato((2.0 * MM, 1.5 * MM, 1.2 * MM), seed=7)
    other = Potato((2.0 * MM, 1.5 * MM, 1.2 * MM), seed=8)
    assert same.waves == potato.waves
    assert other.waves != potato.waves
    explicit = Potato(potato.semi_axes, [tuple(vars(w).values()) for w in potato.waves])
    x, y = grid(1.1 * potato.size, 41)
    g = potato.gap_lower(0.3, x, y)
    assert np.array_equal(same.gap_lower(0.3, x, y), g)
    assert np.array_equal(explicit.gap_lower(0.3, x, y), g)
    fin = np.isfinite(g) & np.isfinite(other.gap_lower(0.3, x, y))
    assert np.max(np.abs(other.gap_lower(0.3, x, y)[fin] - g[fin])) > 1e-3 * potato.size
    # Default drawing: amplitudes in [amplitude/2, amplitude], wavenumbers in the range.
    assert len(potato.waves) == 3
    for w in potato.waves:
        assert 0.025 <= w.amplitude <= 0.05 and 2.0 <= w.wavenumber <= 4.0


def test_potato_is_symmetric_in_y(potato: Potato) -> None:
    x, y = grid(1.1 * potato.size, 41)
    for theta in (0.0, 0.9):
        for z0, z1 in zip(potato.surfaces(theta, x, y), potato.surfaces(theta, x, -y), strict=True):
            assert np.array_equal(np.isnan(z0), np.isnan(z1))
            np.testing.assert_allclose(z1, z0, rtol=0, atol=1e-14 * potato.size)
        assert potato.lowest_point(theta)[1] == 0.0


def test_potato_surfaces_solve_the_implicit_equation(potato: Potato) -> None:
    x, y = grid(1.1 * potato.size, 61)
    for theta in (0.0, 0.5, 2.0):
        z_low, z_up = potato.surfaces(theta, x, y)
        hit = np.isfinite(z_low)
        assert hit.sum() > 1000
        assert np.array_equal(hit, np.isfinite(z_up))
        assert np.all(z_low[hit] <= z_up[hit])
        for z in (z_low, z_up):
            pts = rotate_to_body(np.stack([x[hit], y[hit], z[hit]], axis=-1), theta)
            assert np.max(np.abs(potato.implicit(pts))) < 1e-12
        # Just below z_low and above z_up the ray is outside.
        below = rotate_to_body(np.stack([x[hit], y[hit], z_low[hit] - 1e-6 * MM], -1), theta)
        above = rotate_to_body(np.stack([x[hit], y[hit], z_up[hit] + 1e-6 * MM], -1), theta)
        assert np.all(potato.implicit(below) > 0) and np.all(potato.implicit(above) > 0)
        # Periodicity in θ.
        for z0, z1 in zip((z_low, z_up), potato.surfaces(theta + 2 * np.pi, x, y), strict=True):
            np.testing.assert_allclose(z1, z0, rtol=0, atol=1e-12 * potato.size)


def test_potato_extreme_points_and_gaps(potato: Potato) -> None:
    x, y = grid(1.1 * potato.size, 121)
    for theta in (0.0, 0.6, -1.9):
        low, high = potato.lowest_point(theta), potato.highest_point(theta)
        z_low, z_up = potato.surfaces(theta, x, y)
        # No ray reaches below the lowest point, and the scan gets close to it.
        assert np.nanmin(z_low) >= low[2] - 1e-12 * potato.size
        assert np.nanmin(z_low) - low[2] < 1e-2 * potato.size * (x[1, 0] - x[0, 0]) / MM
        assert np.nanmax(z_up) <= high[2] + 1e-12 * potato.size
        # The extreme points are on the surface, with zero gap there.
        assert abs(potato.gap_lower(theta, low[0], low[1])) < 1e-12 * potato.size
        assert abs(potato.gap_upper(theta, high[0], high[1])) < 1e-12 * potato.size
        assert potato.height(theta) == pytest.approx(high[2] - low[2])
        for gap in (potato.gap_lower(theta, x, y), potato.gap_upper(theta, x, y)):
            assert np.all(gap >= 0.0)
            assert np.array_equal(np.isinf(gap), np.isnan(z_low))


def test_potato_mirrored_mirrors_the_gaps(potato: Potato) -> None:
    mirror = potato.mirrored()
    x, y = grid(1.1 * potato.size, 41)
    for theta in (0.0, 0.7):
        for name in ("gap_lower", "gap_upper"):
            g = getattr(potato, name)(theta, x, y)
            gm = getattr(mirror, name)(-theta, -x, y)
            assert np.array_equal(np.isinf(g), np.isinf(gm))
            fin = np.isfinite(g)
            np.testing.assert_allclose(gm[fin], g[fin], rtol=0, atol=1e-12 * potato.size)
        p, pm = potato.lowest_point(theta), mirror.lowest_point(-theta)
        assert pm[2] == pytest.approx(p[2], abs=1e-12 * potato.size)
        # The position along a flat minimum is only defined to ~√ε of the size.
        np.testing.assert_allclose(pm, p * [-1, 1, 1], rtol=0, atol=1e-6 * potato.size)


def test_potato_validation() -> None:
    axes = (MM, MM, MM)
    with pytest.raises(ValueError, match="amplitude"):
        Potato(axes, [(0.3, 3.0, 0.0, 0.0), (0.3, 2.0, 1.0, 0.0)])
    assert MAX_TOTAL_AMPLITUDE == 0.5
    # Steep short waves tilt the normal away from the radius: not star-shaped with margin.
    with pytest.raises(ValueError, match="star-shaped"):
        Potato(axes, [Wave(0.4, 40.0, 0.0, 0.0)])
    with pytest.raises(ValueError, match="wavenumber"):
        Potato(axes, [(0.1, -1.0, 0.0, 0.0)])
    with pytest.raises(ValueError):
        Potato(axes, [(0.1, 1.0, 0.0)])


def test_potato_without_waves_is_the_ellipsoid() -> None:
    p = Potato((A, B, C), waves=[])
    e = Ellipsoid((A, B, C))
    np.testing.assert_allclose(p.wave_centre, 0.0, atol=1e-15 * A)
    assert p.volume == pytest.approx(4 / 3 * np.pi * A * B * C, rel=1e-13)
    x, y = grid(1.1 * A, 41)
    for theta in (0.0, 0.8):
        np.testing.assert_allclose(p.lowest_point(theta), e.lowest_point(theta), atol=1e-9 * A)
        for z0, z1 in zip(e.surfaces(theta, x, y), p.surfaces(theta, x, y), strict=True):
            hit = np.isfinite(z0) & np.isfinite(z1)
            # Rays grazing the silhouette may differ in hit/miss by rounding only.
            assert np.sum(np.isfinite(z0) != np.isfinite(z1)) <= 2
            np.testing.assert_allclose(z1[hit], z0[hit], rtol=0, atol=1e-9 * A)


def test_elongated_potato_lowest_point_is_the_ellipsoid_one() -> None:
    # The extreme-point search must reach far off-axis lowest points (tan α up to ~10 here).
    axes = (20 * MM, 2 * MM, MM)
    p, e = Potato(axes, waves=[]), Ellipsoid(axes)
    for theta in np.linspace(0.0, np.pi, 7):
        d = p.lowest_point(theta) - e.lowest_point(theta)
        assert abs(d[2]) < 1e-12 * e.size and abs(d[0]) < 1e-6 * e.size


@pytest.mark.parametrize("asymmetric", [False, True])
def test_non_convex_potato_has_two_contact_spots(asymmetric: bool) -> None:
    # −cos(6 d_x) dimples the bottom: the lowest point splits into two, at ±x.
    waves = [(0.05, 6.0, 0.0, -np.pi / 2)]
    if asymmetric:
        waves.append((0.01, 3.0, 0.0, 0.0))
    p = Potato((1.2 * MM, MM, MM), waves)
    minima = p.lower_minima(0.0)
    assert minima.shape == (2, 3)
    assert minima[0, 0] * minima[1, 0] < 0  # one spot on each side
    np.testing.assert_array_equal(minima[:, 1], 0.0)
    x = np.linspace(-1.5 * MM, 1.5 * MM, 6001)
    z_low, _ = p.surfaces(0.0, x, 0.0 * x)
    i = np.nanargmin(z_low)
    low = p.lowest_point(0.0)
    assert low[2] <= z_low[i] + 1e-12 * MM
    assert z_low[i] - low[2] < 1e-7 * MM  # the scan's spacing 0.5 µm, curvature ~1/mm
    if asymmetric:
        assert abs(low[0] - x[i]) < 1e-3 * MM  # the global minimum, not the other one
        assert minima[1, 2] - minima[0, 2] > 1e-3 * MM
    else:
        assert minima[1, 2] == pytest.approx(minima[0, 2], abs=1e-12 * MM)


# --- meshes -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def trimesh():
    return pytest.importorskip("trimesh")


def sphere_gap_error(mesh: MeshShape, sphere: Sphere, theta: float) -> float:
    R = sphere.radius
    x, y = grid(0.8 * R, 61)
    inner = x * x + y * y < (0.8 * R) ** 2
    err = 0.0
    for name in ("gap_lower", "gap_upper"):
        g_mesh = getattr(mesh, name)(theta, x, y)[inner]
        g_exact = getattr(sphere, name)(theta, x, y)[inner]
        err = max(err, float(np.max(np.abs(g_mesh - g_exact))))
    return err


def test_tessellated_sphere_gap_within_faceting_error(trimesh) -> None:
    R = MM
    s = Sphere(R)
    errors = []
    for level in (4, 5):
        m = MeshShape.from_shape(s, subdivisions=level)
        np.testing.assert_allclose(m.centroid, 0.0, atol=1e-15 * R)
        assert m.volume == pytest.approx(4 / 3 * np.pi * R**3, rel=1e-2)
        # Chord sag of a facet is ~ℓ²/(6R); the gap mixes two of them over a tilted surface.
        sag = m.max_edge**2 / (6 * R)
        err = max(sphere_gap_error(m, s, theta) for theta in (0.0, 0.4))
        assert err < 3.0 * sag
        assert m.height(0.3) == pytest.approx(2 * R, abs=2 * sag)
        errors.append(err)
    assert errors[0] / errors[1] > 3.0  # second-order in the edge length


def test_mesh_surfaces_nan_outside_and_ordered(trimesh) -> None:
    m = MeshShape.from_shape(Ellipsoid((A, B, C)), subdivisions=4)
    x, y = grid(1.3 * A, 61)
    z_low, z_up = m.surfaces(0.5, x, y)
    hit = np.isfinite(z_low)
    assert np.array_equal(hit, np.isfinite(z_up))
    assert np.all(z_low[hit] <= z_up[hit])
    assert not hit[0, 0] and hit[30, 30]
    assert np.all(np.isinf(m.gap_lower(0.5, x, y)[~hit]))
    low = m.lowest_point(0.5)
    assert np.nanmin(z_low) >= low[2] - 1e-15
    assert m.gap_lower(0.5, low[0], low[1]) < 1e-12 * m.size


def test_mesh_mirrored_mirrors_the_gaps(trimesh, potato: Potato) -> None:
    m = MeshShape.from_shape(potato, subdivisions=4)
    mm = m.mirrored()
    assert mm.volume == pytest.approx(m.volume, rel=1e-12)
    x, y = grid(1.1 * potato.size, 41)
    g, gm = m.gap_lower(0.4, x, y), mm.gap_lower(-0.4, -x, y)
    assert np.array_equal(np.isinf(g), np.isinf(gm))
    fin = np.isfinite(g)
    np.testing.assert_allclose(gm[fin], g[fin], rtol=0, atol=1e-12 * potato.size)


def test_mesh_from_stl_file(trimesh, tmp_path: Path) -> None:
    ico = trimesh.creation.icosphere(subdivisions=3, radius=2.0)  # millimetres
    ico.apply_translation([5.0, -1.0, 3.0])
    path = tmp_path / "particle.stl"
    ico.export(path)
    m = MeshShape.from_file(path, scale=1e-3)
    np.testing.assert_allclose(m.offset, [5e-3, -1e-3, 3e-3], atol=1e-12)
    np.testing.assert_allclose(m.centroid, 0.0, atol=1e-15)
    assert m.size == pytest.approx(2 * MM, rel=1e-6)
    assert m.volume == pytest.approx(ico.volume * 1e-9, rel=1e-9)
    # Loop refinement to a target edge keeps the mesh closed and close to the sphere.
    fine = MeshShape.from_file(path, scale=1e-3, max_edge=0.1 * MM)
    assert fine.max_edge <= 0.1 * MM
    assert sphere_gap_error(fine, Sphere(fine.size), 0.2) < 0.02 * MM
    smooth = MeshShape.from_file(path, scale=1e-3, subdivisions=1, smooth="taubin")
    assert smooth.volume == pytest.approx(m.volume, rel=0.05)


def test_non_watertight_mesh_is_refused(trimesh, tmp_path: Path) -> None:
    ico = trimesh.creation.icosphere(subdivisions=2)
    holed = trimesh.Trimesh(ico.vertices, ico.faces[1:], process=False)
    path = tmp_path / "holed.stl"
    holed.export(path)
    with pytest.raises(ValueError, match=r"holed\.stl.*not watertight"):
        MeshShape.from_file(path)
    with pytest.raises(ValueError, match="not watertight"):
        MeshShape(ico.vertices, ico.faces[1:])


def test_tessellated_potato_matches_potato(trimesh, potato: Potato) -> None:
    m = MeshShape.from_shape(potato, subdivisions=6)
    x, y = grid(0.6 * potato.size, 61)
    for theta in (0.0, 1.0):
        z0, _ = potato.surfaces(theta, x, y)
        z1, _ = m.surfaces(theta, x, y)
        hit = np.isfinite(z0) & np.isfinite(z1)
        # Faceting error (sag ~ ℓ²κ/6) plus the mesh's own centroid shift.
        assert np.max(np.abs(z1[hit] - z0[hit])) < 2e-3 * potato.size


def test_potato_surfaces_are_pinned_to_their_values_before_the_fast_ray_casting():
    """Issue 13 made the vertical-ray casting cheaper (every fourth sample first, the rest only
    where the Lipschitz bound cannot rule a crossing out; in-place arithmetic). The surfaces of
    three potatoes, four random 3-D orientations each, 500 random rays, equal the ones written
    by the code before the change (``tests/data/surfaces_pinned.npz``) to 1e-16 m (the root
    finder's tolerance is 4 ulp of the size, ~1e-18 m), misses included."""
    from thirdbody.orientation import Rotation

    data = np.load(Path(__file__).parent / "data" / "surfaces_pinned.npz")
    axes = (1.0e-3, 0.8e-3, 0.7e-3)
    shapes = {
        "fig3": Potato(axes, seed=4, amplitude=0.10, wavenumber_range=(4.0, 8.0)),
        "fig4": Potato(axes, seed=27, amplitude=0.055, wavenumber_range=(2.0, 4.0)),
        "small": Potato((0.5e-3, 0.3e-3, 0.2e-3), seed=5, amplitude=0.06,
                        wavenumber_range=(2.0, 6.0)),
    }
    for name, shape in shapes.items():
        x, y = data[f"{name}_xy"]
        for k, quat in enumerate(data[f"{name}_quat"]):
            low, up = shape.surfaces(Rotation.from_quat(quat), x, y)
            for got, want in ((low, data[f"{name}_low"][k]), (up, data[f"{name}_up"][k])):
                assert (np.isnan(got) == np.isnan(want)).all()
                assert np.isfinite(want).sum() > 100
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-16)


def test_potato_implicit_function_against_its_definition(potato: Potato) -> None:
    """F(q) = |q/axes| / (1 + Σ a sin(k (d_x cos β + d_z sin β) + φ)) − 1, d = q/|q|, q the point
    from the wave centre, written out here from the waves; for one point (a float) and for a
    batch (shape kept)."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.2, 1.2, size=(7, 5, 3)) * potato.size
    q = pts - potato.wave_centre
    d = q / np.linalg.norm(q, axis=-1, keepdims=True)
    m = 1.0 + sum(w.amplitude * np.sin(w.wavenumber * (d[..., 0] * np.cos(w.direction)
                                                        + d[..., 2] * np.sin(w.direction))
                                        + w.phase) for w in potato.waves)
    expected = np.linalg.norm(q / potato.semi_axes, axis=-1) / m - 1.0
    got = potato.implicit(pts)
    assert got.shape == (7, 5)
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)
    one = potato.implicit(pts[2, 3])
    assert np.ndim(one) == 0 and float(one) == pytest.approx(expected[2, 3], rel=1e-13)


def test_ray_sampling_skips_only_samples_that_cannot_matter():
    """The sampling behind every ray cast (``_roots._sample``) evaluates every fourth sample and
    skips the rest where the Lipschitz bound rules out a crossing or a near miss. Checked here
    on ray functions whose Lipschitz constant is exact (the bound is tight, unlike a shape's):
    f(z) = min_i (L |z − c_i| − d_i), bodies (d > 0) and near misses (d < 0) at random places.
    Wherever a sample was skipped, the true value has the sign of the stand-in, and a +inf
    stand-in hides no value below L h (a near miss the caller would search); evaluated samples
    are exact."""
    from thirdbody.shapes._roots import _sample

    rng = np.random.default_rng(11)
    m, n, lip = 400, 64, 3.0
    z = np.tile(np.linspace(0.0, 1.0, n), (m, 1))
    h = 1.0 / (n - 1)
    centres = rng.uniform(0.1, 0.9, size=(m, 3))
    depths = rng.uniform(-2.0, 2.0, size=(m, 3)) * lip * h

    def fun(idx, zz):
        idx, zz = np.broadcast_arrays(idx, zz)
        return np.min(lip * np.abs(zz[..., None] - centres[idx]) - depths[idx], axis=-1)

    full = fun(np.arange(m)[:, None], z)
    got = _sample(fun, np.arange(m), z, np.full(m, lip * h))
    finite = np.isfinite(got)
    assert (~finite).sum() > 0.3 * got.size          # it does skip
    np.testing.assert_array_equal(got[finite], full[finite])
    assert (full[got == np.inf] > lip * h).all()
    assert (full[got == -np.inf] < 0).all()
