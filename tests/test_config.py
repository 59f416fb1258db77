"""Configuration values: numbers are strict (an integer is a float, a bool is not a count), and
a coarse grid is named by the key the user set."""

from __future__ import annotations

import pytest

import thirdbody as tb
from _cli import FIG3, ROOT
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


@pytest.mark.parametrize(("old", "new", "line"), [
    ("[plates]", '[layer]\nbox = [1e-3, 1e-3]\ncount = 2\nE = 1e9\nnu = 0.3\n\n[plates]',
     "the configuration: give exactly one of [particle], [[particles]] and [layer] "
     "(got particle, layer)"),
    ("semi_axes = [1.0e-3, 0.8e-3, 0.7e-3]", "semi_axes = [1.0e-3, 0.8e-3]",
     "particle.semi_axes: give 3 values; got 2 ([0.001, 0.0008])"),
    ('program = "linear_ramp"\nstop = 10.0', 'program = "force_table"\nforces = []',
     "load.forces: give at least 1 value(s); got 0"),
    ('shape = "potato"', 'shape = "cube"',
     "particle.shape = 'cube': not one of 'sphere', 'ellipsoid', 'potato', 'mesh'"),
    ('shape = "potato"', 'form = "potato"',
     "particle.shape: required key missing (one of 'sphere', 'ellipsoid', 'potato', 'mesh')"),
    ('program = "linear_ramp"', 'kind = "linear_ramp"',
     "load.program: required key missing (one of 'linear_ramp', 'hold_then_ramp', "
     "'force_table', 'gap_ramp', 'slide')"),
    ("E = 1.0e9", "E = -1.0", "particle.E = -1.0: must be > 0.0"),
    ("orientation_deg = 20.0", "orientation_deg = 20.0\nquaternion = [0.0, 0.0, 0.0, 1.0]",
     "particle: give either a tilt (orientation_deg, tilt_axis_deg, yaw_deg) or a quaternion, "
     "not both"),
    ("maps_every = 5", "maps_every = 2.5", "numerics.maps_every = 2.5: must be a whole number"),
    ("semi_axes = [1.0e-3, 0.8e-3, 0.7e-3]", "semi_axes = [1.0, 0.8, 0.7]",
     "particle.semi_axes: the particle is 2.16 m across (semi_axes = [1.0, 0.8, 0.7]); lengths "
     "are in metres (1 mm = 1.0e-3): are these millimetres?"),
])
def test_each_problem_is_one_line_with_the_key_as_written(old, new, line):
    """pydantic's own texts never reach the user: no "Value error", no empty key, no dump of
    the whole table, no index of a missing list item."""
    import tomllib

    assert old in FIG3
    data = tomllib.loads(FIG3.replace(old, new).replace("steps = 30\n", "steps = 30\n"
                                                        if "force_table" not in new else ""))
    with pytest.raises(ValueError) as refused:
        parse_config(data, source="c.toml")
    text = str(refused.value)
    assert f"  {line}" in text.splitlines() or text.endswith(line), text
    for raw in ("Value error", "{'", "after validation", "Input should", ".2:"):
        assert raw not in text, text


def test_a_mesh_read_at_the_wrong_scale_asks_for_the_unit(tmp_path):
    import tomllib

    grain = (ROOT / "src/thirdbody/examples/grain.toml").read_text()
    data = tomllib.loads(grain.replace("scale = 1.0e-3", "scale = 1.0"))
    with pytest.raises(ValueError, match=r"particle\.scale = 1\.0: the mesh grain\.stl is then "
                                         r"1\.\d+ m across; .* Is that the file's unit\?"):
        parse_config(data, source="g.toml", base_dir=str(ROOT / "src/thirdbody/examples"))


def test_print_config_writes_the_resolved_values():
    import tomllib

    resolved = tomllib.loads(parse_config(tomllib.loads(FIG3)).to_toml())
    assert resolved["plates"]["mu_low"] == resolved["plates"]["mu_up"] == 0.46
    assert resolved["load"]["start"] == pytest.approx(10.0 / 30)
    again = parse_config(resolved)                       # and it reads back the same run
    assert again.build()[2].schedule() == parse_config(tomllib.loads(FIG3)).build()[2].schedule()


def test_the_missing_tag_lists_what_a_wrong_tag_lists():
    """A missing ``shape``/``program`` names the allowed values, the same ones pydantic names
    for a wrong value (taken from the models), so the two lists cannot drift apart."""
    import tomllib

    def refusal(old, new):
        with pytest.raises(ValueError) as refused:
            parse_config(tomllib.loads(FIG3.replace(old, new)), source="c.toml")
        return str(refused.value).rsplit("(one of ", 1)[-1].rsplit("not one of ", 1)[-1]

    for old, missing, wrong in [('shape = "potato"', 'form = "potato"', 'shape = "cube"'),
                                ('program = "linear_ramp"', 'kind = "x"', 'program = "x"')]:
        assert refusal(old, missing).rstrip(")") == refusal(old, wrong)
