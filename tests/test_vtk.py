"""ParaView export (thirdbody.io.vtk): files and time series, particle poses (overlapping each
plate by its approach), plates, contact maps painted on the surfaces (against Hertz) and written
cell for cell as patches in the plates' planes, the files read back by VTK's own XML reader, the
single-particle path through the CLI helper, and its refusals (exit 2, nothing written)."""

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
from thirdbody.io.vtk import COLLECTION, export_vtk, export_vtk_cli

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
    return out, paths, [meshio.read(out / f"particles_{k:04d}.vtu") for k in range(3)]


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
    assert len(paths) == 3 * 3 + 1
    parts = ("particles", "plates", "contact")
    assert names == sorted([f"{part}_{k:04d}.vtu" for k in range(3) for part in parts]
                           + ["results.pvd"])
    assert COLLECTION == "results.pvd"
    assert sorted(p.name for p in out.iterdir()) == names
    entries = ET.parse(out / "results.pvd").getroot().find("Collection").findall("DataSet")
    got = sorted((int(e.get("timestep")), int(e.get("part")), e.get("name"), e.get("file"))
                 for e in entries)
    assert got == sorted((k, i, part, f"{part}_{k:04d}.vtu") for k in range(3)
                         for i, part in enumerate(parts))


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
    out, _, meshes = exported
    for step, mesh in enumerate(meshes):
        for p in range(2):
            ids = _vertices_of(mesh, p)
            state = ds.state.values[step, p]
            assert np.all(mesh.point_data["state"][ids] == state)
            cells = mesh.cell_data_dict["particle"]["triangle"] == p
            assert np.all(mesh.cell_data_dict["state"]["triangle"][cells] == state)
    assert list(ds.state.values[:, 1]) == [5, 5, 5]         # the small sphere: unloaded
    # step 1 has no maps: no sampled fields on the surfaces (no NaN), no contact patches
    assert set(meshes[1].point_data) == {"state"}
    empty = _vtk_read(out / "contact_0001.vtu")     # meshio cannot read an empty grid
    assert (empty.GetNumberOfPoints(), empty.GetNumberOfCells()) == (0, 0)
    for step in (0, 2):
        mesh = meshes[step]
        assert set(mesh.point_data) == {"pressure", "traction", "status", "state"}
        assert set(np.unique(mesh.point_data["status"])) <= {0, 1, 2}
        np.testing.assert_array_equal(mesh.point_data["traction"][:, 2], 0.0)
        assert np.all(mesh.point_data["pressure"][_vertices_of(mesh, 1)] == 0.0)
        assert np.all(np.isfinite(mesh.point_data["pressure"]))


def test_each_plate_overlaps_the_surface_by_its_approach(spheres, exported):
    """The surface is drawn undeformed at the rigid pose: it reaches through each plate it
    touches by that plate's approach (what the half-space takes up elastically)."""
    _, ds = spheres
    _, _, meshes = exported
    for step, mesh in enumerate(meshes):
        v = mesh.points[_vertices_of(mesh, 0)]
        lower, upper = ds.approach.values[step, 0, 1], ds.approach.values[step, 0, 0]
        assert lower > 4e-6 and upper > 4e-6
        # a vertex sits on each pole: the overlaps are the approaches to rounding
        assert -v[:, 2].min() == pytest.approx(lower, rel=1e-6)
        assert v[:, 2].max() - ds.plate_gap.values[step] == pytest.approx(upper, rel=1e-6)


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
    assert "contact patches in 2" in printed and str(out / "results.pvd") in printed
    full = open_results(path)
    ds = tb.particle_view(full)
    assert sorted(p.name for p in out.iterdir()) == [
        "contact_0000.vtu", "contact_0001.vtu", "particles_0000.vtu", "particles_0001.vtu",
        "plates_0000.vtu", "plates_0001.vtu", "results.pvd"]
    shape = particle.shape
    cell = float(ds.map_x.values[1] - ds.map_x.values[0])
    for step in range(2):
        assert abs(ds.position.values[step, 0]) > 3 * cell   # it rolled: the offset matters
        mesh = meshio.read(out / f"particles_{step:04d}.vtu")
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
        mesh = meshio.read(tmp_path / f"particles_{step:04d}.vtu")
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
    mesh = meshio.read(tmp_path / f"particles_{step:04d}.vtu")
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


# --- contact patches ----------------------------------------------------------------------------
def _window(pressure, status):
    """The map cells (columns i, rows j) of a patch: the bounding box of the touching cells, one
    free cell around, within the stored window (none without contact)."""
    touch = (np.nan_to_num(pressure) > 0) | (status > 0)
    rows, cols = np.flatnonzero(touch.any(axis=1)), np.flatnonzero(touch.any(axis=0))
    if not rows.size:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    return (np.arange(max(cols[0] - 1, 0), min(cols[-1] + 2, touch.shape[1])),
            np.arange(max(rows[0] - 1, 0), min(rows[-1] + 2, touch.shape[0])))


