"""Sliding plates (design notes §3d, issue 26): the :class:`thirdbody.Slide` program, its
configuration, the variables a sliding run writes, and single particles sheared between the
plates, against references computed here from the geometry, never by the code under test:

* a sphere between sliding plates rolls without slip on both: its centre moves Δs/2 and it
  turns by Δs/h about the axis perpendicular to the sliding, h = 2(R − δ) with δ Hertz's
  approach; the plates need no tangential force (μ_eff → 0) and the gap does not change;
  sliding back to the start retraces the way out, every contact sticking;
* a flat ellipsoid (its smallest axis vertical) cannot roll on: it tilts until the rigid
  couple ratio ξ(θ) of its own ellipse reaches the smaller μ (a few µm of sliding), then
  slides on the plate with the smaller μ and moves with the other: μ_eff = μ_min, the
  dilatancy the rigid gap change 2(√(A² sin²θ + C² cos²θ) − C) at that tilt;
* the gap held instead of the force.

Resolutions are coarse (20 cells per particle size) and the runs few steps, so that the whole
file takes a few seconds; each tolerance is the measured error with headroom, stated next to it.
"""

from __future__ import annotations

import math
import tomllib
import warnings

import numpy as np
import pytest

import thirdbody as tb
from thirdbody.io import ConfigError, parse_config
from thirdbody.network.cluster import HalfSpaceWarning
from thirdbody.shapes import Sphere

R = 1e-3                            # sphere radius, m
MAT = tb.Material(1e9, 0.3)
E_STAR = 1e9 / (1 - 0.3**2)         # a particle on a rigid plate
F = 1.0                             # N
STEP = 10e-6                        # sphere: sliding increment, m (1 % of R)
A, B, C = 1e-3, 0.8e-3, 0.2e-3      # the flat ellipsoid's semi-axes, m
FLAT_STEP = 5e-6                    # its sliding increment, m
MU_UP, MU_LOW = 0.6, 0.3            # the flat ellipsoid's plates


def run(particle, plates, load, resolution=20.0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HalfSpaceWarning)
        sim = tb.Simulation(particle, plates, load, mu_pp=0.3, resolution=resolution,
                            network_tol=1e-5, maps_every=0)
        ds = sim.run()
    assert sim.status == "complete", sim.status
    return ds


def sliding(ds, name):
    """A per-step variable of one particle (the particle dimension dropped)."""
    return ds[name].squeeze("particle", drop=True) if "particle" in ds[name].dims else ds[name]


# --- a: the program ----------------------------------------------------------------------------
def test_slide_compresses_then_moves_the_plate_through_its_points():
    load = tb.Slide(force=2.0, points=[(30e-6, 0.0), (30e-6, 20e-6), (0.0, 0.0)], steps=3,
                    compress_steps=2)
    schedule = load.schedule()
    assert len(schedule) == 2 + 3 * 3 == len(load)
    assert [(s.kind, s.value) for s in schedule[:2]] == [("force", 1.0), ("force", 2.0)]
    assert not any(s.slides for s in schedule[:2])
    assert all(s.kind == "force" and s.value == 2.0 and s.slides for s in schedule[2:])
    shifts = np.array([s.shift for s in schedule[2:]])
    ends = np.cumsum(shifts, axis=0)[2::3]            # the plate after each segment
    assert ends == pytest.approx(np.array(load.path), abs=1e-20)
    assert shifts[:3] == pytest.approx(np.array([(10e-6, 0.0)] * 3))
    assert shifts[3:6] == pytest.approx(np.array([(0.0, 20e-6 / 3)] * 3))
    assert load.slides and not tb.LinearRamp(stop=1.0).slides
    assert load.max_force == 2.0


def test_slide_by_a_distance_in_a_direction_under_gap_control():
    load = tb.Slide(compression=0.01, distance=40e-6, direction_deg=90.0, steps=4,
                    compress_steps=1)
    schedule = load.schedule()
    assert [(s.kind, s.value) for s in schedule] == [("compression", 0.01)] * 5
    assert np.sum([s.shift for s in schedule], axis=0) == pytest.approx([0.0, 40e-6],
                                                                         abs=1e-20)


