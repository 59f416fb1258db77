"""Run configuration: a TOML file validated by pydantic, with every default in one place.

A configuration has four tables (SI units throughout; angles in degrees)::

    [particle]                      # the shape and its material
    shape = "potato"                # "sphere" | "ellipsoid" | "potato" | "mesh"
    semi_axes = [1.0e-3, 0.8e-3, 0.7e-3]   # m (ellipsoid, potato)
    seed = 4                        # potato: random waves
    amplitude = 0.1                 # potato: relative amplitude of each wave
    wavenumber_range = [4.0, 8.0]   # potato
    E = 1.0e9                       # Pa, > 0
    nu = 0.3                        # (-1, 0.5]
    orientation_deg = 20.0           # tilt, degrees, about the axis at tilt_axis_deg
    tilt_axis_deg = 90.0            # azimuth of the tilt axis from +x (90: +y, the paper's)
    yaw_deg = 0.0                   # about the body z axis, before the tilt
    # azimuth_deg = 30.0            # last: about the world's vertical (turns the whole problem)
    # quaternion = [0, 0.17, 0, 0.98]   # or the orientation as (x, y, z, w)

    [plates]
    mu_up = 0.46                    # >= 0
    mu_low = 0.46                   # >= 0, default mu_up

    [load]
    program = "linear_ramp"         # "linear_ramp" | "hold_then_ramp" | "force_table" | "gap_ramp"
    stop = 10.0                     # N (compression ratio for gap_ramp)
    steps = 30

    [numerics]
    resolution = 80.0               # cells per particle size
    maps_every = 5

A layer of many particles (docs/methods/design.md §3b) replaces ``[particle]`` with either a list of
placed particles, each a ``[particle]`` table plus its centroid position ``x``, ``y`` (m)::

    [[particles]]
    shape = "sphere"
    radius = 1.0e-3
    E = 1.0e9
    nu = 0.3
    x = 0.0
    y = 0.0

or a ``[layer]`` generator table (:meth:`thirdbody.Layer.random`)::

    [layer]
    box = [10.0e-3, 10.0e-3]        # m, the rectangle the centroids are placed in
    count = 30                      # or area_fraction = 0.3 (of the bounding discs)
    shape = "potato"                # "sphere" | "ellipsoid" | "potato"
    size = 1.0e-3                   # m, mean size (sphere radius, largest semi-axis)
    size_std = 0.1e-3               # m
    distribution = "lognormal"      # "fixed" | "normal" | "lognormal" | "list" (sizes = [...])
    orientation = "tilted"          # "random" | "tilted" (up to max_tilt_deg) | "upright"
    seed = 1
    E = 1.0e9
    nu = 0.3

Particles that may touch each other (every contact resolved by the BEM, docs/methods/network.md)
need a ``[network]`` table; without it a layer's particles may not touch::

    [network]
    mu_pp = 0.3                     # friction between particles, >= 0
    periodic = true                 # x and y periodic (default false)
    # box = [10.0e-3, 10.0e-3]      # m, the periodic box (default: the [layer] box)
    tol = 1e-6                      # equilibrium tolerance of each step

The ``slide`` program (:class:`thirdbody.Slide`, needs ``[network]``) compresses, then slides
the upper plate sideways with the normal force (or the gap) held::

    [load]
    program = "slide"
    force = 1.0                     # N, held while sliding (or compression = 0.01: gap held)
    distance = 100.0e-6             # m, along direction_deg (default 0: +x)
    # points = [[50.0e-6, 0.0], [0.0, 0.0]]   # or the plate's path, m: out and back
    steps = 10                      # sliding steps per segment of the path
    compress_steps = 5

Unknown keys, wrong types and out-of-range values are refused with one message per problem,
naming the key and the allowed range (:class:`ConfigError`).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..network.run import CUTBACKS

__all__ = ["Config", "ConfigError", "body_from_results", "load_config"]


_Num = Annotated[float, Field(strict=True)]
_Pos = Annotated[float, Field(strict=True, gt=0)]
_NonNeg = Annotated[float, Field(strict=True, ge=0)]


class ConfigError(ValueError):
    """An invalid configuration; the message lists every problem with its key."""


class _Model(BaseModel):
    # numbers are strict (a string is not a number, true is not a count; an integer is a
    # float) and finite
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class SphereShape(_Model):
    shape: Literal["sphere"]
    radius: Annotated[float, Field(strict=True, gt=0, description="m")]


class EllipsoidShape(_Model):
    shape: Literal["ellipsoid"]
    semi_axes: tuple[_Pos, _Pos,
                     _Pos] = Field(description="m: A (x), B (y), C (z)")


class PotatoShape(_Model):
    shape: Literal["potato"]
    semi_axes: tuple[_Pos, _Pos,
                     _Pos] = Field(description="m")
    seed: Annotated[int, Field(strict=True, ge=0)] = 0
    n_waves: Annotated[int, Field(strict=True, ge=0, le=20)] = 3
    amplitude: Annotated[float, Field(strict=True, ge=0, le=0.5)] = 0.05
    wavenumber_range: tuple[_NonNeg, _NonNeg] = (2, 4)


class MeshShapeConfig(_Model):
    shape: Literal["mesh"]
    file: str = Field(description="STL/OBJ/PLY path, relative to the config file")
    scale: _Pos = 1.0
    subdivisions: Annotated[int, Field(strict=True, ge=0, le=5,
                                       description="Loop subdivisions")] = 0
    max_edge: Annotated[float | None, Field(strict=True, gt=0, description="m, after scale")] = None
    sha256: str | None = Field(None, description="the file's SHA-256; written by thirdbody "
                               "next to the resolved path, checked when given")


class Particle(_Model):
    geometry: Annotated[SphereShape | EllipsoidShape | PotatoShape | MeshShapeConfig,
                        Field(discriminator="shape")]
    E: Annotated[float, Field(strict=True, gt=0, description="Young's modulus, Pa")]
    nu: Annotated[float, Field(strict=True, gt=-1, le=0.5, description="Poisson ratio")]
    orientation_deg: _Num = Field(0.0, allow_inf_nan=False,
                                   description="initial tilt angle, degrees")
    tilt_axis_deg: _Num = Field(90.0, allow_inf_nan=False,
                                 description="azimuth of the tilt axis from +x, degrees")
    yaw_deg: _Num = Field(0.0, allow_inf_nan=False,
                           description="rotation about the body z axis before the tilt")
    quaternion: tuple[_Num, _Num, _Num, _Num] | None = Field(
        None, description="initial orientation (x, y, z, w), instead of the tilt")
    azimuth_deg: _Num | None = Field(None, allow_inf_nan=False,
                                     description="last, a rotation about the world's vertical "
                                     "axis, degrees (turns the whole orientation)")

    @model_validator(mode="after")
    def _one_orientation(self):
        if self.quaternion is not None and (self.orientation_deg, self.tilt_axis_deg,
                                            self.yaw_deg) != (0.0, 90.0, 0.0):
            raise ValueError("give either a tilt (orientation_deg, tilt_axis_deg, yaw_deg) or "
                             "a quaternion, not both")
        return self


class PlacedParticle(Particle):
    x: _Num = Field(0.0, allow_inf_nan=False, description="centroid x, m")
    y: _Num = Field(0.0, allow_inf_nan=False, description="centroid y, m")
    z: _Num | None = Field(None, allow_inf_nan=False,
                           description="centroid height above the lower plate, m (default: "
                                       "resting on it; higher: stacked, needs [network])")


class LayerGenerator(_Model):
    box: tuple[_Pos, _Pos] = Field(
        description="m: the rectangle (L_x, L_y) of the centroids, centred on the origin")
    count: Annotated[int | None, Field(strict=True, ge=1)] = None
    area_fraction: Annotated[float | None, Field(strict=True, gt=0, le=0.8)] = None
    placement: Literal["sequential", "relaxed"] = "sequential"
    shape: Literal["sphere", "ellipsoid", "potato"] = "sphere"
    size: Annotated[float, Field(strict=True, gt=0, description="m")] = 1e-3
    size_std: Annotated[float, Field(strict=True, ge=0, description="m")] = 0.0
    distribution: Literal["fixed", "normal", "lognormal", "list"] = "fixed"
    sizes: list[_Pos] | str | None = Field(
        None, description="m, or a CSV file (relative to the config file)")
    aspect: tuple[_Pos, _Pos,
                  _Pos] = (1.0, 0.8, 0.7)
    amplitude: Annotated[float, Field(strict=True, ge=0, le=0.5)] = 0.05
    n_waves: Annotated[int, Field(strict=True, ge=0, le=20)] = 3
    wavenumber_range: tuple[_NonNeg, _NonNeg] = (2, 4)
    orientation: Literal["random", "tilted", "upright"] = "random"
    max_tilt_deg: Annotated[float, Field(strict=True, ge=0, le=90)] = 30.0
    seed: Annotated[int, Field(strict=True, ge=0)] = 0
    E: Annotated[float, Field(strict=True, gt=0, description="Young's modulus, Pa")]
    nu: Annotated[float, Field(strict=True, gt=-1, le=0.5, description="Poisson ratio")]

    @model_validator(mode="after")
    def _one_amount(self):
        if (self.count is None) == (self.area_fraction is None):
            raise ValueError("give exactly one of count and area_fraction")
        if self.placement == "sequential" and (self.area_fraction or 0) > 0.5:
            raise ValueError("area_fraction above 0.5 needs placement = \"relaxed\" (random "
                             "sequential placement jams near 0.55)")
        return self


class Plates(_Model):
    mu_up: Annotated[float, Field(strict=True, ge=0,
                                  description="friction coefficient, upper plate")]
    mu_low: Annotated[float | None, Field(strict=True, ge=0)] = None


class LinearRampLoad(_Model):
    program: Literal["linear_ramp"]
    stop: Annotated[float, Field(strict=True, gt=0, description="final normal force, N")]
    steps: Annotated[int, Field(strict=True, ge=1)] = 50
    start: Annotated[float | None, Field(strict=True, gt=0)] = None


class HoldThenRampLoad(_Model):
    program: Literal["hold_then_ramp"]
    hold: Annotated[float, Field(strict=True, gt=0, description="N")]
    hold_steps: Annotated[int, Field(strict=True, ge=1)]
    stop: Annotated[float, Field(strict=True, gt=0, description="N")]
    ramp_steps: Annotated[int, Field(strict=True, ge=1)]


class ForceTableLoad(_Model):
    program: Literal["force_table"]
    forces: list[_Pos] = Field(min_length=1, description="N")


class GapRampLoad(_Model):
    program: Literal["gap_ramp"]
    stop: Annotated[float, Field(strict=True, gt=0, le=0.5,
                                 description="final compression (d0-h)/d0")]
    steps: Annotated[int, Field(strict=True, ge=1)] = 50
    start: Annotated[float | None, Field(strict=True, gt=0, le=0.5)] = None


class SlideLoad(_Model):
    program: Literal["slide"]
    force: Annotated[float | None, Field(strict=True, gt=0,
                                         description="normal force held while sliding, "
                                         "N")] = None
    compression: Annotated[float | None, Field(strict=True, gt=0, le=0.5,
                                               description="compression (d0-h)/d0 held "
                                               "while sliding")] = None
    distance: Annotated[float | None, Field(strict=True, gt=0,
                                            description="sliding distance, m")] = None
    direction_deg: Annotated[float, Field(strict=True, description="direction of distance, "
                                          "degrees from +x towards +y")] = 0.0
    points: list[tuple[_Num, _Num]] | None = Field(
        None, min_length=1, description="m: the upper plate's path [[s_x, s_y], ...] from "
                                        "(0, 0)")
    steps: Annotated[int, Field(strict=True, ge=1,
                                description="sliding steps per segment of the path")] = 10
    compress_steps: Annotated[int, Field(strict=True, ge=1)] = 5

    @model_validator(mode="after")
    def _one_of_each(self):
        if (self.force is None) == (self.compression is None):
            raise ValueError("give exactly one of force (N, held while sliding) and "
                             "compression (the ratio (d0 - h)/d0 held while sliding)")
        if (self.distance is None) == (self.points is None):
            raise ValueError("give exactly one of distance (m, along direction_deg) and "
                             "points (the plate's path [[s_x, s_y], ...] in m)")
        return self


class Numerics(_Model):
    resolution: Annotated[float, Field(strict=True, ge=10, le=4000,
                                       description="cells per particle size")] = 80.0
    cell_size: Annotated[float | None, Field(strict=True, gt=0,
                                             description="m; overrides resolution")] = None
    tol: Annotated[float, Field(strict=True, gt=0, lt=1e-2)] = 1e-8
    angle_step_deg: Annotated[float, Field(strict=True, gt=0, le=10)] = 1.0
    angle_tol_deg: Annotated[float, Field(strict=True, gt=0, le=1)] = 0.01
    maps_every: Annotated[int, Field(strict=True, ge=0)] = 5
    classification: Literal["statics", "paper"] = "statics"
    twist_tol: Annotated[float, Field(strict=True, ge=0,
                                      description="twisting moment left unbalanced, "
                                      "relative to max(mu) F_N a")] = 1e-3
    workers: Annotated[int, Field(strict=True, ge=1, le=256,
                                  description="processes turning the particles "
                                  "of a layer in parallel")] = 1
    coupling: Annotated[bool, Field(strict=True, description="normal-tangential coupling "
                                    "(nu < 0.5); default off: Goodman's approximation")] = False


_MATERIAL_KEYS = ("E", "nu", "orientation_deg", "tilt_axis_deg", "yaw_deg", "quaternion",
                  "azimuth_deg")


def _split(table: dict, extra: tuple[str, ...] = ()) -> dict:
    """A [particle] table's geometry keys under ``geometry``, the rest beside them."""
    if not isinstance(table, dict) or "geometry" in table:
        return table
    p = dict(table)
    material = {k: p.pop(k) for k in (*_MATERIAL_KEYS, *extra) if k in p}
    return {"geometry": p, **material}


