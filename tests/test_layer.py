"""A layer of particles between the same two plates: the exact Hertz sum for spheres, equal
shares of identical particles, order independence, the balances at every step, a cascade,
overlap refusals, the generator, the configuration file and a layer of one = the single
particle."""

import math
import warnings

import numpy as np
import pytest
from scipy.optimize import brentq

import thirdbody as tb
from thirdbody.layer import LayerError, first_overlap
from thirdbody.shapes import Ellipsoid, Sphere

STEEL = tb.Material(210e9, 0.3)
SOFT = tb.Material(1e9, 0.3)


def spheres(radii, spacing=3e-3, material=SOFT):
    return tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(r), material), (spacing * i, 0.0))
                     for i, r in enumerate(radii)])


def hertz_sum(radii, E_star, total):
    """The exact answer for spheres between rigid plates: each carries
    F_i = (√2/3) E* √R_i (2R_i − h)^{3/2} (Hertz at both poles, approach (2R_i − h)/2 each);
    h from Σ F_i = total."""
    radii = np.asarray(radii)

    def forces(h):
        return math.sqrt(2) / 3 * E_star * np.sqrt(radii) * np.clip(2 * radii - h, 0, None) ** 1.5

    h = brentq(lambda h: forces(h).sum() - total, 0.5 * radii.max(), 2 * radii.max(),
               xtol=1e-16, rtol=1e-15)
    return h, forces(h)


def quiet_run(sim):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return sim.run()


def test_polydisperse_spheres_match_the_exact_hertz_sum():
    """Ten sizes, R_i = 1 mm (1 + 0.0005 i), at the load where the smallest sphere is pressed
    by 8 µm (2R_0 − h), so the loads range over a factor 2.7. Largest force error (measured):
    0.38 % at 50 cells per radius, 0.11 % at 100, 0.07 % at 200; the stated bound is 1 % at
    100 and 200, and the error must fall from 50 to 200."""
    radii = [1e-3 * (1 + 0.0005 * i) for i in range(10)]
    E_star = SOFT.E_star
    target = 2 * radii[0] - 8e-6
    total = brentq(lambda F: hertz_sum(radii, E_star, F)[0] - target, 1e-2, 1e3)
    h, forces = hertz_sum(radii, E_star, total)
    errors = {}
    for resolution in (50, 100, 200):
        sim = tb.Simulation(spheres(radii), tb.Plates(0.3), tb.ForceTable([total]),
                            resolution=resolution, maps_every=0)
        ds = quiet_run(sim)
        assert sim.status == "complete"
        F = ds.normal_force.values[0]
        assert int(ds.loaded[0]) == 10 and np.all(F > 0)
        assert math.isclose(F.sum(), total, rel_tol=1e-12)
        errors[resolution] = (np.max(np.abs(F / forces - 1)),
                              abs((2 * radii[-1] - ds.plate_gap.values[0])
                                  / (2 * radii[-1] - h) - 1))
    for resolution in (100, 200):
        assert errors[resolution][0] < 0.01 and errors[resolution][1] < 0.01, errors
    assert errors[200][0] < errors[50][0] and errors[200][1] < errors[50][1], errors


def test_identical_spheres_share_equally_and_each_is_the_single_particle_result():
    R, n, total = 1e-3, 4, 8.0
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(R), SOFT), xy)
                      for xy in ((0, 0), (4e-3, 0), (0, 5e-3), (-3e-3, -3e-3))])
    sim = tb.Simulation(layer, tb.Plates(0.3), tb.LinearRamp(stop=total, steps=2),
                        resolution=60, maps_every=0)
    ds = quiet_run(sim)
    single = tb.particle_view(quiet_run(tb.Simulation(
        tb.Particle(Sphere(R), SOFT), tb.Plates(0.3), tb.LinearRamp(stop=total / n, steps=2),
        resolution=60, maps_every=0)))
    shares = ds.load_share.values
    assert np.all(shares == shares[:, :1])                   # the same arithmetic: exactly equal
    assert np.allclose(shares, 1 / n, rtol=1e-14)
    for name in ("normal_force", "contact_area", "approach"):
        expected = single[name].values
        got = ds[name].values
        for i in range(n):
            np.testing.assert_allclose(got[:, i], expected, rtol=1e-6, err_msg=name)
    np.testing.assert_allclose(ds.plate_gap.values, single.plate_gap.values, rtol=1e-9)


