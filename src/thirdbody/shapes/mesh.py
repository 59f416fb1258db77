"""Particles given as closed triangle meshes (STL, OBJ, PLY, ... read by trimesh).

Warning
-------
A faceted mesh has no curvature inside a facet. The contact pressure of an elastic body depends
on the curvature of the gap, so facets comparable to the contact cells give spurious pressure
peaks at edges and flat plateaus inside facets. Refine (and, for coarse input, smooth) the mesh
so that its facets are far below the contact cell size: :meth:`MeshShape.from_file` offers Loop
subdivision (which converges to a smooth surface), midpoint subdivision, Taubin or Laplacian
smoothing and a ``max_edge`` target.
"""

from __future__ import annotations

import math
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from thirdbody.orientation import OrientationLike, Rotation
from thirdbody.shapes.base import FloatArray, Shape, _broadcast_xy, rotate_to_world

if TYPE_CHECKING:
    import trimesh

__all__ = ["MeshShape"]

_MAX_FACES = 8_000_000
_PAIR_CHUNK = 2_000_000


def _trimesh() -> Any:
    try:
        import trimesh
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("mesh shapes need the 'trimesh' package: pip install trimesh") from exc
    return trimesh


def _max_edge(mesh: trimesh.Trimesh) -> float:
    return float(mesh.edges_unique_length.max())


