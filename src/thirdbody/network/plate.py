"""A plate-particle contact in displacement control: the approach comes from the particle's pose
and the plate's height (docs/methods/design.md §3c, for the plates of a dense layer).

The lower plate is the plane z = 0, the upper one the plane z = h; both are rigid
(:meth:`ElasticPair.rigid_plate`). A particle :class:`~thirdbody.network.Body` at centroid c and
rotation R is seen by a plate through vertical rays on the particle's lattice
(:class:`PlateLattice`: cell centres at (c_x + i Δ, c_y + j Δ), world axes), so a horizontal
move of the particle carries the lattice with it and the fields of two solves at the same
spacing are related by whole cells. Every spot the plate can reach is found as for the pairs
(:mod:`~thirdbody.network.window`, the plates' logic of :mod:`thirdbody.particle.surface`
evaluated lazily): the whole footprint is scanned coarsely and refined level by level where the
gap less a curvature allowance lies below the approach, and after the solve no cell next to the
evaluated ones may lie below the approach. In approach control nothing else is needed: the
elastic displacement is positive, so only cells with a gap below the approach can touch.

Conventions (as :class:`~thirdbody.network.PairContact`, the particle in the role of body a and
the plate in that of b; SI units, world frame):

* ``normal`` points from the particle to the plate: −z for the lower plate, +z for the upper;
* the normal force N >= 0 is compressive, the force on the particle is −N n + T;
* the traction τ (world x, y components) and T are what the plate exerts on the particle;
* the shift is the plate's rigid tangential displacement relative to the particle at the
  contact, accumulated over the contact's history (the bem convention); the twist the plate's
  rotation relative to the particle about +z, likewise.

**Kinematics of a step.** Given the particle's pose at the start of the step (``start``) and
its history (``previous``, solved at that pose), the step's shift increment is the plate's
prescribed horizontal displacement less that of the particle's material point at the contact,
Δs = Δu_plate − P (Δc + Δφ × r̄), with Δφ the rotation vector of R R₀ᵀ and r̄ the mean of the
contact point's position relative to the centroid at the start and at the end of the step (the
pressure centroids): the midpoint rule, so that a particle rolling without slip over a plate
gets no shift (the material point at a contact that rolls moves at second order, which a
finite step would otherwise count as slip). The twist increment is −Δφ_z about the contact
point. The history (traction, shift, twist) stays on the particle's lattice in world axes: it
rides with the contact point under the centroid, not with the material that rolls through it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from .._citations import cites
from ..bem import (
    ElasticPair,
    Grid,
    NormalContact,
    TangentialContact,
    solve_tangential,
)
from ..particle.interface import Window, remap
from .body import Body
from .contact import HALF_SPACE_LIMIT, HalfSpaceWarning, _centroid, _radii, _solve_normal
from .narrow import _smoothing
from .window import Lattice, occupied

__all__ = ["PlateContact", "PlateLattice", "cell_separation", "solve_plate"]

_SIDES = ("lower", "upper")
_CATTANEO = ("Cattaneo, C. (1938). Sul contatto di due corpi elastici: distribuzione locale "
             "degli sforzi. Rend. Accad. Naz. Lincei 27, 342-348, 434-436, 474-478; Mindlin, "
             "R. D. (1949). Compliance of elastic bodies in contact. J. Appl. Mech. 16, 259-268.")


@dataclass(frozen=True, eq=False)
class PlateContact:
    """One solved plate-particle contact (module docstring for the conventions).

    Attributes
    ----------
    body : Body
        The particle at the pose the contact was solved at.
    side : {"lower", "upper"}
    plate : float
        Height z of the plate, m.
    normal : (3,) array
        Unit normal from the particle to the plate, world.
    window : Window
        The cells solved, on the particle's lattice (cell (i, j) at (c_x + i Δ, c_y + j Δ)).
    grid : Grid
        The window in lattice coordinates, m, relative to the centroid's horizontal position.
    gap : (ny, nx) array
        Gap from first touch, m (+inf off the cells that can touch).
    pressure : (ny, nx) array
        Contact pressure, Pa (>= 0).
    traction : (2, ny, nx) array
        Tangential traction of the plate on the particle, world x and y components, Pa.
    contact, stick : (ny, nx) bool arrays
    approach : float
        Approach of the plate from first touch (the shape's extreme point), m.
    separation : float
        −approach: the signed separation of the undeformed surfaces, m.
    normal_force : float
        N = Σ p ΔA, N.
    tangential_force : (3,) array
        Σ τ ΔA on the particle, world, N (horizontal).
    moment : (3,) array
        Moment of the contact's forces about the particle's centroid, Σ (x − c) × f ΔA over the
        cells (x on the plate), world, N m.
    twist_moment : float
        Moment of the tractions about the normal through the pressure centroid, N m.
    area, stick_area : float
        m².
    spots : int
        Separate contact spots (cells touching at an edge or a corner are one spot).
    pressure_centroid : (3,) array
        World point of the plate at the pressure centroid, m.
    touch : (3,) array
        World point of the plate below (above) the particle's extreme point: where the
        undeformed particle first touches it, m.
    contact_radius : float
        √(A/π) with A the largest spot's area, m.
    radii : (2,) array
        Principal radii of curvature of the particle's surface at the pressure centroid, m
        (the rolling geometry of the contact as a whole: the Newton model's).
    curvature : (2, 2) array
        Its curvature tensor (1/m, positive convex) on the world x, y axes.
    curvature_radius, half_space_ratio : float
        The smallest |radius| of curvature at the largest spot's own pressure centroid, m, and
        contact_radius / curvature_radius (the half-space measure: each spot is a contact of
        its own bump). With one spot that is the pressure centroid; with several the whole
        contact's centroid can lie between them, where the surface may be concave (the
        two-bump potato of ``tests/test_network_plate.py`` pressed 1 µm: a/R 0.196 from the
        dip between its spots, 0.082 from its bump).
    shift : (2,) array
        The plate's accumulated rigid tangential displacement relative to the particle, m.
    shift_increment : (2,) array
        Its increment in this solve's step, m.
    twist : float
        The plate's accumulated twist relative to the particle about +z, rad.
    slip : (2,) array
        Mean slip increment of the plate over the particle over the slipping cells, m (zero
        when no cell slips).
    mu : float
    normal_solution : NormalContact
    tangential_solution : TangentialContact or None
    methods : tuple of str
    """

    body: Body
    side: str
    plate: float
    normal: np.ndarray
    window: Window
    grid: Grid
    gap: np.ndarray = field(repr=False)
    pressure: np.ndarray = field(repr=False)
    traction: np.ndarray = field(repr=False)
    contact: np.ndarray = field(repr=False)
    stick: np.ndarray = field(repr=False)
    approach: float
    separation: float
    normal_force: float
    tangential_force: np.ndarray
    moment: np.ndarray
    twist_moment: float
    area: float
    stick_area: float
    spots: int
    pressure_centroid: np.ndarray
    touch: np.ndarray
    contact_radius: float
    radii: np.ndarray
    curvature: np.ndarray
    curvature_radius: float
    half_space_ratio: float
    shift: np.ndarray
    shift_increment: np.ndarray
    twist: float
    slip: np.ndarray
    mu: float
    normal_solution: NormalContact = field(repr=False)
    tangential_solution: TangentialContact | None = field(repr=False)
    methods: tuple[str, ...] = ()

    @property
    def force(self) -> np.ndarray:
        """Total force of the plate on the particle, world, N: −N n + T."""
        return -self.normal_force * self.normal + self.tangential_force

    @property
    def lever(self) -> np.ndarray:
        """The pressure centroid relative to the particle's centroid, world, m."""
        c = self.grid
        p = self.pressure
        total = math.fsum(p.ravel())
        X, Y = c.mesh()
        return np.array([math.fsum((p * X).ravel()) / total, math.fsum((p * Y).ravel()) / total,
                         self.plate - float(self.body.centre[2])])

    @property
    def peak_pressure(self) -> float:
        return float(self.pressure.max())

    @property
    def sliding(self) -> bool:
        """No contact cell sticks (with friction: the contact slides as a whole)."""
        return not bool(self.stick.any())


class PlateLattice(Lattice):
    """The gap g₀ (m) between a particle and a plate on the particle's lattice of spacing
    ``spacing`` (m): cell (i, j) at (c_x + i Δ, c_y + j Δ) in world axes, evaluated lazily and
    cached by cell (:class:`~thirdbody.network.window.Lattice`'s every-spot scan).

    The raw gap is the height of the particle's lower surface above the lower plate, or of the
    upper plate above the particle's upper surface; its zero level is the shape's extreme point
    (:meth:`Shape.lowest_point`, :meth:`Shape.highest_point`), so g₀ >= 0 and the plate's
    approach from first touch is −zero.
    """

    def __init__(self, body: Body, side: str, plate: float, spacing: float) -> None:
        self.body, self.side, self.plate = body, side, float(plate)
        self.origin = np.asarray(body.centre, dtype=float)
        if side == "lower":
            zero = self.origin[2] + body.shape.lowest_point(body.rotation)[2] - self.plate
        else:
            zero = self.plate - self.origin[2] - body.shape.highest_point(body.rotation)[2]
        r = body.size
        self._setup(zero, spacing, r, body.shape.feature_length, (-r, r, -r, r))

    def _rays(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        z_low, z_up = self.body.shape._surfaces_rotated(self.body.rotation, self.body.matrix,
                                                        x, y)
        if self.side == "lower":
            raw = self.origin[2] + z_low - self.plate
        else:
            raw = self.plate - self.origin[2] - z_up
        return np.where(np.isnan(raw), np.inf, raw)


def _window_of(grid: Grid) -> Window:
    """The lattice window (integer cells) of a grid in lattice coordinates."""
    dx = grid.dx
    return Window(round(grid.x[0] / dx), round(grid.y[0] / dx), grid.nx, grid.ny)


def _curvature(body: Body, side: str, point: np.ndarray, size: float) -> np.ndarray:
    """Curvature tensor (1/m, positive convex) of the particle's surface facing the plate, at
    the horizontal offset ``point`` (m) from the centroid, from a 3 x 3 stencil of rays."""
    h = 1e-3 * size
    for _ in range(8):
        offsets = np.array([-h, 0.0, h])
        X, Y = np.meshgrid(offsets + point[0], offsets + point[1])
        z_low, z_up = body.shape.surfaces(body.rotation, X, Y)
        z = z_low if side == "lower" else -z_up
        if np.isfinite(z).all():
            hxx = (z[1, 2] - 2 * z[1, 1] + z[1, 0]) / h**2
            hyy = (z[2, 1] - 2 * z[1, 1] + z[0, 1]) / h**2
            hxy = (z[2, 2] - z[2, 0] - z[0, 2] + z[0, 0]) / (4 * h**2)
            return np.array([[hxx, hxy], [hxy, hyy]])
        h *= 0.25
    raise RuntimeError(f"{side} plate: the particle's surface could not be sampled at the "
                       "contact")


def _touch(body: Body, side: str, plate: float) -> np.ndarray:
    extreme = (body.shape.lowest_point(body.rotation) if side == "lower"
               else body.shape.highest_point(body.rotation))
    point = np.asarray(body.centre, dtype=float) + extreme
    point[2] = plate
    return point


def _fsum3(values: np.ndarray) -> np.ndarray:
    flat = values.reshape(-1, 3)
    return np.array([math.fsum(flat[:, k]) for k in range(3)])


def rigid_increment(start: Body, body: Body) -> tuple[np.ndarray, np.ndarray]:
    """(Δc, Δφ): the centroid's displacement (m) and the rotation vector (rad) of R R₀ᵀ from
    ``start`` to ``body``, world."""
    return (np.asarray(body.centre, dtype=float) - np.asarray(start.centre, dtype=float),
            (body.rotation * start.rotation.inv()).as_rotvec())


@cites("cattaneo_mindlin", _CATTANEO)
def solve_plate(body: Body, side: str, *, plate: float = 0.0, mu: float, spacing: float,
                previous: PlateContact | None = None, start: Body | None = None,
                plate_shift=(0.0, 0.0), shift_increment=None, twist_increment=None,
                fraction: float = 1.0, lever_start=None, tol: float = 1e-8,
                warm: PlateContact | None = None,
                half_space_limit: float = HALF_SPACE_LIMIT) -> PlateContact | None:
    """Solve the contact of the particle ``body`` with a rigid plate (module docstring).

    Parameters
    ----------
    body : Body
        The particle at its pose.
    side : {"lower", "upper"}
        The lower plate pushes up, the upper one down.
    plate : float
        Height z of the plate, m.
    mu : float
        Friction coefficient (>= 0); 0: no tangential problem.
    spacing : float
        Cell size Δ, m (the same as ``previous``'s).
    previous : PlateContact, optional
        The contact's last converged state (its history: traction, shift, twist), solved at the
        pose ``start``.
    start : Body, optional
        The particle at the start of the step (default: ``previous.body``, else ``body``): the
        step's rigid motion is from ``start`` to ``body``.
    plate_shift : (2,) array
        The plate's own horizontal displacement in the step, m.
    shift_increment : (2,) array, optional
        Prescribe the step's shift increment (m) instead of deriving it from the motion.
    twist_increment : float, optional
        Prescribe the step's twist increment (rad, plate relative to the particle about +z,
        about the pressure centroid) instead of −Δφ_z.
    fraction : float
        Share of the step's relative motion the contact sees, in [0, 1] (a contact that closed
        during the step: the part after it closed).
    lever_start : (3,) array, optional
        Without ``previous``: where the contact point was at the start of the step, relative to
        the centroid then (m; default: where it is now).
    tol : float
        Tolerance of the normal and tangential solvers.
    warm : PlateContact, optional
        A recent solve of this contact whose pressure starts the normal solve.
    half_space_limit : float
        contact radius / radius of curvature above which a :class:`HalfSpaceWarning` is
        emitted.

    Returns
    -------
    PlateContact, or None when no cell reaches the plate.
    """
    if side not in _SIDES:
        raise ValueError(f"side must be 'lower' or 'upper', got {side!r}")
    mu = float(mu)
    if not (math.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu must be a finite number >= 0, got {mu!r}")
    if not (math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a finite number > 0 m, got {spacing!r}")
    if previous is not None and previous.grid.dx != spacing:
        raise ValueError(f"previous was solved with the spacing {previous.grid.dx!r} m, not "
                         f"{spacing!r} m")
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction must lie in [0, 1], got {fraction!r}")
    lattice = PlateLattice(body, side, plate, spacing)
    delta = -lattice.zero
    if not delta > 0:
        return None
    history = None
    if previous is not None and previous.tangential_solution is not None:
        # the cells its traction occupies (a sliding plate moves the contact a little each
        # step; the whole last window would grow the next by its margin every step)
        history = occupied(previous.window, previous.tangential_solution.traction,
                           previous.pressure)
    initial = None if warm is None or warm.grid.dx != spacing else (warm.window, warm.pressure)
    bound = 1.05 * delta + 1e-12 * spacing
    normal = _solve_normal(lattice, ElasticPair.rigid_plate(body.material), None, delta, bound,
                           tol, history, initial, faceted=_smoothing(body) > 0, from_poses=True)
    if normal is None:          # no cell reaches the plate
        return None
    window = _window_of(normal.grid)
    grid = normal.grid
    p = normal.pressure
    X, Y = grid.mesh()
    total = math.fsum(p.ravel())
    lever_now = np.array([math.fsum((p * X).ravel()) / total,
                          math.fsum((p * Y).ravel()) / total,
                          float(plate) - float(body.centre[2])])
    tangential = None
    twist = 0.0 if previous is None or previous.tangential_solution is None else \
        float(previous.tangential_solution.twist)
    increment = np.zeros(2)
    if mu > 0:
        if shift_increment is None or twist_increment is None:
            origin = start if start is not None else (previous.body if previous is not None
                                                      else body)
            dc, dphi = rigid_increment(origin, body)
            lever_then = previous.lever if previous is not None else (
                lever_now if lever_start is None else np.asarray(lever_start, dtype=float))
            mean = 0.5 * (lever_then + lever_now)
            material = dc + np.cross(dphi, mean)
            kin_shift = fraction * (np.asarray(plate_shift, dtype=float)[:2] - material[:2])
            kin_twist = -fraction * float(dphi[2])
        increment = kin_shift if shift_increment is None else \
            np.asarray(shift_increment, dtype=float).reshape(2)
        d_twist = kin_twist if twist_increment is None else float(twist_increment)
        prev_step = None
        prev_shift = np.zeros(2)
        if previous is not None and previous.tangential_solution is not None:
            step = previous.tangential_solution
            prev_step = replace(step, traction=remap(step.traction, previous.window, window))
            prev_shift = np.asarray(step.shift, dtype=float)
        tangential = solve_tangential(normal, mu, shift=prev_shift + increment, previous=prev_step,
                                      tol=tol, twist=twist + d_twist,
                                      twist_centre=(float(lever_now[0]), float(lever_now[1])))
        twist = float(tangential.twist)
    return _result(body, side, float(plate), window, normal, tangential, lever_now,
                   increment, twist, mu, half_space_limit)


def _result(body, side, plate, window, normal, tangential, lever, increment, twist,
            mu, limit) -> PlateContact:
    grid = normal.grid
    dA = grid.cell_area
    p = normal.pressure
    X, Y = grid.mesh()
    n = np.array([0.0, 0.0, -1.0 if side == "lower" else 1.0])
    tau = np.zeros((2, *grid.shape)) if tangential is None else tangential.traction
    # cell forces on the particle and their lever arms about the centroid (centroid-relative
    # coordinates only: two particles at different places give the same bits)
    f = np.stack([tau[0] * dA, tau[1] * dA, -n[2] * p * dA], axis=-1)
    arm = np.stack([X, Y, np.full(X.shape, plate - float(body.centre[2]))], axis=-1)
    moment = _fsum3(np.cross(arm, f))
    force_n = math.fsum(p.ravel()) * dA
    tangential_force = np.array([math.fsum(f[..., 0].ravel()), math.fsum(f[..., 1].ravel()), 0.0])
    twist_moment = float(n[2]) * math.fsum(((X - lever[0]) * f[..., 1]
                                            - (Y - lever[1]) * f[..., 0]).ravel())
    labels, spots = ndimage.label(normal.contact, structure=np.ones((3, 3), dtype=bool))
    counts = np.bincount(labels.ravel())[1:]
    radius = math.sqrt(int(counts.max()) * dA / math.pi)
    curvature = _curvature(body, side, lever[:2], body.size)
    radii = _radii(curvature)
    if spots > 1:
        # the largest spot's own pressure centroid (the first of equal ones)
        own = _centroid(np.where(labels == int(np.argmax(counts)) + 1, p, 0.0), X, Y)
        curvature_radius = float(np.abs(_radii(_curvature(body, side, own, body.size))).min())
    else:
        curvature_radius = float(np.abs(radii).min())
    ratio = radius / curvature_radius
    if ratio > limit:
        warnings.warn(HalfSpaceWarning(
            f"{side} plate: contact radius / radius of curvature = {ratio:.3g} > {limit:.3g}: "
            f"the half-space model of the contact is out of its range"), stacklevel=3)
    stick = np.zeros(grid.shape, dtype=bool) if tangential is None else tangential.stick
    slip = np.zeros(2)
    if tangential is not None and tangential.slip.any():
        inc = tangential.slip_increment[:, tangential.slip]
        slip = np.array([math.fsum(inc[0]), math.fsum(inc[1])]) / inc.shape[1]
    centre = np.asarray(body.centre, dtype=float)
    methods = normal.methods + (() if tangential is None else tangential.methods) + \
        ("cattaneo_mindlin",)
    return PlateContact(
        body=body, side=side, plate=plate, normal=n, window=window, grid=grid, gap=normal.gap,
        pressure=p, traction=tau, contact=normal.contact, stick=stick,
        approach=float(normal.approach), separation=-float(normal.approach),
        normal_force=force_n, tangential_force=tangential_force, moment=moment,
        twist_moment=twist_moment, area=normal.area,
        stick_area=0.0 if tangential is None else tangential.stick_area, spots=int(spots),
        pressure_centroid=centre + lever, touch=_touch(body, side, plate),
        contact_radius=radius, radii=radii,
        curvature=curvature, curvature_radius=curvature_radius, half_space_ratio=ratio,
        shift=np.zeros(2) if tangential is None else np.asarray(tangential.shift, dtype=float),
        shift_increment=np.asarray(increment, dtype=float), twist=twist, slip=slip, mu=mu,
        normal_solution=normal, tangential_solution=tangential,
        methods=tuple(dict.fromkeys(methods)))


def cell_separation(body: Body, side: str, plate: float, spacing: float) -> float:
    """How much further the plate at height ``plate`` (m) must press into ``body`` before a cell
    of its contact lattice (``spacing``, m) touches, m (>= 0; 0 when one touches): the smallest
    gap g₀ of the cells next to the extreme point less the overlap. Where the shape overlaps
    the plate by less than the surface's sag from its extreme point to the nearest cell centre,
    :func:`solve_plate` finds no contact; this is the separation of that contact as the cells
    see it, which the network's Newton step needs to know when it closes. +inf when no ray
    near the extreme point meets the surface."""
    lattice = PlateLattice(body, side, plate, spacing)
    delta = -lattice.zero
    corner, mask = lattice.candidates(max(delta, 0.0) + spacing)
    jj, ii = np.nonzero(mask)
    gaps = lattice.gap(ii + corner[0], jj + corner[1])
    gaps = gaps[np.isfinite(gaps)]
    if not gaps.size:
        return math.inf
    return max(float(gaps.min()) - delta, 0.0)
