"""Every contact spot is in the problem: the footprint scan against a brute-force solve of the
whole footprint (every lattice cell under the particle, gaps from the shape's own closed-form
``gap_lower``/``gap_upper``, one ``solve_normal``), on non-convex potatoes in general
orientations. The two must give the same pressure field, hence the same spots and couple."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.spatial.transform import Rotation

import thirdbody as tb
from thirdbody.particle import Interface, PairStatics
from thirdbody.particle.surface import LOWER, Surfaces
from thirdbody.shapes import Potato, Shape

MAT = tb.Material(1e9, 0.3)
FIG3 = Potato((1.0e-3, 0.8e-3, 0.7e-3), seed=4, amplitude=0.1, wavenumber_range=(4, 8))


def whole_footprint(shape, rotation, spacing, side, force):
    """Pressure (Pa) on the full (2n+1)² lattice around the centroid, n = ⌈size/Δ⌉ + 2."""
    n = math.ceil(shape.size / spacing) + 2
    grid = tb.Grid(2 * n + 1, spacing)                 # centred on lattice cell 0
    X, Y = grid.mesh()
    gap = (shape.gap_lower if side == "lower" else shape.gap_upper)(rotation, X, Y)
    normal = tb.solve_normal(gap, grid, MAT, force=force, tol=1e-10)
    return normal, n


def on_lattice(solution, n):
    """A solve's pressure placed on the (2n+1)² lattice."""
    out = np.zeros((2 * n + 1, 2 * n + 1))
    w = solution.window
    out[w.j0 + n:w.j0 + n + w.ny, w.i0 + n:w.i0 + n + w.nx] = solution.contact.pressure
    return out


def spots(pressure, dA):
    """(x index centroid, force) of each connected contact piece, sorted by x."""
    labels, count = ndimage.label(pressure > 0, structure=np.ones((3, 3)))
    cols = np.arange(pressure.shape[1])[None, :]
    out = [((pressure * cols)[labels == k].sum() / pressure[labels == k].sum(),
            pressure[labels == k].sum() * dA) for k in range(1, count + 1)]
    return sorted(out)


def compare(shape, rotation, spacing, force):
    statics = PairStatics(shape, MAT, spacing, 1e-10)
    ev = statics.at_force(rotation, force)
    for side, sol in (("lower", ev.low), ("upper", ev.up)):
        reference, n = whole_footprint(shape, rotation, spacing, side, force)
        mine = on_lattice(sol, n)
        assert np.abs(mine - reference.pressure).max() <= 1e-6 * reference.pressure.max()
        assert sol.spots == len(spots(reference.pressure, spacing**2))
    return ev


def test_the_second_spot_of_the_fig3_potato_after_its_big_turn():
    """The issue's case: θ = 9.727° about y, 6 N. The lower surface has two dips 0.75 mm apart
    whose heights differ by ~2e-8 m, far less than the approach: both carry load."""
    spacing = FIG3.size / 80
    rotation = Rotation.from_rotvec([0.0, math.radians(9.727), 0.0])
    ev = compare(FIG3, rotation, spacing, 6.0)
    assert ev.low.spots == 2 and ev.up.spots == 1
    reference, _n = whole_footprint(FIG3, rotation, spacing, "lower", 6.0)
    (x0, f0), (x1, f1) = spots(reference.pressure, spacing**2)
    assert (x1 - x0) * spacing == pytest.approx(0.75e-3, abs=0.02e-3)
    assert min(f0, f1) > 0.4 * 6.0                 # each carries a good part of the load
    # the couple of both spots: the lower plate pushes towards -x (the turn goes on)
    assert ev.demand_force[0] / ev.force == pytest.approx(-0.249, abs=0.002)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 200), rotvec=st.tuples(*[st.floats(-1.2, 1.2)] * 3),
       force=st.floats(0.5, 8.0))
def test_the_scan_finds_what_the_whole_footprint_finds(seed, rotvec, force):
    """Random wavy potatoes (four 10 % waves, wavenumbers 6-10: several dips per side, about
    one side in six touching in more than one spot) in random 3-D orientations: the same
    pressure as the brute-force solve, to the solver tolerance."""
    shape = Potato((1.0e-3, 0.8e-3, 0.6e-3), seed=seed, amplitude=0.1, n_waves=4,
                   wavenumber_range=(6, 10))
    compare(shape, Rotation.from_rotvec(rotvec), shape.size / 40, force)


