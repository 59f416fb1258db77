"""What the command line says when the input is bad: every bad input is a clean refusal (exit
2, one line naming the key or the path, no traceback, nothing written), and a stopped run's
warning is the CLI's own line while numpy's warnings stay visible."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import thirdbody as tb
from _cli import FIG3, ROOT, _cli, _refused


def test_binary_config_and_sweep_files_are_refused(tmp_path):
    binary = tmp_path / "bad.toml"
    binary.write_bytes(b"\x00\x01\xff\xfe\x80binary")
    for command in ("run", "sweep"):
        code, text = _cli(command, str(binary), "-o", str(tmp_path / command))
        _refused(code, text, "bad.toml", "UTF-8")
        assert not (tmp_path / command).exists()

@pytest.mark.parametrize(("old", "new", "key"), [
    ("resolution = 80.0", "cell_size = inf", "numerics.cell_size"),
    ("resolution = 80.0", "cell_size = 1e-9", "numerics.cell_size"),
    ("steps = 30", "steps = 1000000000", "load.steps"),
    ("E = 1.0e9", 'E = "1e9"', "particle.E"),
    ("nu = 0.3", 'nu = "0.27"', "particle.nu"),
    ("steps = 30", "steps = true", "load.steps"),
    ("orientation_deg = 20.0", 'orientation_deg = "20"', "particle.orientation_deg"),
    ("E = 1.0e9", "E = inf", "particle.E"),
])
def test_bad_values_are_refused_at_once_naming_the_key(tmp_path, old, new, key):
    config = tmp_path / "c.toml"
    config.write_text(FIG3.replace(old, new))
    start = time.perf_counter()
    code, text = _cli("run", str(config), "-o", str(tmp_path / "out"))
    _refused(code, text, key)
    assert "Material." not in text
    assert time.perf_counter() - start < 30          # an estimate, not 68 s of silence
    assert not (tmp_path / "out").exists()

@pytest.mark.parametrize("name, text", [("shape.py", "print(1)\n"),
                                        ("shape.step", "ISO-10303-21;\n"),
                                        ("garbage.stl", "garbage \udcff\n"),
                                        ("garbage.obj", "not a mesh\n")])
def test_a_mesh_trimesh_cannot_read_is_refused(tmp_path, name, text):
    (tmp_path / name).write_text(text, errors="surrogateescape")
    grain = (ROOT / "src/thirdbody/examples/grain.toml").read_text()
    config = tmp_path / "g.toml"
    config.write_text(grain.replace('file = "grain.stl"', f'file = "{name}"'))
    code, out = _cli("run", str(config), "-o", str(tmp_path / "out"))
    _refused(code, out, name, "is not a readable", "readable formats: STL")
    assert "Error" not in out                   # no exception's name (ModuleNotFoundError...)
    assert not (tmp_path / "out").exists()

def test_plot_refuses_a_netcdf_file_thirdbody_did_not_write(tmp_path):
    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"a": ("x", np.arange(3.0))}).to_netcdf(foreign, engine="h5netcdf")
    code, text = _cli("plot", str(foreign), "-o", str(tmp_path / "plots"))
    _refused(code, text, "foreign.nc", "not a thirdbody results file")
    assert not (tmp_path / "plots").exists()


def test_the_cli_silences_only_the_stop_message(tmp_path, monkeypatch):
    """The CLI reports a stopped run itself, so it hides SimulationStoppedWarning; numpy's
    RuntimeWarnings (overflow, invalid value, divide by zero) stay visible."""
    import thirdbody.io as tio
    from thirdbody.cli import app

    original = tio.run_to_file

    def noisy(*args, **kwargs):
        np.log(np.zeros(1))                                     # divide by zero
        warnings.warn("simulation stopped: test", tb.SimulationStoppedWarning, stacklevel=1)
        return original(*args, **kwargs)

    monkeypatch.setattr(tio, "run_to_file", noisy)
    cfg = tmp_path / "c.toml"
    cfg.write_text((ROOT / "src/thirdbody/examples/fig3.toml").read_text()
                   .replace("steps = 30", "steps = 1").replace("resolution = 80.0",
                                                                "resolution = 20.0"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = CliRunner().invoke(app, ["run", str(cfg), "-o", str(tmp_path / "o"),
                                          "--no-plots"])
    assert result.exit_code == 0, result.output
    kinds = [(w.category, str(w.message)) for w in caught]
    assert any(c is RuntimeWarning and "divide by zero" in m for c, m in kinds), kinds
    assert not any(c is tb.SimulationStoppedWarning for c, _ in kinds), kinds
