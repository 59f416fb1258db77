"""A particle-particle contact solved by the boundary-element method in its own frame
(docs/methods/design.md §3c).

Two elastic bodies a and b meet at their closest points (:func:`closest_approach`). In the
contact frame (z along the common normal n from a to b, origin at the midpoint of the closest
points, tangent axes tied to the bodies: :func:`~thirdbody.network.frame.pair_frame`) a lies
below and b above. The gap is b's lower surface minus a's upper surface along the frame's
vertical rays, measured from first touch, over every cell that can touch
(:mod:`~thirdbody.network.window`); several spots share the frame of the deepest one and one
rigid approach along its normal, as the spots of a plate do. A spot that faces elsewhere (a
non-convex body touching on two bumps) is measured (``spot_tilt``) and, when it is a minimum
of the gap of its own, tilted by more than :data:`SPLIT_TILT` and :data:`SPLIT_DISTANCE`
contact radii away, handed on with its own closest approach (``facing``): a cluster then
solves one contact per spot, each on its share of the surfaces (``others``). Both bodies are elastic
half-spaces with the pair's compliance (:meth:`ElasticPair.of`: 1/E* = Σ (1 − ν_i²)/E_i,
1/G = Σ 1/G_i; Johnson 1985, §4.2 and §7.2): the frame's problem is the plate solvers' problem
with b in the role of the plate. Normal and tangential problems are uncoupled (Goodman's
approximation: exact for two bodies of one material, whose Dundurs β is 0).

Sign conventions (every vector in the world frame, SI units):

* the normal force N >= 0 is compressive: b pushes a along −n, a pushes b along +n;
* the traction τ (frame components on the tangent axes t₁ = F⁻¹x̂, t₂ = F⁻¹ŷ) and the
  tangential force are what b exerts on a; on b they are the opposite (Newton's third law,
  cell by cell);
* the shift is the rigid tangential displacement of b relative to a at the contact,
  accumulated over the contact's history; friction on a points along b's slip over a;
* the twist is the rotation of b relative to a about n (right-handed), accumulated likewise.

**History across frames.** The tangential problem is incremental (Coulomb's law with history,
:func:`~thirdbody.bem.solve_tangential`). Between two solves the bodies move, and with them the
normal, the contact point and the frame. The history is carried in the contact's frame: a
field point at p (old frame, relative to the old origin) goes to Rot(φ) p (new frame, relative
to the new origin), its 2-vector turned by φ. φ is the angle, in the new frame, of the old
tangent axes turned about the old normal by the bodies' mean twist (the twist part of each
body's rotation since the last solve, in its swing-twist decomposition about the normal) and
carried to the new normal by the smallest rotation. So the fields ride along with a rigid
motion of the whole pair, and keep their direction when the bodies roll (a rotation about a
tangent axis has no twist). Carried are the traction (bilinear interpolation between old cells,
an exact copy when φ = 0 and the spacing is kept), the accumulated shift (turned by φ) and the
twist, to which the twist of b's rotation less a's is added; the previous pressure seeds the
normal solve. Without a prescribed tangential force or shift increment, the step's shift
increment is the displacement of b's material point at the old contact origin relative to
a's, from the bodies' motion. Material points that roll through the contact are not tracked
(the history stays with the contact point), and a contact that opens loses its history (solve
it again without ``previous``).

**Half-space limit.** The model holds while the contact is small against the bodies' radii of
curvature at the contact. Each result reports the contact radius a = √(A/π) (A: the largest
spot's area), the principal radii of curvature of both surfaces at the closest points (from
their own heights in the contact frame) and a/R with R the smallest of them; past
:data:`HALF_SPACE_LIMIT` a :class:`HalfSpaceWarning` is emitted (the measurement behind the
limit is in ``notes/pp_contact.md``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from .._citations import cites
from ..bem import (
    ContactAtEdgeError,
    ElasticPair,
    Grid,
    NormalContact,
    TangentialContact,
    solve_normal,
    solve_tangential,
)
from ..orientation import Rotation
from ..particle.interface import Window, remap
from .body import Body
from .frame import pair_frame, smallest_rotation
from .narrow import Approach, _smoothing, _stencil, closest_approach
from .window import Lattice, carry_field, ring, union, window_around, window_gap

__all__ = ["HALF_SPACE_LIMIT", "HalfSpaceWarning", "PairContact", "solve_contact"]

#: A spot of a contact that is a minimum of the gap of its own, faces away from the contact's
#: normal by more than SPLIT_TILT (rad) and lies more than SPLIT_DISTANCE contact radii (the
#: larger spot's) from its closest points is handed on as a contact of its own
#: (:attr:`PairContact.facing`). Kept in the deepest spot's frame, such a spot's force is taken
#: along the wrong normal (friction carries tan(tilt) of it), and a pair touching on two equal
#: bumps flips its frame from one to the other as the bodies move: a sphere of 8 mm on a
#: potato's two bumps (normals 4.4° apart) found no equilibrium so, nor one of 30 mm (1.2°);
#: split, 8 and 18 passes (tests/test_network_spot_tilt.py). Split, the spots lose their
#: elastic coupling, about 4a/(3πd) of the approach for spots d apart (a point load's far
#: field, Johnson 1985 §3.2): 0.1 at 4 radii.
SPLIT_TILT = 1e-3
SPLIT_DISTANCE = 4.0

#: contact radius / smallest radius of curvature beyond which a HalfSpaceWarning is emitted.
#: Two spheres with their exact gap depart from Hertz by about −0.1 (a/R)² in force at a given
#: approach (−9.6e-4 at a/R = 0.1, −8.9e-3 at 0.3; notes/pp_contact.md), the half-space kernel
#: neglecting terms of the same order that it cannot compute; 0.1 keeps them near 1e-3.
HALF_SPACE_LIMIT = 0.1

_ATTEMPTS = 12
_JOHNSON = ("Johnson, K. L. (1985). Contact Mechanics. Cambridge University Press: §4.2 (two "
            "bodies: relative curvature, 1/E* = Σ(1-ν²)/E), §7.2 (tangential compliance "
            "Σ(2-ν)/G of two bodies); Hertz, H. (1882). Über die Berührung fester elastischer "
            "Körper. J. reine angew. Math. 92, 156-171; Mindlin, R. D. (1949). Compliance of "
            "elastic bodies in contact. J. Appl. Mech. 16, 259-268.")


class HalfSpaceWarning(UserWarning):
    """A contact is too large against the bodies' radii of curvature for the half-space model
    (contact radius / radius of curvature above :data:`HALF_SPACE_LIMIT`)."""


@dataclass(frozen=True, eq=False)
class PairContact:
    """One solved particle-particle contact (module docstring for the sign conventions).

    Attributes
    ----------
    a, b : Body
        The two bodies, at the poses the contact was solved at.
    normal : (3,) array
        Unit common normal, world, from a to b.
    origin : (3,) array
        Contact frame origin (midpoint of the closest points), world, m.
    frame : Rotation
        World -> contact frame (n -> +z).
    grid : Grid
        The window, in contact-frame coordinates (m); cell (i, j) at (i Δ, j Δ).
    gap : (ny, nx) array
        Gap from first touch, m (+inf where no cell can touch).
    pressure : (ny, nx) array
        Contact pressure, Pa (>= 0).
    traction : (2, ny, nx) array
        Tangential traction exerted by b on a, Pa, on the frame's tangent axes.
    contact, stick : (ny, nx) bool arrays
        Cells in contact; cells that stick (none when no tangential problem was solved).
    approach : float
        Mutual approach of the bodies from first touch, m (the solved one under force control).
    separation : float
        Signed separation of the undeformed bodies at their poses, m (< 0: they overlap by
        −separation): the closest approach's, or for a faceted mesh the lowest cell's gap.
    normal_force : float
        N = Σ p ΔA, N, >= 0.
    tangential_force : (3,) array
        Σ τ ΔA on a, world, N (in the tangent plane).
    moment_a, moment_b : (3,) arrays
        Moments about each body's own centroid of the forces on it, Σ (x − c) × f ΔA over the
        cells (x on the contact plane), world, N m.
    area, stick_area : float
        Contact and stick areas, m².
    spots : int
        Separate contact spots (connected pieces of the contact, corners included, as
        :func:`thirdbody.particle.count_spots` counts them).
    pressure_centroid : (3,) array
        World point of the contact plane at the pressure centroid, m.
    contact_radius : float
        √(A/π) with A the area of the largest spot, m.
    radii_a, radii_b : (2,) arrays
        Principal radii of curvature of a's and b's surfaces at the closest points, m, from
        their heights in the contact frame (> 0 convex, < 0 concave, inf flat).
    curvature_radius : float
        The smallest |radius| of both, m.
    half_space_ratio : float
        contact_radius / curvature_radius.
    spot_tilt : float
        The largest angle between a spot's own common normal and :attr:`normal`, rad (0 for one
        spot). Every spot is solved in the deepest one's frame, so a spot that faces elsewhere
        (a non-convex body touching on two bumps) has its force taken along the wrong normal,
        and friction carries the difference, about N tan(spot_tilt); past tan = the half-space
        limit a :class:`HalfSpaceWarning` is emitted.
    shift : (2,) array
        Accumulated rigid tangential displacement of b relative to a, frame components, m.
    shift_increment : (3,) array
        The step's increment of the shift, world, m (zero without a tangential problem).
    slip : (3,) array
        Mean slip increment of b over a in the step over the slipping cells, world, m (zero
        when no cell slips).
    twist_moment : float
        Moment about the normal through the pressure centroid of the tractions on a, N m.
    curvature_a, curvature_b : (2, 2) arrays
        Curvature tensors (1/m, > 0 convex) of a's and b's surfaces at the closest points on the
        frame's tangent axes (a's upper surface is −½ ξᵀK_aξ, b's lower one ½ ξᵀK_bξ).
    twist : float
        Accumulated rotation of b relative to a about the normal, rad (counter-clockwise seen
        from b), from the bodies' spins between solves.
    mu : float
        Friction coefficient.
    normal_solution : NormalContact
    tangential_solution : TangentialContact or None
    closest : Approach
        The narrow phase's result.
    facing : tuple of Approach
        The local closest approaches of the spots that are contacts of their own: separate
        minima of the gap facing away from :attr:`normal` by more than :data:`SPLIT_TILT` and
        farther than :data:`SPLIT_DISTANCE` contact radii from the closest points. A cluster
        splits the pair there into one contact per spot (``others`` of
        :func:`solve_contact`).
    methods : tuple of str
        Published methods behind the result (:func:`thirdbody.citations`).
    """

    a: Body
    b: Body
    normal: np.ndarray
    origin: np.ndarray
    frame: Rotation
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
    moment_a: np.ndarray
    moment_b: np.ndarray
    area: float
    stick_area: float
    spots: int
    pressure_centroid: np.ndarray
    contact_radius: float
    radii_a: np.ndarray
    radii_b: np.ndarray
    curvature_radius: float
    half_space_ratio: float
    spot_tilt: float
    shift: np.ndarray
    shift_increment: np.ndarray
    slip: np.ndarray
    twist_moment: float
    curvature_a: np.ndarray
    curvature_b: np.ndarray
    twist: float
    mu: float
    normal_solution: NormalContact = field(repr=False)
    tangential_solution: TangentialContact | None = field(repr=False)
    closest: Approach = field(repr=False)
    methods: tuple[str, ...] = ()
    facing: tuple[Approach, ...] = field(default=(), repr=False)

    @property
    def tangent_axes(self) -> np.ndarray:
        """(2, 3) world unit vectors t₁, t₂ of the frame's x and y axes (t₁ × t₂ = n)."""
        return self.frame.inv().apply(np.eye(3)[:2])

    @property
    def force_on_a(self) -> np.ndarray:
        """Total force on a, world, N: −N n + the tangential force."""
        return -self.normal_force * self.normal + self.tangential_force

    @property
    def force_on_b(self) -> np.ndarray:
        """Total force on b, world, N: exactly −:attr:`force_on_a`."""
        return -self.force_on_a

    @property
    def peak_pressure(self) -> float:
        """Largest cell pressure, Pa."""
        return float(self.pressure.max())

    @property
    def shift_world(self) -> np.ndarray:
        """:attr:`shift` as a world vector (in the tangent plane), m."""
        return self.shift @ self.tangent_axes

    def cell_positions(self) -> np.ndarray:
        """World positions (ny, nx, 3) of the cell centres on the contact plane, m."""
        X, Y = self.grid.mesh()
        t1, t2 = self.tangent_axes
        return self.origin + X[..., None] * t1 + Y[..., None] * t2


