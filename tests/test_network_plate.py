"""A plate contact's half-space measure (:func:`thirdbody.network.plate.solve_plate`): a/R with
R the smallest radius of curvature where each spot sits, against the surface computed here
from the shapes' own formulas (a sphere; the two-bump potato's radial function, its lowest
surface found by root finding along rays and differentiated by finite differences), not by
the package's ray casting."""

import math
import warnings

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

import thirdbody as tb
from thirdbody.network import Body
from thirdbody.network.contact import HalfSpaceWarning
from thirdbody.network.plate import cell_separation, solve_plate
from thirdbody.shapes import Sphere
from thirdbody.shapes.potato import Potato, Wave

MAT = tb.Material(1e9, 0.3)
AXES = np.array([1e-3, 0.6e-3, 0.6e-3])
AMPLITUDE = 0.12


def two_bumps() -> Potato:
    """Radius r(d) = (1 − A cos(2π d_x)) / |d / axes| about the centroid: two bumps on each
    side at x ≈ ±0.3 mm, a concave dip between them."""
    return Potato(tuple(AXES), [Wave(AMPLITUDE, 2 * np.pi, 0.0, -np.pi / 2)])


def lower_surface(x: float, y: float) -> float:
    """z (m, from the centroid) of the two-bump potato's lower surface above (x, y): the root
    of |q| = r(q/|q|) along the vertical, from the formula."""
    def inside(z):
        q = np.array([x, y, z])
        d = q / np.linalg.norm(q)
        r = (1 - AMPLITUDE * math.cos(2 * math.pi * d[0])) / np.linalg.norm(d / AXES)
        return np.linalg.norm(q) - r
    return brentq(inside, -1e-3, -1e-5, xtol=1e-16, rtol=1e-15)


def smallest_radius(x: float, y: float, h: float = 2e-6) -> float:
    """The smallest |principal radius of curvature| (m) of the lower surface at (x, y), by
    central differences of z (convex downwards: z'' < 0 for a convex bottom)."""
    z = {(i, j): lower_surface(x + i * h, y + j * h) for i in (-1, 0, 1) for j in (-1, 0, 1)}
    zxx = (z[1, 0] - 2 * z[0, 0] + z[-1, 0]) / h**2
    zyy = (z[0, 1] - 2 * z[0, 0] + z[0, -1]) / h**2
    zxy = (z[1, 1] - z[1, -1] - z[-1, 1] + z[-1, -1]) / (4 * h * h)
    kappa = np.linalg.eigvalsh(-np.array([[zxx, zxy], [zxy, zyy]]))
    return float(1 / np.abs(kappa).max())


def test_a_two_spot_plate_contact_measures_each_spot_against_its_own_bump():
    """The two-bump potato pressed 1 µm into the lower plate touches it on two equal spots at
    x ≈ ±0.3 mm. The whole contact's pressure centroid is at x = 0, in the concave dip between
    the bumps (radius −0.105 mm there), so measuring a/R there said 0.196 and warned. Each spot
    sits on a bump of radius 0.249 mm (computed here from the radial function), and a/R is
    0.082: inside the half-space range, no warning. The reported radii stay those at the
    centroid (the contact's rolling geometry)."""
    shape = two_bumps()
    lowest = float(shape.lowest_point(Body(shape, MAT, centre=(0, 0, 0)).rotation)[2])
    body = Body(shape, MAT, centre=(0.0, 0.0, -lowest - 1e-6))
    with warnings.catch_warnings():
        warnings.simplefilter("error", HalfSpaceWarning)
        c = solve_plate(body, "lower", plate=0.0, mu=0.3, spacing=shape.size / 80)
    assert c.spots == 2
    bump_x = float(shape.lowest_point(body.rotation)[0])
    assert abs(bump_x) == pytest.approx(0.318e-3, rel=0.01)
    bump = smallest_radius(bump_x, 0.0)
    dip = smallest_radius(0.0, 0.0)
    assert bump == pytest.approx(0.249e-3, rel=0.01) and dip < 0.5 * bump
    # the spot's own centroid sits a fraction of a cell off the bump's top: 0.2 % off its radius
    assert c.curvature_radius == pytest.approx(bump, rel=0.005)
    assert c.half_space_ratio == pytest.approx(c.contact_radius / bump, rel=0.005)
    assert c.contact_radius / dip > 0.1 > c.half_space_ratio
    assert np.abs(c.radii).min() == pytest.approx(dip, rel=0.01)


