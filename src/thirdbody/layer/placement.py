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
from functools import cached_property
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
    """A particle and the horizontal position (x, y) of its centroid, m, and optionally its
    height ``z`` above the lower plate, m (default None: resting on the lower plate, the
    lowest point of its initial orientation at z = 0). A height above that places it off the
    plate, e.g. on top of other particles (a layer several grains thick); only a network run
    (``mu_pp``) can load such a layer, since a particle off the plate is held by its
    neighbours."""

    particle: Particle
    xy: tuple[float, float] = (0.0, 0.0)
    z: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.particle, Particle):
            raise TypeError("PlacedParticle.particle must be a thirdbody.Particle")
        xy = np.asarray(self.xy, dtype=float)
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise ValueError(f"particle position xy must be two finite numbers (m), got "
                             f"{self.xy!r}")
        object.__setattr__(self, "xy", (float(xy[0]), float(xy[1])))
        if self.z is not None:
            z = float(self.z)
            rest = self.rest_height
            # a rounding below the rest height is resting (1e-12 of the size)
            if not math.isfinite(z) or z < rest - 1e-12 * self.particle.shape.size:
                raise ValueError(
                    f"particle height z must be a finite number >= {rest:.6g} m (its centroid "
                    f"when it rests on the lower plate: lower, it would cut into the plate), "
                    f"got {self.z!r}")
            object.__setattr__(self, "z", max(z, rest))

    @cached_property
    def rest_height(self) -> float:
        """The centroid's height when the particle rests on the lower plate, m."""
        p = self.particle
        return -float(p.shape.lowest_point(p.orientation)[2])

    @property
    def height(self) -> float:
        """The centroid's height above the lower plate, m (``z``, or resting)."""
        return self.rest_height if self.z is None else float(self.z)

    @cached_property
    def top(self) -> float:
        """The height of the particle's highest point above the lower plate, m: the gap at
        which the upper plate first touches it."""
        p = self.particle
        return self.height + float(p.shape.highest_point(p.orientation)[2])

    @property
    def stacked(self) -> bool:
        """Placed above its rest height (off the lower plate)."""
        return self.z is not None and self.z > self.rest_height


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

    Refuses overlapping particles (each resting on the lower plate in its initial orientation,
    or at its height ``z``) with a :class:`LayerError` naming the pair.
    """

    def __init__(self, placed: Sequence[PlacedParticle],
                 box: tuple[float, float] | None = None, periodic: bool = False) -> None:
        placed = list(placed)
        if not placed:
            raise LayerError("a layer needs at least one particle")
        for i, p in enumerate(placed):
            if not isinstance(p, PlacedParticle):
                raise TypeError(f"layer entry {i} must be a PlacedParticle, got "
                                f"{type(p).__name__}")
        self.placed: tuple[PlacedParticle, ...] = tuple(placed)
        rotations = [p.particle.orientation for p in placed]
        centres = [(*p.xy, p.height) for p in placed]
        if periodic and box is None:
            raise LayerError("a periodic layer needs its box (L_x, L_y), m")
        self.box = None if box is None else (float(box[0]), float(box[1]))
        self.periodic = bool(periodic)
        shapes = [p.particle.shape for p in placed]
        hit = first_overlap(shapes, rotations, np.array(centres))
        if hit is None and self.periodic:
            hit = _first_overlap_across(shapes, rotations, np.array(centres), self.box)
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
               max_attempts: int = 20000, placement: str = "sequential",
               periodic: bool = False) -> Layer:
        """A seeded random layer in the rectangle ``box`` = (L_x, L_y) (m, centred on the
        origin).

        Parameters
        ----------
        count, area_fraction
            The number of particles, or the fraction of the box covered by their bounding discs
            (π s², s the particle size): at most 0.5 for ``placement="sequential"`` (random
            sequential addition jams near 0.55), at most 0.8 for ``"relaxed"``.
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
        placement : {"sequential", "relaxed"}
            ``"sequential"``: particles are placed one at a time at uniformly random positions,
            refusing any whose bounding disc (radius s) meets an earlier one's; a
            :class:`LayerError` says when ``max_attempts`` tries in a row fail.
            ``"relaxed"`` (dense layers): every particle at a random position at once, then the
            overlaps of the bounding discs, grown by 0.1 %, are relaxed away (the least-squares
            overlap minimised by L-BFGS; discs that still overlap at a local minimum are moved
            by about their size and the minimisation goes on); discs that overlapped end up to
            0.2 % of their size apart. A :class:`LayerError` says when the discs jam (overlaps
            remain after 10 rounds: typically above 0.75 for equal sizes).
        periodic : bool
            x and y periodic (for a run with a periodic box of the same size): centroids
            anywhere in the box, discs may cross its sides and meet the images of the others.
            Otherwise every bounding disc lies inside the box.
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
        elif placement == "relaxed":
            real("layer.area_fraction", area_fraction, "(0, 0.8] with placement = 'relaxed'",
                 lambda x: 0 < x <= _MAX_RELAXED)
        else:
            real("layer.area_fraction", area_fraction, "(0, 0.5] with placement = "
                 "'sequential' (use placement = 'relaxed' for denser layers)",
                 lambda x: 0 < x <= 0.5)
        if placement not in ("sequential", "relaxed"):
            raise LayerError(f"layer.placement must be 'sequential' or 'relaxed', got "
                             f"{placement!r}")
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
            if placement == "relaxed":
                x = y = 0.0                         # placed below, all at once
            else:
                x, y = _sequential(rng, reach, centres, (Lx, Ly), periodic, max_attempts, k)
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
        if placement == "relaxed":
            radii = np.array([c[2] for c in centres])
            xy = _relaxed(rng, radii, (Lx, Ly), periodic)
            placed = [PlacedParticle(p.particle, (float(x), float(y)))
                      for p, (x, y) in zip(placed, xy, strict=True)]
        return cls(placed, box=(Lx, Ly), periodic=periodic)