def test_permuting_the_particles_gives_identical_results():
    radii = [1e-3, 0.998e-3, 1.003e-3]
    mats = [SOFT, tb.Material(2e9, 0.25), SOFT]
    tilts = [0.0, 0.0, 12.0]
    shapes = [Sphere(radii[0]), Sphere(radii[1]), Ellipsoid((1.1e-3, 1.0e-3, 0.97e-3))]
    placed = [tb.PlacedParticle(tb.Particle(s, m, t), (3e-3 * i, 1e-3 * i))
              for i, (s, m, t) in enumerate(zip(shapes, mats, tilts, strict=True))]
    load = tb.LinearRamp(stop=6.0, steps=2)

    def run(order):
        sim = tb.Simulation(tb.Layer([placed[i] for i in order]), tb.Plates(0.2, 0.25), load,
                            resolution=50, maps_every=0)
        ds = quiet_run(sim)
        assert sim.status == "complete"
        return ds.drop_vars([v for v in ds.data_vars if v.startswith("time_")])

    a, b = run([0, 1, 2]), run([2, 0, 1])
    assert int(a.loaded[-1]) >= 2
    back = b.isel(particle=[1, 2, 0])
    for name, var in a.data_vars.items():
        if name.startswith("event_"):
            continue
        other = back[name] if "particle" in var.dims else b[name]
        assert np.array_equal(var.values, other.values, equal_nan=var.dtype.kind == "f"), name
    # the events, with b's particle numbers mapped back to a's
    to_a = {0: 2, 1: 0, 2: 1}

    def events(ds, mapping):
        return sorted(zip(ds.event_step.values.tolist(),
                          [mapping[int(p)] for p in ds.event_particle.values],
                          ds.event_kind.values.tolist(), ds.event_value.values.tolist(),
                          strict=True))

    assert events(a, {0: 0, 1: 1, 2: 2}) == events(b, to_a) and len(events(a, to_a)) >= 2


def test_every_step_balances_the_load_and_each_particle():
    layer = tb.Layer.random(box=(8e-3, 8e-3), material=SOFT, count=5, size=0.8e-3,
                            size_std=0.02e-3, distribution="normal", shape="ellipsoid",
                            orientation="tilted", max_tilt_deg=25.0, seed=5)
    sim = tb.Simulation(layer, tb.Plates(0.15, 0.2), tb.LinearRamp(stop=20.0, steps=3),
                        resolution=40, maps_every=1)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    F = ds.normal_force.values
    np.testing.assert_allclose(F.sum(axis=1), ds.load_value.values, rtol=1e-12)
    np.testing.assert_allclose(ds.total_force.values, ds.load_value.values, rtol=1e-12)
    assert np.all(ds.share_error.values <= 1e-7)
    loaded = ds.state.values != tb.simulation.STATES.index("unloaded")
    assert np.array_equal(loaded.sum(axis=1), ds.loaded.values)
    assert np.all(F[~loaded] == 0) and np.all(F[loaded] > 0)
    # each loaded particle: its own forces and tilting moment balance (from its fields)
    assert not ds.balanced.values.any()
    for name in ("force_residual", "tangential_force_residual", "moment_residual"):
        assert np.nanmax(ds[name].values[loaded]) < 1e-6, name
    # pressures integrate to each particle's force on both plates
    dA = ds.cell_size.values ** 2
    p = ds.pressure.sum(("map_i", "map_j")).values * dA[None, :, None]
    for k, step in enumerate(ds.map_step.values):
        np.testing.assert_allclose(p[k, :, 0], F[step], rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(p[k, :, 1], F[step], rtol=1e-6, atol=1e-12)
    # every loaded particle's plate gap is the layer's
    assert np.all(ds.compression.values > 0)


def _ellipsoid_and_sphere(R):
    a, b, c = 1e-3, 0.8e-3, 0.6e-3
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Ellipsoid((a, b, c)), STEEL, 20.0), (0, 0)),
                      tb.PlacedParticle(tb.Particle(Sphere(R), STEEL), (4e-3, 0.0))])
    sim = tb.Simulation(layer, tb.Plates(0.3), tb.ForceTable([1.0]), resolution=200,
                        maps_every=0)
    first = sim.sharing.equilibrium(sim.schedule[0], sim._initial_state(), None)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    return first, ds, [tb.simulation.STATES[int(s)] for s in ds.state.values[0]]


