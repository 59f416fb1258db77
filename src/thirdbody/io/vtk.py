"""ParaView export: the particles at their poses, the plates, and the contact maps as patches.

:func:`export_vtk` writes, into one directory, for every load step ``k`` (the ``step``
coordinate of the results):

* ``particles_kkkk.vtu`` — every particle's closed triangle surface at its pose in the world
  (unstructured grid, one triangle block, all particles concatenated in layer order);
* ``plates_kkkk.vtu`` — the two plates as two quads (lower then upper);
* ``contact_kkkk.vtu`` — the contact maps of the step as patches in the plates' planes: one
  quad per map cell, at the solver's own resolution (empty in a step without stored maps);
* ``network_kkkk.vtu`` — a network run's contacts (``[network]``, particles that touch) as
  lines: particle to particle between their centroids, particle to plate from the centroid to
  the pressure centroid, with the normal force, the force, the state and the kind of contact
  as cell data (use ParaView's Tube filter, radius by ``normal_force``, for a force network);
* ``results.pvd`` — a ParaView collection listing the files of every step with
  ``timestep`` = the step index, as ``part`` 0 (``particles``), 1 (``plates``), 2
  (``contact``) and, for a network run, 3 (``network``): open it in ParaView to get a
  multi-block time series.

All lengths are in metres, pressures and tractions in pascals. The files are written with
meshio; only the small ``.pvd`` XML index is written directly.

Geometry
--------
A particle's surface is its shape tessellated by
:meth:`thirdbody.shapes.MeshShape.from_shape` (``subdivisions`` icosphere levels,
``20·4^s`` triangles per particle), expressed in the analytic shape's body frame (volume
centroid at the origin; the tessellation's small centroid offset is added back so every vertex
lies on the analytic surface). A mesh particle (:class:`~thirdbody.shapes.MeshShape`) is written
as it is. A body-frame vertex ``p`` goes to the world at ``R p + c``: ``R`` is the rotation of
the ``quaternion`` variable of the step (x, y, z, w; body to world) and the centroid is
``c = (x0 + position_x, y0 + position_y, centroid_height)``, the lower plate at z = 0 and the
upper plate at z = ``plate_gap``. A single-particle dataset has x0 = y0 = 0. A step whose pose
is not finite reuses the previous step's pose (at step 0: the particle's initial orientation,
resting on the lower plate at its initial position).

The surface is the undeformed shape at the particle's rigid pose, as in the model (rigid
plates, elastic half-space particle): where it is pressed, it reaches through each plate by
that plate's ``approach``, the displacement the half-space takes up elastically. Nothing is
clipped or flattened.

The plates span the rectangle covering every particle's bounding disc over all steps, enlarged
by the largest particle size (m) on every side; the lower quad lies at z = 0 and the upper at
z = ``plate_gap`` of the step.

Contact patches
---------------
For each particle, plate and stored map step, the cells of the map's window where that plate
touches (the bounding box of the cells with pressure or a stick/slip status, one free cell
around, within the stored window) are written as quads of the map's cell size, centred at the
particle's centroid (x, y) plus the cell centres (``map_x``, ``map_y``), at z = 0 for the lower
plate and z = ``plate_gap`` for the upper. Cell data (one value per map cell, as the solver has
it): ``pressure`` (Pa), ``traction`` (3-vector, Pa, z component 0; exerted by the plate on the
particle), ``status`` (0 open, 1 stick, 2 slip), ``particle`` (its index in the layer) and
``plate`` (0 lower, 1 upper). Summing ``pressure`` × cell area over a patch gives the force
that plate exerts on the particle. In a step without stored maps (see ``maps_every``) the file
holds no cells.

Data on the particle surfaces
-----------------------------
Point data, in steps with stored maps only:

``pressure`` (Pa), ``traction`` (3-vector, Pa, z component 0; exerted by the plate on the
particle), ``status`` (0 open, 1 stick, 2 slip)
    Sampled from the stored contact maps of the step, in the cell (nearest cell centre) under
    the vertex's horizontal position relative to the particle's centroid (world axes). A vertex
    takes the lower-interface map if it lies at most 3 cell sizes above the lower plate
    (``z <= 3 h``, overlapping vertices included), the upper-interface map if it lies at most
    3 cell sizes below the upper plate (``z >= plate_gap − 3 h``; the nearer plate if both
    hold), where ``h`` is the particle's BEM cell size. Every other vertex, and a vertex
    outside the map window, gets pressure 0, traction 0 and status 0 (open). A step without
    stored maps has none of these three arrays (no NaN placeholders).

The surface's vertices are far coarser than the maps (a contact spot spans a few vertices), so
the painted pressure is an overview; the contact patches show the maps as they are.

Point data in every step: ``state`` (int8), the particle's state code in the step, as in the
results' ``state`` variable (its ``flag_meanings`` attribute names the codes: stick,
roll_upper, roll_lower, rotate, failed, unloaded, and for network runs roll, slide,
slide_upper, slide_lower).

Cell data: ``particle`` (the particle's index in the layer) and ``state`` (as above).

On the plates: cell data ``plate`` (0 lower, 1 upper).
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import meshio
import numpy as np
import xarray as xr
from scipy.spatial.transform import Rotation

from thirdbody.layer import Layer
from thirdbody.schema import DIMENSIONS
from thirdbody.shapes import MeshShape, Shape

__all__ = ["COLLECTION", "NEAR_PLATE_CELLS", "export_vtk", "export_vtk_cli"]

#: the name of the ParaView collection (time series) that :func:`export_vtk` writes
COLLECTION = "results.pvd"

#: a vertex samples a plate's contact map when it is at most this many cell sizes from it
NEAR_PLATE_CELLS = 3.0

#: the results' variables (:mod:`thirdbody.schema`) the export reads
_POSE_VARIABLES = ("quaternion", "position", "centroid_height", "plate_gap", "state")
_LAYER_VARIABLES = ("x0", "y0", "cell_size")
_MAP_VARIABLES = ("pressure", "traction", "status")


@dataclass(frozen=True)
class _Maps:
    """One interface's contact maps, particle axis first after ``map_step``."""

    pressure: np.ndarray            # (map_step, particle, j, i), Pa
    traction: np.ndarray            # (map_step, particle, 2, j, i), Pa
    status: np.ndarray              # (map_step, particle, j, i)