class TwoDips(Shape):
    """A test surface, fixed in space: two paraboloid bowls, the main one (radius R) lowest at
    the origin, the second (radius ``w``) with its bottom ``depth2`` higher at ``centre``; the
    lower surface is the lower of the two, the top its mirror image. ``feature_length`` is
    ``w``."""

    def __init__(self, R, centre, w, depth2, size):
        super().__init__()
        self.R, self.centre, self.w, self.depth2, self._size = R, centre, w, depth2, size

    def _z(self, x, y):
        x0, y0 = self.centre
        main = (x**2 + y**2) / (2 * self.R)
        second = ((x - x0) ** 2 + (y - y0) ** 2) / (2 * self.w) + self.depth2
        return np.where(x**2 + y**2 < self._size**2, np.minimum(main, second) - self._size,
                        np.nan)

    def surfaces(self, orientation, x, y):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        z = self._z(x, y)
        return z, -z

    def _lowest_point(self, rotation):
        return np.array([0.0, 0.0, -self._size])

    def mirrored(self):
        return self

    @property
    def size(self):
        return self._size

    @property
    def feature_length(self):
        return self.w


def dip_between_samples(depth2):
    """A TwoDips surface (R = 0.5 mm, second bowl 0.1 mm, cells of 2 µm) whose second dip is
    centred between four coarse scan samples: the worst place, as far as can be from each."""
    spacing, size, w = 2e-6, 1e-3, 1e-4
    probe = TwoDips(0.5e-3, (0.0, 0.0), w, depth2, size)
    stride = Surfaces(probe, Rotation.identity(), spacing).stride
    assert stride % 2 == 0                  # the dip's centre is then a lattice cell
    s = stride * spacing
    return TwoDips(0.5e-3, (10.5 * s, 6.5 * s), w, depth2, size), spacing


def test_a_dip_between_scan_samples_is_a_candidate():
    """The curvature allowance: a bound 10 nm above the second dip's bottom, which lies between
    scan samples all some µm higher; only the dip's centre cell is below the bound, and it
    must be a candidate (it is not without the allowance)."""
    shape, spacing = dip_between_samples(1e-6)
    surfaces = Surfaces(shape, Rotation.identity(), spacing)
    n = surfaces.n
    x0, y0 = shape.centre
    bottom = float(shape._z(np.array(x0), np.array(y0))) - surfaces.reference[LOWER]
    bound = bottom + 1e-8
    full = np.ones((surfaces.cells, surfaces.cells), dtype=bool)
    below = surfaces.gap(LOWER, full) < bound
    i, j = round(x0 / spacing) + n, round(y0 / spacing) + n
    assert below[j, i]                                        # the dip's centre is below...
    near = np.hypot(*np.meshgrid((surfaces.coarse_index - i) * spacing,
                                 (surfaces.coarse_index - j) * spacing)) < shape.w
    assert (surfaces.coarse_gap[LOWER][near] > bound + 1e-6).all()   # ...no sample near it is
    assert not (below & ~surfaces.candidates(LOWER, bound)).any()


def test_a_contact_truncated_by_the_scan_is_completed(monkeypatch):
    """If the scan's candidates miss cells (here: those for a bound 300 times smaller, the
    cores of both dips), the check of the cells just outside them widens the problem until
    the contact is whole: the result equals the whole-footprint solve."""
    original = Surfaces.candidates

    def too_few(self, side, bound):
        return original(self, side, bound / 300)

    monkeypatch.setattr(Surfaces, "candidates", too_few)
    rotation = Rotation.from_rotvec([0.0, math.radians(9.727), 0.0])
    compare(FIG3, rotation, FIG3.size / 40, 6.0)
    monkeypatch.setattr(Surfaces, "candidates", original)


def test_an_approach_beyond_the_first_bound_widens_the_problem(monkeypatch):
    """A first bound on the approach far too small (10 nm): the cells chosen for it hold only
    the main bowl, and the second bowl (20 µm higher, beyond a ridge) touches at the approach
    found (about 40 µm). The solve notices that its approach exceeds the bound and repeats
    with a wider one: both bowls carry load, as in the whole-footprint solve."""
    monkeypatch.setattr(Interface, "_bound", lambda self, surfaces, force: 1e-8)
    shape = TwoDips(0.5e-3, (3e-4, 1e-4), 1e-4, 2e-5, 1e-3)
    ev = compare(shape, Rotation.identity(), 1e-5, 10.0)
    assert ev.low.spots == 2