def test_a_turn_hands_the_load_to_a_neighbour():
    """A cascade built by hand, checked with the ellipse's height and Hertz. A: a steel
    ellipsoid 1 x 0.8 x 0.6 mm tilted 20° (height 1.319 mm) with μ = 0.3 < ξ(20°): alone it
    would turn to θ_eq = 10.47° (height 1.2347 mm). B: a steel sphere of radius 0.62 mm
    (height 1.24 mm), not touched at first. As A turns the plate comes down onto B, which takes
    the load; A loses its load, and with it its couple, where its height meets the gap that B
    alone holds under F_N: it stops there, short of θ_eq."""
    a, c, R, total = 1e-3, 0.6e-3, 0.62e-3, 1.0
    first, ds, state = _ellipsoid_and_sphere(R)
    assert first[1] is None and first[0].force == total     # B untouched at the start
    assert int(ds.turned[0, 0]) == 1 and state[1] == "stick"
    h = 2 * R - (3 * total / (math.sqrt(2) * STEEL.E_star * math.sqrt(R))) ** (2 / 3)
    # the tilt at which the ellipse's height 2 sqrt(a² sin²θ + c² cos²θ) is h
    theta = math.degrees(math.asin(math.sqrt(((h / 2) ** 2 - c**2) / (a**2 - c**2))))
    tilt = float(ds.orientation.sel(component="y")[0, 0])
    assert abs(tilt - theta) < 0.2, (tilt, theta)           # the scan's height: ~0.1°
    share_A = float(ds.load_share[0, 0])
    assert share_A < 0.05
    assert abs(float(ds.plate_gap[0]) - h) < 0.05 * (2 * R - h)


def test_a_neighbour_too_short_to_take_the_load_lets_the_turn_reach_the_rigid_angle():
    """The same pair with B's height 1.23 mm, below A's height at θ_eq: A turns to the rigid
    equilibrium angle and B is never touched."""
    from thirdbody import rigid

    first, ds, state = _ellipsoid_and_sphere(0.615e-3)
    assert state == ["rotate", "unloaded"] and first[1] is None
    theta_eq = math.degrees(rigid.ellipsoid_equilibrium_angle(1e-3, 0.6e-3, math.radians(20.0),
                                                             0.3))
    assert abs(float(ds.orientation.sel(component="y")[0, 0]) - theta_eq) < 0.02


def test_overlapping_particles_are_refused_with_the_pair_named():
    p = tb.Particle(Sphere(1e-3), SOFT)
    with pytest.raises(LayerError, match="particles 1 and 2 overlap"):
        tb.Layer([tb.PlacedParticle(p, (0, 0)), tb.PlacedParticle(p, (5e-3, 0)),
                  tb.PlacedParticle(p, (6.9e-3, 0))])
    tb.Layer([tb.PlacedParticle(p, (0, 0)), tb.PlacedParticle(p, (2.05e-3, 0))])


def test_the_overlap_test_agrees_with_sphere_geometry():
    """Two spheres resting on the lower plate overlap exactly when their centres are closer
    than R1 + R2 (in 3-D: the centres are at heights R1 and R2)."""
    rng = np.random.default_rng(3)
    mistakes = 0
    for _ in range(60):
        r1, r2 = rng.uniform(0.5e-3, 1.5e-3, 2)
        d = rng.uniform(0.5, 1.2) * (r1 + r2)
        exact = math.hypot(d, r1 - r2) < r1 + r2
        margin = abs(math.hypot(d, r1 - r2) - (r1 + r2)) / (r1 + r2)
        found = first_overlap([Sphere(r1), Sphere(r2)], [tb.orientation.tilt(0.0)] * 2,
                              np.array([(0.0, 0.0, r1), (d, 0.0, r2)])) is not None
        if margin > 0.01:                                    # beyond the ray sampling
            mistakes += found != exact
    assert mistakes == 0


def test_a_turn_into_a_neighbour_stops_the_run_with_the_step_recorded():
    """The tilted ellipsoid grows wider along x as it turns towards lying flat (half-width
    0.962 mm at 20°, 0.995 mm at the end): a sphere placed 10 µm beyond its start is hit."""
    a, b, c = 1e-3, 0.8e-3, 0.6e-3
    A = tb.PlacedParticle(tb.Particle(Ellipsoid((a, b, c)), STEEL, 20.0), (0.0, 0.0))
    R = 0.3e-3

    def layer(x):
        return tb.Layer([A, tb.PlacedParticle(tb.Particle(Sphere(R), STEEL), (x, 0.0))])

    lo, hi = 1.0e-3, 1.5e-3                                  # closest accepted placement
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        try:
            layer(mid)
            hi = mid
        except LayerError:
            lo = mid
    sim = tb.Simulation(layer(hi + 10e-6), tb.Plates(0.3), tb.ForceTable([0.5, 0.6]),
                        resolution=100, maps_every=0)
    ds = quiet_run(sim)
    assert sim.status.startswith("failed: step 0") and "particles 0 and 1 touch" in sim.status
    assert ds.sizes["step"] == 1 and int(ds.turned[0, 0]) == 1
    far = tb.Simulation(layer(hi + 100e-6), tb.Plates(0.3), tb.ForceTable([0.5]),
                        resolution=100, maps_every=0)
    quiet_run(far)
    assert far.status == "complete"