def _vector3(value, name: str) -> np.ndarray:
    try:
        v = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        v = np.full(0, np.nan)
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ValueError(f"{name} must be a finite world 3-vector, got {value!r}")
    return v


def _positive(value, name: str, unit: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and x > 0):
        raise ValueError(f"{name} must be a finite number > 0 {unit}, got {value!r}")
    return x


def _surfaces_at(a: Body, b: Body, frame, origin):
    """:func:`~thirdbody.network.narrow._stencil` of a's upper and b's lower surface about the
    world point ``origin`` (the frame's axes), its step shrunk until every ray meets; None if
    none does."""
    size = min(a.size, b.size)
    h = max(1e-3 * size, _smoothing(a), _smoothing(b))
    st = _stencil(a, b, frame, origin, h)
    while st is None and h > 1e-6 * size:
        h *= 0.25
        st = _stencil(a, b, frame, origin, h)
    return st


def _curvatures(a: Body, b: Body, frame, origin) -> tuple[np.ndarray, np.ndarray]:
    """Hessians (1/m) of a's upper and b's lower surface heights at the frame origin."""
    st = _surfaces_at(a, b, frame, origin)
    if st is None:
        raise RuntimeError("the surfaces could not be sampled at the closest points")
    return st[0][2], st[1][2]


