"""ParaView export (thirdbody.io.vtk): files and time series, particle poses, plates, contact maps
painted on the surfaces (against Hertz), the single-particle path through the CLI helper, and
its refusals (exit 2, nothing written)."""

import math
import tomllib
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

import thirdbody as tb
from thirdbody import shapes
from thirdbody.io import open_results, write_results
from thirdbody.io.config import parse_config
from thirdbody.io.vtk import export_vtk, export_vtk_cli

E, NU = 1.0e9, 0.3
RADII = (1.0e-3, 0.98e-3)
XY = ((0.0, 0.0), (3.0e-3, 0.5e-3))
SUBDIVISIONS = 6                  # facets ~ 1/60 of the radius: a few inside each contact cell

POTATO = """
[particle]
shape = "potato"
semi_axes = [1.0e-3, 0.8e-3, 0.7e-3]
seed = 27
amplitude = 0.055
wavenumber_range = [2.0, 4.0]
E = 1.0e9
nu = 0.3
orientation_deg = -41.0

[plates]
mu_up = 0.2
mu_low = 0.4

[load]
program = "linear_ramp"
stop = 3.0
steps = 2

[numerics]
resolution = 30.0
maps_every = 1
"""


@pytest.fixture(scope="module")
def spheres():
    """Two spheres; the smaller one never touches the upper plate. Three steps, maps at steps
    0 and 2 only."""
    mat = tb.Material(E, NU)
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(shapes.Sphere(r), mat), xy)
                      for r, xy in zip(RADII, XY, strict=True)])
    sim = tb.Simulation(layer, tb.Plates(0.3), tb.LinearRamp(stop=1.5, steps=3), resolution=40,
                        maps_every=2)
    ds = sim.run()
    assert list(ds.map_step.values) == [0, 2]
    return layer, ds


@pytest.fixture(scope="module")
def exported(spheres, tmp_path_factory):
    layer, ds = spheres
    out = tmp_path_factory.mktemp("vtk") / "out"
    paths = export_vtk(ds, layer, out, subdivisions=SUBDIVISIONS)
    return out, paths, [meshio.read(out / f"step_{k:04d}.vtu") for k in range(3)]


def _vertices_of(mesh, particle):
    tri = mesh.cells_dict["triangle"]
    return np.unique(tri[mesh.cell_data_dict["particle"]["triangle"] == particle])


def _centre(ds, step, particle):
    return np.array([ds.x0.values[particle] + ds.position.values[step, particle, 0],
                     ds.y0.values[particle] + ds.position.values[step, particle, 1],
                     ds.centroid_height.values[step, particle]])


def test_files_and_time_series(exported):
    out, paths, _ = exported
    names = sorted(p.name for p in paths)
    assert len(paths) == 2 * 3 + 1
    assert names == sorted([f"step_{k:04d}.vtu" for k in range(3)]
                           + [f"plates_{k:04d}.vtu" for k in range(3)] + ["layer.pvd"])
    assert sorted(p.name for p in out.iterdir()) == names
    entries = ET.parse(out / "layer.pvd").getroot().find("Collection").findall("DataSet")
    got = sorted((int(e.get("timestep")), int(e.get("part")), e.get("file")) for e in entries)
    assert got == sorted([(k, 0, f"step_{k:04d}.vtu") for k in range(3)]
                         + [(k, 1, f"plates_{k:04d}.vtu") for k in range(3)])


def test_spheres_at_their_poses(spheres, exported):
    _, ds = spheres
    _, _, meshes = exported
    for step, mesh in enumerate(meshes):
        tri = mesh.cells_dict["triangle"]
        assert len(tri) == 2 * 20 * 4**SUBDIVISIONS
        for p, radius in enumerate(RADII):
            v = mesh.points[_vertices_of(mesh, p)]
            assert len(v) == 10 * 4**SUBDIVISIONS + 2
            distance = np.linalg.norm(v - _centre(ds, step, p), axis=1)
            np.testing.assert_allclose(distance, radius, rtol=1e-9)
            # resting on (pressed into) the lower plate, by less than a cell
            assert abs(v[:, 2].min()) < ds.cell_size.values[p]
        # the big sphere also touches the upper plate; the small one is far below it
        gap = ds.plate_gap.values[step]
        top = mesh.points[_vertices_of(mesh, 0), 2].max()
        assert abs(top - gap) < ds.cell_size.values[0]
        assert mesh.points[_vertices_of(mesh, 1), 2].max() < gap - 0.01e-3