def test_the_generator_is_seeded_places_without_overlap_and_draws_the_sizes():
    kw = dict(box=(30e-3, 30e-3), material=SOFT, count=60, size=0.5e-3, size_std=0.1e-3,
              distribution="lognormal", shape="potato", seed=11)
    one, two = tb.Layer.random(**kw), tb.Layer.random(**kw)
    assert [repr(p.particle.shape) for p in one] == [repr(p.particle.shape) for p in two]
    assert np.array_equal(one.positions, two.positions)
    assert repr(tb.Layer.random(**{**kw, "seed": 12})[0].particle.shape) != \
        repr(one[0].particle.shape)
    sizes = np.array([p.particle.shape.size for p in one])
    # potato sizes include their waves (amplitude 0.05): the drawn size is the semi-axis
    semi = np.array([p.particle.shape._axes.max() for p in one])
    assert abs(semi.mean() / 0.5e-3 - 1) < 0.1 and abs(semi.std() / 0.1e-3 - 1) < 0.3
    xy = one.positions
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= sizes[:, None] + sizes[None, :] - 1e-12)
    assert np.all(np.abs(xy) <= 15e-3)
    fraction = tb.Layer.random(box=(20e-3, 20e-3), material=SOFT, area_fraction=0.2,
                               size=1e-3, seed=1)
    covered = sum(math.pi * p.particle.shape.size ** 2 for p in fraction) / 400e-6
    assert 0.2 <= covered < 0.2 + math.pi * 1e-6 / 400e-6 + 1e-12
    listed = tb.Layer.random(box=(20e-3, 20e-3), material=SOFT, count=5,
                             distribution="list", sizes=[1e-3, 0.5e-3], seed=1)
    assert [p.particle.shape.size for p in listed] == [1e-3, 0.5e-3, 1e-3, 0.5e-3, 1e-3]


@pytest.mark.parametrize("kw, message", [
    (dict(count=500), "too full"),
    (dict(count=2, size=20e-3), "does not fit"),
    (dict(count=None), "exactly one of count and area_fraction"),
    (dict(shape="cube"), "layer.shape"),
    (dict(distribution="list"), "needs sizes"),
    (dict(size=-1.0), "layer.size"),
])
def test_the_generator_refuses_what_it_cannot_do(kw, message):
    args = dict(box=(10e-3, 10e-3), material=SOFT, count=3, size=1e-3, max_attempts=200)
    with pytest.raises((LayerError, ValueError), match=message):
        tb.Layer.random(**{**args, **kw})


@pytest.mark.parametrize("name", ["fig3", "fig4a", "fig5"])
def test_a_layer_of_one_is_the_single_particle_bit_for_bit(name):
    """The paper's configurations, first steps (all of them in the slow variant)."""
    _layer_of_one(name, steps=6)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fig3", "fig4a", "fig5"])
def test_a_layer_of_one_is_the_single_particle_bit_for_bit_all_steps(name):
    _layer_of_one(name, steps=None)


def _layer_of_one(name, steps):
    from importlib import resources

    from thirdbody.io import load_config

    cfg = load_config(resources.files("thirdbody") / "examples" / f"{name}.toml")
    particle, plates, load, numerics = cfg.build()
    if steps is not None:
        load = tb.ForceTable([s.value for s in load.schedule()[:steps]])
    single = quiet_run(tb.Simulation(particle, plates, load, **numerics))
    layer = quiet_run(tb.Simulation(tb.Layer.of(particle), plates, load, **numerics))
    compared = 0
    for var in single.data_vars:
        if var.startswith("time_"):
            continue
        a, b = single[var].values, layer[var].values
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), var
        compared += 1
    assert compared >= 40