@pytest.mark.parametrize("kwargs, match", [
    ({"distance": 1e-5}, r"exactly one of load\.force .* load\.compression"),
    ({"force": 1.0, "compression": 0.1, "distance": 1e-5}, r"exactly one of load\.force"),
    ({"force": -1.0, "distance": 1e-5}, r"load\.force .* \(0, inf\)"),
    ({"compression": 0.6, "distance": 1e-5}, r"load\.compression .* \(0, 0\.5\]"),
    ({"force": 1.0}, r"exactly one of load\.distance .* load\.points"),
    ({"force": 1.0, "distance": 0.0}, r"load\.distance .* \(0, inf\)"),
    ({"force": 1.0, "points": []}, r"load\.points must list at least one"),
    ({"force": 1.0, "points": [(1e-5, 0.0), (1e-5, 0.0)]}, r"load\.points\[1\] .* again"),
    ({"force": 1.0, "points": [(1e-5, math.nan)]}, r"load\.points\[0\] must be two finite"),
    ({"force": 1.0, "distance": 1e-5, "steps": 0}, r"load\.steps must be an integer >= 1"),
    ({"force": 1.0, "distance": 1e-5, "compress_steps": 2.5}, r"load\.compress_steps"),
])
def test_a_bad_slide_names_the_argument_and_its_range(kwargs, match):
    with pytest.raises(ValueError, match=match):
        tb.Slide(**kwargs)


def test_the_particle_model_refuses_to_slide_and_says_why():
    with pytest.raises(ValueError, match=r"slides the upper plate sideways, which only the "
                                         r"network engine can do: give mu_pp"):
        tb.Simulation(tb.Particle(Sphere(R), MAT), tb.Plates(0.5),
                      tb.Slide(force=F, distance=1e-5))


# --- b: the configuration ----------------------------------------------------------------------
_CONFIG = {"particle": {"shape": "sphere", "radius": R, "E": 1e9, "nu": 0.3},
           "plates": {"mu_up": 0.5}, "network": {"mu_pp": 0.3},
           "load": {"program": "slide", "force": F, "points": [[20e-6, 0.0], [0.0, 0.0]],
                    "steps": 2, "compress_steps": 1},
           "numerics": {"resolution": 20.0}}


def test_a_slide_table_builds_the_program_and_writes_back_the_same():
    cfg = parse_config(_CONFIG)
    _, _, load, numerics = cfg.build()
    assert load == tb.Slide(force=F, points=[(20e-6, 0.0), (0.0, 0.0)], steps=2,
                            compress_steps=1)
    assert numerics["mu_pp"] == 0.3
    again = parse_config(tomllib.loads(cfg.to_toml()))
    assert again.build()[2] == load


@pytest.mark.parametrize("load, match", [
    ({"force": F, "compression": 0.01, "points": [[1e-5, 0.0]]}, r"load: give exactly one of "
                                                                  r"force"),
    ({"force": F}, r"load: give exactly one of distance"),
    ({"force": 0.0, "distance": 1e-5}, r"load\.force = 0\.0: must be > 0"),
    ({"compression": 0.7, "distance": 1e-5}, r"load\.compression = 0\.7: must be <= 0\.5"),
    ({"force": F, "points": [[1e-5, 0.0, 0.0]]}, r"load\.points\[0\]: give at most 2"),
    ({"force": F, "points": [[0.0, 0.0]]}, r"load\.points\[0\] = \[0\.0, 0\.0\] is the start"),
    ({"force": F, "distance": 1e-5, "steps": 0}, r"load\.steps = 0: must be >= 1"),
    ({"force": F, "distance": 1e-5, "spam": 1}, r"load\.spam: unknown key"),
])
def test_a_bad_slide_table_names_the_key(load, match):
    with pytest.raises(ConfigError, match=match):
        parse_config({**_CONFIG, "load": {"program": "slide", **load}})


def test_a_slide_table_without_a_network_table_is_refused():
    data = {k: v for k, v in _CONFIG.items() if k != "network"}
    with pytest.raises(ConfigError, match=r'load\.program = "slide" .* needs a network run: '
                                          r"add a \[network\] table with mu_pp"):
        parse_config(data)


# --- c: a sliding run --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sphere_run():
    """A sphere pressed by 1 N in one step, slid 3 x 10 µm along +x and back to the start."""
    load = tb.Slide(force=F, points=[(3 * STEP, 0.0), (0.0, 0.0)], steps=3, compress_steps=1)
    return run(tb.Particle(Sphere(R), MAT), tb.Plates(0.5), load)


def test_the_network_engine_moves_the_upper_plate_by_each_step_s_shift(sphere_run):
    """The sphere's centre follows the plate at half its pace: Δs/2 per step, out and back."""
    x = sliding(sphere_run, "position").sel(component="x").values
    plate = np.concatenate([[0.0], np.cumsum([STEP] * 3 + [-STEP] * 3)])
    assert x == pytest.approx(plate / 2, abs=1e-6 * STEP)