def test_plates(spheres, exported):
    _, ds = spheres
    out, _, meshes = exported
    for step, particles in enumerate(meshes):
        plates = meshio.read(out / f"plates_{step:04d}.vtu")
        quads = plates.cells_dict["quad"]
        assert quads.shape == (2, 4)
        assert list(plates.cell_data_dict["plate"]["quad"]) == [0, 1]
        lower, upper = plates.points[quads[0]], plates.points[quads[1]]
        np.testing.assert_array_equal(lower[:, 2], 0.0)
        np.testing.assert_allclose(upper[:, 2], ds.plate_gap.values[step], rtol=1e-12)
        # the plates cover every particle, with a margin
        for corner in (lower, upper):
            assert corner[:, 0].min() < particles.points[:, 0].min() - 0.5e-3
            assert corner[:, 0].max() > particles.points[:, 0].max() + 0.5e-3
            assert corner[:, 1].min() < particles.points[:, 1].min() - 0.5e-3
            assert corner[:, 1].max() > particles.points[:, 1].max() + 0.5e-3


def test_state_and_steps_without_maps(spheres, exported):
    _, ds = spheres
    _, _, meshes = exported
    for step, mesh in enumerate(meshes):
        for p in range(2):
            ids = _vertices_of(mesh, p)
            state = ds.state.values[step, p]
            assert np.all(mesh.point_data["state"][ids] == state)
            cells = mesh.cell_data_dict["particle"]["triangle"] == p
            assert np.all(mesh.cell_data_dict["state"]["triangle"][cells] == state)
    assert list(ds.state.values[:, 1]) == [5, 5, 5]         # the small sphere: unloaded
    no_maps = meshes[1]
    assert np.all(np.isnan(no_maps.point_data["pressure"]))
    assert np.all(np.isnan(no_maps.point_data["traction"]))
    assert np.all(no_maps.point_data["status"] == -1)
    for step in (0, 2):
        mesh = meshes[step]
        assert set(np.unique(mesh.point_data["status"])) <= {0, 1, 2}
        np.testing.assert_array_equal(mesh.point_data["traction"][:, 2], 0.0)
        assert np.all(mesh.point_data["pressure"][_vertices_of(mesh, 1)] == 0.0)


def _hertz(force, radius):
    """Contact radius (m) and peak pressure (Pa) of a sphere on a rigid flat."""
    e_star = E / (1 - NU**2)
    a = (3 * force * radius / (4 * e_star)) ** (1 / 3)
    return a, 3 * force / (2 * math.pi * a**2)


def _vertex_areas(mesh):
    """Horizontal projection of the area lumped to each vertex (a third of each triangle's)."""
    tri = mesh.cells_dict["triangle"]
    p = mesh.points[tri]
    u, w = p[:, 1, :2] - p[:, 0, :2], p[:, 2, :2] - p[:, 0, :2]
    projected = 0.5 * np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
    area = np.zeros(len(mesh.points))
    np.add.at(area, tri.ravel(), np.repeat(projected / 3, 3))
    return area


@pytest.mark.parametrize("step", [0, 2])
def test_pressure_on_vertices_is_hertzian(spheres, exported, step):
    _, ds = spheres
    _, _, meshes = exported
    mesh = meshes[step]
    force = float(ds.normal_force.values[step, 0])
    a, p0 = _hertz(force, RADII[0])
    centre = _centre(ds, step, 0)
    ids = _vertices_of(mesh, 0)
    v, pressure = mesh.points[ids], mesh.point_data["pressure"][ids]
    area = _vertex_areas(mesh)[ids]
    map_peak = float(ds.pressure.sel(map_step=step, particle=0).max())
    assert 0.9 * map_peak < pressure.max() <= map_peak
    assert abs(map_peak / p0 - 1) < 0.1
    gap = ds.plate_gap.values[step]
    r = np.hypot(v[:, 0] - centre[0], v[:, 1] - centre[1])
    for near in (v[:, 2] < centre[2], v[:, 2] > centre[2]):      # lower, upper halves
        inner = near & (r < 0.5 * a)
        assert inner.sum() > 10
        expected = p0 * np.sqrt(1 - (r[inner] / a) ** 2)
        assert np.max(np.abs(pressure[inner] - expected)) < 0.12 * p0
        assert np.all(pressure[near & (r > 1.3 * a)] == 0.0)
        # the force carried by each plate
        assert abs(np.sum(pressure[near] * area[near]) / force - 1) < 0.05
    # only vertices within 3 cells of a plate carry pressure
    z = v[pressure > 0, 2]
    band = 3 * ds.cell_size.values[0]
    assert np.all((z <= band) | (z >= gap - band))