def _cell_centres(mesh):
    quads = mesh.cells_dict["quad"]
    return mesh.points[quads].mean(axis=1)


@pytest.mark.parametrize("case, step", [("spheres", 0), ("spheres", 2), ("potato", 0),
                                        ("potato", 1)])
def test_contact_patches_hold_the_maps_cell_for_cell(case, step, spheres, exported,
                                                      potato_exported):
    """Each plate's patch of a loaded particle (the big sphere; the rolled potato, whose
    tractions are not zero) is the map's window around its contact (the bounding box of the
    touching cells, one free cell around), one quad per map cell of the map's size, centred at
    the centroid plus the cell centres, in the plate's plane, carrying the map's values; the
    small sphere, unloaded, has none."""
    if case == "spheres":
        (_, ds), (out, _, _) = spheres, exported
    else:
        out, ds = potato_exported
    mesh = meshio.read(out / f"contact_{step:04d}.vtu")
    data = {name: mesh.cell_data_dict[name]["quad"] for name in
            ("pressure", "traction", "status", "particle", "plate")}
    assert set(mesh.cell_data) == set(data)
    assert set(np.unique(data["particle"])) == {0}
    quads = mesh.cells_dict["quad"]
    centres = _cell_centres(mesh)
    h = ds.cell_size.values[0]
    centre = _centre(ds, step, 0)
    one = tb.particle_view(ds, 0).sel(map_step=step)
    for interface, code, z in (("lower", 0, 0.0), ("upper", 1, ds.plate_gap.values[step])):
        mine = data["plate"] == code
        p = one.pressure.sel(interface=interface).values
        tau = one.traction.sel(interface=interface).transpose("component", ...).values
        status = one.status.sel(interface=interface).values
        touch = (p > 0) | (status > 0)
        i, j = _window(p, status)
        assert mine.sum() == len(i) * len(j)
        if case == "spheres":
            # the stored window holds the largest contact (step 2's): step 0's is smaller
            assert (len(i) < p.shape[1]) == (step == 0)
        else:
            assert np.abs(tau[0]).max() > 0.1 * p.max() and np.abs(tau[1]).max() > 0
        # the cells: where the map's are, in the plate's plane, of the map's size
        got_i = np.rint((centres[mine, 0] - centre[0] - one.map_x.values[0]) / h).astype(int)
        got_j = np.rint((centres[mine, 1] - centre[1] - one.map_y.values[0]) / h).astype(int)
        assert sorted(zip(got_j, got_i, strict=True)) == [(a, b) for a in j for b in i]
        np.testing.assert_allclose(centres[mine, 0], centre[0] + one.map_x.values[got_i],
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(centres[mine, 1], centre[1] + one.map_y.values[got_j],
                                   rtol=0, atol=1e-12)
        corners = mesh.points[quads[mine]]
        np.testing.assert_array_equal(corners[..., 2], z)
        np.testing.assert_allclose(np.ptp(corners[..., 0], axis=1), h, rtol=1e-9)
        np.testing.assert_allclose(np.ptp(corners[..., 1], axis=1), h, rtol=1e-9)
        # the values: the map's, cell for cell
        np.testing.assert_array_equal(data["pressure"][mine], p[got_j, got_i])
        np.testing.assert_array_equal(data["traction"][mine][:, 0], tau[0][got_j, got_i])
        np.testing.assert_array_equal(data["traction"][mine][:, 1], tau[1][got_j, got_i])
        np.testing.assert_array_equal(data["traction"][mine][:, 2], 0.0)
        np.testing.assert_array_equal(data["status"][mine], status[got_j, got_i])
        assert touch[got_j, got_i].sum() == touch.sum()
        # normals into the gap, as the plates'
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        assert np.all(np.sign(normal[:, 2]) == (1 if interface == "lower" else -1))


# --- read back by VTK's own XML reader -----------------------------------------------------------
def _vtk_read(path):
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def _vtk_arrays(data):
    return {data.GetArrayName(k): data.GetArray(k) for k in range(data.GetNumberOfArrays())}


def _vtk_integral(grid, particle, plate):
    """VTK's integral of one particle's patch on one plate: ∫p dA (N), its area (m²) and its
    number of cells."""
    from vtkmodules.vtkCommonDataModel import vtkDataObject
    from vtkmodules.vtkFiltersCore import vtkThreshold
    from vtkmodules.vtkFiltersParallel import vtkIntegrateAttributes

    current = grid
    for name, value in (("particle", particle), ("plate", plate)):
        threshold = vtkThreshold()
        threshold.SetInputData(current)
        threshold.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_CELLS, name)
        threshold.SetLowerThreshold(value - 0.5)
        threshold.SetUpperThreshold(value + 0.5)
        threshold.SetThresholdFunction(vtkThreshold.THRESHOLD_BETWEEN)
        threshold.Update()
        current = threshold.GetOutput()
    n = current.GetNumberOfCells()
    if n == 0:
        return 0.0, 0.0, 0
    integrate = vtkIntegrateAttributes()
    integrate.SetInputData(current)
    integrate.Update()
    cells = _vtk_arrays(integrate.GetOutput().GetCellData())
    return cells["pressure"].GetValue(0), cells["Area"].GetValue(0), n


