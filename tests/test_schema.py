"""The one registry of output variables (thirdbody.schema) and the one dataset form.

Every variable a run writes is declared in the schema with the dimensions, units and dtype the
file has; a variable added in one place reaches the results file, the sweep summary and the
documentation's table; a single particle's results are a layer of one; files of the earlier
format are read in today's form with the values a run of today gives."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import thirdbody as tb
from thirdbody import schema
from thirdbody.io.results import open_results, write_results
from thirdbody.shapes import Ellipsoid, Potato, Sphere

DATA = Path(__file__).parent / "data"


def ellipsoid_run(**kw):
    particle = tb.Particle(Ellipsoid((1.0e-3, 0.8e-3, 0.6e-3)), tb.Material(1e9, 0.3), 25.0)
    sim = tb.Simulation(particle, tb.Plates(0.3), tb.ForceTable([0.3, 0.6]), resolution=40,
                        maps_every=1, **kw)
    return sim, sim.run()


def layer_run():
    material = tb.Material(1e9, 0.3)
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(1.0e-3), material), (0.0, 0.0)),
                      tb.PlacedParticle(tb.Particle(Ellipsoid((1.0e-3, 0.8e-3, 0.6e-3)),
                                                    material, 20.0), (3.0e-3, 0.0)),
                      tb.PlacedParticle(tb.Particle(Sphere(0.5e-3), material), (0.0, 3e-3))])
    sim = tb.Simulation(layer, tb.Plates(0.3), tb.ForceTable([0.5, 1.0]), resolution=30,
                        maps_every=1)
    return sim, sim.run()


@pytest.fixture(scope="module")
def particle_ds():
    return ellipsoid_run()[1]


@pytest.fixture(scope="module")
def layer_ds():
    return layer_run()[1]


def _check_against_schema(ds, n_particles):
    assert ds.attrs["thirdbody_format"] == schema.FORMAT_VERSION
    assert ds.sizes["particle"] == n_particles
    for name, var in ds.data_vars.items():
        declared = schema.variable(name)
        assert var.dims == declared.dims, name
        assert var.attrs["units"] == declared.units or name == "load_value", name
        assert var.attrs["long_name"] == declared.long_name or name == "load_value", name
        if declared.dtype == "str":
            assert var.dtype.kind == "U", name
        else:
            assert var.dtype == np.dtype(declared.dtype), name
        if declared.flags:
            assert var.attrs["flag_meanings"].split() == list(declared.flags)
    written = {"step", "particle", "static", "event", "map"}
    expected = {v.name for v in schema.VARIABLES.values() if v.kind in written}
    assert set(ds.data_vars) == expected


def test_a_particle_and_a_layer_write_every_variable_as_the_schema_declares(particle_ds,
                                                                           layer_ds):
    _check_against_schema(particle_ds, 1)
    _check_against_schema(layer_ds, 3)


def test_maps_are_in_metres_for_every_particle(layer_ds):
    """map_x, map_y are each particle's cell centres (m): its cell size times the index."""
    for p in range(3):
        cell = float(layer_ds.cell_size[p])
        assert np.allclose(layer_ds.map_x.isel(particle=p), cell * layer_ds.map_i)
        assert np.allclose(layer_ds.map_y.isel(particle=p), cell * layer_ds.map_j)
    view = tb.particle_view(layer_ds, 1)
    assert view.pressure.dims == ("map_step", "interface", "map_y", "map_x")
    assert float(view.map_x[1] - view.map_x[0]) == pytest.approx(float(layer_ds.cell_size[1]))


def test_a_single_particle_is_a_layer_of_one(particle_ds):
    """The step's totals of one particle are its own: F_N, a load share of 1, one loaded."""
    view = tb.particle_view(particle_ds)
    assert "particle" not in view.dims
    assert np.array_equal(particle_ds.total_force.values, view.normal_force.values)
    assert np.array_equal(view.load_share.values, np.ones(2))
    assert particle_ds.loaded.values.tolist() == [1, 1]
    # the plate's force is F' (the lower plate's on the particle), its moment the couple
    assert np.array_equal(particle_ds.plate_force.values,
                          view.tangential_force.transpose("step", "component").values)
    assert particle_ds.event_kind.values[0] == "loaded"


