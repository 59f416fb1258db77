"""What the results say about themselves: units and long names of the step variables, and a
record that prints as one line for progress output."""

from __future__ import annotations

import thirdbody as tb
from thirdbody.shapes import Sphere


def _sphere_run(load, maps_every: int = 1):
    sim = tb.Simulation(tb.Particle(Sphere(0.5e-3), tb.Material(1e9, 0.3)), tb.Plates(0.3),
                        load, resolution=20, maps_every=maps_every)
    return sim.run()

def test_units_and_long_names_of_the_step_variables():
    ds = _sphere_run(tb.LinearRamp(stop=1.0, steps=2))
    assert ds.load_value.attrs["units"] == "N"
    for name in ("step", "map_step", "load_kind"):
        assert ds[name].attrs.get("units") == "1", name
        assert ds[name].attrs.get("long_name"), name
    assert "magnitude" in ds.ratio.attrs["long_name"]
    gap = _sphere_run(tb.GapRamp(stop=0.01, steps=2), maps_every=0)
    assert gap.load_value.attrs["units"] == "1"
    assert "compression" in gap.load_value.attrs["long_name"]

def test_a_record_prints_as_one_line():
    lines = []
    sim = tb.Simulation(tb.Particle(Sphere(0.5e-3), tb.Material(1e9, 0.3)), tb.Plates(0.3),
                        tb.LinearRamp(stop=1.0, steps=2), resolution=20, maps_every=0)
    sim.run(progress=lambda r: lines.append(str(r)))
    assert len(lines) == 2
    for k, line in enumerate(lines):
        assert "\n" not in line and len(line) < 100, line
        assert line.startswith(f"step {k}: F_N ") and "stick" in line
    assert "values=" in repr(sim.records[0])          # the full record is still there