class MeshShape(Shape):
    """A closed, consistently oriented triangle mesh, re-centred on its volume centroid.

    Parameters
    ----------
    vertices:
        (n, 3) vertex coordinates (m) in the input frame.
    faces:
        (m, 3) vertex indices of the triangles.
    name:
        Used in error messages and ``repr`` (e.g. the file name).

    The body frame is the input frame translated so that the volume centroid (trimesh's
    ``center_mass`` of the closed mesh) is at the origin; :attr:`offset` is the input-frame
    position of that centroid. An inside-out mesh (negative volume) is inverted.

    Vertical rays are intersected with every triangle by a vectorised Möller–Trumbore test
    specialised to vertical rays (barycentric coordinates of the ray's foot in the projected
    triangle), with a uniform grid on the horizontal plane so that each ray only meets the
    triangles whose bounding boxes share its grid cell. The extreme points are the lowest and
    highest vertices, exact for the piecewise-planar surface.

    See the module docstring: facets must be far below the contact cell size.
    """

    def __init__(self, vertices: ArrayLike, faces: ArrayLike, *, name: str = "mesh") -> None:
        super().__init__()
        tm = _trimesh()
        v = np.asarray(vertices, dtype=float)
        f = np.asarray(faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"{name}: vertices must be (n, 3) and faces (m, 3)")
        mesh = tm.Trimesh(vertices=v, faces=f, process=False)
        _check_closed(mesh, name)
        if mesh.volume < 0:
            mesh.invert()
        self._name = name
        self._offset = np.asarray(mesh.center_mass, dtype=float).copy()
        self._vertices = np.ascontiguousarray(mesh.vertices - self._offset)
        self._faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        body = tm.Trimesh(vertices=self._vertices, faces=self._faces, process=False)
        self._centroid = np.asarray(body.center_mass, dtype=float).copy()
        self._volume = float(body.volume)
        self._size = float(np.linalg.norm(self._vertices, axis=1).max())
        self._vertices.setflags(write=False)
        self._faces.setflags(write=False)

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def from_file(
        cls,
        path: str | PathLike[str],
        *,
        scale: float = 1.0,
        subdivisions: int = 0,
        max_edge: float | None = None,
        scheme: Literal["loop", "midpoint"] = "loop",
        smooth: Literal["taubin", "laplacian"] | None = None,
        smooth_iterations: int = 10,
    ) -> MeshShape:
        """Read a closed mesh file (any format trimesh reads: STL, OBJ, PLY, ...).

        Parameters
        ----------
        path:
            Mesh file.
        scale:
            Factor converting the file's length unit to metres (e.g. 1e-3 for millimetres).
        subdivisions:
            Rounds of subdivision applied at least (each splits every triangle in four).
        max_edge:
            If given (m), keep subdividing until no edge is longer. Choose it well below the
            contact cell size.
        scheme:
            ``"loop"``: Loop subdivision, converging to a smooth surface (it slightly shrinks
            convex parts); ``"midpoint"``: splits facets without moving them (no curvature
            added: only useful together with ``smooth``).
        smooth:
            Optional smoothing after refinement: ``"taubin"`` (λ|μ, nearly volume preserving)
            or ``"laplacian"`` (with trimesh's volume constraint).
        smooth_iterations:
            Iterations of the smoothing filter.

        Raises
        ------
        ValueError
            If the file is missing or in a format trimesh cannot read here, if the mesh is not
            watertight, not consistently oriented, has several bodies, or
            the refinement would exceed the face budget.
        """
        tm = _trimesh()
        name = str(path)
        if not Path(path).is_file():
            raise ValueError(f"mesh file {name!r} does not exist")
        readable = "readable formats: STL (binary or ASCII), OBJ, PLY, OFF, GLB/GLTF"
        try:
            mesh = tm.load(path, force="mesh")
        except PermissionError as exc:
            raise ValueError(f"cannot read mesh file {name!r}: {exc.strerror}") from exc
        except Exception as exc:
            # each format's parser fails in its own words (ValueError, IndexError, ...); an
            # unknown type is a NotImplementedError, a format whose optional backend is missing
            # an ImportError: none of them says what the user needs to know
            kind = Path(path).suffix.lstrip(".").upper() or "mesh"
            raise ValueError(f"mesh file {name!r} is not a readable {kind} file; "
                             f"{readable}") from exc
        if not isinstance(mesh, tm.Trimesh) or len(mesh.faces) == 0:
            raise ValueError(f"mesh file {name!r} is not a readable "
                             f"{Path(path).suffix.lstrip('.').upper() or 'mesh'} file: no "
                             f"triangles in it; {readable}")
        if scale != 1.0:
            mesh.apply_scale(float(scale))
        _check_closed(mesh, name)
        mesh = _refine(mesh, name, subdivisions, max_edge, scheme)
        if smooth is not None:
            mesh = _smooth(mesh, smooth, smooth_iterations)
        return cls(mesh.vertices, mesh.faces, name=name)

    @classmethod
    def from_shape(cls, shape: Shape, *, subdivisions: int = 5) -> MeshShape:
        """Tessellate a star-shaped analytic shape (sphere, ellipsoid, potato).

        The vertices of an icosphere with ``subdivisions`` levels (``20·4^s`` triangles) are
        moved radially onto the surface. The mesh centroid differs from the analytic one by the
        faceting error, and is re-centred like any mesh.
        """
        tm = _trimesh()
        ico = tm.creation.icosphere(subdivisions=subdivisions)
        verts = shape._radial_surface(np.asarray(ico.vertices, dtype=float))
        return cls(verts, ico.faces, name=f"tessellated {shape!r}")

    # --- properties ---------------------------------------------------------------------------
    @property
    def vertices(self) -> FloatArray:
        """(n, 3) body-frame vertex coordinates (m), centroid at the origin."""
        return self._vertices.copy()

    @property
    def faces(self) -> np.ndarray:
        """(m, 3) vertex indices, counter-clockwise seen from outside."""
        return self._faces.copy()

    @property
    def offset(self) -> FloatArray:
        """Input-frame position (m) of the centroid (the translation applied to the input)."""
        return self._offset.copy()

    @property
    def centroid(self) -> FloatArray:
        """Volume centroid (m) of the body-frame mesh, recomputed: zero to rounding."""
        return self._centroid.copy()

    @property
    def volume(self) -> float:
        """Enclosed volume (m³)."""
        return self._volume

    @property
    def size(self) -> float:
        """Largest vertex distance (m) from the centroid."""
        return self._size

    @property
    def max_edge(self) -> float:
        """Longest edge (m): compare it with the contact cell size."""
        e = self._vertices[self._faces]
        lengths = np.linalg.norm(e - np.roll(e, 1, axis=1), axis=-1)
        return float(lengths.max())

    def __repr__(self) -> str:
        return f"MeshShape(name={self._name!r}, faces={len(self._faces)})"

    def mirrored(self) -> MeshShape:
        """Mirror image in body x; faces are reversed to keep them outward oriented."""
        v = self._vertices * np.array([-1.0, 1.0, 1.0])
        return MeshShape(v, self._faces[:, ::-1], name=f"mirrored {self._name}")

    # --- extreme points -----------------------------------------------------------------------
    def _lowest_point(self, rotation: Rotation) -> FloatArray:
        v = rotate_to_world(self._vertices, rotation)
        return v[np.argmin(v[:, 2])].copy()

    def _highest_point(self, rotation: Rotation) -> FloatArray:
        v = rotate_to_world(self._vertices, rotation)
        return v[np.argmax(v[:, 2])].copy()

    # --- vertical rays ------------------------------------------------------------------------
    def surfaces(self, orientation: OrientationLike, x: ArrayLike,
                 y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest crossing heights z (m) of vertical rays at world (x, y).

        See :meth:`Shape.surfaces`. Exact for the faceted surface (barycentric interpolation
        inside the hit triangle); rays through an edge or vertex are counted with a relative
        tolerance of 1e-12 so that they cannot slip between facets. NaN where the ray misses.
        """
        xa, ya = _broadcast_xy(x, y)
        shape = xa.shape
        rx, ry = xa.ravel(), ya.ravel()
        z_low = np.full(rx.size, np.inf)
        z_up = np.full(rx.size, -np.inf)
        tri = rotate_to_world(self._vertices, orientation)[self._faces]
        tx, ty = tri[..., 0], tri[..., 1]
        area2 = (tx[:, 1] - tx[:, 0]) * (ty[:, 2] - ty[:, 0]) - (tx[:, 2] - tx[:, 0]) * (
            ty[:, 1] - ty[:, 0]
        )
        bx0, bx1 = tx.min(axis=1), tx.max(axis=1)
        by0, by1 = ty.min(axis=1), ty.max(axis=1)
        ext = np.maximum(bx1 - bx0, by1 - by0)
        # Facets seen edge-on have no interior crossing; their neighbours cover the silhouette.
        keep = np.abs(area2) > 1e-12 * ext * ext
        ok = np.isfinite(rx) & np.isfinite(ry)
        ok &= (rx >= bx0.min()) & (rx <= bx1.max()) & (ry >= by0.min()) & (ry <= by1.max())
        rays = np.flatnonzero(ok)
        if rays.size and keep.any():
            self._cast(rays, rx, ry, tri, area2, keep, (bx0, bx1, by0, by1), ext, z_low, z_up)
        z_low[~np.isfinite(z_low)] = np.nan
        z_up[~np.isfinite(z_up)] = np.nan
        return z_low.reshape(shape), z_up.reshape(shape)

    @staticmethod
    def _cast(
        rays: np.ndarray,
        rx: FloatArray,
        ry: FloatArray,
        tri: FloatArray,
        area2: FloatArray,
        keep: np.ndarray,
        bbox: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
        ext: FloatArray,
        z_low: FloatArray,
        z_up: FloatArray,
    ) -> None:
        bx0, bx1, by0, by1 = bbox
        px, py = rx[rays], ry[rays]
        ox, oy = px.min(), py.min()
        cell = float(np.median(ext[keep]))
        span = max(px.max() - ox, py.max() - oy)
        cell = max(cell, span / 4096.0, np.finfo(float).tiny)
        nx = int((px.max() - ox) // cell) + 1
        ny = int((py.max() - oy) // cell) + 1
        ray_cell = ((px - ox) // cell).astype(np.int64) * ny + ((py - oy) // cell).astype(np.int64)
        order = np.argsort(ray_cell, kind="stable")
        sorted_cell = ray_cell[order]
        sorted_ray = rays[order]

        ix0 = np.floor((bx0 - ox) / cell).astype(np.int64)
        ix1 = np.floor((bx1 - ox) / cell).astype(np.int64)
        iy0 = np.floor((by0 - oy) / cell).astype(np.int64)
        iy1 = np.floor((by1 - oy) / cell).astype(np.int64)
        sel = keep & (ix1 >= 0) & (ix0 < nx) & (iy1 >= 0) & (iy0 < ny)
        tids = np.flatnonzero(sel)
        if tids.size == 0:
            return
        ix0, ix1 = np.clip(ix0[tids], 0, nx - 1), np.clip(ix1[tids], 0, nx - 1)
        iy0, iy1 = np.clip(iy0[tids], 0, ny - 1), np.clip(iy1[tids], 0, ny - 1)
        wy = iy1 - iy0 + 1
        ncell = (ix1 - ix0 + 1) * wy
        # (triangle, grid cell) pairs.
        t_rep = np.repeat(np.arange(tids.size), ncell)
        local = np.arange(t_rep.size) - np.repeat(np.cumsum(ncell) - ncell, ncell)
        cx = ix0[t_rep] + local // wy[t_rep]
        cy = iy0[t_rep] + local % wy[t_rep]
        cid = cx * ny + cy
        start = np.searchsorted(sorted_cell, cid, side="left")
        count = np.searchsorted(sorted_cell, cid, side="right") - start
        nz = count > 0
        t_rep, start, count = t_rep[nz], start[nz], count[nz]
        # Split the (triangle, ray) expansion into chunks of bounded size.
        csum = np.cumsum(count)
        lo = 0
        while lo < count.size:
            done = csum[lo - 1] if lo else 0
            hi = max(int(np.searchsorted(csum, done + _PAIR_CHUNK, side="right")), lo + 1)
            cnt = count[lo:hi]
            pt = np.repeat(tids[t_rep[lo:hi]], cnt)
            off = np.arange(pt.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            pr = sorted_ray[np.repeat(start[lo:hi], cnt) + off]
            _hit_triangles(pt, pr, rx, ry, tri, area2, z_low, z_up)
            lo = hi


def _hit_triangles(
    pt: np.ndarray,
    pr: np.ndarray,
    rx: FloatArray,
    ry: FloatArray,
    tri: FloatArray,
    area2: FloatArray,
    z_low: FloatArray,
    z_up: FloatArray,
) -> None:
    """Barycentric test of vertical rays ``pr`` against triangles ``pt`` (pairs); update z."""
    t = tri[pt]
    x0 = t[:, 0, 0] - rx[pr]
    y0 = t[:, 0, 1] - ry[pr]
    x1 = t[:, 1, 0] - rx[pr]
    y1 = t[:, 1, 1] - ry[pr]
    x2 = t[:, 2, 0] - rx[pr]
    y2 = t[:, 2, 1] - ry[pr]
    inv = 1.0 / area2[pt]
    l0 = (x1 * y2 - x2 * y1) * inv
    l1 = (x2 * y0 - x0 * y2) * inv
    l2 = (x0 * y1 - x1 * y0) * inv
    tol = -1e-12
    hit = (l0 >= tol) & (l1 >= tol) & (l2 >= tol)
    z = l0 * t[:, 0, 2] + l1 * t[:, 1, 2] + l2 * t[:, 2, 2]
    np.minimum.at(z_low, pr[hit], z[hit])
    np.maximum.at(z_up, pr[hit], z[hit])


def _check_closed(mesh: trimesh.Trimesh, name: str) -> None:
    tm = _trimesh()
    if not mesh.is_watertight:
        open_edges = len(tm.grouping.group_rows(mesh.edges_sorted, require_count=1))
        raise ValueError(
            f"mesh {name!r} is not watertight ({open_edges} boundary edges): a particle must "
            "be a closed surface; repair the holes before use"
        )
    if not mesh.is_winding_consistent:
        raise ValueError(f"mesh {name!r} has inconsistently oriented faces")
    if mesh.body_count != 1:
        raise ValueError(f"mesh {name!r} has {mesh.body_count} separate bodies, expected one")


def _refine(
    mesh: trimesh.Trimesh,
    name: str,
    subdivisions: int,
    max_edge: float | None,
    scheme: str,
) -> trimesh.Trimesh:
    if scheme not in ("loop", "midpoint"):
        raise ValueError(f"unknown subdivision scheme {scheme!r}: use 'loop' or 'midpoint'")
    if subdivisions < 0:
        raise ValueError(f"subdivisions must be >= 0, got {subdivisions}")
    if max_edge is not None and not max_edge > 0:
        raise ValueError(f"max_edge must be positive (m), got {max_edge}")
    rounds = int(subdivisions)
    if max_edge is not None:
        rounds = max(rounds, math.ceil(math.log2(max(_max_edge(mesh) / max_edge, 1.0))))
    if len(mesh.faces) * 4**rounds > _MAX_FACES:
        raise ValueError(
            f"refining mesh {name!r} ({len(mesh.faces)} faces) {rounds} times would exceed "
            f"{_MAX_FACES} faces; coarsen the target max_edge"
        )
    for _ in range(rounds):
        mesh = mesh.subdivide_loop(1) if scheme == "loop" else mesh.subdivide()
    while max_edge is not None and _max_edge(mesh) > max_edge:
        if len(mesh.faces) * 4 > _MAX_FACES:
            raise ValueError(f"refining mesh {name!r} to max_edge={max_edge} needs too many faces")
        mesh = mesh.subdivide_loop(1) if scheme == "loop" else mesh.subdivide()
    return mesh


def _smooth(mesh: trimesh.Trimesh, method: str, iterations: int) -> trimesh.Trimesh:
    tm = _trimesh()
    mesh = mesh.copy()
    if method == "taubin":
        tm.smoothing.filter_taubin(mesh, lamb=0.5, nu=0.53, iterations=iterations)
    elif method == "laplacian":
        tm.smoothing.filter_laplacian(mesh, lamb=0.5, iterations=iterations)
    else:
        raise ValueError(f"unknown smoothing {method!r}: use 'taubin' or 'laplacian'")
    return mesh