def _centroid(w: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The centroid (x, y) of the cell weights ``w`` (pressures) on the cell coordinates X, Y,
    m (exact ``math.fsum`` sums)."""
    total = math.fsum(w.ravel())
    return np.array([math.fsum((w * X).ravel()) / total, math.fsum((w * Y).ravel()) / total])


def _slope_tilt(st) -> tuple[np.ndarray, float]:
    """The mean slope ½(g_a + g_b) of both surfaces in a :func:`_surfaces_at` stencil and the
    angle (rad) by which a normal of that slope is tilted from the frame's."""
    slope = 0.5 * (st[0][1] + st[1][1])
    return slope, math.atan(float(np.hypot(*slope)))


def _spot_normals(a: Body, b: Body, frame, origin, n, axes, X, Y, p, labels, spots: int,
                  counts: np.ndarray, cell_area: float) -> list[tuple[float, Approach | None,
                                                                  bool]]:
    """Each spot's angle (rad) between its own common normal and the frame's, with the local
    closest approach that gave it (or None) and whether the spot is a contact of its own
    (:data:`SPLIT_TILT`, :data:`SPLIT_DISTANCE`), the spot holding the frame origin left out.

    A spot's own normal is the common normal of the surfaces' local closest points there: the
    narrow phase's local search (``closest_approach(local=True)``) started at the spot's
    pressure centroid with the frame normal tilted by the surfaces' mean slope there
    (atan|½(g_a + g_b)|, which is the tilt itself up to the centroid's offset of a fraction of
    a cell). Where that search fails (normal not within 1e-6 rad) or ends nearer the frame
    origin than the spot, the slope's
    estimate stands (and no approach). The spot holding the closest points faces the frame
    normal by construction. A spot whose surfaces cannot be sampled is left out."""
    if spots < 2:
        return []
    home = int(labels.ravel()[int(np.argmin((X * X + Y * Y).ravel()))])
    t1, t2 = axes
    out = []
    for spot in range(1, spots + 1):
        if spot == home:
            continue
        w = np.where(labels == spot, p, 0.0)
        if not math.fsum(w.ravel()) > 0:
            continue
        xc, yc = _centroid(w, X, Y)
        point = origin + xc * t1 + yc * t2
        st = _surfaces_at(a, b, frame, point)
        if st is None:
            continue
        slope, tilt = _slope_tilt(st)
        guess = frame.inv().apply(np.array([-slope[0], -slope[1], 1.0]))
        found = closest_approach(a, b, normal=guess, near=point, local=True)
        # its normal to 1e-6 rad (a shallow pair, two flat surfaces, may not meet the search's
        # step tolerance in its iterations with the normal already found)
        if found is not None and (found.converged or found.slope < 1e-6) and \
                np.linalg.norm(found.midpoint - point) < np.linalg.norm(found.midpoint - origin):
            own = found.normal
            tilt = math.atan2(float(np.linalg.norm(np.cross(own, n))), float(own @ n))
        else:
            found = None
        radius = math.sqrt(max(counts[spot], counts[home]) * cell_area / math.pi)
        apart = found is not None and tilt > SPLIT_TILT and \
            float(np.linalg.norm(found.midpoint - origin)) > SPLIT_DISTANCE * radius
        out.append((tilt, found, apart))
    return out


def _radii(curvature: np.ndarray) -> np.ndarray:
    """Principal radii of curvature (m, signed: positive convex, inf where flat) of a
    curvature tensor (1/m)."""
    kappa = np.linalg.eigvalsh(curvature)
    with np.errstate(divide="ignore"):
        return np.where(kappa != 0, 1.0 / np.where(kappa != 0, kappa, 1.0), np.inf)


def _estimates(relative: np.ndarray, a: Body, b: Body, E_star: float,
               force: float | None, approach: float | None) -> tuple[float, float]:
    """Hertz estimates from the gap's Hessian: (contact half-width of the narrower side, m;
    an upper bound on the approach, m)."""
    lam = np.linalg.eigvalsh(relative)     # gap ≈ ½ ξᵀ H ξ
    fallback = 1.0 / min(a.shape.feature_length, b.shape.feature_length)
    lo, hi = (float(lam[0]), float(lam[1])) if lam[0] > 0 else (fallback, max(fallback, lam[1]))
    R_eff = 1.0 / math.sqrt(lo * hi)
    if force is not None:
        a_eq = (3.0 * force * R_eff / (4.0 * E_star)) ** (1.0 / 3.0)
        # a sphere as curved as the most curved direction needs the largest approach
        bound = (9.0 * force**2 * hi / (16.0 * E_star**2)) ** (1.0 / 3.0)
    else:
        a_eq = math.sqrt(approach * R_eff)
        bound = approach
    narrow = a_eq * (lo / hi) ** (1.0 / 3.0)
    return narrow, bound


@cites("johnson1985_pair", _JOHNSON)
def solve_contact(a: Body, b: Body, *, mu: float, normal_force: float | None = None,
                  approach: float | None = None, tangential_force=None, shift_increment=None,
                  previous: PairContact | None = None, spacing: float | None = None,
                  cells_per_radius: float = 16.0, tol: float = 1e-8,
                  half_space_limit: float = HALF_SPACE_LIMIT, closest: Approach | None = None,
                  warm: PairContact | None = None, others=()) -> PairContact | None:
    """Solve the contact of bodies a and b (module docstring).

    Parameters
    ----------
    a, b : Body
        The bodies at their poses; the normal points from a to b.
    mu : float
        Coulomb friction coefficient of the pair, >= 0.
    normal_force : float, optional
        Force control: N > 0 (N); the approach is solved for, the poses fix the normal only.
    approach : float, optional
        Approach control: mutual approach from first touch, m, > 0. Without ``normal_force``
        and ``approach`` the approach is the poses' overlap, −separation.
    tangential_force : (3,) array, optional
        Force control of the tangential problem: the force b exerts on a, world, N; its
        component along the normal is ignored. |·| <= μN.
    shift_increment : (3,) array, optional
        Shift control: the rigid tangential displacement of b relative to a at the contact in
        this step, world, m (component along the normal ignored). Without it and without
        ``tangential_force``: the displacement of b's material point at the previous contact
        origin relative to a's, from the bodies' motion since ``previous`` (zero without
        ``previous``). With μ = 0 and neither, no tangential problem is solved.
    previous : PairContact, optional
        The last solve of this contact (same two shapes, a and b in the same roles): its
        traction, accumulated shift and twist are carried into the current frame (module
        docstring), its pressure starts the normal solve and its spacing is kept. The bodies'
        relative spin about the normal since then is added to the twist.
    spacing : float, optional
        Cell size Δ, m; default: the previous one, or the Hertz estimate of the contact's
        narrower half-width divided by ``cells_per_radius``.
    cells_per_radius : float
        Cells across that half-width when the spacing is chosen here (>= 2).
    tol : float
        Tolerance of the normal and tangential solvers.
    half_space_limit : float
        a/R beyond which a :class:`HalfSpaceWarning` is emitted.
    closest : Approach, optional
        The narrow phase's result for these poses (:func:`closest_approach`), if known.
    warm : PairContact, optional
        A recent solve of this contact (same roles) whose pressure starts the normal solve
        instead of ``previous``'s.
    others : sequence of (3,) arrays
        World points (the midpoints of the closest points) of the pair's other contacts, where
        the bodies touch facing other ways: the surfaces are split between the contacts by the
        bisecting planes of the points (:class:`~thirdbody.network.window.Lattice`), and this
        contact is solved on its own part. Give ``closest`` with them (the local approach).

    Returns
    -------
    PairContact, or None when the bodies do not touch (bounding spheres apart, or, without a
    normal force, a non-positive approach).

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    FrictionLimitError
        |tangential_force| > μN.
    ContactAtEdgeError
        The contact spreads over a body (far beyond the half-space model).
    ConvergenceError
        A solver did not converge.
    """
    if not isinstance(a, Body) or not isinstance(b, Body):
        raise TypeError("solve_contact takes two Body objects, a and b")
    try:
        mu = float(mu)
    except (TypeError, ValueError):
        mu = math.nan
    if not (math.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu (friction coefficient) must be a finite number >= 0, got {mu!r}")
    if normal_force is not None and approach is not None:
        raise ValueError("give at most one of normal_force (N) and approach (m)")
    if normal_force is not None:
        normal_force = _positive(normal_force, "normal_force", "N")
    if approach is not None:
        approach = _positive(approach, "approach", "m")
    if tangential_force is not None and shift_increment is not None:
        raise ValueError("give at most one of tangential_force (N) and shift_increment (m)")
    if tangential_force is not None:
        tangential_force = _vector3(tangential_force, "tangential_force")
    if shift_increment is not None:
        shift_increment = _vector3(shift_increment, "shift_increment")
    if previous is not None:
        if not isinstance(previous, PairContact):
            raise ValueError("previous must be a PairContact (the last solve of this contact)")
        if previous.a.shape is not a.shape or previous.b.shape is not b.shape:
            raise ValueError("previous was solved for other shapes (or a and b exchanged)")
    if spacing is not None:
        spacing = _positive(spacing, "spacing", "m")
    cells_per_radius = _positive(cells_per_radius, "cells_per_radius", "cells")
    if cells_per_radius < 2:
        raise ValueError(f"cells_per_radius must be >= 2, got {cells_per_radius!r}")
    tol = _positive(tol, "tol", "")
    half_space_limit = _positive(half_space_limit, "half_space_limit", "")

    if warm is not None and (warm.a.shape is not a.shape or warm.b.shape is not b.shape):
        raise ValueError("warm was solved for other shapes (or a and b exchanged)")
    if closest is None:
        guess = None
        if previous is not None:
            # the last normal, turned with the bodies
            guess = sum((new.rotation * old.rotation.inv()).apply(previous.normal)
                        for new, old in ((a, previous.a), (b, previous.b)))
        closest = closest_approach(a, b, normal=guess)
    if closest is None:
        return None
    delta = None
    if normal_force is None:
        delta = -closest.separation if approach is None else approach
        if not delta > 0:
            return None
    n, origin = closest.normal, closest.midpoint
    frame = pair_frame(a, b, n)
    Ha, Hb = _curvatures(a, b, frame, origin)
    pair = ElasticPair.of(a.material, b.material)
    half_width, bound = _estimates(Hb - Ha, a, b, pair.E_star, normal_force, delta)
    if spacing is None:
        spacing = previous.grid.dx if previous is not None else half_width / cells_per_radius
    bound = 1.05 * bound + 1e-12 * spacing

    lattice = Lattice(a, b, frame, origin, closest.separation, spacing, others)
    carry = None if previous is None else _Carry.of(previous, a, b, frame, spacing)
    seed = None if carry is None else carry.pressure
    if warm is not None and warm.grid.dx == spacing:
        seed = _Carry.of(warm, a, b, frame, spacing).pressure
    faceted = _smoothing(a) > 0 or _smoothing(b) > 0
    normal = _solve_normal(lattice, pair, normal_force, delta, bound, tol,
                           None if carry is None else carry.support, seed,
                           faceted=faceted, from_poses=normal_force is None and approach is None)
    if normal is None:
        return None
    grid = normal.grid
    _check_extent(normal, a, b)

    tangential = None
    twist = 0.0 if carry is None else carry.twist
    if mu > 0 or tangential_force is not None or shift_increment is not None:
        prev_step = None if carry is None else carry.step(grid)
        prev_shift = np.zeros(2) if prev_step is None else prev_step.shift
        if tangential_force is not None:
            load = {"force": frame.apply(tangential_force)[:2]}
        elif shift_increment is not None:
            load = {"shift": prev_shift + frame.apply(shift_increment)[:2]}
        else:
            load = {"shift": prev_shift + (np.zeros(2) if carry is None else carry.shift)}
        tangential = solve_tangential(normal, mu, previous=prev_step, tol=tol, twist=twist,
                                      twist_centre=(0.0, 0.0), **load)
        increment = np.asarray(tangential.shift, dtype=float) - prev_shift
    else:
        increment = np.zeros(2)
    return _result(a, b, closest, lattice.zero, frame, origin, n, normal, tangential, Ha, Hb,
                   mu, twist, half_space_limit, increment)


@dataclass(frozen=True, eq=False)
class _Carry:
    """What a previous solve hands to the next one, seen from the new frame.

    angle : where the old frame's tangent axes went, in the new frame's axes (rad): the old
        axes turned about the old normal by the bodies' mean twist (swing-twist decomposition of
        each body's rotation since then), then carried to the new normal by the smallest
        rotation. A field point p of the old frame (relative to the old origin) sits at
        Rot(angle) p in the new one (relative to the new origin).
    twist : the previous twist plus the twist of b's rotation minus a's (rad).
    shift : the rigid tangential displacement (m, new frame) of b's material point at the old
        origin relative to a's, from the bodies' motion.
    """

    previous: PairContact
    angle: float
    twist: float
    shift: np.ndarray
    support: Window | None
    pressure: tuple[Window, np.ndarray]

    @classmethod
    def of(cls, previous: PairContact, a: Body, b: Body, frame, spacing: float) -> _Carry:
        t1_old = previous.frame.inv().apply([1.0, 0.0, 0.0])
        n_old = previous.normal
        n_new = frame.inv().apply([0.0, 0.0, 1.0])
        spins = []
        moved = []
        for new, old in ((a, previous.a), (b, previous.b)):
            turn = new.rotation * old.rotation.inv()
            spins.append(_twist_angle(turn, n_old))
            moved.append(turn.apply(previous.origin - old.centre) + new.centre)
        relative = math.remainder(spins[1] - spins[0], 2.0 * math.pi)
        mean_spin = Rotation.from_rotvec((spins[0] + 0.5 * relative) * n_old)
        u = frame.apply(smallest_rotation(n_old, n_new).apply(mean_spin.apply(t1_old)))
        angle = math.atan2(u[1], u[0])
        twist = (0.0 if previous.tangential_solution is None
                 else float(previous.tangential_solution.twist)) + relative
        shift = frame.apply(moved[1] - moved[0])[:2]
        # the new lattice cells that cover the cells the history occupies (its pressure and
        # traction; the whole previous window, margin included, would grow the next window by
        # its margin every step)
        old = previous.grid
        fields = [previous.pressure]
        if previous.tangential_solution is not None:
            fields.append(previous.tangential_solution.traction)
        live = np.zeros(previous.pressure.shape, dtype=bool)
        for f in fields:
            live |= (np.asarray(f) != 0).reshape(-1, *live.shape).any(axis=0)
        if not live.any():
            live[:] = True
        rows, cols = np.flatnonzero(live.any(axis=1)), np.flatnonzero(live.any(axis=0))
        xs, ys = (old.x[cols[0]], old.x[cols[-1]]), (old.y[rows[0]], old.y[rows[-1]])
        corners = np.array([[x, y] for x in xs for y in ys])
        c, s = math.cos(angle), math.sin(angle)
        q = corners @ np.array([[c, s], [-s, c]])
        i0, i1 = (math.floor(q[:, 0].min() / spacing) - 1, math.ceil(q[:, 0].max() / spacing) + 1)
        j0, j1 = (math.floor(q[:, 1].min() / spacing) - 1, math.ceil(q[:, 1].max() / spacing) + 1)
        window = Window(i0, j0, i1 - i0 + 1, j1 - j0 + 1)
        pressure = carry_field(previous.pressure, old, window.grid(spacing), angle, np.zeros(2),
                               vector=False)
        support = window if previous.tangential_solution is not None else None
        return cls(previous, angle, twist, shift, support, (window, pressure))

    def step(self, grid: Grid) -> TangentialContact | None:
        """The previous tangential step with its traction and shift in the new frame, on
        ``grid`` (the ``previous`` of :func:`~thirdbody.bem.solve_tangential`)."""
        step = self.previous.tangential_solution
        if step is None:
            return None
        c, s = math.cos(self.angle), math.sin(self.angle)
        shift = np.array([c * step.shift[0] - s * step.shift[1],
                          s * step.shift[0] + c * step.shift[1]])
        traction = carry_field(step.traction, self.previous.grid, grid, self.angle,
                               np.zeros(2), vector=True)
        return replace(step, traction=traction, shift=shift)


def _twist_angle(rotation: Rotation, axis: np.ndarray) -> float:
    """The twist of ``rotation`` about the unit ``axis`` in its swing-twist decomposition
    (rotation = swing · twist, the swing about an axis ⟂ ``axis``), rad in (−π, π]."""
    x, y, z, w = rotation.as_quat()
    return math.remainder(2.0 * math.atan2(float(np.dot([x, y, z], axis)), w), 2.0 * math.pi)


def _solve_normal(lattice: Lattice, pair: ElasticPair, force: float | None,
                  delta: float | None, bound: float, tol: float,
                  history: Window | None, warm: tuple[Window, np.ndarray] | None,
                  faceted: bool = False, from_poses: bool = False) -> NormalContact | None:
    """The normal solve on a window holding every cell that can touch (see
    :mod:`~thirdbody.network.window`): grows the bound or the evaluated cells until the
    approach is below the bound and no cell next to the evaluated ones is below the approach.
    None under approach control when no cell of the window reaches the approach (an overlap
    thinner than the lattice resolves).

    A cell below the closest approach means the narrow phase missed a deeper minimum, an error
    for smooth shapes. A faceted mesh's closest approach comes from a smoothed surface (its
    stencil spans several facets), so its first touch is moved to the lowest cell instead: the
    lattice's zero level drops, and an approach taken from the poses grows with it."""
    extra = None
    for _ in range(_ATTEMPTS):
        corner, mask = lattice.candidates(bound)
        if extra is not None:
            corner, mask = union((corner, mask), extra)
        jj, ii = np.nonzero(mask)
        g = np.full(mask.shape, np.inf)
        g[jj, ii] = lattice.gap(ii + corner[0], jj + corner[1])
        below = g < bound
        if not below.any() and force is None and float(g.min()) >= delta:
            return None         # an overlap thinner than the lattice resolves: no contact
        if not below.any():
            raise RuntimeError("no cell of the contact frame lies below the approach bound: "
                               "the closest approach is inconsistent with the lattice")
        floor = float(g.min())
        if floor < -1e-9 * lattice.spacing - 1e-12 * abs(lattice.zero):
            if not faceted:
                jf, i_f = np.unravel_index(int(np.argmin(g)), g.shape)
                raise RuntimeError(f"a cell lies {-floor:.3g} m below the closest approach: "
                                   + _deeper_cell(lattice, i_f + corner[0], jf + corner[1]))
            lattice.lower_zero(-floor)
            if from_poses:
                delta -= floor
            bound -= floor
            continue
        window = window_around(below, corner, history)
        gap = window_gap(lattice, window, corner, mask)
        grid = window.grid(lattice.spacing)
        if force is None and delta <= float(np.min(gap)):
            # the bodies overlap by less than the lattice resolves (its cells sample the
            # surfaces beside the exact closest points): no cell touches, no contact
            return None
        initial = None
        if warm is not None:
            initial = remap(warm[1], warm[0], window)
            if not initial.any():
                initial = None
        try:
            normal = solve_normal(gap, grid, pair, force=force, approach=delta, tol=tol,
                                  initial=initial)
        except ContactAtEdgeError:
            # the contact outgrew the cells below the bound: the bound was too small
            bound *= 2.0
            continue
        warm = (window, normal.pressure)
        found = normal.approach
        if found >= bound:
            bound = max(2.0 * bound, 1.5 * found)
            continue
        # cells next to the evaluated ones must not lie below the approach
        rc, rmask = ring(corner, mask)
        rj, ri = np.nonzero(rmask)
        low = lattice.gap(ri + rc[0], rj + rc[1]) <= found
        if low.any():
            add = np.zeros_like(rmask)
            add[rj[low], ri[low]] = True
            grown = union(ring(rc, add, width=lattice.stride), (rc, add))
            extra = grown if extra is None else union(extra, grown)
            continue
        return normal
    raise RuntimeError("the contact window did not settle")   # pragma: no cover


def _deeper_cell(lattice: Lattice, i: int, j: int) -> str:
    """Why cell (i, j) of the lattice lies below the closest approach: a spot that faces away
    from the contact's normal (two bumps of a non-convex body, each overlapping the other body,
    one of them deeper along the frame's rays than along its own normal), or else a deeper
    minimum of the gap that the narrow phase missed."""
    t1, t2 = lattice.frame.inv().apply(np.eye(3)[:2])
    point = lattice.origin + lattice.spacing * (i * t1 + j * t2)
    st = _surfaces_at(lattice.a, lattice.b, lattice.frame, point)
    if st is not None:
        tilt = math.degrees(_slope_tilt(st)[1])
        if tilt > 1.0:
            return (f"there the surfaces face {tilt:.3g}° away from the contact's normal, a "
                    f"second spot of a non-convex pair that one contact frame cannot hold "
                    f"(solve_cluster solves such a spot as a contact of its own)")
    return "the narrow phase missed a deeper minimum of the gap"


def _check_extent(normal: NormalContact, a: Body, b: Body) -> None:
    rows = np.flatnonzero(normal.contact.any(axis=1))
    cols = np.flatnonzero(normal.contact.any(axis=0))
    extent = max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1) * normal.grid.dx
    size = min(a.size, b.size)
    if extent > 1.5 * size:
        raise ContactAtEdgeError(
            f"the contact spreads over a body ({extent:.3g} m across, smaller body size "
            f"{size:.3g} m): far beyond the half-space model's range")


def _fsum(values: np.ndarray) -> np.ndarray:
    """Order-independent sums over the cells of a (ny, nx, 3) field."""
    flat = values.reshape(-1, 3)
    return np.array([math.fsum(flat[:, k]) for k in range(3)])


def _result(a, b, closest, separation, frame, origin, n, normal, tangential, Ha, Hb, mu, twist,
            limit, increment) -> PairContact:
    grid = normal.grid
    dA = grid.cell_area
    p = normal.pressure
    tau = np.zeros((2, *grid.shape)) if tangential is None else tangential.traction
    t1, t2 = frame.inv().apply(np.eye(3)[:2])
    X, Y = grid.mesh()
    cells = origin + X[..., None] * t1 + Y[..., None] * t2
    traction_world = tau[0][..., None] * t1 + tau[1][..., None] * t2
    on_a = (-p[..., None] * n + traction_world) * dA
    moment_a = _fsum(np.cross(cells - a.centre, on_a))
    moment_b = _fsum(np.cross(cells - b.centre, -on_a))
    force_n = math.fsum(p.ravel()) * dA
    tangential_force = _fsum(traction_world * dA)
    xc, yc = _centroid(p, X, Y)
    area = normal.area
    labels, spots = ndimage.label(normal.contact, structure=np.ones((3, 3), dtype=bool))
    counts = np.bincount(labels.ravel())
    radius = math.sqrt(int(counts[1:].max()) * dA / math.pi)
    radii_a, radii_b = _radii(-Ha), _radii(Hb)
    curvature = float(np.abs(np.concatenate([radii_a, radii_b])).min())
    ratio = radius / curvature
    if ratio > limit:
        warnings.warn(HalfSpaceWarning(
            f"contact radius / radius of curvature = {ratio:.3g} > {limit:.3g}: the half-space "
            f"model of the contact is out of its range (a = {radius:.3g} m, R = "
            f"{curvature:.3g} m)"), stacklevel=3)
    normals = _spot_normals(a, b, frame, origin, n, (t1, t2), X, Y, p, labels, spots, counts,
                            dA)
    tilt = max((t for t, _, _ in normals), default=0.0)
    facing = tuple(found for _, found, apart in normals if apart)
    if math.tan(tilt) > limit:
        warnings.warn(HalfSpaceWarning(
            f"a spot of the contact faces {math.degrees(tilt):.3g}° away from its normal "
            f"(tan = {math.tan(tilt):.3g} > {limit:.3g}): its force is taken along the "
            f"contact's normal, and friction carries the difference"), stacklevel=3)
    stick = np.zeros(grid.shape, dtype=bool) if tangential is None else tangential.stick
    slip = np.zeros(3)
    if tangential is not None and tangential.slip.any():
        inc = tangential.slip_increment[:, tangential.slip]
        slip = (math.fsum(inc[0]) * t1 + math.fsum(inc[1]) * t2) / inc.shape[1]
    twist_moment = math.fsum((((X - xc) * tau[1] - (Y - yc) * tau[0]) * dA).ravel())
    methods = normal.methods + (() if tangential is None else tangential.methods) + \
        ("johnson1985_pair",)
    return PairContact(
        a=a, b=b, normal=n, origin=origin, frame=frame, grid=grid, gap=normal.gap,
        pressure=p, traction=tau, contact=normal.contact, stick=stick,
        approach=float(normal.approach), separation=float(separation),
        normal_force=force_n, tangential_force=tangential_force, moment_a=moment_a,
        moment_b=moment_b, area=area,
        stick_area=0.0 if tangential is None else tangential.stick_area,
        spots=int(spots),
        pressure_centroid=origin + xc * t1 + yc * t2, contact_radius=radius,
        radii_a=radii_a, radii_b=radii_b, curvature_radius=curvature,
        half_space_ratio=ratio, spot_tilt=tilt, facing=facing,
        shift=np.zeros(2) if tangential is None else np.asarray(tangential.shift, dtype=float),
        shift_increment=increment[0] * t1 + increment[1] * t2, slip=slip,
        twist_moment=twist_moment, curvature_a=-Ha, curvature_b=Hb, twist=twist, mu=mu,
        normal_solution=normal, tangential_solution=tangential, closest=closest,
        methods=tuple(dict.fromkeys(methods)))