def test_config_files_accept_a_list_of_particles_and_a_generator(tmp_path):
    from thirdbody.io import ConfigError, load_config

    listed = tmp_path / "listed.toml"
    listed.write_text("""
[[particles]]
shape = "sphere"
radius = 1.0e-3
E = 1.0e9
nu = 0.3
x = 0.0
y = 0.0

[[particles]]
shape = "ellipsoid"
semi_axes = [1.0e-3, 0.8e-3, 0.7e-3]
E = 2.0e9
nu = 0.25
orientation_deg = 10.0
x = 4.0e-3
y = 1.0e-3

[plates]
mu_up = 0.3

[load]
program = "linear_ramp"
stop = 2.0
steps = 2
""")
    cfg = load_config(listed)
    layer, *_ = cfg.build()
    assert isinstance(layer, tb.Layer) and len(layer) == 2
    assert layer[1].xy == (4e-3, 1e-3) and layer[1].particle.material.E == 2e9
    again = tmp_path / "again.toml"
    again.write_text(cfg.to_toml())
    assert load_config(again).build()[0][1].xy == (4e-3, 1e-3)
    generated = tmp_path / "generated.toml"
    generated.write_text("""
[layer]
box = [10.0e-3, 10.0e-3]
count = 4
shape = "potato"
size = 0.8e-3
E = 1.0e9
nu = 0.3
seed = 2

[plates]
mu_up = 0.3

[load]
program = "gap_ramp"
stop = 0.02
steps = 2
""")
    layer, *_ = load_config(generated).build()
    assert len(layer) == 4
    bad = tmp_path / "bad.toml"
    bad.write_text(generated.read_text().replace("count = 4", "count = 4\narea_fraction = 0.1"))
    with pytest.raises(ConfigError, match="exactly one of count and area_fraction"):
        load_config(bad)
    both = tmp_path / "both.toml"
    both.write_text(listed.read_text() + generated.read_text().split("[plates]")[0])
    with pytest.raises(ConfigError, match=r"exactly one of \[particle\]"):
        load_config(both)
    overlapping = tmp_path / "overlap.toml"
    overlapping.write_text(listed.read_text().replace("x = 4.0e-3", "x = 1.0e-3"))
    with pytest.raises(ConfigError, match="particles 0 and 1 overlap"):
        load_config(overlapping)


def test_gap_control_loads_only_the_particles_the_gap_reaches():
    radii = [1e-3, 0.99e-3, 0.95e-3]
    sim = tb.Simulation(spheres(radii), tb.Plates(0.3), tb.GapRamp(stop=0.01, steps=2),
                        resolution=100, maps_every=0)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    h = 2e-3 * (1 - ds.load_value.values)
    np.testing.assert_allclose(ds.plate_gap.values, h, rtol=1e-9)
    for k in range(2):
        expected = [math.sqrt(2) / 3 * SOFT.E_star * math.sqrt(r) * max(2 * r - h[k], 0) ** 1.5
                    for r in radii]
        F = ds.normal_force.values[k]
        for f, e in zip(F, expected, strict=True):
            assert (f == 0) == (e == 0)
            if e:
                assert abs(f / e - 1) < 0.02


def test_the_events_table_and_a_resumed_layer_run():
    """Events follow the per-particle states; a layer run resumed from its snapshot after step
    0 ends exactly as the uninterrupted one."""
    a, b, c = 1e-3, 0.8e-3, 0.6e-3

    def make():
        layer = tb.Layer([
            tb.PlacedParticle(tb.Particle(Ellipsoid((a, b, c)), STEEL, 20.0), (0, 0)),
            tb.PlacedParticle(tb.Particle(Sphere(0.62e-3), STEEL), (4e-3, 0.0))])
        return tb.Simulation(layer, tb.Plates(0.3), tb.ForceTable([1.0, 2.0]), resolution=100,
                             maps_every=1)

    blobs = []
    whole = make()
    ds = whole.run(checkpoint=lambda sim, state: blobs.append(sim.snapshot(state)))
    assert whole.status == "complete"
    kinds = list(zip(ds.event_step.values.tolist(), ds.event_particle.values.tolist(),
                     ds.event_kind.values.tolist(), strict=True))
    # step 0: the ellipsoid turns until the sphere holds the plates above it (it rolls off,
    # 8.8°) and the sphere takes the load; at step 1 the plates come down a little further
    # and the ellipsoid, touched again, rolls off again by a fraction of a degree
    assert kinds == [(0, 0, "rolled_off"), (0, 1, "loaded"), (1, 0, "rolled_off")]
    values = ds.event_value.values
    assert values[1] == ds.normal_force.values[0, 1] == 1.0
    np.testing.assert_array_equal(values[[0, 2]], ds.rotation_angle.values[:, 0])
    assert 8.0 < values[0] < 10.5 and 0 < values[2] < 0.2
    resumed = make()
    _, start = resumed.restore(blobs[0])
    assert start == 1
    again = quiet_run_resume(resumed, blobs[0])
    for name, var in ds.data_vars.items():
        if name.startswith("time_"):
            continue
        assert np.array_equal(var.values, again[name].values,
                              equal_nan=var.dtype.kind == "f"), name


def quiet_run_resume(sim, blob):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return sim.run(resume_from=blob)