@pytest.fixture(scope="module")
def potato_exported(potato_file, tmp_path_factory):
    path, particle = potato_file
    out = tmp_path_factory.mktemp("potato_vtk")
    export_vtk(open_results(path), tb.Layer.of(particle), out)
    return out, open_results(path)


@pytest.mark.parametrize("case", ["spheres", "potato"])
def test_read_back_by_vtk(case, spheres, exported, potato_exported):
    """Every file the collection lists, read by vtkXMLUnstructuredGridReader: the numbers of
    points and cells, the arrays and their ranges; and each patch integrated by VTK's
    vtkIntegrateAttributes gives the particle's normal force (the map's cells times their
    area) at each plate."""
    if case == "spheres":
        (_, ds), (out, _, _) = spheres, exported
        triangles = 20 * 4**SUBDIVISIONS
    else:
        out, ds = potato_exported
        triangles = 20 * 4**3
    n_particles = ds.sizes["particle"]
    entries = ET.parse(out / COLLECTION).getroot().find("Collection").findall("DataSet")
    assert len(entries) == 3 * ds.sizes["step"]
    stored = list(ds.map_step.values)
    checked = 0
    for entry in entries:
        step, part = int(entry.get("timestep")), entry.get("name")
        grid = _vtk_read(out / entry.get("file"))
        points, cells = _vtk_arrays(grid.GetPointData()), _vtk_arrays(grid.GetCellData())
        has_maps = step in stored
        if part == "particles":
            assert grid.GetNumberOfCells() == n_particles * triangles
            assert grid.GetNumberOfPoints() == n_particles * (triangles // 2 + 2)
            assert set(cells) == {"particle", "state"}
            assert set(points) == ({"pressure", "traction", "status", "state"} if has_maps
                                   else {"state"})
            if has_maps:
                peak = float(ds.pressure.sel(map_step=step).max())
                low, high = points["pressure"].GetRange()
                assert low == 0.0 and 0.5 * peak < high <= peak
                assert points["traction"].GetNumberOfComponents() == 3
                assert set(points["status"].GetRange()) <= {0.0, 1.0, 2.0}
            assert cells["particle"].GetRange() == (0.0, n_particles - 1.0)
        elif part == "plates":
            assert (grid.GetNumberOfPoints(), grid.GetNumberOfCells()) == (8, 2)
            assert set(cells) == {"plate"} and cells["plate"].GetRange() == (0.0, 1.0)
        else:
            assert part == "contact"
            assert set(cells) == {"pressure", "traction", "status", "particle", "plate"}
            if not has_maps:
                assert grid.GetNumberOfCells() == 0
                continue
            windows = [_window(ds.pressure.sel(map_step=step, particle=p, interface=side).values,
                               ds.status.sel(map_step=step, particle=p, interface=side).values)
                       for p in range(n_particles) for side in ("lower", "upper")]
            sizes = [(len(i), len(j)) for i, j in windows if len(i)]
            assert grid.GetNumberOfCells() == sum(ni * nj for ni, nj in sizes)
            assert grid.GetNumberOfPoints() == sum((ni + 1) * (nj + 1) for ni, nj in sizes)
            assert cells["pressure"].GetRange() == (
                0.0, float(ds.pressure.sel(map_step=step).max()))
            assert cells["traction"].GetNumberOfComponents() == 3
            assert cells["status"].GetRange()[0] == 0.0 and cells["status"].GetRange()[1] <= 2
            for p in range(n_particles):
                force = float(ds.normal_force.sel(step=step).values[p])
                h = float(ds.cell_size.values[p])
                for interface, plate in (("lower", 0), ("upper", 1)):
                    integral, area, n = _vtk_integral(grid, p, plate)
                    assert area == pytest.approx(n * h * h, rel=1e-9)
                    assert integral == pytest.approx(force, rel=1e-9, abs=1e-12)
                    on_map = float(ds.pressure.sel(map_step=step, particle=p,
                                                   interface=interface).sum()) * h * h
                    assert integral == pytest.approx(on_map, rel=1e-12, abs=1e-15)
                    checked += force > 0
    assert checked >= 4
