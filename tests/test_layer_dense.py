"""Dense layers: Layer.random(placement="relaxed"), periodic placement, and overlaps across a
periodic side (issue 25). Overlaps are checked here from the positions and sizes directly."""

from __future__ import annotations

import math

import numpy as np
import pytest

import thirdbody as tb
from thirdbody.io import ConfigError, parse_config
from thirdbody.layer import LayerError
from thirdbody.shapes import Sphere

SOFT = tb.Material(1e9, 0.3)
L = 10e-3


def gaps(layer, periodic: bool) -> np.ndarray:
    """Every pair's gap between bounding discs (m), through the nearest image if periodic."""
    xy = layer.positions
    size = np.array([p.particle.shape.size for p in layer])
    d = xy[None, :, :] - xy[:, None, :]
    if periodic:
        d -= L * np.round(d / L)
    gap = np.hypot(d[..., 0], d[..., 1]) - size[None, :] - size[:, None]
    return gap[np.triu_indices(len(xy), 1)]


@pytest.mark.parametrize("periodic", [True, False])
def test_a_relaxed_layer_is_dense_and_nothing_overlaps(periodic):
    """Polydisperse spheres (lognormal, std 0.2 mm) at an area fraction of 0.7, which
    sequential placement cannot reach: no two bounding discs overlap, and discs the relaxation
    pushed apart sit within 0.2 % of the mean size (it grows the discs by 0.1 %)."""
    layer = tb.Layer.random(box=(L, L), material=SOFT, area_fraction=0.7, size=1e-3,
                            size_std=0.2e-3, distribution="lognormal", placement="relaxed",
                            periodic=periodic, seed=3)
    size = np.array([p.particle.shape.size for p in layer])
    covered = math.pi * np.sum(size**2) / L**2
    assert 0.7 <= covered < 0.7 + math.pi * size.max() ** 2 / L**2
    g = gaps(layer, periodic)
    assert g.min() > 1e-4 * size.min()          # apart: the grown discs do not overlap
    assert (g < 2e-3 * size.mean() * 1.01).any()
    xy = layer.positions
    if periodic:
        assert ((xy >= -L / 2) & (xy < L / 2)).all()
        assert layer.periodic and layer.box == (L, L)
    else:
        assert (np.abs(xy) <= L / 2 - size[:, None] + 1e-15).all()
    with pytest.raises(LayerError, match="could not place"):
        tb.Layer.random(box=(L, L), material=SOFT, area_fraction=0.5, size=1e-3,
                        size_std=0.2e-3, distribution="lognormal", periodic=periodic, seed=3,
                        max_attempts=200)


def test_the_same_seed_places_the_same_layer():
    kw = dict(box=(L, L), material=SOFT, area_fraction=0.6, size=1e-3, shape="ellipsoid",
              orientation="tilted", placement="relaxed", periodic=True, seed=5)
    a, b = tb.Layer.random(**kw), tb.Layer.random(**kw)
    assert np.array_equal(a.positions, b.positions)


def test_sequential_periodic_placement_uses_the_whole_box():
    """Periodic: discs may cross a side (some do here) but never meet an image."""
    layer = tb.Layer.random(box=(L, L), material=SOFT, area_fraction=0.4, size=1e-3,
                            periodic=True, seed=2)
    xy, size = layer.positions, 1e-3
    assert (np.abs(xy) > L / 2 - size).any()
    assert gaps(layer, True).min() >= 0.0


@pytest.mark.parametrize("kw, message", [
    (dict(area_fraction=0.6), r"\(0, 0.5\] with placement = 'sequential'"),
    (dict(area_fraction=0.85, placement="relaxed"), r"\(0, 0.8\] with placement = 'relaxed'"),
    (dict(area_fraction=0.3, placement="dense"), "layer.placement"),
])
def test_what_cannot_be_placed_is_refused_naming_the_key(kw, message):
    with pytest.raises((LayerError, ValueError), match=message):
        tb.Layer.random(box=(L, L), material=SOFT, size=1e-3, **kw)


def test_discs_that_jam_are_refused():
    with pytest.raises(LayerError, match="jam"):
        tb.Layer.random(box=(4e-3, 4e-3), material=SOFT, count=5, size=1e-3,
                        placement="relaxed", periodic=True, seed=0)


def test_an_overlap_across_a_periodic_side_names_the_pair():
    """Two spheres of 1 mm at x = ±4.5 mm in a 10 mm box are 1 mm apart through the side: they
    overlap there (but not directly)."""
    placed = [tb.PlacedParticle(tb.Particle(Sphere(1e-3), SOFT), (x, 0.0))
              for x in (-4.5e-3, 0.0, 4.5e-3)]
    tb.Layer(placed)                                     # unbounded: fine
    with pytest.raises(LayerError, match="particles 0 and 2 overlap"):
        tb.Layer(placed, box=(L, L), periodic=True)
    with pytest.raises(LayerError, match="needs its box"):
        tb.Layer(placed, periodic=True)


_LAYER = {"box": [L, L], "count": 4, "size": 1e-3, "E": 1e9, "nu": 0.3}
_REST = {"plates": {"mu_up": 0.3}, "load": {"program": "linear_ramp", "stop": 1.0}}


def test_the_configuration_places_dense_periodic_layers():
    table = {k: v for k, v in _LAYER.items() if k != "count"}
    cfg = parse_config({"layer": {**table, "area_fraction": 0.7, "placement": "relaxed"},
                        "network": {"mu_pp": 0.3, "periodic": True}, **_REST})
    layer, plates, load, numerics = cfg.build()
    assert layer.periodic and numerics["box"] == (L, L)
    assert gaps(layer, True).min() >= 0.0
    sim = tb.Simulation(layer, plates, load, **numerics)
    assert sim.box == (L, L)


@pytest.mark.parametrize("layer, network, message", [
    ({"area_fraction": 0.6}, None, "placement"),
    ({"placement": "random"}, None, r"layer\.placement"),
    ({}, {"mu_pp": 0.3, "periodic": True, "box": [5e-3, 5e-3]}, "network.box must be the"),
])
def test_a_bad_dense_layer_table_names_the_key(layer, network, message):
    table = {**_LAYER, **layer}
    if "area_fraction" in layer:
        table.pop("count")
    data = {"layer": table, **_REST, **({"network": network} if network else {})}
    with pytest.raises(ConfigError, match=message):
        parse_config(data)
