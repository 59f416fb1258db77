"""Touching particles over several load steps, each step started from the poses and contact
histories the last one left (as a run chains them), against references computed here:

* identical spheres pressed into each other on a periodic square lattice, compressed in three
  force steps: at every step each plate contact carries F_N/9 and the gap is Hertz's at each
  plate, the pair contacts keep Hertz's force at the unchanged overlap, and every particle
  carries the same bits (the histories of identical contacts stay identical);
* a touching lattice of random radii compressed in 20 force steps (slow): at every step each
  particle is balanced, the pair forces cancel, Coulomb holds cell by cell, every overlap of
  the rigid shapes found by brute force over all pairs and images is a loaded contact with
  that approach and no contact is loaded without one, and the particles numbered in reverse
  give the same bits step after step;
* a step in which the particles turn, after :func:`wrap` moved one across a side of the box
  and renamed its contact: the same step as without the wrap;
* a lattice of random radii shrunk apart, whose first step pushes a sphere sideways along the
  plates and then takes the neighbour that pushed it away: every sphere held by the plates
  alone ends with no friction and no sideways motion (its statics), as a sphere alone would.

The overlaps are the spheres' own geometry (centre distances, all nine images), not the
package's contact detection.
"""

import itertools
import math

import numpy as np
import pytest

from test_network_cluster import (
    E_STAR,
    E_STAR_PAIR,
    F,
    R,
    check_balanced,
    check_contact_laws,
    sphere,
    square_lattice,
)
from thirdbody.network import Body, cluster
from thirdbody.network.cluster import (
    ClusterConvergenceError,
    ClusterNumerics,
    solve_cluster,
    wrap,
)
from thirdbody.shapes import Sphere

MU = 0.3


def compress(bodies, side, loads, numerics, check, mu=MU):
    """Force steps to each of ``loads`` (N, total), each from the last one's poses and
    histories after :func:`wrap`, friction ``mu`` everywhere; ``check(result, step)`` after
    each."""
    histories, gap = {}, None
    for k, load in enumerate(loads):
        result = solve_cluster(bodies, histories, mu_up=mu, mu_low=mu, mu_pp=mu, force=load,
                               gap_start=gap, box=(side, side), numerics=numerics)
        check(result, k)
        bodies, histories = wrap(result.bodies, result.histories, (side, side))
        gap = result.gap


def overlaps(bodies, side, gap):
    """Every overlap of the rigid spheres, by brute force: {(i, j, image): depth} for j's image
    (j's centre plus image times the side) closer to i than r_i + r_j, and {(i, plate): depth}
    for a sphere through a plate (m)."""
    out = {}
    for i, j in itertools.combinations(range(len(bodies)), 2):
        for image in itertools.product((-1, 0, 1), repeat=2):
            d = bodies[j].centre + side * np.array([*image, 0.0]) - bodies[i].centre
            depth = bodies[i].shape.radius + bodies[j].shape.radius - float(np.linalg.norm(d))
            if depth > 0:
                out[(i, j, image)] = depth
    for i, b in enumerate(bodies):
        r, z = b.shape.radius, b.centre[2]
        if z - r < 0:
            out[(i, "lower")] = r - z
        if z + r > gap:
            out[(i, "upper")] = z + r - gap
    return out