def test_remap_moves_fields_between_lattice_windows():
    """Fields move between windows by their integer offsets; cells not covered are zero."""
    from thirdbody.particle.interface import Window, remap

    source = Window(3, -2, 4, 3)                    # cells i = 3..6, j = -2..0
    field = np.arange(12.0).reshape(3, 4) + 1.0
    target = Window(5, -1, 5, 4)                    # cells i = 5..9, j = -1..2
    out = remap(np.stack([field, -field]), source, target)
    expected = np.zeros((4, 5))
    expected[0:2, 0:2] = field[1:3, 2:4]            # overlap i = 5..6, j = -1..0
    np.testing.assert_array_equal(out[0], expected)
    np.testing.assert_array_equal(out[1], -expected)
    assert not remap(field, source, Window(7, -2, 2, 2)).any()      # side by side: no overlap
    assert not remap(field, source, Window(3, 1, 4, 2)).any()
    np.testing.assert_array_equal(remap(field, source, source), field)


def test_spots_are_connected_through_edges_and_corners():
    from thirdbody.particle import count_spots

    contact = np.zeros((6, 7), dtype=bool)
    contact[1, 1] = contact[2, 2] = True            # touching at a corner: one spot
    contact[4, 4:6] = True                           # a second one
    contact[1, 5] = True                             # a third, alone
    assert count_spots(contact) == 3
    assert count_spots(np.zeros((3, 3), dtype=bool)) == 0


def test_the_curvature_allowance_of_a_quadratic_surface():
    """g = a x² + b y² + c x y on unit samples: the second differences are 2a (x), 2b (y),
    2(a + b ± c) (diagonals); the allowance is half the largest, a + b + |c|, inside, and
    leaves out the neighbours that miss the body (inf) or lie beyond the scan."""
    from thirdbody.particle.surface import _allowance

    a, b, c = 1.0, 3.0, 0.5
    x, y = np.meshgrid(np.arange(-3.0, 4.0), np.arange(-3.0, 4.0))
    g = a * x**2 + b * y**2 + c * x * y
    out = _allowance(g)
    np.testing.assert_allclose(out[1:-1, 1:-1], a + b + abs(c), rtol=1e-12)
    # on the border only the stencils inside the scan count: along the edge row, x only
    np.testing.assert_allclose(out[0, 1:-1], a, rtol=1e-12)
    np.testing.assert_allclose(out[1:-1, 0], b, rtol=1e-12)
    saddle = 3.0 * x**2 - y**2                       # axis x gives 3, the diagonals 2
    assert _allowance(saddle)[3, 2] == pytest.approx(3.0)
    saddle[3, 3] = np.inf                            # a ray that misses: no allowance there,
    out = _allowance(saddle)                         # nor through it for its neighbours
    assert out[3, 3] == 0.0 and out[3, 2] == pytest.approx(2.0)
    concave = _allowance(-(x**2))                    # a crest dips nowhere: no allowance
    assert not concave.any()


@pytest.mark.parametrize("k", [1, 3, 5, 9])
def test_dilation_by_a_square_is_every_cell_within_reach(k):
    """The footprint's k x k dilation (two running maxima) against the definition, summed here
    cell by cell: a cell is set when any set cell lies within (k - 1)/2 cells along both axes;
    nothing wraps round or comes in from beyond the edges (set cells on every edge and a
    corner, a lattice narrower than k)."""
    from thirdbody.particle.surface import dilate

    rng = np.random.default_rng(k)
    reach = (k - 1) // 2
    for shape in ((23, 31), (4, 40)):
        mask = rng.random(shape) < 0.03
        mask[0, 5] = mask[-1, 7] = mask[3, 0] = mask[2, -1] = mask[-1, -1] = True
        expected = np.zeros(shape, dtype=bool)
        for j, i in zip(*np.nonzero(mask), strict=True):
            expected[max(j - reach, 0):j + reach + 1, max(i - reach, 0):i + reach + 1] = True
        out = dilate(mask, k)
        assert out.dtype == bool
        np.testing.assert_array_equal(out, expected)