def test_layer_must_match(spheres, tmp_path):
    layer, ds = spheres
    mat = tb.Material(E, NU)
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="particles"):
        export_vtk(ds, tb.Layer([layer[0]]), out)
    moved = tb.Layer([layer[0], tb.PlacedParticle(tb.Particle(shapes.Sphere(RADII[1]), mat),
                                                  (3.0e-3, -0.5e-3))])
    with pytest.raises(ValueError, match="positions"):
        export_vtk(ds, moved, out)
    with pytest.raises(ValueError, match=r"centroid_height.*re-run"):
        export_vtk(ds.drop_vars("centroid_height"), layer, out)
    assert not out.exists()


@pytest.fixture(scope="module")
def potato_file(tmp_path_factory):
    """A single-particle results file with its configuration, as ``thirdbody run`` writes it."""
    cfg = parse_config(tomllib.loads(POTATO))
    particle, plates, load, numerics = cfg.build()
    ds = tb.Simulation(particle, plates, load, **numerics).run()
    path = tmp_path_factory.mktemp("potato") / "results.nc"
    write_results(ds.assign_attrs(config=POTATO), path)
    return path, particle


def test_cli_single_particle(potato_file, tmp_path, capsys):
    path, particle = potato_file
    out = tmp_path / "vtk"
    assert export_vtk_cli(path, out) == 0
    printed = capsys.readouterr().out.strip()
    assert printed.count("\n") == 0 and str(out) in printed and "2 steps" in printed
    full = open_results(path)
    ds = tb.particle_view(full)
    assert sorted(p.name for p in out.iterdir()) == [
        "layer.pvd", "plates_0000.vtu", "plates_0001.vtu", "step_0000.vtu", "step_0001.vtu"]
    shape = particle.shape
    cell = float(ds.map_x.values[1] - ds.map_x.values[0])
    for step in range(2):
        assert abs(ds.position.values[step, 0]) > 3 * cell   # it rolled: the offset matters
        mesh = meshio.read(out / f"step_{step:04d}.vtu")
        centre = np.array([*ds.position.values[step], ds.centroid_height.values[step]])
        rotation = tb.orientation.Rotation.from_quat(ds.quaternion.values[step])
        v = mesh.points - centre
        # every vertex lies on the analytic surface seen by vertical rays
        lower, upper = shape.surfaces(rotation, v[:, 0], v[:, 1])
        miss = np.minimum(np.abs(v[:, 2] - lower), np.abs(v[:, 2] - upper))
        on_ray = np.isfinite(miss)
        assert on_ray.mean() > 0.99
        assert np.median(miss[on_ray]) < 1e-9
        assert abs(mesh.points[:, 2].min()) < cell
        assert abs(mesh.points[:, 2].max() - ds.plate_gap.values[step]) < cell
        pressure = mesh.point_data["pressure"]
        assert pressure.max() <= float(ds.pressure.sel(map_step=step).max())
        assert pressure.max() > 0.5 * float(ds.pressure.sel(map_step=step).max())


def test_cli_refuses(potato_file, spheres, tmp_path, capsys):
    path, _ = potato_file
    out = tmp_path / "out"
    missing = tmp_path / "missing.nc"
    assert export_vtk_cli(missing, out) == 2
    assert "error:" in capsys.readouterr().err and not out.exists()

    _, ds = spheres
    no_config = tmp_path / "layer.nc"
    write_results(ds, no_config)
    assert export_vtk_cli(no_config, out) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and "config" in err and not out.exists()

    text = tmp_path / "notes.nc"
    text.write_text("not a results file")
    assert export_vtk_cli(text, out) == 2
    assert "not a thirdbody results file" in capsys.readouterr().err and not out.exists()

    old = tmp_path / "old.nc"
    write_results(open_results(path).drop_vars("centroid_height"), old)
    assert export_vtk_cli(old, out) == 2
    assert "centroid_height" in capsys.readouterr().err and not out.exists()


