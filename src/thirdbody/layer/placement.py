"""A third-body layer: many particles, each with its own shape, size, material and orientation,
between the same two rigid plates (docs/methods/design.md §3b).

Particles sit at horizontal positions (x, y) (m, the centroid; the plates are unbounded). The
plates are rigid, so particles interact only through the common plate gap h: each loaded
particle is the single-particle problem at its own share of the load. A particle shorter than
h carries nothing.

Placement is checked in 3-D: two particles overlap when, on some vertical line, the solid
intervals of both (each resting on the lower plate, or pressed at the run's gap) overlap. The
test samples each particle's footprint on a 24 × 24 lattice of vertical rays, so overlaps
thinner than about 1/12 of a particle size can be missed; :meth:`Layer.random` places particles
so that their bounding spheres do not meet, which is always safe.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..material import Material
from ..orientation import Rotation
from ..particle.model import Particle
from ..shapes import Ellipsoid, Potato, Shape, Sphere

__all__ = ["Layer", "LayerError", "PlacedParticle", "first_overlap"]

#: vertical rays per footprint side in the overlap test
_OVERLAP_RAYS = 24


class LayerError(ValueError):
    """An invalid layer (overlapping particles, an empty layer, a generator that cannot place
    its particles)."""


@dataclass(frozen=True)
class PlacedParticle:
    """A particle and the horizontal position (x, y) of its centroid, m."""

    particle: Particle
    xy: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not isinstance(self.particle, Particle):
            raise TypeError("PlacedParticle.particle must be a thirdbody.Particle")
        xy = np.asarray(self.xy, dtype=float)
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise ValueError(f"particle position xy must be two finite numbers (m), got "
                             f"{self.xy!r}")
        object.__setattr__(self, "xy", (float(xy[0]), float(xy[1])))


def _footprint(shape: Shape, rotation: Rotation) -> tuple[np.ndarray, ...]:
    """Sample points (x, y) of the footprint (centroid frame, m) with the solid's lower and
    upper heights there."""
    s = np.linspace(-shape.size, shape.size, _OVERLAP_RAYS)
    X, Y = np.meshgrid(s, s)
    lo, up = shape.surfaces(rotation, X.ravel(), Y.ravel())
    hit = np.isfinite(lo) & np.isfinite(up)
    return X.ravel()[hit], Y.ravel()[hit], lo[hit], up[hit]


def first_overlap(shapes: Sequence[Shape], rotations: Sequence[Rotation],
                  centres: np.ndarray) -> tuple[int, int, float, float] | None:
    """The first pair (i, j, x, y) of particles whose solids overlap on a vertical line through
    (x, y), or None. ``centres`` (n, 3) are the centroids' world positions (m)."""
    centres = np.asarray(centres, dtype=float)
    n = len(shapes)
    feet: dict[int, tuple[np.ndarray, ...]] = {}
    for i, j in itertools.combinations(range(n), 2):
        d = centres[j] - centres[i]
        if math.hypot(d[0], d[1]) >= shapes[i].size + shapes[j].size:
            continue
        if abs(d[2]) >= shapes[i].size + shapes[j].size:
            continue
        for a, b in ((i, j), (j, i)):
            if a not in feet:
                feet[a] = _footprint(shapes[a], rotations[a])
            x, y, lo, up = feet[a]
            ca, cb = centres[a], centres[b]
            lo_b, up_b = shapes[b].surfaces(rotations[b], x + ca[0] - cb[0], y + ca[1] - cb[1])
            both = np.isfinite(lo_b) & np.isfinite(up_b)
            top = np.minimum(up + ca[2], up_b + cb[2])
            bottom = np.maximum(lo + ca[2], lo_b + cb[2])
            hit = both & (top > bottom)
            if hit.any():
                k = int(np.flatnonzero(hit)[0])
                return i, j, float(x[k] + ca[0]), float(y[k] + ca[1])
    return None