def test_the_load_sharing_converges_in_a_few_solves_per_particle(monkeypatch):
    """Warm starts and the secant of each particle's compliance: ten spheres over three load
    steps need 3.7 normal solves per particle and step (measured; Newton steps alone, without
    the secant, need 4.3)."""
    from thirdbody.particle.member import Member

    radii = [1e-3 * (1 + 0.0005 * i) for i in range(10)]
    total = brentq(lambda F: hertz_sum(radii, SOFT.E_star, F)[0] - (2 * radii[0] - 8e-6),
                   1e-2, 1e3)
    solves = []
    original = Member.at_force

    def counting(self, rotation, force):
        solves.append(force)
        return original(self, rotation, force)

    monkeypatch.setattr(Member, "at_force", counting)
    sim = tb.Simulation(spheres(radii), tb.Plates(0.3), tb.LinearRamp(stop=total, steps=3),
                        resolution=100, maps_every=0)
    ds = quiet_run(sim)
    assert sim.status == "complete" and int(ds.loaded[-1]) == 10
    assert len(solves) / 30 <= 4.0


def _five_tilted(layer, workers: int = 1):
    sim = tb.Simulation(layer, tb.Plates(0.1, 0.15), tb.LinearRamp(stop=20.0, steps=2),
                        resolution=40, maps_every=1, workers=workers)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    return ds


@pytest.fixture(scope="module")
def five_tilted():
    """Five tilted ellipsoids with low friction, in one process: several turn in the same
    round."""
    layer = tb.Layer.random(box=(10e-3, 10e-3), material=SOFT, count=5, size=0.8e-3,
                            size_std=0.02e-3, distribution="normal", shape="ellipsoid",
                            orientation="tilted", max_tilt_deg=25.0, seed=5)
    ds = _five_tilted(layer)
    assert int(ds.turned[0].sum()) >= 2
    return layer, ds


@pytest.mark.slow
def test_two_worker_processes_give_the_same_results_as_one(five_tilted):
    """The five tilted ellipsoids in two processes: the results are identical to the
    in-process run, bit for bit."""
    layer, one = five_tilted
    two = _five_tilted(layer, workers=2)
    for name, var in one.data_vars.items():
        if name.startswith("time_"):
            continue
        assert np.array_equal(var.values, two[name].values,
                              equal_nan=var.dtype.kind == "f"), name


def test_workers_must_be_a_positive_integer():
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(1e-3), SOFT), (0.0, 0.0))])
    with pytest.raises(ValueError, match="workers must be an integer >= 1"):
        tb.Simulation(layer, tb.Plates(0.1), tb.LinearRamp(stop=1.0, steps=1), workers=0)


def test_several_particles_turning_in_one_round_do_not_depend_on_their_order(five_tilted):
    """The five tilted ellipsoids in reverse order: several turn in the same rounds, each
    against the others as they were at the round's start; identical results."""
    layer, a = five_tilted
    b = _five_tilted(tb.Layer(list(layer)[::-1]))
    back = b.isel(particle=slice(None, None, -1))
    for name, var in a.data_vars.items():
        if name.startswith(("time_", "event_")):
            continue
        other = back[name] if "particle" in var.dims else b[name]
        assert np.array_equal(var.values, other.values, equal_nan=var.dtype.kind == "f"), name


def test_the_share_of_a_turning_particle_balances_the_others_compliance():
    """share_while_turning against arithmetic done here: the others are Hertz springs
    (compliances without solves: F = (4/3) E* √R ((reach − h)/2)^{3/2}); the particle's share
    F_i must satisfy F_i + Σ F_j(h_i) = F_N to 1e-9, h_i being the gap of its own solve; with
    the others alone holding the plates above its top it is unloaded."""
    from thirdbody.particle.compliance import Compliance, share_while_turning
    from thirdbody.particle.member import Member

    R = 1e-3
    member = Member(tb.Particle(Sphere(R), SOFT), tb.Plates(0.3), R / 60, 1e-8, 1e-3)
    rotation = tb.orientation.tilt(0.0)
    reach = member.reach(rotation)
    total = 5.0

    def spring(top):
        return Compliance((), top, SOFT.E_star, 0.9e-3)

    def hertz(top, h):
        return 4 / 3 * SOFT.E_star * math.sqrt(0.9e-3) * max((top - h) / 2, 0) ** 1.5

    for tops, guess in (((reach - 2e-6, reach + 1e-6), 1.0), ((reach - 5e-6,), 4.9),
                        ((reach + 3e-6, reach - 1e-6, reach), 0.01)):
        ev = share_while_turning(member, rotation, total, [spring(t) for t in tops], guess)
        assert ev.force > 0
        rest = sum(hertz(t, ev.gap) for t in tops)
        assert abs(ev.force + rest - total) <= 1e-9 * total, (tops, ev.force, rest)
        # with twins: n identical particles turning alike, each carrying F_i
        for n in (2, 3):
            ev = share_while_turning(member, rotation, total, [spring(t) for t in tops],
                                     guess, twins=n)
            rest = sum(hertz(t, ev.gap) for t in tops)
            assert abs(n * ev.force + rest - total) <= 1e-9 * total, (n, tops, ev.force)
    # the others alone carry F_N with the plates above this particle's top: unloaded
    high = reach + 1e-3
    ev = share_while_turning(member, rotation, total, [spring(high)], 1.0)
    assert ev.force == 0 and ev.rotation is rotation