class Network(_Model):
    mu_pp: Annotated[float, Field(strict=True, ge=0,
                                  description="friction coefficient between particles")]
    periodic: Annotated[bool, Field(strict=True)] = False
    box: tuple[_Pos, _Pos] | None = Field(
        None, description="m: the periodic box (L_x, L_y), centred on the origin; default "
                          "the [layer] box")
    tol: Annotated[float, Field(strict=True, gt=0, lt=1e-2,
                                description="equilibrium tolerance of each step")] = 1e-6
    cutbacks: Annotated[int, Field(strict=True, ge=0, le=8,
                                   description="how many times a load step that does not "
                                               "converge is cut into halves")] = CUTBACKS
    energy_tol: Annotated[float | None, Field(
        strict=True, gt=0, lt=1,
        description="a load step whose energy residual exceeds this is cut into halves "
                    "too (within cutbacks); default: never")] = None

    @model_validator(mode="after")
    def _box_is_periodic(self):
        if self.box is not None and not self.periodic:
            raise ValueError("box is the periodic box: give periodic = true with it")
        return self


class Config(_Model):
    particle: Particle | None = None
    particles: list[PlacedParticle] | None = Field(None, min_length=1)
    layer: LayerGenerator | None = None
    network: Network | None = None
    plates: Plates
    load: Annotated[LinearRampLoad | HoldThenRampLoad | ForceTableLoad | GapRampLoad
                    | SlideLoad, Field(discriminator="program")]
    numerics: Numerics = Numerics()
    base_dir: str = Field(default=".", exclude=True)

    @model_validator(mode="before")
    @classmethod
    def _split_particle(cls, data):
        # the TOML's [particle] table holds both the geometry keys and the material keys
        if isinstance(data, dict) and isinstance(data.get("particle"), dict):
            data = {**data, "particle": _split(data["particle"])}
        if isinstance(data, dict) and isinstance(data.get("particles"), list):
            data = {**data, "particles": [_split(p, ("x", "y", "z"))
                                          for p in data["particles"]]}
        return data

    @model_validator(mode="after")
    def _one_body(self):
        given = [k for k in ("particle", "particles", "layer") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of [particle], [[particles]] and [layer]"
                             + (f" (got {', '.join(given)})" if given else ""))
        net = self.network
        if net is None and isinstance(self.load, SlideLoad):
            raise ValueError('load.program = "slide" moves the upper plate sideways, which '
                             "needs a network run: add a [network] table with mu_pp (the "
                             "friction between particles; one particle is a network of one)")
        if net is not None and net.periodic and net.box is None and self.layer is None:
            raise ValueError("network.periodic = true needs network.box = [L_x, L_y] (m) when "
                             "the particles are not generated by [layer]")
        if net is not None and net.periodic and net.box is not None and self.layer is not None \
                and tuple(net.box) != tuple(self.layer.box):
            raise ValueError("network.box must be the [layer] box (or left out) when [layer] "
                             "generates the particles of a periodic network")
        return self

    # --- building the objects ---------------------------------------------------------------
    def _shape(self, g):
        from thirdbody import shapes

        if isinstance(g, SphereShape):
            shape = shapes.Sphere(g.radius)
        elif isinstance(g, EllipsoidShape):
            shape = shapes.Ellipsoid(g.semi_axes)
        elif isinstance(g, PotatoShape):
            shape = shapes.Potato(g.semi_axes, seed=g.seed, n_waves=g.n_waves,
                                  amplitude=g.amplitude, wavenumber_range=g.wavenumber_range)
        else:
            path = self._mesh_path(g)
            if g.sha256 is not None and path.is_file() and _sha256(path) != g.sha256:
                raise ValueError(f"mesh file {path} has changed since this configuration was "
                                 f"written (sha256 {_sha256(path)[:12]}..., expected "
                                 f"{g.sha256[:12]}...)")
            shape = shapes.MeshShape.from_file(path, scale=g.scale, subdivisions=g.subdivisions,
                                               max_edge=g.max_edge)
        return shape

    def _mesh_path(self, g: MeshShapeConfig) -> Path:
        path = Path(g.file)
        return path if path.is_absolute() else Path(self.base_dir) / path

    def _geometries(self) -> list:
        if self.particle is not None:
            return [self.particle.geometry]
        return [p.geometry for p in self.particles or []]

    def mesh_digests(self) -> list[str]:
        """SHA-256 of every mesh file the configuration uses (what a sweep's case hash covers,
        so that an edited file is a new case)."""
        return [_sha256(self._mesh_path(g)) for g in self._geometries()
                if isinstance(g, MeshShapeConfig) and self._mesh_path(g).is_file()]

    def _particle(self, pc):
        import thirdbody as tb

        return tb.Particle(self._shape(pc.geometry), tb.Material(pc.E, pc.nu),
                           pc.orientation_deg, pc.tilt_axis_deg, pc.yaw_deg, pc.quaternion,
                           pc.azimuth_deg or 0.0)

    def build(self):
        """(Particle or Layer, Plates, load program, Simulation keyword arguments)."""
        import thirdbody as tb

        if self.particle is not None:
            body = self._particle(self.particle)
        elif self.particles is not None:
            body = tb.Layer([tb.PlacedParticle(self._particle(p), (p.x, p.y), p.z)
                             for p in self.particles])
        else:
            lc = self.layer
            sizes = lc.sizes
            if isinstance(sizes, str) and not Path(sizes).is_absolute():
                sizes = str(Path(self.base_dir) / sizes)
            body = tb.Layer.random(
                box=lc.box, material=tb.Material(lc.E, lc.nu), count=lc.count,
                area_fraction=lc.area_fraction, size=lc.size, size_std=lc.size_std,
                distribution=lc.distribution, sizes=sizes, shape=lc.shape, aspect=lc.aspect,
                amplitude=lc.amplitude, n_waves=lc.n_waves,
                wavenumber_range=lc.wavenumber_range, orientation=lc.orientation,
                max_tilt_deg=lc.max_tilt_deg, seed=lc.seed, placement=lc.placement,
                periodic=self.network is not None and self.network.periodic)
        plates = tb.Plates(self.plates.mu_up, self.plates.mu_low)
        ld = self.load
        if isinstance(ld, LinearRampLoad):
            load = tb.LinearRamp(stop=ld.stop, steps=ld.steps, start=ld.start)
        elif isinstance(ld, HoldThenRampLoad):
            load = tb.HoldThenRamp(ld.hold, ld.hold_steps, ld.stop, ld.ramp_steps)
        elif isinstance(ld, ForceTableLoad):
            load = tb.ForceTable(ld.forces)
        elif isinstance(ld, GapRampLoad):
            load = tb.GapRamp(stop=ld.stop, steps=ld.steps, start=ld.start)
        else:
            load = tb.Slide(force=ld.force, compression=ld.compression, distance=ld.distance,
                            direction_deg=ld.direction_deg, points=ld.points, steps=ld.steps,
                            compress_steps=ld.compress_steps)
        numerics = self.numerics.model_dump()
        if self.network is not None:
            net = self.network
            box = net.box
            if net.periodic and box is None:
                box = self.layer.box            # required by _one_body otherwise
            numerics.update(mu_pp=net.mu_pp, box=box if net.periodic else None,
                            network_tol=net.tol, network_cutbacks=net.cutbacks,
                            network_energy_tol=net.energy_tol)
        return body, plates, load, numerics

    def to_toml(self) -> str:
        """The resolved configuration (defaults filled in) as TOML text. A mesh file is written
        as its absolute path with its SHA-256, so the text reruns from any directory and
        refuses an edited file."""
        data = self.model_dump(exclude={"base_dir"}, exclude_none=True)
        for table, geometry in zip(
                [data["particle"]] if "particle" in data else data.get("particles", []),
                self._geometries(), strict=True):
            if isinstance(geometry, MeshShapeConfig):
                path = self._mesh_path(geometry).resolve()
                table["geometry"]["file"] = str(path)
                if path.is_file():
                    table["geometry"]["sha256"] = _sha256(path)
        # values the inputs leave to a rule, written out
        data["plates"].setdefault("mu_low", data["plates"]["mu_up"])
        if data["load"]["program"] in ("linear_ramp", "gap_ramp"):
            data["load"].setdefault("start", data["load"]["stop"] / data["load"]["steps"])
        head: dict = {}
        if "particle" in data:
            particle = data.pop("particle")
            head["particle"] = {**particle.pop("geometry"), **particle}
        if "particles" in data:
            head["particles"] = [{**p.pop("geometry"), **p} for p in data.pop("particles")]
        if "layer" in data:
            head["layer"] = data.pop("layer")
        return _dump_toml({**head, **data})