def test_a_one_spot_plate_contact_measures_at_its_pressure_centroid():
    """A sphere of R = 1 mm pressed 2 µm: one spot under the centre, curvature radius R (the
    stencil's error below 1e-6) and a/R = √(δR)/R within the grid's area error (measured +1.1 %
    at 11 cells across the radius)."""
    body = Body(Sphere(1e-3), MAT, centre=(0.0, 0.0, 1e-3 - 2e-6))
    c = solve_plate(body, "lower", plate=0.0, mu=0.3, spacing=4e-6)
    assert c.spots == 1
    assert c.curvature_radius == pytest.approx(1e-3, rel=1e-6)
    assert np.abs(c.radii).min() == c.curvature_radius
    assert c.half_space_ratio == pytest.approx(math.sqrt(2e-6 * 1e-3) / 1e-3, rel=0.05)


def test_a_step_left_with_contacts_below_a_cell_says_so():
    """The two-bump potato alone between the plates, 0.002 N, at 40 cells per size (22 µm): its
    bump tops lie between the centroid lattice's cell centres, so a plate 1.6e-7 m into the
    shape touches no cell (less than the sag to the nearest one): that contact's law jumps from
    nothing to a cell's stiffness 5e-8 m further on, and the passes end with the upper plate
    carrying F_N/2 and the lower one open. The error says that (and what resolves it); at 80
    cells the step converges, with the load on two equal spots at each plate (the
    symmetry)."""
    from thirdbody.network.cluster import ClusterConvergenceError, ClusterNumerics, solve_cluster

    shape = two_bumps()
    lowest = float(shape.lowest_point(Body(shape, MAT, centre=(0, 0, 0)).rotation)[2])
    body = Body(shape, MAT, centre=(0.0, 0.0, -lowest))
    with pytest.raises(ClusterConvergenceError,
                       match=r"contact\(s\) overlap by less than their cells resolve \(the "
                             r"deepest, \(0, '(lower|upper)'\), by .* m.*\(numerics\.resolution\)"):
        solve_cluster([body], mu_up=0.3, mu_low=0.3, force=0.002,
                      numerics=ClusterNumerics(resolution=40, tol=1e-6))
    result = solve_cluster([body], mu_up=0.3, mu_low=0.3, force=0.002,
                           numerics=ClusterNumerics(resolution=80, tol=1e-6))
    for c in result.contacts:
        assert c.spots == 2
        assert c.normal_force == pytest.approx(0.002, rel=1e-5)


def test_plates_that_left_every_particle_are_named():
    """The end of that error when nothing overlaps a plate any more, and when something does
    (a sphere of 1 mm between plates 5 mm apart; 0.1 mm into the lower one)."""
    from types import SimpleNamespace as NS

    from thirdbody.network import cluster

    def problem(z):
        return NS(n=1, body=lambda k, c, r: Body(Sphere(1e-3), MAT, centre=(0.0, 0.0, z)))

    ev = NS(centres=None, rotations=None, h=5e-3)
    assert cluster._why_nothing_touches(problem(2e-3), ev) == \
        ": the plates have moved off every particle"
    assert "overlap the plates (by up to 0.0001 m)" in cluster._why_nothing_touches(
        problem(0.9e-3), ev)


