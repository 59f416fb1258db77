"""Issue 15, the smaller items: error and warning classes, units and long names of the stored
variables, one-line progress records, and the sweep summary's signed ratios and exact zero
rotation."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

import thirdbody as tb
from thirdbody.shapes import Sphere

ROOT = Path(__file__).resolve().parents[1]


def _sphere_run(load, maps_every: int = 1):
    sim = tb.Simulation(tb.Particle(Sphere(0.5e-3), tb.Material(1e9, 0.3)), tb.Plates(0.3),
                        load, resolution=20, maps_every=maps_every)
    return sim.run()


# --- errors and warnings -----------------------------------------------------------------------
def test_contact_at_edge_is_a_runtime_error():
    # the inputs were valid: the solution outgrew its window, like a ConvergenceError
    assert issubclass(tb.ContactAtEdgeError, RuntimeError)
    assert not issubclass(tb.ContactAtEdgeError, ValueError)


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


def test_a_stopped_run_warns_with_its_own_class():
    assert issubclass(tb.SimulationStoppedWarning, RuntimeWarning)
    # a load far beyond the half-space model: the run stops, with this warning only
    with pytest.warns(tb.SimulationStoppedWarning, match="simulation stopped"):
        ds = _sphere_run(tb.LinearRamp(stop=1e7, steps=1), maps_every=0)
    assert ds.attrs["status"].startswith("failed")


# --- what the results say about themselves -----------------------------------------------------
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


# --- the sweep summary -------------------------------------------------------------------------
def _case(quaternions, turned, forces, ratio_low):
    from thirdbody.sweep import _CaseData

    n = len(turned)
    arrays = {"turned": np.asarray(turned, dtype=np.int8), "state": np.zeros(n, dtype=np.int8),
              "quaternion": np.asarray(quaternions, dtype=float),
              "ratio": np.stack([np.full(n, 0.5), ratio_low], axis=1),
              "compression": np.linspace(0.01, 0.03, n), "normal_force": np.arange(1.0, n + 1),
              "time_total": np.ones(n), "tangential_force": np.asarray(forces, dtype=float)}
    start = Rotation.from_euler("y", 20, degrees=True).as_quat()
    return _CaseData("complete", False, json.dumps({"quaternion": list(start)}), "0", arrays, {})


def test_a_case_that_never_turned_rotated_by_exactly_zero():
    from thirdbody.sweep import _case_summary

    # the stored orientation is the input's up to round-off (another route to the same turn)
    same = Rotation.from_euler("y", 20, degrees=True).as_quat()
    for _ in range(8):
        same[1] = np.nextafter(same[1], 1.0)
    off = (Rotation.from_quat(same) * Rotation.from_euler("y", 20, degrees=True).inv())
    assert off.magnitude() > 0                       # the round-off the summary must not report
    out = _case_summary(_case([same] * 3, [0, 0, 0], [[1.0, 0.0]] * 3, [0.2, 0.3, 0.4]))
    assert out["total_rotation"] == 0.0 and math.copysign(1.0, out["total_rotation"]) == 1.0
    assert math.isnan(out["turn_azimuth"])


def test_final_ratios_are_signed_like_the_state_plot():
    """F' reverses (its x component changes sign) in the last step: the summary reports the
    ratio negative, as the plot draws it; a run that keeps its direction stays positive."""
    from thirdbody.plot import _signed
    from thirdbody.sweep import _case_summary

    q = [Rotation.from_euler("y", 20, degrees=True).as_quat()] * 3
    forces = [[0.0, 0.0], [2.0, 0.5], [-1.0, 0.1]]
    out = _case_summary(_case(q, [0, 0, 0], forces, [0.2, 0.3, 0.072]))
    assert out["final_ratio_low"] == -0.072
    assert out["final_ratio_up"] == -0.5
    # the same sign as the plot's: computed here by hand, F'·F'_first < 0
    assert float(np.dot(forces[2], forces[1])) < 0
    import xarray as xr
    ds = xr.Dataset({"tangential_force": (("step", "component"), np.array(forces))})
    assert _signed(ds)[-1] == -1.0
    kept = _case_summary(_case(q, [0, 0, 0], [[1.0, 0.0]] * 3, [0.2, 0.3, 0.4]))
    assert kept["final_ratio_low"] == 0.4