def test_an_unloaded_particle_has_the_schema_blanks(layer_ds):
    """The small sphere is shorter than the gap: every variable of its record is the
    schema's fill, except its pose."""
    small = layer_ds.isel(particle=2)
    assert (small.state == schema.STATES.index("unloaded")).all()
    pose = {"quaternion", "orientation", "tilt", "tilt_azimuth", "yaw", "rotation",
            "rotation_angle", "position", "centroid_height", "slip", "turned",
            "time_normal", "time_tangential", "time_geometry"}
    for var in schema.by_kind("particle"):
        if var.name in pose:
            continue
        values = small[var.name].values
        fill = var.fill
        if var.flags:
            fill = var.flags.index(fill)
        if isinstance(fill, float) and math.isnan(fill):
            assert np.isnan(values).all(), var.name
        else:
            assert (values == fill).all(), var.name


def test_a_variable_added_in_one_place_reaches_the_file_the_summary_and_the_docs(
        tmp_path, monkeypatch):
    """One entry in schema.VARIABLES, derived from the record's own values: it is in the
    results file with its units, in a sweep's summary along its steps, and in the docs'
    table."""
    from thirdbody.sweep import parse_sweep, run_case, summarize

    added = schema.Variable(
        "total_contact_area", ("step", "particle"), "m2",
        "contact area of both plates together",
        derive=lambda v: v["contact_area"][0] + v["contact_area"][1], summary=True)
    monkeypatch.setitem(schema.VARIABLES, added.name, added)

    _, ds = ellipsoid_run()
    write_results(ds, tmp_path / "results.nc")
    back = open_results(tmp_path / "results.nc")
    assert back.total_contact_area.attrs["units"] == "m2"
    assert np.array_equal(back.total_contact_area.values,
                          back.contact_area.sum("interface").values)

    base = {"particle": {"shape": "ellipsoid", "semi_axes": [1.0e-3, 0.8e-3, 0.6e-3],
                         "E": 1.0e9, "nu": 0.3, "orientation_deg": 25.0},
            "plates": {"mu_up": 0.3}, "load": {"program": "force_table", "forces": [0.3]},
            "numerics": {"resolution": 60.0, "maps_every": 0}}
    sweep = parse_sweep({"base": base, "axes": {"plates.mu": [0.3, 0.5]}}, tmp_path)
    (tmp_path / "cases").mkdir()
    for case in sweep.cases():
        record = run_case(case.data, str(tmp_path), str(tmp_path / "cases"), case.case_id)
        assert record["status"] == "complete", record
    summary = summarize(sweep, tmp_path)
    assert summary.total_contact_area.dims == ("mu", "step", "particle")
    assert summary.total_contact_area.attrs["long_name"] == added.long_name
    assert (summary.total_contact_area > 0).all()

    assert "| `total_contact_area` | step, particle | m2 |" in schema.markdown_table()


@pytest.mark.parametrize("name", ["format1_particle.nc", "format1_layer.nc"])
def test_files_of_the_earlier_format_open_in_todays_form(name):
    ds = open_results(DATA / name)
    assert ds.attrs["upgraded_from_format"] == 1
    assert "particle" in ds.dims and "map_x" in ds.coords
    view = tb.particle_view(ds)
    assert view.pressure.dims == ("map_step", "interface", "map_y", "map_x")