@dataclass(frozen=True)
class _Results:
    """The parts of a results dataset the export needs, with a particle axis."""

    steps: np.ndarray               # (S,) step indices
    quaternion: np.ndarray          # (S, P, 4) x, y, z, w
    centre: np.ndarray              # (S, P, 3) m
    plate_gap: np.ndarray           # (S,) m
    state: np.ndarray               # (S, P) int8
    cell_size: np.ndarray           # (P,) m
    map_steps: np.ndarray           # (M,) step indices of the stored maps
    map_x: np.ndarray               # (P, I) m, cell centres relative to the centroid
    map_y: np.ndarray               # (P, J) m
    maps: dict[str, _Maps]          # by interface name, "upper" and "lower"


def _read(ds: xr.Dataset) -> _Results:
    """Check ``ds`` (in today's form: :func:`~thirdbody.io.results.upgrade`) and take out what
    the export needs (ValueError naming what is missing)."""
    if "step" not in ds.dims:
        raise ValueError("not a thirdbody results dataset: it has no 'step' dimension")
    missing = [v for v in _POSE_VARIABLES + _LAYER_VARIABLES if v not in ds.variables]
    if "centroid_height" in missing:
        raise ValueError("the results have no 'centroid_height' variable (written by an older "
                         "thirdbody): re-run the simulation to export it")
    if missing:
        raise ValueError(f"not a thirdbody results dataset: missing {', '.join(missing)}")

    def per_particle(name: str, *tail: str) -> np.ndarray:
        da = ds[name]
        for dim in ("quaternion_component", "component"):
            if dim in tail:
                da = da.sel({dim: list(DIMENSIONS[dim].labels)})
        return np.asarray(da.transpose("step", "particle", *tail).values, dtype=float)

    quat = per_particle("quaternion", "quaternion_component")
    position = per_particle("position", "component")
    height = per_particle("centroid_height")
    state = np.asarray(ds["state"].transpose("step", "particle").values).astype(np.int8)
    n_steps, n_particles = height.shape
    x0 = np.asarray(ds["x0"].values, dtype=float)
    y0 = np.asarray(ds["y0"].values, dtype=float)
    centre = np.stack([x0 + position[..., 0], y0 + position[..., 1], height], axis=-1)
    cell = np.asarray(ds["cell_size"].values, dtype=float)

    maps: dict[str, _Maps] = {}
    if all(v in ds.variables for v in _MAP_VARIABLES):
        # the cell centres (m): each particle's cell size times the lattice index
        map_x = cell[:, None] * np.asarray(ds["map_i"].values, dtype=float)[None, :]
        map_y = cell[:, None] * np.asarray(ds["map_j"].values, dtype=float)[None, :]

        def field(name: str, interface: str, *extra: str) -> np.ndarray:
            da = ds[name].sel(interface=interface)
            if "component" in extra:
                da = da.sel(component=list(DIMENSIONS["component"].labels))
            return np.asarray(da.transpose("map_step", "particle", *extra, "map_j",
                                           "map_i").values)

        for interface in DIMENSIONS["interface"].labels:
            maps[interface] = _Maps(field("pressure", interface),
                                    field("traction", interface, "component"),
                                    field("status", interface).astype(np.int8))
        map_steps = np.asarray(ds["map_step"].values, dtype=np.int64)
    else:
        map_x = map_y = np.zeros((n_particles, 0))
        map_steps = np.zeros(0, dtype=np.int64)

    return _Results(
        steps=np.asarray(ds["step"].values, dtype=np.int64), quaternion=quat, centre=centre,
        plate_gap=np.asarray(ds["plate_gap"].values, dtype=float).reshape(n_steps),
        state=state, cell_size=cell, map_steps=map_steps, map_x=map_x, map_y=map_y, maps=maps)