def test_maps_follow_each_interface(potato_file, tmp_path):
    """The rolled potato touches the plates off-centre, on opposite sides: the pressure painted
    near each plate is centred where that interface's map is."""
    path, particle = potato_file
    full = open_results(path)
    ds = tb.particle_view(full)
    export_vtk(full, tb.Layer.of(particle), tmp_path, subdivisions=5)
    cell = float(ds.map_x.values[1] - ds.map_x.values[0])
    X, Y = np.meshgrid(ds.map_x.values, ds.map_y.values)
    for step in range(2):
        mesh = meshio.read(tmp_path / f"step_{step:04d}.vtu")
        centre = np.array([*ds.position.values[step], ds.centroid_height.values[step]])
        weight = mesh.point_data["pressure"] * _vertex_areas(mesh)
        rel = mesh.points - centre
        for interface, near in (("lower", rel[:, 2] < 0), ("upper", rel[:, 2] > 0)):
            p = ds.pressure.sel(map_step=step, interface=interface).values
            expected = np.array([(p * X).sum(), (p * Y).sum()]) / p.sum()
            got = (weight[near] @ rel[near, :2]) / weight[near].sum()
            assert abs(expected[0]) > 3 * cell
            np.testing.assert_allclose(got, expected, atol=0.3 * cell)
            # the force on each plate, by the vertices and by the map
            np.testing.assert_allclose(weight[near].sum(), p.sum() * cell**2, rtol=0.15)


@pytest.mark.parametrize("window", ["stored", "wide"])
def test_which_vertices_sample_which_map(spheres, tmp_path, window):
    """Constant maps, distinct per interface and component: a vertex takes the lower map up to
    3 cells above the lower plate, the upper one from 3 cells below the upper plate, and
    nothing in between nor outside the map window (the stored one, or one of ±41 cells, wider
    than the spheres, so that only the height decides)."""
    layer, ds = spheres
    values = {"lower": (1.0, 10.0, 20.0, 1), "upper": (2.0, 30.0, 40.0, 2)}
    if window == "wide":
        fake = ds.reindex(map_i=np.arange(-41, 42), map_j=np.arange(-41, 42))
    else:
        fake = ds.copy(deep=True)
    for interface, (p, tx, ty, st) in values.items():
        fake["pressure"].loc[{"interface": interface}] = p
        fake["traction"].loc[{"interface": interface, "component": "x"}] = tx
        fake["traction"].loc[{"interface": interface, "component": "y"}] = ty
        fake["status"].loc[{"interface": interface}] = st
    export_vtk(fake, layer, tmp_path, subdivisions=4)
    step = 2
    mesh = meshio.read(tmp_path / f"step_{step:04d}.vtu")
    gap = ds.plate_gap.values[step]
    for p in range(2):
        ids = _vertices_of(mesh, p)
        v = mesh.points[ids]
        band = 3 * ds.cell_size.values[p]
        # the map window: cells map_i, map_j (cell centres at index * cell size)
        i, j = ((v[:, :2] - _centre(ds, step, p)[:2]) / ds.cell_size.values[p]).T
        cells_i, cells_j = fake.map_i.values, fake.map_j.values
        in_map = ((i >= cells_i.min() - 0.5) & (i < cells_i.max() + 0.5)
                  & (j >= cells_j.min() - 0.5) & (j < cells_j.max() + 0.5))
        expected = {"lower": (v[:, 2] <= band) & in_map,
                    "upper": (v[:, 2] >= gap - band) & in_map}
        middle = ~expected["lower"] & ~expected["upper"]
        assert middle.sum() > 0.9 * len(ids)
        for interface, where in expected.items():
            p_, tx, ty, st = values[interface]
            np.testing.assert_array_equal(mesh.point_data["pressure"][ids][where], p_)
            np.testing.assert_array_equal(mesh.point_data["traction"][ids][where],
                                          np.tile([tx, ty, 0.0], (where.sum(), 1)))
            np.testing.assert_array_equal(mesh.point_data["status"][ids][where], st)
        assert expected["lower"].sum() > 10
        if window == "wide":
            assert np.all(in_map) and np.any(expected["lower"] & (v[:, 2] > 2 * band / 3))
            assert expected["upper"].sum() > (10 if p == 0 else 0)
        else:
            assert not np.all(in_map[v[:, 2] <= band])
        np.testing.assert_array_equal(mesh.point_data["pressure"][ids][middle], 0.0)
        np.testing.assert_array_equal(mesh.point_data["traction"][ids][middle], 0.0)
        np.testing.assert_array_equal(mesh.point_data["status"][ids][middle], 0)