@pytest.mark.parametrize("mu", [MU, 0.0])
def test_identical_pressed_spheres_compressed_in_three_steps_stay_hertzian_at_every_step(mu):
    """3 × 3 identical spheres pressed 0.1 % of 2R into each other, F_N/9 = 0.2, 0.35 and
    0.5 N each over three steps (60 cells per size, tol 1e-6). By symmetry the pair contacts
    stay horizontal and carry no vertical load, so at every step each plate contact carries
    F_N/9, the gap is 2R − 2 δ(F_N/9) with δ = (9 W²/(16 E*² R))^(1/3), and every pair keeps
    Hertz's load between two spheres at the overlap 2R·10⁻³ (the centres do not move
    sideways). Measured: the gap within 0.27 % of δ, the pair forces −1.0 % (both the grid's
    error at 4 cells across the radius). Frictionless too (μ = 0: the spheres' spins are free
    modes the solve must leave alone). The histories carried from step to step keep the
    particles' tractions identical: every contact with the upper plate carries the same force to
    1e-9, and so does every contact with the lower plate and every pair."""
    n = 3
    bodies, side = square_lattice(n, -1e-3)
    hertz_pair = 4 / 3 * E_STAR_PAIR * math.sqrt(R / 2) * (2 * R * 1e-3) ** 1.5
    loads = [0.2, 0.35, 0.5]
    seen = []

    def check(result, k):
        check_balanced(result)
        check_contact_laws(result, mu)
        load = loads[k]
        assert result.normal_force == pytest.approx(n * n * load, rel=1e-5)
        for side_ in ("lower", "upper"):
            plates = [c.normal_force for c in result.contacts if c.j == side_]
            assert len(plates) == n * n
            assert max(plates) - min(plates) <= 1e-9 * load
            assert np.mean(plates) == pytest.approx(load, rel=1e-5)
        delta = (9 * load**2 / (16 * E_STAR**2 * R)) ** (1 / 3)
        assert result.gap == pytest.approx(2 * R - 2 * delta, abs=0.01 * delta)
        pairs = [c.normal_force for c in result.contacts if not isinstance(c.j, str)]
        assert len(pairs) == 2 * n * n
        assert max(pairs) - min(pairs) <= 1e-9 * load
        assert np.mean(pairs) == pytest.approx(hertz_pair, rel=0.03)
        assert np.abs(result.translation[:, :2]).max() < 1e-3 * delta
        seen.append(result.gap)

    compress(bodies, side, [n * n * w for w in loads], ClusterNumerics(resolution=60, tol=1e-6),
             check, mu)
    assert len(seen) == 3 and seen[0] > seen[1] > seen[2]


@pytest.mark.slow
def test_a_touching_lattice_of_random_radii_compressed_in_twenty_steps_keeps_every_law():
    """The 3 × 3 lattice of benchmarks/cluster_lattice.py at gap 0 (radii R (1 + 5e-4 N(0,1)),
    seed 2: 11 pair contacts load), compressed in 20 force steps of 0.025 N a sphere to 0.5 N,
    20 cells per size, tol 1e-6, and again with the particles numbered in reverse. At every
    step: each particle balanced, the pair forces cancel and Coulomb holds cell by cell; every
    overlap of the rigid spheres (brute force over all pairs and images) is a contact with a
    positive normal force and that approach (to 1e-9 of it), and no pair is loaded without an
    overlap; the reversed numbering gives the same poses, gap and forces bit for bit. Measured:
    15 passes in the first step, 4-10 in the others; about 15 s each way."""
    n = 3
    bodies, side = square_lattice(n, 0.0, spread=5e-4, seed=2)
    loads = [n * n * 0.5 * k / 20 for k in range(1, 21)]
    numerics = ClusterNumerics(resolution=20, tol=1e-6)
    forward = []

    def check(result, k):
        check_balanced(result)
        check_contact_laws(result, MU)
        assert result.normal_force == pytest.approx(loads[k], rel=1e-5)
        rigid = overlaps(list(result.bodies), side, result.gap)
        reports = {c.key: c for c in result.contacts}
        for key, depth in rigid.items():
            assert key in reports, f"step {k}: {key} overlaps by {depth:.2e} m, no contact"
            assert reports[key].normal_force > 0
            assert reports[key].approach == pytest.approx(depth, rel=1e-9)
        loaded = {key for key, c in reports.items() if c.normal_force > 0}
        assert loaded <= set(rigid)
        assert sum(not isinstance(key[1], str) for key in loaded) >= 8      # a network
        forward.append(result)

    compress(bodies, side, loads, numerics, check)
    assert len(forward) == 20
    backward = []
    compress(bodies[::-1], side, loads, numerics, lambda result, k: backward.append(result))
    for a, b in zip(forward, backward, strict=True):
        assert np.array_equal(b.translation[::-1], a.translation)
        assert np.array_equal(b.rotation[::-1], a.rotation)
        assert np.array_equal(b.force_residual[::-1], a.force_residual)
        assert b.gap == a.gap