def _sha256(path: Path) -> str:
    import hashlib

    digest = hashlib.sha256()
    with Path(path).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


_SHAPES = ("sphere", "ellipsoid", "potato", "mesh")
_PROGRAMS = ("linear_ramp", "hold_then_ramp", "force_table", "gap_ramp", "slide")
_TAGS = _SHAPES + _PROGRAMS
# the allowed values of each tagged choice (pydantic names them only when the tag is wrong)
_CHOICES = {"shape": ", ".join(map(repr, _SHAPES)), "program": ", ".join(map(repr, _PROGRAMS))}
_BOUNDS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}


def _key(loc: tuple) -> str:
    """The key as the user wrote it: ``particle.E``, ``particles[1].radius``, ``load.forces``
    (without pydantic's inner names: the geometry table, the tags of the tables' kinds)."""
    key = ""
    for part in loc:
        if isinstance(part, int):
            key += f"[{part}]"
        elif part != "geometry" and part not in _TAGS and not str(part).endswith(
                ("Shape", "Load", "ShapeConfig")):
            key += f".{part}" if key else str(part)
    return key


def _got(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _error_line(err: dict) -> str | None:
    """One line for one pydantic error: the key, what is allowed, what was given."""
    kind, loc, ctx = err["type"], tuple(err["loc"]), err.get("ctx") or {}
    key, got = _key(loc), err.get("input")
    if kind == "missing" and loc and isinstance(loc[-1], int):
        return None                     # a list too short: said once, by _short_lists
    if kind == "missing":
        return f"{key}: required key missing"
    if kind == "extra_forbidden":
        return f"{key}: unknown key"
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        name = ctx.get("discriminator", "").strip("'")
        tags = ctx.get("expected_tags") or _CHOICES.get(name, "")
        where = f"{key}.{name}"
        if kind == "union_tag_not_found":
            return f"{where}: required key missing (one of {tags})"
        return f"{where} = {ctx.get('tag')!r}: not one of {tags}"
    if kind == "literal_error":
        return f"{key} = {_got(got)}: not one of {ctx.get('expected')}"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        bound = next((f"{_BOUNDS[k]} {v}" for k, v in ctx.items() if k in _BOUNDS), "")
        return f"{key} = {_got(got)}: must be {bound}"
    if kind in ("float_type", "float_parsing"):
        return f"{key} = {_got(got)}: not a valid number"
    if kind == "finite_number":
        return f"{key} = {_got(got)}: must be a finite number"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"{key} = {_got(got)}: must be a whole number"
    if kind in ("bool_type", "bool_parsing"):
        return f"{key} = {_got(got)}: must be true or false"
    if kind in ("string_type",):
        return f"{key} = {_got(got)}: must be a string"
    if kind in ("too_short", "too_long"):
        n = len(got) if hasattr(got, "__len__") else "?"
        if kind == "too_short":
            return f"{key}: give at least {ctx.get('min_length')} value(s); got {n}"
        return f"{key}: give at most {ctx.get('max_length')} values; got {n}"
    if kind in ("list_type", "tuple_type"):
        return f"{key} = {_got(got)}: must be a list [...]"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"{key}: must be a table" + (f" ([{key}])" if key else "")
    if kind == "value_error":
        message = str(err["msg"]).removeprefix("Value error, ")
        return f"{key or 'the configuration'}: {message}"
    return f"{key}: {err['msg']}; got {_got(got)}"


def _short_lists(exc: ValidationError) -> list[str]:
    """One line per fixed-length list given too few values (pydantic reports each missing
    position)."""
    missing: dict[tuple, tuple[int, object]] = {}
    for err in exc.errors():
        loc = tuple(err["loc"])
        if err["type"] == "missing" and loc and isinstance(loc[-1], int):
            n, _ = missing.get(loc[:-1], (0, None))
            missing[loc[:-1]] = (max(n, loc[-1] + 1), err.get("input"))
    return [f"{_key(loc)}: give {n} values; got {len(got) if hasattr(got, '__len__') else 0}"
            + (f" ({_got(got)})" if got is not None else "")
            for loc, (n, got) in missing.items()]


def _format_errors(exc: ValidationError, source: str) -> str:
    lines = [f"invalid configuration {source}:"]
    for line in [*(_error_line(err) for err in exc.errors()), *_short_lists(exc)]:
        if line is not None and f"  {line}" not in lines:
            lines.append(f"  {line}")
    return "\n".join(lines)


#: a particle larger than this across (m) is taken for a units mistake
MAX_ACROSS = 0.1


def _check_sizes(cfg: Config, body) -> None:
    """Refuse a particle more than MAX_ACROSS across: lengths are in metres, and a grain of
    1 m is, far more often, one in millimetres (or a mesh file read with the wrong scale)."""
    placed = [body] if cfg.particle is not None else [p.particle for p in body]
    tables = ([cfg.particle] if cfg.particle is not None
              else list(cfg.particles) if cfg.particles is not None else None)
    for k, particle in enumerate(placed):
        across = 2 * particle.shape.size
        if across <= MAX_ACROSS:
            continue
        if tables is None:
            key, given = "layer.size", f"size = {cfg.layer.size!r}"
        else:
            g = tables[k].geometry
            where = "particle" if cfg.particle is not None else f"particles[{k}]"
            if isinstance(g, MeshShapeConfig):
                raise ConfigError(
                    f"{where}.scale = {g.scale!r}: the mesh {g.file} is then {across:.3g} m "
                    "across; scale converts the file's unit to metres (1.0e-3 for a file in "
                    "millimetres). Is that the file's unit?")
            name = "radius" if isinstance(g, SphereShape) else "semi_axes"
            value = getattr(g, name)
            value = list(value) if isinstance(value, tuple) else value
            key, given = f"{where}.{name}", f"{name} = {value!r}"
        raise ConfigError(f"{key}: the particle is {across:.3g} m across ({given}); lengths "
                          "are in metres (1 mm = 1.0e-3): are these millimetres?")


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration; :class:`ConfigError` lists every problem."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(f"cannot read configuration {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"configuration {path} is not UTF-8 text (a binary file?); a "
                          "configuration is TOML") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"configuration {path} is not valid TOML: {exc}") from None
    return parse_config(data, source=str(path), base_dir=str(path.parent))


