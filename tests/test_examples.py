"""The example scripts run end to end at a small size and produce sane output."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import thirdbody

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses resolve annotations through sys.modules
    spec.loader.exec_module(module)
    return module


def test_fig2_example_runs(tmp_path):
    pytest.importorskip("matplotlib")
    fig2 = load_example("fig2_partial_slip")
    run = fig2.main(["--out", str(tmp_path), "--n", "48", "--steps", "3",
                     "--dpi", "60"])

    for name in ["fig2.png", "fig2_stick_slip.png", "fig2_tau_x.png", "fig2_force_shift.png"]:
        path = tmp_path / name
        assert path.is_file() and path.stat().st_size > 5_000, name
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    summary = (tmp_path / "summary.txt").read_text()
    assert "F_N" in summary and "Pa" in summary
    # one table row per step: step, shift, F_x, F_x/muF_N, stick fraction, ...
    rows = [line.split() for line in summary.splitlines()
            if line.split() and line.split()[0] in {"1", "2", "3"}]
    assert len(rows) == 3
    shift, fx, ratio, stick = (np.array([float(r[i]) for r in rows]) for i in (1, 2, 3, 4))
    assert (np.diff(shift) > 0).all() and (np.diff(fx) > 0).all()
    assert (np.diff(stick) < 0).all() and 0 < stick[-1] < 0.6
    assert ratio[-1] == pytest.approx(0.8, abs=0.02)  # the default target F_x = 0.8 mu F_N

    assert len(run.steps) == 3
    contact_cells_x = run.normal.contact.any(axis=0).sum()
    assert contact_cells_x >= 30
    p = run.normal.pressure
    for step in run.steps:
        assert step.residual < 1e-6
        assert (np.hypot(*step.traction) <= run.mu * p * (1 + 1e-9) + 1e-300).all()
        assert step.stick.any() and step.slip.any()


def test_paper_figure5_example_runs(tmp_path):
    """Figs. 3-5 share one script; Fig. 5 (unequal μ, hold then ramp) exercises rolling and every
    plot. Coarse and short here; `make demo` runs Fig. 3 at the default resolution."""
    paper_figures = load_example("paper_figures")

    results = paper_figures.main(["--figure", "5", "--out", str(tmp_path), "--steps", "4",
                                  "--resolution", "40", "--maps-every", "2"])
    (run,) = results.values()
    assert run.attrs["status"] == "complete"
    ds = thirdbody.particle_view(run, 0)
    names = ds.state.attrs["flag_meanings"].split()
    assert names[int(ds.state[0])] == "roll_lower"          # μ_up < μ_low: rolls on the lower
    slip = ds.slip.sel(component="x")
    assert float(slip.sel(interface="lower")[0]) == 0.0
    assert float(slip.sel(interface="upper")[0]) != 0.0
    assert (ds.rotation_angle[1:] == 0).all()                # then stable
    for name in ("state", "orientation", "contact_maps"):
        for ext in ("png", "pdf"):
            assert (tmp_path / f"{name}.{ext}").stat().st_size > 1000
    assert (tmp_path / "summary.txt").read_text().count("\n") == ds.sizes["step"] + 2


def test_fig4c_turns_once_then_its_tangential_force_changes_sign():
    """The bundled Fig. 4(b) sign-change example, coarsened (50 cells per size, 10 steps): it
    turns at first contact only, sticks, and F' reverses (its component along the first F'
    becomes negative) while the lower plate touches in two spots."""
    from thirdbody.io import load_config
    from thirdbody.simulation import Simulation

    config = load_config(Path(thirdbody.__file__).parent / "examples" / "fig4c.toml")
    particle, plates, _, numerics = config.build()
    numerics.update(resolution=50.0, maps_every=0)
    sim = Simulation(particle, plates, thirdbody.LinearRamp(stop=10.0, steps=10), **numerics)
    ds = thirdbody.particle_view(sim.run(), 0)
    assert sim.status == "complete"
    assert ds.turned.values.tolist() == [1] + [0] * 9
    assert 8.0 < float(ds.rotation_angle[0]) < 10.5
    force = ds.tangential_force.transpose("step", "component").values
    along = force @ (force[0] / np.linalg.norm(force[0]))
    assert along[1] > 0 and along[-1] < 0                       # it changes sign
    assert (ds.ratio.values[1:] < 1).all()                      # sticking all along
    assert int(ds.spots.sel(interface="lower")[-1]) == 2