def test_a_turning_step_after_wrap_is_the_step_without_it():
    """The groove of test_network_cluster (sphere C on A and B, μ = 0.6) with A starting left
    of the box (x = −1.2R in a box of 10R): wrap moves it to 8.8R and renames its contact with
    C to the image (1, 0), translating the stored history. Then the upper plate moves by
    (0.5, 0.25) µm and the spheres turn (by 1.4e-4 rad; 3e-3 rad further without the
    histories, which therefore matter here). With or without the wrap the step gives the same
    turns and translations to 1e-8 of the turn (measured 3e-10) and the same forces to 1e-9 of F
    (measured 1.4e-13 N)."""
    L = 10 * R
    s = 1.2 * R
    zc = R + math.sqrt(4 * R * R - s * s) - 8e-6
    # tol 1e-5, not 1e-6: without histories this step stalls at 2.1e-6 (30 cells per size,
    # the tolerance floor of docs/methods/network.md), and at 1e-6 the passes near that floor
    # spread the wrap's rounding to 4.5e-8 of the turn (3e-10 at 1e-5)
    numerics = ClusterNumerics(resolution=30, tol=1e-5)
    first = solve_cluster([sphere(-s, R), sphere(s, R), sphere(0.0, zc)], mu_up=0.6,
                          mu_low=0.6, mu_pp=0.6, force=F, numerics=numerics, box=(L, L))
    assert (0, 2, (0, 0)) in first.histories
    moved, histories = wrap(first.bodies, first.histories, (L, L))
    assert (0, 2, (1, 0)) in histories
    assert moved[0].centre[0] == pytest.approx(L - s, abs=1e-5)

    def turn(bodies, hist):
        result = solve_cluster(bodies, hist, mu_up=0.6, mu_low=0.6, mu_pp=0.6, force=F,
                               gap_start=first.gap, plate_shift=(5e-7, 2.5e-7),
                               numerics=numerics, box=(L, L))
        check_balanced(result)
        return result

    plain, wrapped = turn(list(first.bodies), first.histories), turn(moved, histories)
    forgetful = turn(list(first.bodies), {})
    turned = np.abs(plain.rotation).max()
    assert turned > 1e-4
    assert np.abs(forgetful.rotation - plain.rotation).max() > 10 * turned
    # rounding only (measured 2.7e-10 and 3e-10 of these scales)
    assert np.abs(wrapped.rotation - plain.rotation).max() <= 1e-8 * turned
    assert np.abs(wrapped.translation - plain.translation).max() <= 1e-8 * turned * R
    assert wrapped.gap == pytest.approx(plain.gap, abs=1e-15)

    def forces(result):
        return {(c.i, c.j): np.array([c.normal_force, *c.tangential_force])
                for c in result.contacts}

    got, expected = forces(wrapped), forces(plain)
    assert set(got) == set(expected)
    for key, value in expected.items():
        assert np.abs(got[key] - value).max() <= 1e-9 * F


def apart_lattice(n, seed):
    """``square_lattice(n, 0, 5e-4, seed)`` with every radius shrunk by half the largest overlap
    of the rigid spheres (:func:`overlaps`), each still standing on the lower plate: no overlap,
    the closest pair touching, the others up to a few micrometres apart."""
    bodies, side = square_lattice(n, 0.0, spread=5e-4, seed=seed)
    cut = 0.5 * max(overlaps(bodies, side, math.inf).values()) * (1 + 1e-9)
    return [Body(Sphere(b.shape.radius - cut), b.material,
                 centre=(b.centre[0], b.centre[1], b.shape.radius - cut)) for b in bodies], side