def parse_config(data: dict, source: str = "<dict>", base_dir: str = ".") -> Config:
    try:
        cfg = Config.model_validate({**data, "base_dir": base_dir})
    except ValidationError as exc:
        raise ConfigError(_format_errors(exc, source)) from None
    try:
        body = cfg.build()[0]
    except (ValueError, OSError) as exc:       # checks only the objects can make
        raise ConfigError(f"invalid configuration {source}: {exc}") from None
    try:
        _check_sizes(cfg, body)
    except ConfigError as exc:
        raise ConfigError(f"invalid configuration {source}: {exc}") from None
    return cfg


def body_from_results(ds, source: str = "the results"):
    """The Particle or Layer of a run, rebuilt from its results' ``config`` attribute (the
    TOML that ``thirdbody run`` and sweeps store). Raises :class:`ConfigError` when there is
    none or it cannot be built."""
    text = ds.attrs.get("config")
    if not isinstance(text, str) or not text.strip():
        raise ConfigError(f"{source} has no 'config' attribute (the run's configuration), so "
                          "its particles cannot be rebuilt")
    where = f"{source} (config attribute)"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid configuration in {where}: {exc}") from None
    return parse_config(data, source=where).build()[0]


def _dump_toml(data: dict) -> str:
    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    out = []
    for table, entries in data.items():
        for entry in entries if isinstance(entries, list) else [entries]:
            out.append(f"[[{table}]]" if isinstance(entries, list) else f"[{table}]")
            for k, v in entry.items():
                if v is not None:
                    out.append(f"{k} = {value(v)}")
            out.append("")
    return "\n".join(out)