@pytest.mark.slow
def test_an_earlier_file_reads_as_the_same_run_today(tmp_path):
    """``tests/data/format1_particle.nc`` was written by the format-1 code (a coarse Fig. 3
    potato, 4 steps); the same configuration run today gives every variable to rounding (the
    wall times aside): within 1e-12 of the variable's largest value, or 1e-15 of its unit for
    one that is rounding itself (a residual, a yaw of 1e-16 degrees). It was bit for bit until
    numpy 2.4 changed the last bits (the plate gap by 2e-19 m, the pressure by 1e-13 of its
    peak); integer variables still are."""
    particle = tb.Particle(Potato((1.0e-3, 0.8e-3, 0.7e-3), seed=4, amplitude=0.1,
                                  wavenumber_range=(4, 8)), tb.Material(1e9, 0.3), 20.0)
    ds = tb.Simulation(particle, tb.Plates(0.46), tb.LinearRamp(stop=6.0, steps=4),
                       resolution=30.0, maps_every=2).run()
    old = open_results(DATA / "format1_particle.nc")
    for name in ds.data_vars:
        if name.startswith("time_"):
            continue
        before, now = old[name].values, ds[name].values
        if before.dtype.kind == "f":
            scale = float(np.nanmax(np.abs(before), initial=0.0))
            assert np.allclose(now, before, rtol=0, atol=1e-12 * scale + 1e-15,
                               equal_nan=True), name
        else:
            assert np.array_equal(before, now), name
    for name in ("map_x", "map_y", "map_i", "map_j", "map_step"):
        assert np.array_equal(old[name].values, ds[name].values), name


def test_a_file_of_the_earlier_format_is_not_resumed(tmp_path):
    import shutil

    from thirdbody.io.results import RESUME_VARIABLE, run_to_file

    path = tmp_path / "results.nc"
    shutil.copy(DATA / "format1_particle.nc", path)
    # make it look unfinished: a resume variable
    import h5py
    with h5py.File(path, "r+") as f:
        f.create_dataset(RESUME_VARIABLE, data=np.zeros(3, dtype=np.uint8))
    sim, _ = ellipsoid_run()
    with pytest.raises(ValueError, match="earlier thirdbody"):
        run_to_file(sim, path, resume=True)


def test_the_world_azimuth_turns_the_whole_problem_about_z():
    """azimuth_deg α rotates the orientation about the world's vertical: tilt(θ, φ, ψ) turned
    by α is tilt(θ, φ + α, ψ + α); a run turned so keeps every scalar and turns F'."""
    shape = Ellipsoid((1.0e-3, 0.8e-3, 0.6e-3))
    material = tb.Material(1e9, 0.3)
    turned = tb.Particle(shape, material, 25.0, 60.0, 10.0, azimuth_deg=40.0)
    same = tb.Particle(shape, material, 25.0, 100.0, 50.0)
    assert np.allclose(turned.orientation.as_matrix(), same.orientation.as_matrix(), atol=1e-15)
    runs = []
    for azimuth in (0.0, 40.0):
        p = tb.Particle(shape, material, 25.0, azimuth_deg=azimuth)
        sim = tb.Simulation(p, tb.Plates(0.6), tb.ForceTable([0.4]), resolution=40,
                            maps_every=0)
        runs.append(tb.particle_view(sim.run()))
    a, b = runs
    # the lattice stays on the world axes: the turned particle is sampled on other cells, so
    # the two agree within the discretisation (the contact spans about 15 cells)
    assert np.array_equal(a.normal_force.values, b.normal_force.values)
    assert np.allclose(a.tilt.values, b.tilt.values, rtol=1e-12)
    assert np.allclose(a.plate_gap.values, b.plate_gap.values, rtol=1e-4)
    assert np.allclose(a.contact_area.values, b.contact_area.values, rtol=0.05)
    c, s = math.cos(math.radians(40.0)), math.sin(math.radians(40.0))
    fa = a.tangential_force.transpose("step", "component").values[0]
    fb = b.tangential_force.transpose("step", "component").values[0]
    assert np.linalg.norm(fb - [c * fa[0] - s * fa[1], s * fa[0] + c * fa[1]]) \
        < 0.02 * np.linalg.norm(fa)
    assert float(b.tilt_azimuth[0]) == pytest.approx(float(a.tilt_azimuth[0]) + 40.0)