class Layer:
    """Particles placed between the plates (:class:`PlacedParticle`), in a fixed order.

    Refuses overlapping particles (each resting on the lower plate in its initial orientation)
    with a :class:`LayerError` naming the pair.
    """

    def __init__(self, placed: Sequence[PlacedParticle]) -> None:
        placed = list(placed)
        if not placed:
            raise LayerError("a layer needs at least one particle")
        for i, p in enumerate(placed):
            if not isinstance(p, PlacedParticle):
                raise TypeError(f"layer entry {i} must be a PlacedParticle, got "
                                f"{type(p).__name__}")
        self.placed: tuple[PlacedParticle, ...] = tuple(placed)
        rotations = [p.particle.orientation for p in placed]
        centres = [(*p.xy, -p.particle.shape.lowest_point(r)[2])
                   for p, r in zip(placed, rotations, strict=True)]
        hit = first_overlap([p.particle.shape for p in placed], rotations, np.array(centres))
        if hit is not None:
            i, j, x, y = hit
            raise LayerError(f"particles {i} and {j} overlap (near x = {x:.4g} m, y = {y:.4g} m):"
                             " move them apart")

    @classmethod
    def of(cls, particle: Particle) -> Layer:
        """A layer of one particle at the origin."""
        return cls([PlacedParticle(particle, (0.0, 0.0))])

    def __len__(self) -> int:
        return len(self.placed)

    def __iter__(self) -> Iterator[PlacedParticle]:
        return iter(self.placed)

    def __getitem__(self, i: int) -> PlacedParticle:
        return self.placed[i]

    @property
    def particles(self) -> list[Particle]:
        return [p.particle for p in self.placed]

    @property
    def positions(self) -> np.ndarray:
        """(n, 2) centroid positions, m."""
        return np.array([p.xy for p in self.placed], dtype=float)

    def __repr__(self) -> str:
        return f"Layer({len(self)} particles)"

    # --- a generator ---------------------------------------------------------------------------
    @classmethod
    def random(cls, *, box: tuple[float, float], material: Material, count: int | None = None,
               area_fraction: float | None = None, size: float = 1e-3,
               size_std: float = 0.0, distribution: str = "fixed",
               sizes: Sequence[float] | str | Path | None = None, shape: str = "sphere",
               aspect: tuple[float, float, float] = (1.0, 0.8, 0.7),
               amplitude: float = 0.05, n_waves: int = 3,
               wavenumber_range: tuple[float, float] = (2.0, 4.0),
               orientation: str = "random", max_tilt_deg: float = 30.0, seed: int = 0,
               max_attempts: int = 20000) -> Layer:
        """A seeded random layer in the rectangle ``box`` = (L_x, L_y) (m, centred on the
        origin).

        Parameters
        ----------
        count, area_fraction
            The number of particles, or the fraction of the box covered by their bounding discs
            (π s², s the particle size; at most 0.5, random packing jams near 0.55).
        size, size_std : float
            Mean and standard deviation of the particle size s, m: the sphere radius, or the
            largest semi-axis of an ellipsoid or potato.
        distribution : {"fixed", "normal", "lognormal", "list"}
            How sizes are drawn; ``"normal"`` redraws sizes below 0.1 ``size``. ``"list"`` cycles
            through ``sizes`` (numbers in m, or a CSV file with one size per row, first column).
        shape : {"sphere", "ellipsoid", "potato"}
            The family. Ellipsoids and potatoes have semi-axes ``s * aspect``; each potato gets
            its own random seed (``amplitude``, ``n_waves``, ``wavenumber_range`` as in
            :class:`~thirdbody.shapes.Potato`).
        orientation : {"random", "tilted", "upright"}
            Uniformly random 3-D orientations; a random yaw, then a tilt of up to
            ``max_tilt_deg`` (degrees, uniform) about a random horizontal axis; or the body axes
            along the world axes.
        seed : int
            Seed of everything random: the same inputs give the same layer.

        Particles are placed one at a time at uniformly random positions, refusing any whose
        bounding sphere (radius s) meets an earlier one's; a :class:`LayerError` says when
        ``max_attempts`` tries in a row fail.
        """
        from .._validate import positive, real

        Lx, Ly = (positive("layer.box[0] (m)", box[0]), positive("layer.box[1] (m)", box[1]))
        if (count is None) == (area_fraction is None):
            raise LayerError("layer: give exactly one of count and area_fraction")
        if shape not in ("sphere", "ellipsoid", "potato"):
            raise LayerError(f"layer.shape must be 'sphere', 'ellipsoid' or 'potato', got "
                             f"{shape!r}")
        if orientation not in ("random", "tilted", "upright"):
            raise LayerError(f"layer.orientation must be 'random', 'tilted' or 'upright', got "
                             f"{orientation!r}")
        real("layer.max_tilt_deg (degrees)", max_tilt_deg, "[0, 90]", lambda x: 0 <= x <= 90)
        if distribution not in ("fixed", "normal", "lognormal", "list"):
            raise LayerError("layer.distribution must be 'fixed', 'normal', 'lognormal' or "
                             f"'list', got {distribution!r}")
        positive("layer.size (m)", size)
        real("layer.size_std (m)", size_std, "[0, inf)", lambda x: x >= 0)
        rng = np.random.default_rng(seed)
        listed = _read_sizes(sizes) if distribution == "list" else None

        def draw(k: int) -> float:
            if listed is not None:
                return listed[k % len(listed)]
            if distribution == "fixed" or size_std == 0:
                return size
            if distribution == "normal":
                while True:
                    s = rng.normal(size, size_std)
                    if s >= 0.1 * size:
                        return float(s)
            sigma2 = math.log1p((size_std / size) ** 2)
            return float(rng.lognormal(math.log(size) - sigma2 / 2, math.sqrt(sigma2)))

        if count is not None:
            if isinstance(count, bool) or not isinstance(count, int) or count < 1:
                raise LayerError(f"layer.count must be an integer >= 1, got {count!r}")
        else:
            real("layer.area_fraction", area_fraction, "(0, 0.5]", lambda x: 0 < x <= 0.5)
        aspect_arr = np.asarray(aspect, dtype=float)
        if aspect_arr.shape != (3,) or not np.all(aspect_arr > 0):
            raise LayerError(f"layer.aspect must be three positive numbers, got {aspect!r}")

        placed: list[PlacedParticle] = []
        centres: list[tuple[float, float, float]] = []
        covered, k = 0.0, 0
        while (count is not None and k < count) or (
                area_fraction is not None and covered < area_fraction * Lx * Ly):
            s = draw(k)
            if shape == "sphere":
                body: Shape = Sphere(s)
            elif shape == "ellipsoid":
                body = Ellipsoid(s * aspect_arr / aspect_arr.max())
            else:
                body = Potato(s * aspect_arr / aspect_arr.max(),
                              seed=int(rng.integers(0, 2**31 - 1)), n_waves=n_waves,
                              amplitude=amplitude, wavenumber_range=wavenumber_range)
            reach = float(body.size)                # the bounding sphere's radius
            if 2 * reach > min(Lx, Ly):
                raise LayerError(f"layer: a particle of size {reach:.4g} m does not fit in the "
                                 f"box {Lx:.4g} m x {Ly:.4g} m")
            for _ in range(max_attempts):
                x = rng.uniform(-Lx / 2 + reach, Lx / 2 - reach)
                y = rng.uniform(-Ly / 2 + reach, Ly / 2 - reach)
                if all(math.hypot(x - cx, y - cy) >= reach + cs for cx, cy, cs in centres):
                    break
            else:
                raise LayerError(f"layer: could not place particle {k} (size {reach:.4g} m) "
                                 f"after {max_attempts} tries: the box is too full")
            if orientation == "random" and shape != "sphere":
                q = Rotation.random(random_state=rng).as_quat()
                particle = Particle(body, material, quaternion=tuple(q))
            elif orientation == "tilted" and shape != "sphere":
                angle, azimuth, yaw = rng.uniform((0.0, 0.0, 0.0), (max_tilt_deg, 360.0, 360.0))
                particle = Particle(body, material, float(angle), float(azimuth), float(yaw))
            else:
                particle = Particle(body, material)
            placed.append(PlacedParticle(particle, (float(x), float(y))))
            centres.append((float(x), float(y), float(body.size)))
            covered += math.pi * body.size**2
            k += 1
        return cls(placed)


def _read_sizes(sizes) -> list[float]:
    if sizes is None:
        raise LayerError("layer: distribution 'list' needs sizes (numbers in m or a CSV file)")
    if isinstance(sizes, (str, Path)):
        path = Path(sizes)
        try:
            with path.open(newline="") as f:
                rows = [r for r in csv.reader(f) if r and r[0].strip()]
        except OSError as exc:
            raise LayerError(f"layer.sizes: cannot read {path}: {exc.strerror}") from None
        values = []
        for n, row in enumerate(rows, start=1):
            try:
                values.append(float(row[0]))
            except ValueError:
                if n == 1:
                    continue                # a header
                raise LayerError(f"layer.sizes: {path} row {n}: {row[0]!r} is not a size "
                                 "in m") from None
    else:
        values = [float(v) for v in sizes]
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise LayerError(f"layer.sizes must be positive sizes in m, got {values!r}")
    return values