def _surface(shape: Shape, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame vertices (m) and triangles of a particle's surface."""
    if isinstance(shape, MeshShape):
        return shape.vertices, shape.faces
    mesh = MeshShape.from_shape(shape, subdivisions=subdivisions)
    # back to the analytic body frame, where the simulation's centroid (and pose) is defined
    return mesh.vertices + mesh.offset, mesh.faces


def _fill_poses(results: _Results, layer: Layer) -> tuple[np.ndarray, np.ndarray]:
    """Quaternions and centres with non-finite poses replaced by the previous step's (at step
    0: the initial orientation, at the initial position and height)."""
    quat = results.quaternion.copy()
    centre = results.centre.copy()
    for p, placed in enumerate(layer):
        for s in range(len(results.steps)):
            if np.all(np.isfinite(quat[s, p])) and np.all(np.isfinite(centre[s, p])):
                continue
            if s > 0:
                quat[s, p], centre[s, p] = quat[s - 1, p], centre[s - 1, p]
            else:
                rotation = placed.particle.orientation
                quat[s, p] = rotation.as_quat()
                centre[s, p] = (*placed.xy, placed.height)
    return quat, centre


def _nearest(coords: np.ndarray, values: np.ndarray, cell: float) -> tuple[np.ndarray, ...]:
    """Index of the nearest cell centre of a uniform axis ``coords`` and whether it exists."""
    if len(coords) == 0:
        return np.zeros(len(values), dtype=np.int64), np.zeros(len(values), dtype=bool)
    k = np.rint((values - coords[0]) / cell).astype(np.int64)
    inside = (k >= 0) & (k < len(coords))
    return np.clip(k, 0, len(coords) - 1), inside


def _map_index(results: _Results, s: int) -> int | None:
    """The index along ``map_step`` of the maps stored for step index ``s`` (None: none)."""
    hit = np.flatnonzero(results.map_steps == results.steps[s])
    return int(hit[-1]) if len(hit) else None


def _point_data(results: _Results, s: int, p: int, world: np.ndarray,
                centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Pressure (n,), traction (n, 3) and status (n,) of particle ``p``'s vertices in step
    index ``s`` (see the module docstring for the rules); None in a step without maps."""
    m = _map_index(results, s)
    if m is None:
        return None
    n = len(world)
    pressure, traction = np.zeros(n), np.zeros((n, 3))
    status = np.zeros(n, dtype=np.int8)
    h = results.cell_size[p]
    gap = results.plate_gap[s]
    z = world[:, 2]
    band = NEAR_PLATE_CELLS * h
    near_lower = z <= band
    near_upper = z >= gap - band
    both = near_lower & near_upper
    near_lower &= ~both | (z <= gap - z)
    near_upper &= ~near_lower
    cell_x = abs(results.map_x[p, 1] - results.map_x[p, 0]) if results.map_x.shape[1] > 1 else h
    cell_y = abs(results.map_y[p, 1] - results.map_y[p, 0]) if results.map_y.shape[1] > 1 else h
    for interface, near in (("lower", near_lower), ("upper", near_upper)):
        rel = world[near, :2] - centre[:2]
        i, in_x = _nearest(results.map_x[p], rel[:, 0], cell_x)
        j, in_y = _nearest(results.map_y[p], rel[:, 1], cell_y)
        inside = in_x & in_y
        rows = np.flatnonzero(near)[inside]
        i, j = i[inside], j[inside]
        maps = results.maps[interface]
        pressure[rows] = maps.pressure[m, p, j, i]
        traction[rows, 0] = maps.traction[m, p, 0, j, i]
        traction[rows, 1] = maps.traction[m, p, 1, j, i]
        status[rows] = maps.status[m, p, j, i]
    return pressure, traction, status


#: the plates' codes in the ``plate`` cell data of the plates and of the contact patches
_PLATE_CODES = {"lower": 0, "upper": 1}


def _patch(results: _Results, m: int, p: int, interface: str, xy: np.ndarray,
           z: float) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]] | None:
    """One contact patch: the corner points (n, 3) and quads (k, 4) of the cells of the map
    window where ``interface`` touches particle ``p`` at map index ``m``, one free cell around,
    at height ``z`` around the centroid's ``xy``; with their cell data. None without contact."""
    maps = results.maps[interface]
    pressure = maps.pressure[m, p]
    status = maps.status[m, p]
    with np.errstate(invalid="ignore"):
        touch = (pressure > 0) | (status > 0)
    rows, cols = np.flatnonzero(touch.any(axis=1)), np.flatnonzero(touch.any(axis=0))
    if not rows.size:
        return None
    ny, nx = touch.shape
    j0, j1 = max(rows[0] - 1, 0), min(rows[-1] + 2, ny)
    i0, i1 = max(cols[0] - 1, 0), min(cols[-1] + 2, nx)
    h = results.cell_size[p]
    x = xy[0] + np.append(results.map_x[p, i0:i1] - h / 2, results.map_x[p, i1 - 1] + h / 2)
    y = xy[1] + np.append(results.map_y[p, j0:j1] - h / 2, results.map_y[p, j1 - 1] + h / 2)
    X, Y = np.meshgrid(x, y)
    points = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
    ni, nj = i1 - i0, j1 - j0
    corner = (np.arange(nj)[:, None] * (ni + 1) + np.arange(ni)[None, :]).ravel()
    quads = np.column_stack([corner, corner + 1, corner + ni + 2, corner + ni + 1])
    if interface == "upper":            # normals into the gap, as the plates'
        quads = quads[:, ::-1]
    traction = maps.traction[m, p, :, j0:j1, i0:i1].reshape(2, -1).T
    data = {"pressure": pressure[j0:j1, i0:i1].ravel().astype(float),
            "traction": np.column_stack([traction, np.zeros(len(traction))]),
            "status": status[j0:j1, i0:i1].ravel().astype(np.int8),
            "particle": np.full(len(quads), p, dtype=np.int32),
            "plate": np.full(len(quads), _PLATE_CODES[interface], dtype=np.int8)}
    return points, quads, data


def _contact_mesh(results: _Results, s: int, centre: np.ndarray) -> meshio.Mesh:
    """The contact patches of every particle and plate in step index ``s`` (``centre``: the
    particles' centroids (P, 3), m); no cells in a step without maps."""
    points, quads = [np.zeros((0, 3))], [np.zeros((0, 4), dtype=np.int64)]
    data: dict[str, list[np.ndarray]] = {
        "pressure": [np.zeros(0)], "traction": [np.zeros((0, 3))],
        "status": [np.zeros(0, dtype=np.int8)], "particle": [np.zeros(0, dtype=np.int32)],
        "plate": [np.zeros(0, dtype=np.int8)]}
    m = _map_index(results, s)
    if m is not None:
        n_points = 0
        for p in range(len(results.cell_size)):
            for interface, z in (("lower", 0.0), ("upper", float(results.plate_gap[s]))):
                patch = _patch(results, m, p, interface, centre[p, :2], z)
                if patch is None:
                    continue
                patch_points, patch_quads, patch_data = patch
                points.append(patch_points)
                quads.append(patch_quads + n_points)
                n_points += len(patch_points)
                for name, values in patch_data.items():
                    data[name].append(values)
    return meshio.Mesh(np.concatenate(points), [("quad", np.concatenate(quads))],
                       cell_data={name: [np.concatenate(v)] for name, v in data.items()})


def _network_mesh(ds: xr.Dataset, step: int, centre: np.ndarray) -> meshio.Mesh:
    """A network run's contacts of ``step`` as line cells: a particle contact from particle i's
    centroid to the centroid of the image of j that touches it, a plate contact from the
    particle's centroid to the contact's pressure centroid on the plate. Cell data: normal
    force (N), the force on i (N, 3-vector), state (0 stick, 1 slide), kind (0 particle, 1 lower
    plate, 2 upper plate) and the two ends' indices (j = −1 lower, −2 upper plate)."""
    rows = np.flatnonzero((ds.contact_step.values == step)
                          & (ds.contact_normal_force.values > 0))
    i = ds.contact_i.values[rows].astype(int)
    j = ds.contact_j.values[rows].astype(int)
    point = ds.contact_point.transpose("contact", "xyz").values[rows]
    box = json.loads(ds.attrs.get("inputs", "{}")).get("box")
    start = centre[i]
    end = point.copy()
    pair = j >= 0
    if pair.any():
        end[pair] = centre[j[pair]]
        if box:     # centroids are not wrapped: the image of j nearest to i
            L = np.array([box[0], box[1], np.inf])
            d = end[pair] - start[pair]
            d[:, :2] -= L[:2] * np.round(d[:, :2] / L[:2])
            end[pair] = start[pair] + d
    points = np.concatenate([start, end]) if len(rows) else np.zeros((0, 3))
    lines = np.column_stack([np.arange(len(rows)), len(rows) + np.arange(len(rows))])
    kind = np.where(j >= 0, 0, np.where(j == -1, 1, 2)).astype(np.int8)
    data = {"normal_force": [ds.contact_normal_force.values[rows]],
            "force": [ds.contact_force.transpose("contact", "xyz").values[rows]],
            "state": [ds.contact_state.values[rows].astype(np.int8)],
            "kind": [kind], "i": [i.astype(np.int32)], "j": [j.astype(np.int32)]}
    return meshio.Mesh(points, [("line", lines.astype(np.int64))], cell_data=data)


def _write_pvd(path: Path, entries: list[tuple[int, int, str, str]]) -> None:
    """A ParaView collection: (timestep, part, name, file) per data set."""
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for timestep, part, name, file in entries:
        ET.SubElement(collection, "DataSet", timestep=str(timestep), group="", part=str(part),
                      name=name, file=file)
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def export_vtk(ds: xr.Dataset, layer: Layer, out_dir: str | Path, *,
               subdivisions: int = 3) -> list[Path]:
    """Write a results dataset as a ParaView time series (see the module docstring).

    Parameters
    ----------
    ds : xarray.Dataset
        A results dataset of a layer (with a ``particle`` dimension) or of a single particle,
        as written by :class:`thirdbody.Simulation`; it must have ``centroid_height`` (m).
    layer : thirdbody.Layer
        The particles of the run, in the dataset's order (``Layer.of(particle)`` for a single
        particle); their shapes are drawn.
    out_dir : str or Path
        Output directory, created if needed; existing files of the same names are replaced.
    subdivisions : int
        Icosphere levels of the tessellation of analytic shapes (``20·4^s`` triangles per
        particle); mesh particles are written as they are.

    Returns
    -------
    list of Path
        The written files: per step ``particles_kkkk.vtu``, ``plates_kkkk.vtu`` and
        ``contact_kkkk.vtu``, then ``results.pvd``.

    Raises
    ------
    ValueError
        If ``ds`` lacks a variable the export needs (including ``centroid_height``), or the
        layer does not match the dataset (number or positions of the particles). Nothing is
        written then.
    """
    if isinstance(subdivisions, bool) or not isinstance(subdivisions, int) \
            or not 0 <= subdivisions <= 8:
        raise ValueError(f"subdivisions must be an integer in [0, 8], got {subdivisions!r}")
    if not isinstance(layer, Layer):
        raise TypeError("layer must be a thirdbody.Layer (use Layer.of(particle) for one "
                        "particle)")
    from thirdbody.io.results import upgrade

    if "step" in ds.dims:
        ds = upgrade(ds)
    results = _read(ds)
    n_steps, n_particles = results.state.shape
    if len(layer) != n_particles:
        raise ValueError(f"the layer has {len(layer)} particles but the results have "
                         f"{n_particles}")
    xy0 = np.stack([ds["x0"].values, ds["y0"].values], axis=-1)
    scale = max(float(np.max(np.abs(xy0))), 1e-12)
    if not np.allclose(layer.positions, xy0, rtol=0.0, atol=1e-9 * scale + 1e-15):
        raise ValueError("the layer's particle positions differ from the results' x0, y0: "
                         "pass the layer the results were computed for")

    surfaces = [_surface(placed.particle.shape, subdivisions) for placed in layer]
    offsets = np.cumsum([0] + [len(v) for v, _ in surfaces])
    faces = np.concatenate([f + offsets[p] for p, (_, f) in enumerate(surfaces)])
    n_points = int(offsets[-1])
    face_particle = np.concatenate([np.full(len(f), p, dtype=np.int32)
                                    for p, (_, f) in enumerate(surfaces)])
    radius = np.array([float(np.linalg.norm(v, axis=1).max()) for v, _ in surfaces])
    quat, centre = _fill_poses(results, layer)

    margin = float(radius.max())
    x_lo = float(np.min(centre[..., 0] - radius) - margin)
    x_hi = float(np.max(centre[..., 0] + radius) + margin)
    y_lo = float(np.min(centre[..., 1] - radius) - margin)
    y_hi = float(np.max(centre[..., 1] + radius) + margin)

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    entries: list[tuple[int, int, str, str]] = []

    def write(mesh: meshio.Mesh, name: str, step: int, part: int, part_name: str) -> None:
        meshio.write(out_dir / name, mesh, file_format="vtu")
        written.append(out_dir / name)
        entries.append((step, part, part_name, name))

    for s in range(n_steps):
        step = int(results.steps[s])
        points = np.empty((n_points, 3))
        sampled = [] if _map_index(results, s) is not None else None
        for p, (vertices, _) in enumerate(surfaces):
            world = Rotation.from_quat(quat[s, p]).apply(vertices) + centre[s, p]
            points[offsets[p]:offsets[p + 1]] = world
            if sampled is not None:
                sampled.append(_point_data(results, s, p, world, centre[s, p]))
        point_data = {"state": np.repeat(results.state[s], np.diff(offsets))}
        if sampled is not None:         # no NaN placeholders in a step without maps
            point_data = {"pressure": np.concatenate([d[0] for d in sampled]),
                          "traction": np.concatenate([d[1] for d in sampled]),
                          "status": np.concatenate([d[2] for d in sampled]), **point_data}
        particles = meshio.Mesh(points, [("triangle", faces)], point_data=point_data,
                                cell_data={"particle": [face_particle],
                                           "state": [results.state[s][face_particle]]})
        write(particles, f"particles_{step:04d}.vtu", step, 0, "particles")

        gap = float(results.plate_gap[s])
        corners = np.array([[x_lo, y_lo], [x_hi, y_lo], [x_hi, y_hi], [x_lo, y_hi]])
        plate_points = np.concatenate([np.column_stack([corners, np.zeros(4)]),
                                       np.column_stack([corners, np.full(4, gap)])])
        # lower plate normal up (into the gap), upper plate normal down
        quads = np.array([[0, 1, 2, 3], [4, 7, 6, 5]])
        plates = meshio.Mesh(plate_points, [("quad", quads)],
                             cell_data={"plate": [np.array([0, 1], dtype=np.int8)]})
        write(plates, f"plates_{step:04d}.vtu", step, 1, "plates")
        write(_contact_mesh(results, s, centre[s]), f"contact_{step:04d}.vtu", step, 2,
              "contact")
        if "contact" in ds.dims:
            write(_network_mesh(ds, step, centre[s]), f"network_{step:04d}.vtu", step, 3,
                  "network")

    pvd = out_dir / COLLECTION
    _write_pvd(pvd, entries)
    written.append(pvd)
    return written


def export_vtk_cli(results: Path, out: Path) -> int:
    """``thirdbody export-vtk RESULTS DIR``: export a results file for ParaView.

    The particles are rebuilt from the configuration stored in the file (global attribute
    ``config``, TOML text). Everything is checked before ``out`` is created: a missing file, a
    file that is not a thirdbody results file, one without ``config`` (or with an invalid
    one), or results the export cannot draw print ``error: ...`` to stderr and return 2
    without writing anything.

    Parameters
    ----------
    results : Path
        The results file (NetCDF) written by ``thirdbody run``.
    out : Path
        Output directory (see :func:`export_vtk`).

    Returns
    -------
    int
        Exit code: 0 written, 2 bad input, 1 the files could not be written.
    """
    from thirdbody.io.config import ConfigError, body_from_results
    from thirdbody.io.results import open_results
    from thirdbody.particle import Particle

    def fail(message: str, code: int = 2) -> int:
        print(f"error: {message}", file=sys.stderr)
        return code

    results, out = Path(results), Path(out)
    if not results.is_file():
        return fail(f"{results} does not exist" if not results.exists()
                    else f"{results} is not a file")
    try:
        ds = open_results(results)
    except Exception as exc:          # h5netcdf/h5py/xarray raise many kinds for a bad file
        return fail(f"{results} is not a thirdbody results file ({type(exc).__name__}: {exc})")
    if "step" not in ds.dims or "quaternion" not in ds.variables:
        return fail(f"{results} is not a thirdbody results file (no 'step' dimension or "
                    "'quaternion' variable)")
    try:
        body = body_from_results(ds, str(results))
    except ConfigError as exc:
        return fail(str(exc))
    layer = Layer.of(body) if isinstance(body, Particle) else body
    if out.exists() and not out.is_dir():
        return fail(f"{out} exists and is not a directory")
    try:
        paths = export_vtk(ds, layer, out)      # checks everything before making ``out``
    except (ValueError, TypeError) as exc:
        return fail(f"{results}: {exc}")
    except OSError as exc:
        return fail(f"cannot write {out}: {exc}", code=1)
    n_steps = sum(path.name.startswith("particles_") for path in paths)
    n_maps = int(np.isin(ds["step"].values, ds["map_step"].values).sum()) \
        if "map_step" in ds.variables else 0
    print(f"wrote {n_steps} steps of {len(layer)} particle{'s' if len(layer) != 1 else ''}, "
          f"with contact patches in {n_maps}, to {out} (open {out / COLLECTION} in ParaView)")
    return 0
