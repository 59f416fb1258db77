"""Broad phase: the KD-tree candidate pairs equal a brute-force O(n²) test of every pair (and,
in a periodic box, of every pair with each of the nine images in x and y), on random
polydisperse sets; bodies and bad inputs."""

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import thirdbody as tb
from thirdbody.network import Body, candidate_pairs
from thirdbody.shapes import Ellipsoid, Sphere


def brute_force(centres, radii, box=None):
    """{(i, j): shift} for every pair whose bounding spheres meet, testing all n² pairs (and, in
    a box, the nine images of j around i after wrapping both into the box)."""
    c = np.array(centres, dtype=float)
    r = np.asarray(radii, dtype=float)
    if box is not None:
        box = np.asarray(box, dtype=float)
        wrapped = c.copy()
        wrapped[:, :2] = np.mod(c[:, :2], box)
        base = wrapped[:, :2] - c[:, :2]            # what wrapping added to each centre
    images = [(0, 0)] if box is None else list(itertools.product((-1, 0, 1), repeat=2))
    out = {}
    for mx, my in images:
        shift = np.zeros((len(r), len(r), 3))
        if box is not None:
            shift[..., :2] = base[None, :, :] - base[:, None, :] + (mx * box[0], my * box[1])
        d = c[None, :, :] + shift - c[:, None, :]
        meet = np.linalg.norm(d, axis=-1) <= r[:, None] + r[None, :]
        for i, j in zip(*np.nonzero(np.triu(meet, k=1)), strict=True):
            assert (i, j) not in out, "two images of one pair meet"
            out[(int(i), int(j))] = shift[i, j]
    return out


def as_dict(result):
    return {(i, j): s for i, j, s in result}


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("periodic", [False, True])
def test_equals_brute_force_on_random_polydisperse_sets(seed, periodic):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 120))
    box = np.array([10.0, 7.0]) if periodic else None
    radii = rng.uniform(0.1, 1.0, n) * rng.choice([0.3, 1.0], n)     # two families of sizes
    centres = np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 7, n),
                               rng.uniform(-1, 1, n)])
    if periodic:       # some centres outside the box: they are wrapped
        centres[: n // 5, :2] += rng.integers(-2, 3, (n // 5, 2)) * box
    found = candidate_pairs(centres, radii, box=box)
    expected = brute_force(centres, radii, box)
    assert len(expected) > 5
    assert set(as_dict(found)) == set(expected)
    for key, shift in as_dict(found).items():
        np.testing.assert_allclose(shift, expected[key], atol=1e-12)
    assert (found.pairs[:, 0] < found.pairs[:, 1]).all()
    assert [tuple(p) for p in found.pairs] == sorted(tuple(p) for p in found.pairs)


def test_pairs_across_the_periodic_boundary_get_the_image_shift():
    centres = [[0.2, 3.0, 0.0], [9.9, 3.1, 0.1], [5.0, 6.9, 0.0], [5.1, 0.05, 0.0]]
    found = as_dict(candidate_pairs(centres, [0.3, 0.3, 0.2, 0.2], box=(10.0, 7.0)))
    assert set(found) == {(0, 1), (2, 3)}
    np.testing.assert_allclose(found[(0, 1)], [-10.0, 0.0, 0.0])
    np.testing.assert_allclose(found[(2, 3)], [0.0, 7.0, 0.0])
    # without the box they are far apart
    assert len(candidate_pairs(centres, [0.3, 0.3, 0.2, 0.2])) == 0


def test_touching_bounding_spheres_count_and_z_is_not_periodic():
    found = candidate_pairs([[0, 0, 0], [1.0, 0, 0], [0, 0, 9.5]], [0.5, 0.5, 0.5],
                            box=(10.0, 10.0))
    assert [tuple(p) for p in found.pairs] == [(0, 1)]


def test_bad_inputs_name_the_argument():
    with pytest.raises(ValueError, match="centres"):
        candidate_pairs(np.zeros((3, 2)), [1, 1, 1])
    with pytest.raises(ValueError, match="radii"):
        candidate_pairs(np.zeros((3, 3)), [1, 1])
    with pytest.raises(ValueError, match="radii"):
        candidate_pairs(np.zeros((2, 3)), [1, -1])
    with pytest.raises(ValueError, match="box"):
        candidate_pairs(np.zeros((2, 3)), [1, 1], box=(3.0,))
    with pytest.raises(ValueError, match="box"):
        candidate_pairs(np.zeros((2, 3)), [1, 1], box=(3.0, 30.0))    # < 4 r_max
    assert len(candidate_pairs(np.zeros((1, 3)), [1.0])) == 0


def test_body_validates_and_moves_rigidly():
    mat = tb.Material(1e9, 0.3)
    body = Body(Ellipsoid((1.0, 0.5, 0.3)), mat, Rotation.from_rotvec([0, 0, 0.3]), (1, 2, 3))
    assert body.size == 1.0
    R = Rotation.from_rotvec([0.2, -0.1, 0.4])
    moved = body.transformed(R, (0.5, 0, 0))
    p = np.array([0.1, 0.2, -0.3])
    np.testing.assert_allclose(moved.to_world(p), R.apply(body.to_world(p)) + np.array([0.5, 0, 0]))
    with pytest.raises(ValueError, match="centre"):
        Body(Sphere(1.0), mat, centre=(0, 0))
    with pytest.raises(ValueError, match="centre"):
        Body(Sphere(1.0), mat, centre=(0, np.nan, 0))
    with pytest.raises(TypeError, match="shape"):
        Body("sphere", mat)
    with pytest.raises(TypeError, match="material"):
        Body(Sphere(1.0), 1e9)
    with pytest.raises(ValueError, match="rotation"):
        Body(Sphere(1.0), mat, rotation=Rotation.random(2, random_state=0))