def test_a_layer_under_gap_control_turns_each_particle_at_the_prescribed_gap():
    """A tilted ellipsoid (μ = 0.46 just below ξ(20°) = 0.473: a small turn) with a shorter
    sphere far away, under gap control: the sphere never touches, and the ellipsoid turns
    exactly as it does alone at the same gaps (the compression is relative to the tallest
    particle, the ellipsoid in both runs)."""
    a, b, c = 1e-3, 0.8e-3, 0.6e-3
    alone = tb.Particle(Ellipsoid((a, b, c)), SOFT, 20.0)
    load = tb.GapRamp(stop=0.03, steps=2)
    single = tb.particle_view(quiet_run(tb.Simulation(alone, tb.Plates(0.46), load,
                                                      resolution=80, maps_every=0)))
    layer = tb.Layer([tb.PlacedParticle(alone, (0.0, 0.0)),
                      tb.PlacedParticle(tb.Particle(Sphere(0.5e-3), SOFT), (5e-3, 0.0))])
    sim = tb.Simulation(layer, tb.Plates(0.46), load, resolution=80, maps_every=0)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    assert int(ds.turned[0, 0]) == 1 and not ds.normal_force.values[:, 1].any()
    for name in ("normal_force", "orientation", "ratio", "position", "contact_area"):
        np.testing.assert_array_equal(ds[name].isel(particle=0).values, single[name].values,
                                      err_msg=name)
    np.testing.assert_array_equal(ds.plate_gap.values, single.plate_gap.values)
    # the gap is the prescribed one, from the ellipse's height done here
    t = math.radians(20.0)
    d0 = 2 * math.sqrt(a**2 * math.sin(t) ** 2 + c**2 * math.cos(t) ** 2)
    np.testing.assert_allclose(ds.plate_gap.values, d0 * (1 - ds.load_value.values),
                               rtol=1e-7)


def test_sizes_from_a_csv_file(tmp_path):
    """One size per row (m), first column, an optional header; a bad row is refused with its
    number."""
    path = tmp_path / "sizes.csv"
    path.write_text("size_m,comment\n1.0e-3,big\n0.5e-3,small\n")
    layer = tb.Layer.random(box=(20e-3, 20e-3), material=SOFT, count=3, distribution="list",
                            sizes=path, seed=1)
    assert [p.particle.shape.size for p in layer] == [1e-3, 0.5e-3, 1e-3]
    path.write_text("1.0e-3\nbig\n")
    with pytest.raises(LayerError, match="row 2"):
        tb.Layer.random(box=(20e-3, 20e-3), material=SOFT, count=3, distribution="list",
                        sizes=path, seed=1)
    with pytest.raises(LayerError, match="cannot read"):
        tb.Layer.random(box=(20e-3, 20e-3), material=SOFT, count=3, distribution="list",
                        sizes=tmp_path / "missing.csv", seed=1)


def test_the_plate_reactions_are_the_moments_of_the_particles_forces():
    """plate_force and plate_moment, against arithmetic done here. Four identical spheres at
    known places carry F_N/4 each with no tangential force: the moment about the origin of their
    pushes on the upper plate is (F/4) Σ (y_i, −x_i). A tilted ellipsoid adds its couple: the
    tangential force F' at height h and its normal force at its upper pressure centroid."""
    R, total = 1e-3, 8.0
    places = ((1e-3, 0.0), (5e-3, 2e-3), (-2e-3, 5e-3), (-3e-3, -4e-3))
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(R), SOFT), xy) for xy in places])
    ds = quiet_run(tb.Simulation(layer, tb.Plates(0.3), tb.ForceTable([total]), resolution=40,
                                 maps_every=0))
    expected = total / 4 * np.array([sum(y for _, y in places), -sum(x for x, _ in places)])
    np.testing.assert_allclose(ds.plate_moment.values[0], expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ds.plate_force.values[0], 0.0, atol=1e-9 * total)

    tilted = tb.Layer([tb.PlacedParticle(tb.Particle(Ellipsoid((1e-3, 0.8e-3, 0.6e-3)), SOFT,
                                                     20.0, 60.0), (2e-3, -1e-3))])
    ds = quiet_run(tb.Simulation(tilted, tb.Plates(0.6), tb.ForceTable([1.0]), resolution=60,
                                 maps_every=0))
    F = float(ds.normal_force[0, 0])
    fx, fy = ds.tangential_force.values[0, 0]
    cx, cy = ds.centroid.sel(interface="upper").values[0, 0]
    h = float(ds.plate_gap[0])
    assert math.hypot(fx, fy) > 0.05 * F                    # a real couple
    x, y = 2e-3 + float(ds.position[0, 0, 0]) + cx, -1e-3 + float(ds.position[0, 0, 1]) + cy
    # r × f with r = (x, y, h) and f = (F'_x, F'_y, F): the particle on the upper plate
    np.testing.assert_allclose(ds.plate_moment.values[0], (y * F - h * fy, h * fx - x * F),
                               rtol=1e-12)
    np.testing.assert_allclose(ds.plate_force.values[0], (fx, fy), rtol=1e-12)


