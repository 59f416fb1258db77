"""Layers from the command line and in sweeps: `thirdbody run` on a [layer] and a
[[particles]] file (results along particle, the layer figures, exit codes), `export-vtk` on
its results, refusals, and a sweep over a layer key whose summary reads the state fractions."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from thirdbody.cli import app
from thirdbody.io import open_results
from thirdbody.sweep import load_sweep, run_case, summarize

runner = CliRunner()

LISTED = """
[[particles]]
shape = "sphere"
radius = 1.0e-3
E = 1.0e9
nu = 0.3
x = 0.0
y = 0.0

[[particles]]
shape = "ellipsoid"
semi_axes = [1.0e-3, 0.8e-3, 0.6e-3]
E = 1.0e9
nu = 0.3
orientation_deg = 30.0
x = 4.0e-3
y = 0.0

[plates]
mu_up = 0.2
mu_low = 0.3

[load]
program = "linear_ramp"
stop = 4.0
steps = 2

[numerics]
resolution = 40.0
maps_every = 1
"""

GENERATED = """
[layer]
box = [9.0e-3, 9.0e-3]
count = 4
shape = "ellipsoid"
size = 0.8e-3
size_std = 0.02e-3
distribution = "normal"
orientation = "tilted"
max_tilt_deg = 25.0
seed = 3
E = 1.0e9
nu = 0.3

[plates]
mu_up = 0.15
mu_low = 0.2

[load]
program = "linear_ramp"
stop = 6.0
steps = 2

[numerics]
resolution = 45.0
maps_every = 1
"""


def test_run_a_listed_layer_then_export_it_for_paraview(tmp_path):
    config = tmp_path / "layer.toml"
    config.write_text(LISTED)
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(config), "-o", str(out)])
    assert result.exit_code == 0, result.output
    ds = open_results(out / "results.nc")
    assert ds.sizes["particle"] == 2 and ds.sizes["step"] == 2
    assert ds.attrs["status"] == "complete"
    # the sphere (2 mm tall) is taller than the ellipsoid at 30° (1.46 mm): it carries it all
    assert np.array_equal(ds.normal_force.values[:, 0], ds.load_value.values)
    assert ds.state.attrs["flag_meanings"].split()[int(ds.state[0, 1])] == "unloaded"
    for name in ("layer_top_view", "load_shares", "state_fractions", "particle_ratios"):
        assert (out / f"{name}.png").exists(), name
    vtk = tmp_path / "vtk"
    result = runner.invoke(app, ["export-vtk", str(out / "results.nc"), str(vtk)])
    assert result.exit_code == 0, result.output
    assert (vtk / "results.pvd").exists() and len(list(vtk.glob("particles_*.vtu"))) == 2


def test_bad_layer_inputs_exit_2_and_write_nothing(tmp_path):
    out = tmp_path / "out"
    for text, words in ((LISTED.replace("x = 4.0e-3", "x = 1.5e-3"), "particles 0 and 1 overlap"),
                        (GENERATED.replace("count = 4", "count = 400"), "too full"),
                        (GENERATED.replace("size_std = 0.02e-3", "size_std = -1.0"),
                         "layer.size_std")):
        config = tmp_path / "bad.toml"
        config.write_text(text)
        result = runner.invoke(app, ["run", str(config), "-o", str(out)])
        assert result.exit_code == 2, result.output
        assert words in result.output
        assert not out.exists()
    result = runner.invoke(app, ["export-vtk", str(tmp_path / "missing.nc"), str(out)])
    assert result.exit_code == 2 and not out.exists()


def test_a_sweep_over_a_layer_key_summarises_the_state_fractions(tmp_path):
    (tmp_path / "base.toml").write_text(GENERATED)
    (tmp_path / "sweep.toml").write_text(
        'base = "base.toml"\n[axes]\n"plates.mu" = [0.02, 0.6]\n')
    sweep = load_sweep(tmp_path / "sweep.toml")
    cases_dir = tmp_path / "out" / "cases"
    cases_dir.mkdir(parents=True)
    for case in sweep.cases():
        record = run_case(case.data, str(tmp_path), str(cases_dir), case.case_id)
        assert record["status"] == "complete", record
    summary = summarize(sweep, tmp_path / "out")
    low, high = (summary.sel(mu=mu) for mu in (0.02, 0.6))
    # with μ = 0.6 every loaded particle sticks; with μ = 0.02 none can
    assert float(high.final_fraction_stick) == 1.0 and int(high.turning_steps) == 0
    assert float(low.final_fraction_stick) == 0.0 and int(low.turning_steps) >= 1
    assert float(low.final_fraction_rotate) == 1.0          # equal μ: they rotate
    assert int(low.final_loaded) >= 1
    for case in sweep.cases():
        ds = open_results(cases_dir / case.filename)
        k = -1
        assert float(ds.fraction_stick[k]) == float(
            summary.final_fraction_stick.sel(mu=case.values["plates.mu"]))
        assert json.loads(ds.attrs["inputs"])["mu_up"] == case.values["plates.mu"]
    assert summary.fraction_stick.dims == ("mu", "step")
    from thirdbody.plot import state_map

    fig = state_map(summary)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert "0% roll\n100% rot." in texts and "0% roll\n0% rot." in texts


@pytest.mark.parametrize("name", ["layer_polydisperse"])
def test_the_layer_example_is_listed_and_valid(name):
    result = runner.invoke(app, ["examples"])
    assert result.exit_code == 0 and name in result.output
    from importlib import resources

    from thirdbody.io import load_config

    layer, *_ = load_config(resources.files("thirdbody") / "examples" / f"{name}.toml").build()
    assert len(layer) == 30
