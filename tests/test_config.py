"""Configuration values: numbers are strict (an integer is a float, a bool is not a count), and
a coarse grid is named by the key the user set."""

from __future__ import annotations

import pytest

import thirdbody as tb
from _cli import FIG3
from thirdbody.io import parse_config


def test_an_integer_is_a_float_but_a_bool_is_not_a_count():
    import tomllib

    data = tomllib.loads(FIG3.replace("E = 1.0e9", "E = 1000000000"))
    assert parse_config(data).particle.E == 1e9
    data = tomllib.loads(FIG3.replace("maps_every = 5", "maps_every = false"))
    with pytest.raises(ValueError, match=r"numerics\.maps_every"):
        parse_config(data)

def test_a_coarse_cell_size_is_named_as_set():
    sim = tb.Simulation(tb.Particle(tb.shapes.Sphere(0.5e-3), tb.Material(1e9, 0.3)),
                        tb.Plates(0.3), tb.LinearRamp(stop=0.01, steps=1), cell_size=1e-4,
                        maps_every=0)
    with pytest.raises(ValueError, match=r"cell_size \(numerics.cell_size\).*too coarse"):
        sim.preflight()