def test_a_sphere_that_would_carry_less_than_a_millionth_is_unloaded_and_the_rest_adds_up():
    """Two spheres carry F_N; a third one reaches just past the gap they hold, where Hertz
    gives it 1e-8 F_N: below MIN_SHARE, so it is dropped, and the other two still add up to
    F_N exactly (their shares are rescaled) and match Hertz."""
    big = [1e-3, 0.999e-3]
    total = 4.0
    # the gap the two hold (the third sphere is placed relative to it)
    h = float(quiet_run(tb.Simulation(spheres(big), tb.Plates(0.3), tb.ForceTable([total]),
                                      resolution=100, maps_every=0)).plate_gap[0])
    tiny = 1e-8 * total
    delta = (3 * tiny / (math.sqrt(2) * SOFT.E_star * math.sqrt(0.9e-3))) ** (2 / 3)
    radii = [*big, (h + delta) / 2]
    sim = tb.Simulation(spheres(radii), tb.Plates(0.3), tb.ForceTable([total]), resolution=100,
                        maps_every=0)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    F = ds.normal_force.values[0]
    assert F[2] == 0 and int(ds.loaded[0]) == 2
    assert math.isclose(F.sum(), total, rel_tol=1e-12)
    _, expected = hertz_sum(big, SOFT.E_star, total)
    np.testing.assert_allclose(F[:2], expected, rtol=0.01)


@pytest.mark.parametrize("n", [2, 4])
def test_identical_particles_turn_together_as_one_alone_at_its_share(n):
    """Identical tilted ellipsoids (1 × 0.6 × 0.5 mm, 35°, μ = 0.1) in a regular array: each
    needs far more friction than the plates give, so all turn in the first step. They turn
    alike (twins), each equal to the particle alone at F_N/n: the same tilt in every step and
    a share of exactly 1/n. (Turning each against the others as they were at the round's
    start, they undid each other's turns and the layer never settled.)"""
    particle = tb.Particle(Ellipsoid((1.0e-3, 0.6e-3, 0.5e-3)), SOFT, 35.0)
    spots = [(0.0, 0.0), (6e-3, 0.0), (0.0, 6e-3), (6e-3, 6e-3)][:n]
    layer = tb.Layer([tb.PlacedParticle(particle, xy) for xy in spots])
    total = 0.4 * n
    sim = tb.Simulation(layer, tb.Plates(0.1), tb.LinearRamp(stop=total, steps=2),
                        resolution=40, maps_every=0)
    ds = quiet_run(sim)
    assert sim.status == "complete"
    alone = tb.particle_view(quiet_run(tb.Simulation(
        particle, tb.Plates(0.1), tb.LinearRamp(stop=total / n, steps=2), resolution=40,
        maps_every=0)))
    assert alone.turned.values.tolist()[0] == 1 and ds.turned.values[0].all()
    assert np.array_equal(ds.load_share.values, np.full((2, n), 1.0 / n))
    tilt = ds.orientation.sel(component="y").values
    for i in range(n):
        np.testing.assert_allclose(tilt[:, i], alone.orientation.sel(component="y").values,
                                   atol=0.01)
        np.testing.assert_allclose(ds.normal_force.values[:, i], alone.normal_force.values,
                                   rtol=1e-9)
    assert np.array_equal(ds.state.values, np.repeat(alone.state.values[:, None], n, axis=1))
    # the same turn: the same orientations evaluated, at the share of the particle alone
    assert np.array_equal(ds.turn_evaluations.values,
                          np.repeat(alone.turn_evaluations.values[:, None], n, axis=1))