@pytest.mark.parametrize("depth", [1e-7, 3e-6])
def test_a_plate_overlapping_between_the_cells_knows_how_far_they_are(depth):
    """The two-bump potato overlapping the lower plate by ``depth`` at its lowest point, on a
    lattice of 22 µm whose cells (at the centroid's x, y plus whole cells) miss the bump tops:
    how much further the plate must rise before a cell centre touches is the smallest height
    of the lower surface above the plate over the cells, from the radial function
    (root finding along each cell's vertical, not the package's rays). At 0.1 µm no cell
    touches (no contact: it is positive); at 3 µm some does (zero)."""
    spacing = 22e-6
    bottom = minimize_scalar(lambda x: lower_surface(x, 0.0), bounds=(0.05e-3, 0.6e-3),
                             method="bounded", options={"xatol": 1e-12})
    centre_z = -float(bottom.fun) - depth                   # lowest point at z = −depth
    body = Body(two_bumps(), MAT, centre=(0.0, 0.0, centre_z))
    heights = [centre_z + lower_surface(i * spacing, j * spacing)
               for i in range(-25, 26) for j in range(-3, 4) if abs(i) > 3]
    expected = max(min(heights), 0.0)
    found = cell_separation(body, "lower", 0.0, spacing)
    if depth < 1e-6:
        assert solve_plate(body, "lower", plate=0.0, mu=0.3, spacing=spacing) is None
        assert expected > 1e-8
        assert found == pytest.approx(expected, rel=1e-6, abs=1e-15)
    else:
        assert expected == 0.0 and found == 0.0


def test_a_plate_between_the_cells_is_an_open_contact_of_the_step():
    """The network's evaluation of the potato 0.1 µm into the lower plate on cells of 22 µm
    (the upper plate 0.5 mm above it): no contact is solved, and both plates are open contacts
    of the Newton step. The lower one: apart by the cells' smallest height above the plate
    (from the radial function, as above), the overlap 0.1 µm, normal −z, at the lowest point
    (a bump top, x = ±0.318 mm by the formula) on the plate, with the potato's E*, (2 − ν)/G
    and μ_low. Dropped, the Newton model held nothing there (docs/methods/network.md)."""
    from thirdbody.network import cluster
    from thirdbody.network.cluster import ClusterNumerics

    spacing, depth = 22e-6, 1e-7
    bottom = minimize_scalar(lambda x: lower_surface(x, 0.0), bounds=(0.05e-3, 0.6e-3),
                             method="bounded", options={"xatol": 1e-12})
    centre_z = -float(bottom.fun) - depth
    body = Body(two_bumps(), MAT, centre=(0.0, 0.0, centre_z))
    heights = [centre_z + lower_surface(i * spacing, j * spacing)
               for i in range(-25, 26) for j in range(-3, 4) if abs(i) > 3]
    top = centre_z + AXES[2] * 1.2                       # above the potato's top
    gap = top + 0.5e-3
    problem = cluster._Problem([body], {}, 0.4, 0.2, cluster._mu_function(0.0), gap, None, gap,
                               (0.0, 0.0), None, ClusterNumerics(cell_size=spacing))
    ev = problem.evaluate(np.array([body.centre]), [body.rotation], gap, None)
    assert not ev.contacts
    lower = {p.roles[1]: p for p in ev.potential}["lower"]
    assert lower.roles == (0, "lower")
    assert lower.sigma == pytest.approx(min(heights), rel=1e-6)
    assert lower.overlap == pytest.approx(depth, rel=1e-6)
    np.testing.assert_array_equal(lower.normal, [0.0, 0.0, -1.0])
    assert abs(abs(lower.point[0]) - float(bottom.x)) < 1e-6 and lower.point[2] == 0.0
    np.testing.assert_array_equal(lower.centre_a, body.centre)
    assert lower.E_star == MAT.E_star and lower.mu == 0.2
    assert lower.compliance == pytest.approx((2 - MAT.nu) / MAT.G, rel=1e-15)
    upper = {p.roles[1]: p for p in ev.potential}["upper"]
    np.testing.assert_array_equal(upper.normal, [0.0, 0.0, 1.0])
    assert upper.overlap == 0.0 and upper.mu == 0.4 and upper.point[2] == gap