#: the densest area fraction of bounding discs ``placement="relaxed"`` accepts (random discs
#: jam near 0.82-0.84)
_MAX_RELAXED = 0.8
#: the discs' growth while relaxing: neighbours end touching or up to this share apart
_INFLATE = 1e-3


def _minimum_image(d: np.ndarray, box: tuple[float, float], periodic: bool) -> np.ndarray:
    """Horizontal offsets (…, 2) to the nearest periodic image (unchanged if not periodic)."""
    if not periodic:
        return d
    L = np.asarray(box, dtype=float)
    return d - L * np.round(d / L)


def _sequential(rng, reach: float, centres: list, box: tuple[float, float], periodic: bool,
                max_attempts: int, k: int) -> tuple[float, float]:
    """A random position whose disc of radius ``reach`` meets none of ``centres`` (x, y, r)."""
    Lx, Ly = box
    margin = 0.0 if periodic else reach
    for _ in range(max_attempts):
        x = rng.uniform(-Lx / 2 + margin, Lx / 2 - margin)
        y = rng.uniform(-Ly / 2 + margin, Ly / 2 - margin)
        if not centres:
            return x, y
        c = np.asarray(centres)
        d = _minimum_image(c[:, :2] - (x, y), box, periodic)
        if (np.hypot(d[:, 0], d[:, 1]) >= reach + c[:, 2]).all():
            return x, y
    raise LayerError(f"layer: could not place particle {k} (size {reach:.4g} m) after "
                     f"{max_attempts} tries: the box is too full (placement = 'relaxed' "
                     f"places denser layers)")