@pytest.mark.parametrize("way_back", [True, False])
def test_a_sphere_pushed_along_the_plates_comes_back_when_its_neighbour_leaves(monkeypatch,
                                                                                way_back):
    """The 4 × 4 lattice of seed 3 shrunk apart (:func:`apart_lattice`; 0.89 µm off every
    radius), 0.025 N a sphere, 20 cells per size, tol 1e-6. In the rotation-free first phase
    a neighbour pushes sphere 8 2.55 µm sideways while the upper plate reaches it, then moves
    back: sphere 8 is left sliding at both plates, 2μN unbalanced, on the plateau of its
    contacts' law (their force stays μN until the motion takes the step's slip back), where
    its model has no stiffness along the slip. Without the step back for stranded groups
    (``_WAY_BACK``) the attempt fails there (scaled residual 0.07); with it, it converges
    (measured: 9 passes).

    Reference, from statics alone: a sphere whose only loaded contacts are the two rigid plates
    balances its moment about the centre only with equal tangential forces at both contacts,
    and its force only with opposite ones: both are zero, both contacts stick, and since
    nothing loads it sideways it has not moved sideways. Measured: the 11 such spheres carry
    exactly zero tangential force and moved exactly 0 sideways. Also every particle balanced,
    Newton's third law, Coulomb cell by cell."""
    monkeypatch.setattr(cluster, "_WAY_BACK", way_back)
    bodies, side = apart_lattice(4, 3)
    assert not overlaps(bodies, side, math.inf)
    kwargs = dict(mu_up=MU, mu_low=MU, mu_pp=MU, force=16 * 0.025, box=(side, side),
                  numerics=ClusterNumerics(resolution=20, tol=1e-6), retry=False)
    if not way_back:
        with pytest.raises(ClusterConvergenceError, match="particle 8"):
            solve_cluster(bodies, **kwargs)
        return
    result = solve_cluster(bodies, **kwargs)
    check_balanced(result)
    check_contact_laws(result, MU)
    held = 0
    for i in range(len(bodies)):
        loaded = [c for c in result.contacts_of(i) if c.normal_force > 0]
        if {c.j for c in loaded} != {"lower", "upper"}:
            continue
        held += 1
        for c in loaded:
            assert c.state == "stick"
            assert np.linalg.norm(c.tangential_force) <= 1e-9 * c.normal_force   # measured 0
        assert np.abs(result.translation[i, :2]).max() <= 1e-12        # m; measured 0
    assert held >= 10                                                    # measured 11


def test_the_way_back_is_kept_only_where_the_model_falls(monkeypatch):
    """The step back of the case above, taken from the solve where it was used, overshooting
    tenfold: the stranded sphere's contacts would slide the other way, its residual no smaller
    in the model, and the passes' step is kept (None)."""
    taken = []
    way_back = cluster._way_back

    def spy(*args):
        out = way_back(*args)
        if out is not None:
            taken.append((args, out))
        return out

    monkeypatch.setattr(cluster, "_way_back", spy)
    bodies, side = apart_lattice(4, 3)
    solve_cluster(bodies, mu_up=MU, mu_low=MU, mu_pp=MU, force=16 * 0.025, box=(side, side),
                  numerics=ClusterNumerics(resolution=20, tol=1e-6), retry=False)
    assert taken
    args, (step, _, _) = taken[0]
    assert not np.array_equal(step, args[6])                 # it replaced the passes' step
    solve_model = cluster._solve_model

    def overshooting(*a, **k):
        x, dh = solve_model(*a, **k)
        return 10.0 * x, dh

    monkeypatch.setattr(cluster, "_solve_model", overshooting)
    assert way_back(*args) is None
