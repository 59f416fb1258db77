"""ParaView export: the particles' surfaces at their poses, with the contact maps painted on.

:func:`export_vtk` writes, into one directory, for every load step ``k`` (the ``step``
coordinate of the results):

* ``step_kkkk.vtu`` — every particle's closed triangle surface at its pose in the world
  (unstructured grid, one triangle block, all particles concatenated in layer order);
* ``plates_kkkk.vtu`` — the two plates as two quads (lower then upper);
* ``layer.pvd`` — a ParaView collection listing both files of every step with
  ``timestep`` = the step index, as ``part`` 0 (``particles``) and ``part`` 1 (``plates``):
  open it in ParaView to get a two-block time series.

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

The drawn surface is the undeformed shape: under load it overlaps the plates by about the
particle's approach, as in the BEM model (rigid plates, half-space particle).

The plates span the rectangle covering every particle's bounding disc over all steps, enlarged
by the largest particle size (m) on every side; the lower quad lies at z = 0 and the upper at
z = ``plate_gap`` of the step.

Data on the particle surfaces
-----------------------------
Point data:

``pressure`` (Pa), ``traction`` (3-vector, Pa, z component 0; exerted by the plate on the
particle), ``status`` (0 open, 1 stick, 2 slip)
    Sampled from the stored contact maps of the step, in the cell (nearest cell centre) under
    the vertex's horizontal position relative to the particle's centroid (world axes). A vertex
    takes the lower-interface map if it lies at most 3 cell sizes above the lower plate
    (``z <= 3 h``, overlapping vertices included), the upper-interface map if it lies at most
    3 cell sizes below the upper plate (``z >= plate_gap − 3 h``; the nearer plate if both
    hold), where ``h`` is the particle's BEM cell size. Every other vertex, and a vertex
    outside the map window, gets pressure 0, traction 0 and status 0 (open). In steps without
    stored maps (see ``maps_every``) every vertex gets NaN pressure and traction and
    status -1.
``state`` (int8)
    The particle's state code in the step, as in the results' ``state`` variable (its
    ``flag_meanings`` attribute names the codes: stick, roll_upper, roll_lower, rotate,
    failed, unloaded).

Cell data: ``particle`` (the particle's index in the layer) and ``state`` (as above).

On the plates: cell data ``plate`` (0 lower, 1 upper).

The pressure is known only at the vertices, so a contact patch smaller than the facets is
missed or shown as a single vertex: raise ``subdivisions`` (5 gives facets of about 1/30 of the
particle size) to resolve contact patches.
"""

from __future__ import annotations

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

__all__ = ["NEAR_PLATE_CELLS", "export_vtk", "export_vtk_cli"]

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
    0: the initial orientation, resting on the lower plate at the initial position)."""
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
                z = -placed.particle.shape.lowest_point(rotation)[2]
                centre[s, p] = (*placed.xy, z)
    return quat, centre


def _nearest(coords: np.ndarray, values: np.ndarray, cell: float) -> tuple[np.ndarray, ...]:
    """Index of the nearest cell centre of a uniform axis ``coords`` and whether it exists."""
    if len(coords) == 0:
        return np.zeros(len(values), dtype=np.int64), np.zeros(len(values), dtype=bool)
    k = np.rint((values - coords[0]) / cell).astype(np.int64)
    inside = (k >= 0) & (k < len(coords))
    return np.clip(k, 0, len(coords) - 1), inside


def _point_data(results: _Results, s: int, p: int, world: np.ndarray,
                centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pressure (n,), traction (n, 3) and status (n,) of particle ``p``'s vertices in step
    index ``s`` (see the module docstring for the rules)."""
    n = len(world)
    hit = np.flatnonzero(results.map_steps == results.steps[s])
    if len(hit) == 0:
        return (np.full(n, np.nan), np.full((n, 3), np.nan), np.full(n, -1, dtype=np.int8))
    m = int(hit[-1])
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
        The written files: per step ``step_kkkk.vtu`` then ``plates_kkkk.vtu``, then
        ``layer.pvd``.

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
    for s in range(n_steps):
        step = int(results.steps[s])
        points = np.empty((n_points, 3))
        pressure = np.empty(n_points)
        traction = np.empty((n_points, 3))
        status = np.empty(n_points, dtype=np.int8)
        point_state = np.empty(n_points, dtype=np.int8)
        for p, (vertices, _) in enumerate(surfaces):
            rows = slice(offsets[p], offsets[p + 1])
            world = Rotation.from_quat(quat[s, p]).apply(vertices) + centre[s, p]
            points[rows] = world
            pressure[rows], traction[rows], status[rows] = _point_data(
                results, s, p, world, centre[s, p])
            point_state[rows] = results.state[s, p]
        gap = float(results.plate_gap[s])
        mesh = meshio.Mesh(
            points, [("triangle", faces)],
            point_data={"pressure": pressure, "traction": traction, "status": status,
                        "state": point_state},
            cell_data={"particle": [face_particle],
                       "state": [results.state[s][face_particle]]})
        name = f"step_{step:04d}.vtu"
        meshio.write(out_dir / name, mesh, file_format="vtu")
        written.append(out_dir / name)
        entries.append((step, 0, "particles", name))

        corners = np.array([[x_lo, y_lo], [x_hi, y_lo], [x_hi, y_hi], [x_lo, y_hi]])
        plate_points = np.concatenate([np.column_stack([corners, np.zeros(4)]),
                                       np.column_stack([corners, np.full(4, gap)])])
        # lower plate normal up (into the gap), upper plate normal down
        quads = np.array([[0, 1, 2, 3], [4, 7, 6, 5]])
        plates = meshio.Mesh(plate_points, [("quad", quads)],
                             cell_data={"plate": [np.array([0, 1], dtype=np.int8)]})
        name = f"plates_{step:04d}.vtu"
        meshio.write(out_dir / name, plates, file_format="vtu")
        written.append(out_dir / name)
        entries.append((step, 1, "plates", name))

    pvd = out_dir / "layer.pvd"
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
    n_steps = (len(paths) - 1) // 2
    print(f"wrote {n_steps} steps of {len(layer)} particle{'s' if len(layer) != 1 else ''} "
          f"to {out} (open {out / 'layer.pvd'} in ParaView)")
    return 0