def _relaxed(rng, radii: np.ndarray, box: tuple[float, float], periodic: bool) -> np.ndarray:
    """Centres (n, 2), m, of discs of ``radii`` in ``box`` (centred on the origin) that do not
    overlap: random positions, then Σ overlap² of the discs grown by :data:`_INFLATE` minimised
    by L-BFGS-B (inside the box, or periodic), restarted from a perturbation while overlaps of
    the true discs remain. Raises :class:`LayerError` when they jam."""
    from scipy.optimize import minimize
    from scipy.spatial import cKDTree

    n = len(radii)
    L = np.asarray(box, dtype=float)
    grown = radii * (1 + _INFLATE)
    if periodic:
        lo, hi = -L / 2, L / 2
        bounds = None
    else:
        lo, hi = -L / 2 + radii[:, None], L / 2 - radii[:, None]
        bounds = list(zip(np.ravel(np.broadcast_to(lo, (n, 2))),
                          np.ravel(np.broadcast_to(hi, (n, 2))), strict=True))
    reach = 2 * grown.max()

    def pairs(P: np.ndarray) -> np.ndarray:
        if periodic:
            Q = np.mod(P + L / 2, L)
            Q[Q >= L] = 0.0                 # a rounding below 0 wraps to L
            tree = cKDTree(Q, boxsize=L)
        else:
            tree = cKDTree(P)
        return tree.query_pairs(min(reach, 0.499 * L.min()) if periodic else reach,
                                output_type="ndarray")

    def overlaps(P: np.ndarray, r: np.ndarray):
        ij = pairs(P)
        if not len(ij):
            return ij, np.zeros((0, 2)), np.zeros(0), np.zeros(0)
        d = _minimum_image(P[ij[:, 1]] - P[ij[:, 0]], box, periodic)
        dist = np.hypot(d[:, 0], d[:, 1])
        return ij, d, dist, r[ij[:, 0]] + r[ij[:, 1]] - dist

    def energy(flat: np.ndarray):
        P = flat.reshape(n, 2)
        ij, d, dist, over = overlaps(P, grown)
        hit = over > 0
        if not hit.any():
            return 0.0, np.zeros_like(flat)
        ij, d, dist, over = ij[hit], d[hit], dist[hit], over[hit]
        unit = d / np.maximum(dist, 1e-300)[:, None]
        grad = np.zeros((n, 2))
        np.add.at(grad, ij[:, 0], 2 * over[:, None] * unit)
        np.add.at(grad, ij[:, 1], -2 * over[:, None] * unit)
        return float(np.sum(over**2)), grad.ravel()

    P = rng.uniform(np.broadcast_to(lo, (n, 2)), np.broadcast_to(hi, (n, 2)))
    for _ in range(_RELAX_ROUNDS):
        res = minimize(energy, P.ravel(), jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": 2000, "ftol": 0.0, "gtol": 0.0})
        P = res.x.reshape(n, 2)
        if periodic:
            P = np.mod(P + L / 2, L) - L / 2
        *_, over = overlaps(P, radii)
        if not (over > 0).any():
            return P
        # a local minimum: move the discs that still overlap by up to their overlap's size,
        # and go on
        ij, _, _, over = overlaps(P, grown)
        stuck = np.unique(ij[over > 0])
        P[stuck] += rng.normal(scale=radii[stuck, None], size=(len(stuck), 2))
        if not periodic:
            P = np.clip(P, lo, hi)
    worst = float(over.max() / radii.mean())
    raise LayerError(f"layer: the particles' bounding discs jam (overlaps of up to "
                     f"{worst:.2g} of the mean size remain): lower layer.area_fraction or "
                     f"enlarge layer.box")


#: restarts of the relaxation before the discs count as jammed
_RELAX_ROUNDS = 10


def _first_overlap_across(shapes, rotations, centres: np.ndarray,
                          box: tuple[float, float]) -> tuple[int, int, float, float] | None:
    """:func:`first_overlap` of the pairs that are nearer through a periodic side of ``box``
    than directly (each with j moved to the image nearest to i)."""
    L = np.asarray(box, dtype=float)
    for i, j in itertools.combinations(range(len(shapes)), 2):
        d = centres[j, :2] - centres[i, :2]
        image = -L * np.round(d / L)
        if not image.any() or np.hypot(*(d + image)) >= shapes[i].size + shapes[j].size:
            continue
        moved = centres[[i, j]].copy()
        moved[1, :2] += image
        hit = first_overlap([shapes[i], shapes[j]], [rotations[i], rotations[j]], moved)
        if hit is not None:
            return i, j, hit[2], hit[3]
    return None


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
