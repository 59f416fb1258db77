"""Equilibrium of a cluster of touching particles between the plates (docs/methods/design.md
§3c, issue 25; the method and its validation: docs/methods/network.md).

Given the particles' poses at the start of a load step, their contact histories and the plates'
load (a prescribed gap h, or a prescribed normal force F_N on the upper plate with h unknown),
:func:`solve_cluster` finds every particle's pose (centroid and rotation) at which the
resolved tractions of its contacts balance in force and moment.

**Method: an implicit Newton iteration over all poses, with the BEM as the residual and a
model of each contact as the tangent.** One iteration:

1. *Contacts at the current poses.* Plates: every particle that reaches a plate
   (:func:`~thirdbody.network.plate.solve_plate`, approach from the pose). Pairs: the broad
   phase (:func:`~thirdbody.network.candidate_pairs` over the bounding spheres grown by a
   quarter of the size, periodic in x and y if a box is given), the narrow phase
   (:func:`~thirdbody.network.closest_approach`); pairs that overlap are solved in approach
   control (:func:`~thirdbody.network.solve_contact`), the others are open contacts with their
   separation (that of the bounding spheres when these are apart). A pair that touches on
   spots facing different ways (a non-convex particle: a sphere on two bumps) is split into
   one contact per spot, each with its own closest points, frame, history and model, when a
   spot is a minimum of the gap of its own, faces away from the contact's normal and lies
   apart from it (:attr:`~thirdbody.network.PairContact.facing`,
   :data:`~thirdbody.network.contact.SPLIT_TILT`): keys ``(k, m, image)`` and
   ``(k, m, image, s)``, s = 1, 2, ...; each is found again by a local search from its last
   solve, and the surfaces are shared out by the bisecting planes of their closest points
   (``others`` of :func:`~thirdbody.network.solve_contact`). The tangential problem
   of each contact is one increment from its history at the start of the step (or from zero
   for a new contact) under the shift increment of the bodies' rigid motion since then
   (midpoint rule, :mod:`~thirdbody.network.plate`); a contact that closed during the step sees
   the share of the motion after it closed, −σ/(σ₀ − σ) by linear interpolation of its
   separation (σ₀ > 0 at the start, σ < 0 now).
2. *Residuals from the resolved tractions*: each particle's force and moment about its
   centroid, summed over its contacts from the cell fields (``math.fsum``), and under force
   control Σ N_upper − F_N.
3. *Converged* when every particle's force residual is below ``tol`` times the force scale
   (the mean normal force of the cluster's contacts), its moment residual below ``tol`` times
   the force scale times its size, and the plate force within ``tol`` F_N. Then the result is
   returned; otherwise:
4. *Newton step* on the tangent of :class:`~thirdbody.network.stiffness.ContactModel`: normal
   stiffness 3N/(2δ), Mindlin's partial-slip tangential stiffness reduced by the stick zone, μN
   along the slip of a sliding contact, Lubkin's torsion, and the rigid geometry (contact points
   migrating over the curved surfaces, normals turning). Rolling modes have no contact
   stiffness: the geometry alone drives them, as the one-particle turn is driven by the moment
   its pressure centroids leave. Open contacts act as springs once the step closes them (one
   closer than its Hertz approach at the force scale starts closed). Each contact's branch
   (stick or slide, open or closed) follows the predicted motion, in passes until it settles;
   a sliding contact starts on its stick branch, from which the step can reverse its slip
   (on the slide branch it has no stiffness along the slip, and a particle that must roll back
   would see a singular model). That branch is the elastic predictor from the start of the
   step, T + k₀ (ds + s) with s the contact's slip in the step: the BEM solves the step as one
   increment, so a contact that slid keeps μN until the motion has taken its slip back. Each
   pass must lower the merit of the piecewise-linear model at the branches of its own step,
   else the step is halved towards the last pass's (undamped, the passes cycle between a
   saturated contact's plateau and beyond it). The linear system is solved per connected
   component of the particle-particle contacts (the plate gap, under force control, by a Schur
   complement), by a truncated pseudo-inverse (singular values below 1e-9 of the largest
   dropped): modes without any stiffness (a particle that touches nothing, the free
   translation of a particle sliding on both plates) do not move, and a residual the model
   cannot change asks for no step along them: the minimum-norm least-squares step. (A shifted
   diagonal answered such a residual with the residual over the shift: a 600 m move of a
   sphere sliding on both plates, which the trust region's common factor turned into a step
   of nothing for every particle.)
5. *Trust region.* The step is scaled as a whole so that no particle turns by more than 0.05 ρ
   rad or moves by more than 0.05 ρ of its size, and no contact's normal force changes by more
   than ρ times itself (or the force scale). The trial poses are evaluated (step 1-2); the step
   is accepted if the sum of squared scaled residuals fell, and ρ doubles when the model
   predicted the fall well (the piecewise model's, at the scaled step), halves when it did
   not; a rejected step (or one at which a contact solve failed) quarters ρ and is retried from
   the same state. A step of zero (the model sees no way down) ends the attempt.
6. *Two phases.* Far from equilibrium a step first moves the particles without turning them
   (:func:`_iterate`). When that leads to a state the full iteration does not leave (its
   residual stalls), the step is solved again from its start without that phase.

All particles move together in every iteration, from one consistent state: identical particles
in identical situations stay identical. The particles are processed in a canonical order (by
their centroids at the start of the step) and every sum over particles or contacts is an exact
``math.fsum``, so the result does not depend on the numbering (bit for bit; tested in
``tests/test_network_cluster.py``). A solve that does not converge raises
:class:`ClusterConvergenceError` naming the residual; a wrong answer is never returned.

A periodic box (L_x, L_y) makes x and y periodic: contacts act across the sides between a
particle and the nearest image of the other. Centres are not wrapped into the box here (a
contact's key holds the image; :func:`wrap` moves centres into the box and renames the keys).

Conventions as in :mod:`~thirdbody.network.contact` and :mod:`~thirdbody.network.plate`: SI
units, world frame, the lower plate at z = 0 and the upper one at z = h.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.linalg import lapack
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..bem import ContactAtEdgeError, ConvergenceError, ElasticPair
from ..material import Material
from ..orientation import Rotation
from .body import Body
from .broad import candidate_pairs
from .contact import HALF_SPACE_LIMIT, HalfSpaceWarning, PairContact, solve_contact
from .narrow import closest_approach
from .plate import PlateContact, cell_separation, solve_plate
from .stiffness import ContactModel, ModelStack, TangentialLaws, cross, cross_rows

__all__ = ["ClusterConvergenceError", "ClusterNumerics", "ClusterResult", "ContactHistory",
           "ContactReport", "solve_cluster", "wrap"]

PLATES = ("lower", "upper")
#: the broad phase looks this share of a particle's size beyond its bounding sphere
_REACH = 0.25
KINEMATICS = ("free", "stick", "roll", "slide")


class ClusterConvergenceError(ConvergenceError):
    """The equilibrium of a cluster was not found (the message names the residual)."""


@dataclass(frozen=True)
class ClusterNumerics:
    """Numerical settings of :func:`solve_cluster`.

    Attributes
    ----------
    cell_size : float or sequence of float, optional
        BEM cell size Δ per particle, m (a pair uses the smaller of its two); default
        ``size / resolution``.
    resolution : float
        Cells per particle size (bounding radius) when ``cell_size`` is not given.
    tol : float
        Equilibrium tolerance: force residuals relative to the force scale (the mean normal
        force of the contacts), moment residuals relative to it times the particle's size, the
        plate force relative to F_N.
    solver_tol : float
        Tolerance of the BEM normal and tangential solvers.
    max_iterations : int
        Evaluations (BEM passes) allowed.
    radius : float
        Initial trust radius ρ: per iteration a particle turns by at most 0.05 ρ rad and moves
        by at most 0.05 ρ of its size, and a contact's normal force changes by at most ρ times
        itself (or the force scale if larger).
    min_radius : float
        The iteration gives up when ρ falls below this.
    stick_rotation : float
        A particle whose contacts all have stick cells sticks if it turned by less than this in
        the step (rad); otherwise it rolls.
    half_space_limit : float
        a/R of a contact beyond which a :class:`HalfSpaceWarning` is emitted (final contacts).
    """

    cell_size: float | Sequence[float] | None = None
    resolution: float = 160.0
    tol: float = 1e-6
    solver_tol: float = 1e-8
    max_iterations: int = 80
    radius: float = 1.0
    min_radius: float = 1e-8
    stick_rotation: float = 1e-3
    half_space_limit: float = HALF_SPACE_LIMIT

    def __post_init__(self) -> None:
        for name in ("resolution", "tol", "solver_tol", "radius", "min_radius",
                     "stick_rotation", "half_space_limit"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and not isinstance(value, bool)
                    and math.isfinite(value) and value > 0):
                raise ValueError(f"ClusterNumerics.{name} must be a finite number > 0, got "
                                 f"{value!r}")
        if not (isinstance(self.max_iterations, int) and not isinstance(self.max_iterations, bool)
                and self.max_iterations >= 1):
            raise ValueError(f"ClusterNumerics.max_iterations must be an integer >= 1, got "
                             f"{self.max_iterations!r}")

    def cells(self, bodies: Sequence[Body]) -> list[float]:
        if self.cell_size is None:
            return [b.size / self.resolution for b in bodies]
        sizes = np.atleast_1d(np.asarray(self.cell_size, dtype=float))
        if sizes.size == 1:
            sizes = np.full(len(bodies), float(sizes[0]))
        if sizes.shape != (len(bodies),) or not np.isfinite(sizes).all() or (sizes <= 0).any():
            raise ValueError(f"ClusterNumerics.cell_size must be one size or one per particle "
                             f"(> 0 m), got {self.cell_size!r}")
        return [float(s) for s in sizes]


@dataclass(frozen=True, eq=False)
class ContactHistory:
    """What a contact carries to the next step.

    Attributes
    ----------
    key : tuple
        ``(i, j, (m_x, m_y))`` for particles i < j (j's centre plus (m_x L_x, m_y L_y, 0) is the
        image that meets i), ``(i, j, (m_x, m_y), s)`` for the s-th further contact of a pair
        split into contacts facing different ways (s >= 1), or ``(i, "lower" | "upper")``.
    roles : tuple
        (index of body a, index of body b) for a pair (the solve's roles, kept while the
        contact lives); (i, side) for a plate.
    solved : PairContact or PlateContact
        The contact's last converged solve (traction, shift, twist, pressure), at the poses of
        the end of the step.
    """

    key: tuple
    roles: tuple
    solved: PairContact | PlateContact


@dataclass(frozen=True, eq=False)
class ContactReport:
    """One contact of a converged cluster, seen from particle ``i`` (SI, world frame).

    Attributes
    ----------
    key : tuple
        As :attr:`ContactHistory.key`.
    i : int
        The particle (for a pair: the smaller index).
    j : int or str
        The other particle, or "lower"/"upper".
    normal : (3,) array
        Unit normal from i to j (or the plate).
    force : (3,) array
        Force on i, N (on j: exactly −force).
    normal_force : float
        N >= 0.
    tangential_force : (3,) array
        Tangential part of ``force``, N.
    point : (3,) array
        Pressure centroid, m, beside particle i (across a periodic side: between i and the
        image of j that meets it).
    moment_i, moment_j : (3,) arrays
        Moments of the contact's tractions about i's and j's centroid (j's image), N m
        (``moment_j`` zero for a plate).
    approach : float
        Approach from first touch, m.
    area, stick_area : float
        m².
    spots : int
    slip : (3,) array
        Mean slip increment of j over i in the step over the slipping cells, m (zero if none).
    shift_increment : (3,) array
        The step's rigid tangential displacement of j relative to i at the contact, m.
    sliding : bool
        No stick cell: the contact slides (a frictionless contact always does).
    state : {"stick", "slide"}
    half_space_ratio : float
        Contact radius over the smallest radius of curvature.
    mu : float
    spot_tilt : float
        The largest angle between a spot's own normal and the contact's, rad (0 for one spot
        and for a plate: :attr:`PairContact.spot_tilt`).
    """

    key: tuple
    i: int
    j: int | str
    normal: np.ndarray
    force: np.ndarray
    normal_force: float
    tangential_force: np.ndarray
    point: np.ndarray
    moment_i: np.ndarray
    moment_j: np.ndarray
    approach: float
    area: float
    stick_area: float
    spots: int
    slip: np.ndarray
    shift_increment: np.ndarray
    sliding: bool
    state: str
    half_space_ratio: float
    mu: float
    spot_tilt: float = 0.0


@dataclass(frozen=True, eq=False)
class ClusterResult:
    """The equilibrium of a cluster at the end of a step (plain data, picklable).

    Attributes
    ----------
    bodies : tuple of Body
        The particles at their new poses, in the input order.
    translation : (n, 3) array
        Each centroid's displacement in the step, m.
    rotation : (n, 3) array
        Each particle's rotation vector of the step (R_new R_oldᵀ), rad.
    histories : dict
        The contact histories to carry to the next step (:class:`ContactHistory` by key);
        contacts that opened are dropped.
    gap : float
        Plate gap h, m.
    plate_force : (3,) array
        Total force of the upper plate on the particles, N (its z component is −F_N).
    lower_force : (3,) array
        Total force of the lower plate on the particles, N.
    contacts : tuple of ContactReport
        Every contact, sorted by key.
    force_residual, moment_residual : (n, 3) arrays
        Each particle's resultant force (N) and moment about its centroid (N m) from the
        resolved tractions.
    residual : float
        The largest scaled residual (forces / force_scale, moments / (force_scale size), the
        plate force / F_N).
    force_scale : float
        The mean normal force of the contacts, N.
    kinematics : tuple of str
        Per particle: "free" (touches nothing: left where it was, zero force), "stick" (every
        contact has stick cells and the particle turned less than ``stick_rotation``), "roll"
        (some contacts slide and others stick, or all stick while it turns), "slide" (every
        contact slides: sliding or rotating about its centroid).
    iterations : int
        BEM passes (evaluations of every contact), including those of a first attempt that
        failed (:func:`solve_cluster` then tries once more without the rotation-free phase).
    bem_solves : int
        Contact solves over all passes.
    history : tuple of (float, float, float, bool)
        Per pass of the attempt that converged: the largest scaled residual, the merit (half
        the sum of squared scaled residuals), the trust radius (rad) and whether the pass's
        step was accepted.
    timings : dict
        Wall time (s): "narrow" (broad and narrow phases), "contacts" (the BEM solves,
        including their ray casting), "newton" (models, assembly and linear solves).
    tol : float
    """

    bodies: tuple
    translation: np.ndarray
    rotation: np.ndarray
    histories: dict
    gap: float
    plate_force: np.ndarray
    lower_force: np.ndarray
    contacts: tuple
    force_residual: np.ndarray
    moment_residual: np.ndarray
    residual: float
    force_scale: float
    kinematics: tuple
    iterations: int
    bem_solves: int
    history: tuple
    timings: dict = field(default_factory=dict)
    tol: float = 0.0

    @property
    def normal_force(self) -> float:
        """F_N, the upper plate's normal force on the particles, N."""
        return float(-self.plate_force[2])

    @property
    def free(self) -> tuple[bool, ...]:
        return tuple(k == "free" for k in self.kinematics)

    def contacts_of(self, i: int) -> list[ContactReport]:
        """The contacts of particle i."""
        return [c for c in self.contacts if c.i == i or c.j == i]


# --- inputs --------------------------------------------------------------------------------
def _mu_function(mu_pp) -> Callable[[Material, Material], float]:
    if callable(mu_pp):
        return mu_pp
    if isinstance(mu_pp, Mapping):
        table = dict(mu_pp)

        def lookup(a: Material, b: Material) -> float:
            for k in ((a, b), (b, a)):
                if k in table:
                    return float(table[k])
            raise KeyError(f"mu_pp has no entry for the materials {a!r} and {b!r}")
        return lookup
    value = float(mu_pp)
    return lambda a, b: value


def _nonnegative(value, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and x >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return x


def _image(shift: np.ndarray, box) -> tuple[int, int]:
    if box is None:
        return (0, 0)
    return (round(float(shift[0]) / box[0]), round(float(shift[1]) / box[1]))


def _shift(image: tuple[int, int], box) -> np.ndarray:
    if box is None:
        return np.zeros(3)
    return np.array([image[0] * box[0], image[1] * box[1], 0.0])


# --- one evaluation of every contact ---------------------------------------------------------
@dataclass
class _Solved:
    key: tuple                      # internal key
    roles: tuple                    # internal (a, b) or (k, side)
    contact: PairContact | PlateContact
    model: ContactModel


@dataclass
class _Potential:
    """An open contact a step may close: plate or pair, its separation σ >= 0 (m), where and
    along which normal it would touch, and the contact modulus and a radius of curvature for
    its predicted stiffness."""

    roles: tuple
    sigma: float
    normal: np.ndarray
    point: np.ndarray
    centre_a: np.ndarray
    centre_b: np.ndarray
    E_star: float
    radius: float
    compliance: float               # Σ (2 − ν_i)/G_i, 1/Pa
    mu: float
    #: the shapes overlap by ``overlap`` (m) but no cell of the contact's lattice touches
    overlap: float = 0.0


@dataclass
class _Evaluation:
    centres: np.ndarray
    rotations: list
    h: float
    contacts: list
    potential: list
    forces: np.ndarray
    moments: np.ndarray
    plate_normal: float             # Σ N over the upper plate's contacts
    scale: float                    # mean normal force of the contacts (or 0)
    solves: int


class _Problem:
    """Everything fixed during one step (internal, canonical order)."""

    def __init__(self, bodies, histories, mu_up, mu_low, mu_pp, gap, force, gap_start,
                 plate_shift, box, numerics) -> None:
        self.numerics = numerics
        self.n = len(bodies)
        order = sorted(range(self.n), key=lambda i: tuple(float(v) for v in bodies[i].centre))
        self.order = order                            # internal k -> user index
        self.user_to_internal = {u: k for k, u in enumerate(order)}
        self.start = [bodies[u] for u in order]
        self.cells = [numerics.cells(bodies)[u] for u in order]
        self.sizes = np.array([b.size for b in self.start])
        # the broad phase's reach: the bounding spheres grown by _REACH of the size, so that a
        # pair about to close is known to the Newton step as an open contact (for spheres the
        # bounding sphere is the surface: without the margin a separated pair is never seen
        # until it overlaps), less in a periodic box too small for it (minimum image)
        grow = _REACH
        if box is not None:
            grow = min(grow, max(0.0, min(box) / (4.0 * float(self.sizes.max())) - 1.0))
        self.radii = self.sizes * (1.0 + grow)
        self.mu = {"lower": mu_low, "upper": mu_up}
        self.mu_pp = mu_pp
        self.box = None if box is None else (float(box[0]), float(box[1]))
        self.force = force
        self.gap = gap
        self.gap_start = gap_start
        self.plate_shift = np.zeros(3)
        self.plate_shift[:2] = plate_shift
        self.histories = {}
        for hist in histories.values():
            key, roles = self._internal(hist)
            self.histories[key] = (roles, hist.solved)
        self._start: dict = {}
        self.phase_one_used = False
        self.correction: dict = {}     # (row, column) -> (6, 6): the models' learnt error
        self.failed = (0, 0)           # passes and contact solves of an attempt that failed
        self.beyond = ""               # the last failed attempt's note beyond the contact model
        self.guessed = (0, 0)          # the same of a guess the first pass did not keep
        self.timings = {"narrow": 0.0, "contacts": 0.0, "newton": 0.0}

    # keys and roles between user and internal numbering
    def _internal(self, hist: ContactHistory):
        key = hist.key
        u2k = self.user_to_internal
        if len(key) == 2:
            if key[0] not in u2k or key[1] not in PLATES:
                raise ValueError(f"history key {key!r} names no particle of this cluster")
            return (u2k[key[0]], key[1]), (u2k[key[0]], key[1])
        i, j, image, *part = key
        if i not in u2k or j not in u2k:
            raise ValueError(f"history key {key!r} names no particle of this cluster")
        ki, kj = u2k[i], u2k[j]
        image = (int(image[0]), int(image[1]))
        if ki > kj:
            ki, kj, image = kj, ki, (-image[0], -image[1])
        roles = (u2k[hist.roles[0]], u2k[hist.roles[1]])
        return (ki, kj, image, *part), roles

    def user_key(self, key: tuple) -> tuple:
        if len(key) == 2:
            return (self.order[key[0]], key[1])
        k, m, image, *part = key
        i, j = self.order[k], self.order[m]
        if i > j:
            return (j, i, (-image[0], -image[1]), *part)
        return (i, j, image, *part)

    def body(self, k: int, centres, rotations) -> Body:
        b = self.start[k]
        return Body(b.shape, b.material, rotations[k], centres[k])

    def pair_bodies(self, key, roles, centres, rotations):
        """Bodies a and b of a pair (b at the image that meets a)."""
        second, image = key[1], key[2]
        shift = _shift(image, self.box)          # added to the second's centre
        a, b = roles
        A = self.body(a, centres, rotations)
        B = self.body(b, centres, rotations)
        if b == second:
            B = B.moved(centre=B.centre + shift)
        else:
            B = B.moved(centre=B.centre - shift)
        return A, B

    def start_contact(self, key, roles, near=None) -> tuple[float, np.ndarray | None]:
        """A contact's signed separation at the start of the step (m) and where it would touch
        then (world, m; None if unknown), for a contact without history. A split pair's
        contact (key (k, m, image, s)) is found by the local search from ``near`` (its
        approach at the current poses)."""
        hit = self._start.get(key)
        if hit is None:
            centres = np.array([b.centre for b in self.start])
            rotations = [b.rotation for b in self.start]
            if len(key) == 2:
                k, side = key
                b = self.start[k]
                if side == "lower":
                    point = b.centre + b.shape.lowest_point(b.rotation)
                    separation = float(point[2])
                    point[2] = 0.0
                else:
                    point = b.centre + b.shape.highest_point(b.rotation)
                    separation = float(self.gap_start) - float(point[2])
                    point[2] = float(self.gap_start)
                hit = (separation, point)
            else:
                A, B = self.pair_bodies(key, roles, centres, rotations)
                if len(key) == 4 and near is not None:
                    closest = closest_approach(A, B, normal=near.normal, near=near.midpoint,
                                               local=True)
                else:
                    closest = closest_approach(A, B)
                hit = ((float(np.linalg.norm(B.centre - A.centre)) - A.size - B.size, None)
                       if closest is None else (closest.separation, closest.midpoint))
            self._start[key] = hit
        return hit

    def fraction(self, key, roles, depth: float, near=None) -> float:
        """Share of the step's motion a contact without history saw (module docstring)."""
        if depth <= 0:
            return 0.0
        before = self.start_contact(key, roles, near)[0]
        if not before > 0:
            return 1.0
        return depth / (depth + before)

    def pair_mu(self, a: int, b: int) -> float:
        mu = self.mu_pp(self.start[a].material, self.start[b].material)
        return _nonnegative(mu, "mu_pp")

    # --- the contacts at some poses --------------------------------------------------------
    def evaluate(self, centres, rotations, h: float, last: dict | None) -> _Evaluation:
        numerics = self.numerics
        last = last or {}
        contacts: list[_Solved] = []
        potential: list[_Potential] = []
        solves = 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HalfSpaceWarning)
            # plates
            t0 = time.perf_counter()
            for k in range(self.n):
                body = self.body(k, centres, rotations)
                for side in PLATES:
                    key = (k, side)
                    plate = 0.0 if side == "lower" else h
                    previous = self.histories.get(key)
                    previous = None if previous is None else previous[1]
                    fraction = 1.0
                    depth, extreme = _plate_depth(body, side, h)
                    if depth <= 0:
                        potential.append(self._plate_potential(key, body, extreme, plate,
                                                               -depth))
                        continue
                    lever_start = None
                    if previous is None:
                        fraction = self.fraction(key, key, depth)
                        lever_start = self.start_contact(key, key)[1] - self.start[k].centre
                    warm = last.get(key)
                    solved = solve_plate(
                        body, side, plate=plate, mu=self.mu[side], spacing=self.cells[k],
                        previous=previous, start=self.start[k],
                        plate_shift=self.plate_shift[:2] if side == "upper" else (0.0, 0.0),
                        fraction=fraction, lever_start=lever_start, tol=numerics.solver_tol,
                        warm=None if warm is None else warm.contact,
                        half_space_limit=numerics.half_space_limit)
                    solves += 1
                    if solved is None:
                        # overlapping by less than the cells resolve: an open contact,
                        # apart by what its cells still miss (dropped, a potato resting on the
                        # lower plate at 1e-19 m had no support in the model)
                        sigma = cell_separation(body, side, plate, self.cells[k])
                        if math.isfinite(sigma):
                            potential.append(replace(self._plate_potential(
                                key, body, extreme, plate, sigma), overlap=depth))
                        continue
                    then = previous.lever if previous is not None else lever_start
                    model = _plate_model(solved).stepping(
                        mid_a=0.5 * (then + solved.lever), mid_b=np.zeros(3),
                        turn_a=(body.rotation * self.start[k].rotation.inv()).as_rotvec(),
                        turn_b=np.zeros(3), fraction=fraction)
                    contacts.append(_Solved(key, key, solved, _secant(model, solved, warm)))
            t1 = time.perf_counter()
            self.timings["contacts"] += t1 - t0
            # pairs
            pairs = candidate_pairs(centres, self.radii, self.box) if self.n > 1 else []
            split = self._parts(last)
            todo = []
            for k, m, shift in pairs:
                key = (k, m, _image(shift, self.box))
                parts = split.get(key, ())
                hist = self.histories.get(key)
                roles = (k, m) if hist is None else hist[0]
                if hist is None and parts:
                    roles = self._part_roles(parts[0], last)
                A, B = self.pair_bodies(key, roles, centres, rotations)
                guess = near = None
                warm = last.get(key)
                if warm is not None:
                    # the last pass's closest points, moved with the bodies, start the search
                    guess, near = _moved_point(warm.contact, A, B)
                elif hist is not None:
                    old = hist[1]
                    guess = sum((new.rotation * prev.rotation.inv()).apply(old.normal)
                                for new, prev in ((A, old.a), (B, old.b)))
                if parts:
                    # a pair split into contacts facing different ways: each keeps its own
                    # minimum of the gap (a scan would find the deepest for every one); the
                    # pair's first contact, if it opened, is looked for anew (the deepest)
                    if near is None and hist is not None:
                        near = _moved_point(hist[1], A, B)[1]
                    closest = closest_approach(A, B, normal=guess, near=near,
                                               local=near is not None)
                    todo.append((key, roles, hist, A, B, closest, warm, parts))
                    continue
                closest = closest_approach(A, B, normal=guess, near=near)
                if closest is None:
                    d = B.centre - A.centre
                    distance = float(np.linalg.norm(d))
                    sigma = distance - A.size - B.size
                    if not sigma > 0:
                        continue
                    # bounding spheres apart: the separation is at least their gap (exactly it
                    # for spheres), along the line of the centres
                    n = d / distance
                    potential.append(self._pair_potential(
                        roles, A, B, sigma, n, A.centre + (A.size + 0.5 * sigma) * n))
                    continue
                if not closest.separation < 0:
                    potential.append(self._pair_potential(
                        roles, A, B, closest.separation, closest.normal, closest.midpoint))
                    continue
                todo.append((key, roles, hist, A, B, closest, warm, ()))
            t2 = time.perf_counter()
            self.timings["narrow"] += t2 - t1
            for key, roles, hist, A, B, closest, warm, parts in todo:
                members = []            # (key, closest approach, history or None, warm or None)
                opened = []             # (key, approach) of the pair's contacts now open
                for part in parts:
                    found = self._part_approach(part, A, B, last)
                    if found is not None and found.separation < 0:
                        old = self.histories.get(part)
                        members.append((part, found, None if old is None else old[1],
                                        last.get(part)))
                    elif found is not None:
                        opened.append((part, found))
                if closest is not None and closest.separation < 0:
                    # first, unless it was found anew: then a known contact at the same place
                    # keeps its key and history
                    first = hist is not None or warm is not None
                    members.insert(0 if first else len(members),
                                   (key, closest, None if hist is None else hist[1], warm))
                elif closest is not None:
                    opened.insert(0, (key, closest))
                members = _distinct(members, min(A.size, B.size))
                # each contact of a split pair that opened stays known to the Newton step as
                # an open contact at its own minimum of the gap (once, and not where a closed
                # one lies), as an unsplit pair's open contact does
                for _, c in _distinct(opened, min(A.size, B.size),
                                      [c for _, c, _, _ in members]):
                    potential.append(self._pair_potential(roles, A, B, c.separation, c.normal,
                                                          c.midpoint))
                count = 1 + max((p[3] for p in parts), default=0)
                for _ in range(_SPLIT_ROUNDS):
                    points = [c.midpoint for _, c, _, _ in members]
                    done = []
                    for i, (mkey, mclosest, mhist, mwarm) in enumerate(members):
                        out = self._solve_pair(mkey, roles, A, B, mclosest, mhist, mwarm,
                                               points[:i] + points[i + 1:])
                        solves += 1
                        if out is not None:
                            done.append(out)
                    # spots of a contact that are minima of the gap of their own, facing away
                    # from it and apart from it (PairContact.facing), become contacts of
                    # their own (keys (k, m, image, s)), and the pair is solved again on its
                    # shares
                    new = [f for d in done for f in d.contact.facing]
                    new = _distinct([(None, f, None, None) for f in new], min(A.size, B.size),
                                    [c for _, c, _, _ in members])
                    if not new:
                        break
                    for _, f, _, _ in new:
                        members.append(((*key, count), f, None, None))
                        count += 1
                contacts.extend(done)
            self.timings["contacts"] += time.perf_counter() - t2
        forces, moments = self._sums(contacts)
        upper = [c.contact.normal_force for c in contacts if c.key[-1] == "upper"]
        normals = [c.contact.normal_force for c in contacts]
        scale = math.fsum(normals) / len(normals) if normals else 0.0
        return _Evaluation(np.array(centres, dtype=float), list(rotations), h, contacts,
                           potential, forces, moments, math.fsum(upper), scale, solves)

    def _plate_potential(self, key, body: Body, extreme, plate: float,
                         sigma: float) -> _Potential:
        """The open contact ``key`` of ``body`` with a plate at height ``plate`` (m): its
        extreme point ``extreme`` (from the centre) under the plate, separation ``sigma``."""
        point = body.centre + extreme
        point[2] = plate
        mat = body.material
        side = key[1]
        return _Potential(key, sigma, np.array([0.0, 0.0, -1.0 if side == "lower" else 1.0]),
                          point, body.centre, point, mat.E_star, body.shape.feature_length,
                          (2.0 - mat.nu) / mat.G, self.mu[side])

    def _pair_potential(self, roles, A: Body, B: Body, sigma: float, normal, point):
        """An open pair contact, σ (m) apart along ``normal`` at ``point``: the pair's contact
        modulus, half the smaller feature length as its radius, Σ (2 − ν)/G and μ_pp."""
        ma, mb = A.material, B.material
        return _Potential(roles, sigma, normal, point, A.centre, B.centre,
                          ElasticPair.of(ma, mb).E_star,
                          0.5 * min(A.shape.feature_length, B.shape.feature_length),
                          (2.0 - ma.nu) / ma.G + (2.0 - mb.nu) / mb.G, self.pair_mu(*roles))

    def _solve_pair(self, key, roles, A, B, closest, previous, warm, others):
        """One pair contact solved at these poses (its share of the step, kinematics, the BEM
        and its model), or None when it does not touch."""
        a, b = roles
        mu = self.pair_mu(a, b)
        numerics = self.numerics
        fraction = 1.0 if previous is not None else \
            self.fraction(key, roles, -closest.separation, closest)
        kinematics = self._pair_kinematics(key, roles, A, B, closest, previous)
        shift = fraction * kinematics[0] if mu > 0 else None
        solved = solve_contact(
            A, B, mu=mu, previous=previous, spacing=min(self.cells[a], self.cells[b]),
            tol=numerics.solver_tol, closest=closest,
            warm=None if warm is None else warm.contact, shift_increment=shift,
            half_space_limit=numerics.half_space_limit, others=others)
        if solved is None:
            return None
        _, mid_a, mid_b, turn_a, turn_b = kinematics
        model = _pair_model(solved, A, B, mu).stepping(
            mid_a=mid_a, mid_b=mid_b, turn_a=turn_a, turn_b=turn_b, fraction=fraction)
        return _Solved(key, roles, solved, _secant(model, solved, warm))

    def _parts(self, last: dict) -> dict:
        """The contacts a pair was split into (keys (k, m, image, s), s >= 1) that the histories
        or the last pass hold, by the pair's key (k, m, image)."""
        out: dict = {}
        for key in {*self.histories, *last}:
            if len(key) == 4:
                out.setdefault(key[:3], []).append(key)
        return {k: tuple(sorted(v, key=lambda key: key[3])) for k, v in out.items()}

    def _part_roles(self, part: tuple, last: dict) -> tuple:
        hist = self.histories.get(part)
        return hist[0] if hist is not None else last[part].roles

    def _part_approach(self, part: tuple, A: Body, B: Body, last: dict):
        """A split pair's contact: the local closest approach from its last solve (the last
        pass's, or its history's), moved with the bodies; None if the search fails."""
        warm = last.get(part)
        old = warm.contact if warm is not None else self.histories[part][1]
        guess, near = _moved_point(old, A, B)
        return closest_approach(A, B, normal=guess, near=near, local=True)

    def _pair_kinematics(self, key, roles, A, B, closest, old):
        """The step's rigid motion at a pair contact: (the shift increment of b relative to a,
        world, m, by the midpoint rule; the levers at the middle of the step from a's and b's
        centroids; a's and b's rotation vectors since the start of the step)."""
        centres0 = np.array([b.centre for b in self.start])
        rotations0 = [b.rotation for b in self.start]
        A0, B0 = self.pair_bodies(key, roles, centres0, rotations0)
        o1 = closest.midpoint
        if old is not None:
            o0 = old.origin
        else:
            o0 = self.start_contact(key, roles, closest)[1]
            o0 = o1 if o0 is None else o0
        motion, mids, turns = [], [], []
        for new, then in ((A, A0), (B, B0)):
            dc = new.centre - then.centre
            dphi = (new.rotation * then.rotation.inv()).as_rotvec()
            arm = 0.5 * ((o0 - then.centre) + (o1 - new.centre))
            motion.append(dc + cross(dphi, arm))
            mids.append(arm)
            turns.append(dphi)
        return motion[1] - motion[0], mids[0], mids[1], turns[0], turns[1]

    def _sums(self, contacts: list[_Solved]) -> tuple[np.ndarray, np.ndarray]:
        """Each particle's force and moment about its centroid from its contacts (fsum)."""
        terms_f: list[list[np.ndarray]] = [[] for _ in range(self.n)]
        terms_m: list[list[np.ndarray]] = [[] for _ in range(self.n)]
        for c in contacts:
            s = c.contact
            if isinstance(s, PlateContact):
                k = c.key[0]
                terms_f[k].append(s.force)
                terms_m[k].append(s.moment)
            else:
                a, b = c.roles
                terms_f[a].append(s.force_on_a)
                terms_m[a].append(s.moment_a)
                terms_f[b].append(s.force_on_b)
                terms_m[b].append(s.moment_b)
        forces = np.zeros((self.n, 3))
        moments = np.zeros((self.n, 3))
        for k in range(self.n):
            if terms_f[k]:
                F = np.array(terms_f[k])
                M = np.array(terms_m[k])
                forces[k] = [math.fsum(F[:, d]) for d in range(3)]
                moments[k] = [math.fsum(M[:, d]) for d in range(3)]
        return forces, moments


#: rounds of splitting a pair into contacts facing different ways in one evaluation
_SPLIT_ROUNDS = 3


def _moved_point(solved: PairContact, A: Body, B: Body) -> tuple[np.ndarray, np.ndarray]:
    """A pair contact's last normal and its closest points' midpoint moved with the bodies'
    mean translation since: where a local search for it starts."""
    return solved.normal, solved.origin + 0.5 * ((A.centre - solved.a.centre)
                                                 + (B.centre - solved.b.centre))


def _distinct(members: list, size: float, existing=()) -> list:
    """``members`` (key, approach, ...) less those whose closest points lie within 1e-3 of the
    smaller body's ``size`` of an earlier one's or of an ``existing`` approach's (two local
    searches that found the same minimum of the gap)."""
    kept: list = []
    seen = [c.midpoint for c in existing]
    for member in members:
        point = member[1].midpoint
        if all(np.linalg.norm(point - q) > 1e-3 * size for q in seen):
            kept.append(member)
            seen.append(point)
    return kept


def _tangential_state(c) -> tuple[np.ndarray, np.ndarray]:
    """(tangential force, shift increment of the step), world 3-vectors, of a solved contact."""
    if isinstance(c, PlateContact):
        return c.tangential_force, np.append(c.shift_increment, 0.0)
    return c.tangential_force, c.shift_increment


def _secant(model: ContactModel, solved, warm: _Solved | None) -> ContactModel:
    """The model with the stiffnesses measured between this solve and the last one of the same
    contact (secants along the last step, when it was large enough to be measured; for the
    tangential one, when both solves stuck), in place of the estimates (Hertz's 3N/(2δ), which a
    contact a few cells across misses by tens of per cent, and Mindlin's k₀ c/a): the Newton
    iteration then converges faster than its rate with the estimates (0.28 per pass for an
    ellipsoid sticking between the plates with 2.6 cells across its contact radius)."""
    if warm is None:
        return model
    old = warm.contact
    d_approach = solved.approach - old.approach
    # a step too small to be measured (the solvers' tolerance is 1e-8 of the force) keeps the
    # last measurement: near convergence the steps shrink, and a contact a few cells across
    # whose cells no longer change is stiffer than one whose contact grows (a punch against
    # Hertz; 0.72 of Hertz's tangent at 2.6 cells per contact radius)
    if abs(d_approach) > 1e-6 * max(solved.approach, old.approach) and old.normal_force > 0:
        k = (solved.normal_force - old.normal_force) / d_approach
        if 0.2 * model.k_normal <= k <= 5.0 * model.k_normal:
            model = replace(model, k_normal=k)
    elif 0.2 * model.k_normal <= warm.model.k_normal <= 5.0 * model.k_normal:
        model = replace(model, k_normal=warm.model.k_normal)
    if model.sliding or model.k_stick <= 0:
        return model
    if not old.stick.any() or not solved.stick.any():
        return model
    T1, s1 = _tangential_state(solved)
    T0, s0 = _tangential_state(old)
    ds = s1 - s0
    length2 = float(ds @ ds)
    scale = model.mu * model.normal_force / model.k_stick   # the slip distance scale, m
    if length2 <= (1e-6 * scale) ** 2:
        if not warm.model.sliding and 0.05 * model.k_stick <= warm.model.k_loading \
                <= 1.5 * model.k_stick:
            return replace(model, k_loading=warm.model.k_loading)
        return model
    k = float((T1 - T0) @ ds) / length2
    if not 0.05 * model.k_stick <= k <= 1.5 * model.k_stick:
        return model
    return replace(model, k_loading=k)


def _plate_model(c: PlateContact) -> ContactModel:
    mat = c.body.material
    K = np.zeros((3, 3))
    K[:2, :2] = c.curvature
    return replace(ContactModel.of(
        normal=c.normal, point=c.pressure_centroid, centre_a=c.body.centre,
        centre_b=c.pressure_centroid, normal_force=c.normal_force,
        tangential_force=c.tangential_force, twist_moment=c.twist_moment, approach=c.approach,
        area=c.area, stick_area=c.stick_area, mu=c.mu, slip=np.append(c.slip, 0.0),
        compliance=(2.0 - mat.nu) / mat.G, torsion=1.0 / mat.G, curvature_a=K,
        curvature_b=np.zeros((3, 3)), sliding=c.mu > 0 and not c.stick.any()), touch=c.touch)


def _pair_model(c: PairContact, A: Body, B: Body, mu: float) -> ContactModel:
    t = c.tangent_axes                       # (2, 3)
    ma, mb = A.material, B.material
    return replace(ContactModel.of(
        normal=c.normal, point=c.pressure_centroid, centre_a=A.centre, centre_b=B.centre,
        normal_force=c.normal_force, tangential_force=c.tangential_force,
        twist_moment=c.twist_moment, approach=c.approach, area=c.area,
        stick_area=c.stick_area, mu=mu, slip=c.slip,
        compliance=(2.0 - ma.nu) / ma.G + (2.0 - mb.nu) / mb.G,
        torsion=1.0 / ma.G + 1.0 / mb.G, curvature_a=t.T @ c.curvature_a @ t,
        curvature_b=t.T @ c.curvature_b @ t, sliding=mu > 0 and not c.stick.any()),
        touch=c.origin)


# --- the Newton step -----------------------------------------------------------------------
@dataclass
class _Terms:
    """The contacts of the linear model, stacked (m terms, the first axis of every array): the
    solved contacts (``bem``) and the open ones that a step may close (a spring of the stiffness
    it would have at the force scale, separation ``sigma``)."""

    a: np.ndarray                   # (m,) int
    b: np.ndarray                   # (m,) int, −1: a plate
    upper: np.ndarray               # (m,) bool: the upper plate
    models: ModelStack
    base_a: np.ndarray              # (m, 6, 12)
    base_b: np.ndarray
    wrench_a: np.ndarray            # (m, 6) of the current force, or of −k σ for a spring
    wrench_b: np.ndarray
    N: np.ndarray                   # (m,)
    kn: np.ndarray
    sigma: np.ndarray
    bem: np.ndarray                 # (m,) bool
    reach: np.ndarray               # an open contact's Hertz approach at the force scale, m
    #: (m, 4): the slots of the blocks (a, a), (a, b), (b, a), (b, b) (−1: none, a plate);
    #: ``keys`` (slots, 2) their (row, column) particles
    slots: np.ndarray
    keys: np.ndarray

    def __len__(self) -> int:
        return len(self.a)

    @property
    def pair(self) -> np.ndarray:
        return self.b >= 0

    def motion(self, step: np.ndarray, dh: float) -> np.ndarray:
        """(m, 12): each term's (du_a, dφ_a, du_b, dφ_b) of a step (the upper plate moves by dh
        along z)."""
        out = np.zeros((len(self.a), 12))
        out[:, :6] = step[self.a]
        pair = self.pair
        out[pair, 6:] = step[self.b[pair]]
        out[self.upper, 8] = dh
        return out

    def approach_change(self, step: np.ndarray, dh: float) -> tuple[np.ndarray, np.ndarray]:
        """Each term's change of approach under a step (m,), m, and its motions (m, 12)."""
        v = self.motion(step, dh)
        return np.matmul(self.models.approach_rows[:, None, :], v[:, :, None])[:, 0, 0], v


def _terms(problem: _Problem, ev: _Evaluation) -> _Terms:
    scale = ev.scale if ev.scale > 0 else (problem.force or 0.0)
    rows = []                       # (a, b, upper, model, N, k, σ, bem, reach)
    for c in ev.contacts:
        m = c.model
        plate = isinstance(c.contact, PlateContact)
        a, b = (c.key[0], -1) if plate else c.roles
        rows.append((a, b, plate and c.key[1] == "upper", m, m.normal_force, m.k_normal, 0.0,
                     True, 0.0))
    for p in ev.potential if scale > 0 else ():
        # Hertz at the force scale: δ = (9 N² / (16 E*² R))^(1/3), k = 3N/(2δ)
        delta = (9.0 * scale**2 / (16.0 * p.E_star**2 * p.radius)) ** (1.0 / 3.0)
        k = 1.5 * scale / delta
        k0 = 8.0 * math.sqrt(p.radius * delta) / p.compliance if p.mu > 0 else 0.0
        m = ContactModel.spring(normal=p.normal, point=p.point, centre_a=p.centre_a,
                                centre_b=p.centre_b, stiffness=k, tangential=k0, mu=p.mu)
        plate = p.roles[1] in PLATES
        a, b = (p.roles[0], -1) if plate else p.roles
        rows.append((a, b, plate and p.roles[1] == "upper", m, 0.0, k, p.sigma, False, delta))
    count = len(rows)
    models = ModelStack([r[3] for r in rows])
    a = np.array([r[0] for r in rows], dtype=int)
    b = np.array([r[1] for r in rows], dtype=int)
    slots = np.full((count, 4), -1, dtype=int)
    keys: dict = {}
    for m, (r, q) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
        for j, key in enumerate(((r, r), (r, q), (q, r), (q, q)) if q >= 0 else ((r, r),)):
            slots[m, j] = keys.setdefault(key, len(keys))
    N, kn, sigma, bem, reach = (np.array([r[j] for r in rows], dtype=float).reshape(count)
                                for j in range(4, 9))
    bem = bem.astype(bool)
    # an open contact's wrench: of −N n with N = −k σ
    f = (kn * sigma)[:, None] * models.normal
    spring_a = np.concatenate([f, cross_rows(models.arm_a, f)], axis=1)
    spring_b = np.concatenate([-f, -cross_rows(models.arm_b, f)], axis=1)
    return _Terms(a, b, np.array([r[2] for r in rows], dtype=bool), models, models.base_a,
                  models.base_b, np.where(bem[:, None], models.wrench_a, spring_a),
                  np.where(bem[:, None], models.wrench_b, spring_b), N, kn, sigma, bem, reach,
                  slots, np.array(list(keys), dtype=int).reshape(len(keys), 2))


def _components(n: int, pairs: list[tuple[int, int]]) -> list[list[int]]:
    """The connected components of n particles linked by ``pairs``, each in ascending order."""
    if not pairs:
        return [[k] for k in range(n)]
    rows = [a for a, _ in pairs]
    cols = [b for _, b in pairs]
    graph = coo_matrix((np.ones(len(pairs)), (rows, cols)), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    groups: list[list[int]] = [[] for _ in range(count)]
    for k in range(n):
        groups[labels[k]].append(k)
    return groups


#: singular values of a group's scaled Newton matrix below this share of the largest are modes
#: without stiffness: the step leaves them alone (a truncated pseudo-inverse). At 1e-9, 100
#: touching spheres failed their first compression step: a sphere sliding at its three contacts
#: kept a turning mode at about 1e-8 of the largest stiffness, whose step of 0.8-23 rad set the
#: trust region's common factor (10⁻³ to 10⁻⁹ for every other particle) until the attempt
#: stalled; at 1e-7 that mode is left alone and the step converges in 31 passes
_RCOND = 1e-7
#: 0: the truncated pseudo-inverse; a positive value: the former Levenberg-Marquardt shift of
#: the diagonal by this share of its largest entry (kept to show what the pseudo-inverse fixes)
_LM = 0.0


#: the LU solve replaces the truncated SVD when LAPACK's estimate of the reciprocal 1-norm
#: condition number is above this: the 2-norm condition is then below n / _LU_RCOND (< 1 /
#: :data:`_RCOND` for n < 1000), so no singular value would have been truncated
_LU_RCOND = 1e-4
#: False: always the SVD (kept to measure what the LU path saves)
_LU = True


def _least_norm(J: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The minimum-norm least-squares solution of J X = B (truncated SVD, :data:`_RCOND`): modes
    without stiffness do not move, and a residual the model cannot change (a particle that
    slides on both plates, whose model has no stiffness along its slip, while its force along
    the slip is unbalanced) asks for no step, where a shifted diagonal asked for the residual
    over the shift (hundreds of metres, which the trust region's common factor then imposed on
    every particle as a step of nothing)."""
    if _LM > 0:
        diag = np.abs(np.diag(J))
        top = float(diag.max()) if diag.size else 0.0
        J = J.copy()
        J[np.diag_indices(J.shape[0])] += _LM * top if top > 0 else 1.0
        return np.linalg.solve(J, B)
    if _LU and J.shape[0] == J.shape[1] and J.size:
        # a well-conditioned matrix has no singular value to truncate: its LU solution is the
        # SVD's to rounding, at a fraction of the cost (the SVD was 33 % of a 36-sphere touching
        # lattice's solve, its matrix factorised about 165 times per pass by the active set)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lu, piv, info = lapack.dgetrf(J)
            if info == 0:
                rcond, info = lapack.dgecon(lu, float(np.abs(J).sum(axis=0).max()), norm="1")
                if info == 0 and rcond > _LU_RCOND:
                    X, info = lapack.dgetrs(lu, piv, B)
                    if info == 0:
                        return X
    U, s, Vt = np.linalg.svd(J)
    if s.size == 0 or s[0] == 0:
        return np.zeros((J.shape[1], *B.shape[1:]))
    keep = s > _RCOND * s[0]
    UB = U[:, keep].T @ B
    return Vt[keep].T @ (UB / (s[keep] if B.ndim == 1 else s[keep][:, None]))


#: True: a group of touching particles whose Newton step reaches past the trust radius takes
#: the Levenberg-Marquardt step of that radius (:func:`_damped`) instead of sharing the trust
#: region's common factor. Off: on the first compression step of touching lattices
#: (``benchmarks/cluster_robustness.py``) it converged 18 of 24 small ones where the common
#: factor converges 17, but it lost the 10 x 10 lattice of seed 1, which the common factor
#: solves in 31 passes (kept to measure)
_LEVENBERG_MARQUARDT = False
#: bisections of log λ for the Levenberg-Marquardt parameter (the reach is met to 1e-9 of it)
_LM_BISECTIONS = 40


def _reach(step: np.ndarray, sizes: np.ndarray) -> float:
    """How far a (k, 6) step goes in trust radii: the largest over its particles of the
    rotation over :data:`_ROTATION` (rad) and the translation over :data:`_TRANSLATION` sizes
    (the bounds :func:`_limit` holds at radius 1)."""
    if not len(step):
        return 0.0
    rot = np.linalg.norm(step[:, 3:], axis=1) / _ROTATION
    trans = np.linalg.norm(step[:, :3], axis=1) / (sizes * _TRANSLATION)
    return float(max(rot.max(), trans.max()))


def _damped(J: np.ndarray, b: np.ndarray, keep: np.ndarray, col_scale: np.ndarray,
            sizes: np.ndarray, radius: float) -> np.ndarray:
    """The Levenberg-Marquardt step of one group: x(λ) = argmin |J x − b|² + λ |x|² (scaled
    unknowns, ``keep`` of the group's 6 k), with λ ≥ 0 the smallest for which the step's reach
    (:func:`_reach`, in physical units: ``col_scale`` (k, 6)) is within ``radius``; returns the
    physical (k, 6) step. Moré, "The Levenberg-Marquardt algorithm: implementation and theory",
    Lecture Notes in Mathematics 630 (1978) 105-116: the trust-region step is the shifted
    normal equations' solution (JᵀJ + λI) x = Jᵀb, λ found by a scalar search, here a bisection
    of log λ on the SVD J = U S Vᵀ, x(λ) = V (s c / (s² + λ)), c = Uᵀ b.

    Where the common factor of :func:`_limit` scales every particle's step by the one that goes
    furthest, the shift damps the soft modes most: a nearly unloaded sphere among 36 touching
    ones asked for 2-6 rad, and the common factor held every other particle to 10⁻² of its step
    pass after pass. Modes below :data:`_RCOND` of the stiffest stay out, as in
    :func:`_least_norm`, so that λ → 0 is that solution. Used only with
    :data:`_LEVENBERG_MARQUARDT` (off: what it measured is there)."""
    k = len(sizes)
    U, s, Vt = np.linalg.svd(J)
    out = np.zeros(6 * k)
    if s.size == 0 or s[0] == 0:
        return out.reshape(k, 6)
    on = s > _RCOND * s[0]
    U, s, Vt = U[:, on], s[on], Vt[on]
    c = U.T @ b

    def physical(lam: float) -> np.ndarray:
        out[keep] = Vt.T @ (s * c / (s * s + lam))
        return out.reshape(k, 6) * col_scale

    if _reach(physical(0.0), sizes) <= radius:
        return physical(0.0)
    top = float(s[0]) ** 2
    lo, hi = math.log(top * 1e-16), math.log(top * 1e8)
    if _reach(physical(math.exp(hi)), sizes) > radius:
        return physical(math.exp(hi))
    for _ in range(_LM_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if _reach(physical(math.exp(mid)), sizes) > radius:
            lo = mid
        else:
            hi = mid
    return physical(math.exp(hi))


_ACTIVE_SET_PASSES = 12


@dataclass
class _Model:
    """The linear model of the residuals with a given set of active terms."""

    rows: np.ndarray                # (s,) int: the blocks' row particles
    cols: np.ndarray                # (s,) int: their column particles
    blocks: np.ndarray              # (s, 6, 6)
    constant: np.ndarray            # (n, 6): the residual's change at a zero step
    h_col: np.ndarray               # (n, 6)
    h_row: np.ndarray               # (n, 6)
    h_diag: float
    plate_constant: float

    def residual(self, R: np.ndarray, plate: float, step: np.ndarray, dh: float):
        out = R + self.constant + self.h_col * dh
        np.add.at(out, self.rows, np.matmul(self.blocks, step[self.cols][:, :, None])[:, :, 0])
        plate_out = plate + self.plate_constant + math.fsum((self.h_row * step).ravel()) + \
            self.h_diag * dh
        return out, plate_out


def _ordered_sum(values: np.ndarray) -> float:
    """The sum of ``values`` added one after the other (as a loop would)."""
    return float(np.cumsum(values)[-1]) if values.size else 0.0


def _model(n: int, terms: _Terms, active: np.ndarray, laws: TangentialLaws,
           correction: dict | None = None) -> _Model:
    """The linear model of the active terms on their laws' branches. Every sum over terms adds
    them in the terms' order (``np.add.at`` is sequential), as the loop over terms that this
    replaced did: the same model bit for bit."""
    on = np.asarray(active, dtype=bool)
    pair, bem = terms.pair, terms.bem
    la, lb, ca, cb = terms.models.law_blocks(laws)
    block_a, block_b = terms.base_a + la, terms.base_b + lb
    # the constant, term after term: a solved contact that the step opens loses its force;
    # an active term adds its law's offset, an active spring its force −k σ
    gone = bem & ~on
    first = on | bem
    values = np.stack([np.where(gone[:, None], -terms.wrench_a, ca),
                       np.where(gone[:, None], -terms.wrench_b, cb),
                       terms.wrench_a, terms.wrench_b], axis=1)
    valid = np.stack([first, first & pair, on & ~bem, on & ~bem & pair], axis=1)
    where = np.stack([terms.a, terms.b, terms.a, terms.b], axis=1)
    constant = np.zeros((n, 6))
    np.add.at(constant, where[valid], values[valid])
    upper = terms.upper
    plate_constant = _ordered_sum(np.where(gone, -terms.N, -(terms.kn * terms.sigma))[
        upper & (gone | (on & ~bem))])
    # the blocks, in the order the terms first touch them
    contributions = np.stack([block_a[:, :, :6], block_a[:, :, 6:], block_b[:, :, :6],
                              block_b[:, :, 6:]], axis=1)
    valid = on[:, None] & np.stack([np.ones_like(pair), pair, pair, pair], axis=1)
    slots = terms.slots[valid]
    used, first_use = np.unique(slots, return_index=True)
    order = used[np.argsort(first_use)]
    position = np.empty(len(terms.keys), dtype=int)
    position[order] = np.arange(len(order))
    blocks = np.zeros((len(order), 6, 6))
    np.add.at(blocks, position[slots], contributions[valid])
    rows, cols = terms.keys[order, 0], terms.keys[order, 1]
    # the upper plate's gap: its column, the row of its force and the diagonal
    lid = on & upper
    h_col = np.zeros((n, 6))
    np.add.at(h_col, terms.a[lid], block_a[lid, :, 8])
    h_row = np.zeros((n, 6))
    np.add.at(h_row, terms.a[lid], terms.kn[lid, None] * terms.models.approach_rows[lid, :6])
    h_diag = _ordered_sum(terms.kn[lid] * terms.models.approach_rows[lid, 8])
    if correction:
        found = {(int(r), int(c)): m for m, (r, c) in enumerate(zip(rows, cols, strict=True))}
        extra = []
        for key, blk in correction.items():
            if key in found:
                blocks[found[key]] = blocks[found[key]] + blk
            else:
                extra.append((key, blk))
        if extra:
            rows = np.concatenate([rows, [k[0] for k, _ in extra]]).astype(int)
            cols = np.concatenate([cols, [k[1] for k, _ in extra]]).astype(int)
            blocks = np.concatenate([blocks, [blk for _, blk in extra]])
    return _Model(rows, cols, blocks, constant, h_col, h_row, h_diag, plate_constant)


def _solve_model(problem: _Problem, model: _Model, R: np.ndarray, plate: float,
                 translate: bool = False, radius: float | None = None,
                 damped: list | None = None) -> tuple[np.ndarray, float]:
    """The step (n, 6) and dh that zero the model's residuals, minimum-norm on modes without
    stiffness; per connected component of the model (particles linked by an active pair
    contact: an open one within reach does not link them), in scaled units (rotations times
    size, moments over size), the plate gap by a Schur complement. ``translate``: the
    rotations are held and the moments left out (the first phase of a step,
    :func:`_iterate`). ``radius``: a group of two or more particles whose step (at that dh)
    reaches past this trust radius takes the Levenberg-Marquardt step of the radius
    (:func:`_damped`) and is appended to ``damped``; a lone particle keeps its Newton step for
    the common factor of :func:`_limit` (damped, a turning ellipsoid's step kept its
    translation and lost its rotation, and pressed it 50 µm into the plates)."""
    n = problem.n
    L = problem.sizes
    # unknowns in metres (a rotation as the arc at the particle's size: dq̂ = L dφ, so
    # dq = S dq̂ with S = 1/L), equations in newtons (a moment over the size)
    col_scale = np.hstack([np.ones((n, 3)), np.repeat(1.0 / L[:, None], 3, 1)])
    row_scale = np.hstack([np.ones((n, 3)), np.repeat(1.0 / L[:, None], 3, 1)])
    force_control = problem.force is not None
    x = np.zeros((n, 6))
    y = np.zeros((n, 6))
    target = R + model.constant
    rows, cols = model.rows, model.cols
    scaled = row_scale[rows][:, :, None] * model.blocks * col_scale[cols][:, None, :]
    off = rows != cols
    groups = _components(n, list(zip(rows[off].tolist(), cols[off].tolist(), strict=True)))
    label = np.empty(n, dtype=int)
    local = np.empty(n, dtype=int)
    for g, group in enumerate(groups):
        label[group] = g
        local[group] = np.arange(len(group))
    by_group = np.argsort(label[rows], kind="stable")
    bounds = np.searchsorted(label[rows][by_group], np.arange(len(groups) + 1))
    systems = {}
    for g, group in enumerate(groups):
        size = 6 * len(group)
        J = np.zeros((size, size))
        mine = by_group[bounds[g]:bounds[g + 1]]
        J.reshape(len(group), 6, len(group), 6)[local[rows[mine]], :, local[cols[mine]], :] \
            += scaled[mine]
        rhs = (-target[group] * row_scale[group]).ravel()
        hcol = (model.h_col[group] * row_scale[group]).ravel()
        keep = np.arange(size)
        if translate:
            keep = keep[keep % 6 < 3]
            J = J[np.ix_(keep, keep)]
            rhs, hcol = rhs[keep], hcol[keep]
        xs, ys = np.zeros(size), np.zeros(size)
        if force_control and hcol.any():
            sol = _least_norm(J, np.column_stack([rhs, hcol]))
            xs[keep], ys[keep] = sol[:, 0], sol[:, 1]
        else:
            xs[keep] = _least_norm(J, rhs)
        x[group] = xs.reshape(-1, 6) * col_scale[group]
        y[group] = ys.reshape(-1, 6) * col_scale[group]
        if radius is not None and len(group) > 1:
            systems[g] = (J, rhs, hcol, keep)
    dh = 0.0
    if force_control:
        # Σ_k h_row_k · (x_k − y_k dh) + h_diag dh = −(ΣN − F + constant)
        num = -(plate + model.plate_constant) - math.fsum((model.h_row * x).ravel())
        den = model.h_diag - math.fsum((model.h_row * y).ravel())
        if den != 0:
            dh = num / den
    step = x - y * dh
    for g, (J, rhs, hcol, keep) in systems.items():
        group = groups[g]
        if _reach(step[group], L[group]) > radius:
            step[group] = _damped(J, rhs - hcol * dh, keep, col_scale[group], L[group], radius)
            if damped is not None:
                damped.append(group)
    return step, dh


#: a solved contact stays closed (at zero force) when the step takes its modelled force to zero
#: within this share of its force: the rounding of the kink at which the normal law opens
_KINK = 1e-9


def _statuses(terms: _Terms, step: np.ndarray, dh: float) -> tuple[np.ndarray,
                                                                  TangentialLaws]:
    """Each term's normal status (in contact after the step, (m,) bool) and tangential branch,
    from the predicted motion. A solved contact that the step unloads exactly to zero (the root
    of a particle lifting off its only contact: N + k_n dδ = 0 to rounding, :data:`_KINK`)
    stays closed: open, it would leave its particle without stiffness, whose minimum-norm step
    is then no lift at all (12 spheres in an 8 mm box: a sphere pressed 0.5 µm into the lower
    plate with nothing above, N + dN = −3 × 10⁻¹⁸ N at the root, its step zeroed pass after
    pass)."""
    d, v = terms.approach_change(step, dh)
    bem = terms.bem
    dN = np.where(bem, terms.kn * d, terms.kn * (d - terms.sigma))
    active = np.where(bem, terms.N + dN > -_KINK * terms.N, dN > 0)
    ds = np.matmul(terms.models.tangential_rows, v[:, :, None])[:, :, 0]
    return active, terms.models.laws(ds, dN)


#: sliding contacts start the active-set passes of a Newton step on their stick branch
_STICK_FIRST = True


def _same(laws_a: TangentialLaws, laws_b: TangentialLaws) -> bool:
    """The same branches: stick or slide, and a slide branch along the same direction."""
    if not np.array_equal(laws_a.slide, laws_b.slide):
        return False
    x, y = laws_a.g[laws_a.slide], laws_b.g[laws_a.slide]
    atol = 1e-12 * (np.abs(x).max(axis=1, initial=0.0) + 1e-300)
    return bool((np.abs(x - y) <= atol[:, None] + 1e-6 * np.abs(y)).all())


def _keep_plate_loaded(problem: _Problem, terms: _Terms, active: np.ndarray) -> None:
    """Under force control, while no contact presses the upper plate its open contacts stay
    active (the plate must come down to them)."""
    if problem.force is not None and not active[terms.upper].any():
        active[terms.upper & ~terms.bem] = True


def _piecewise(problem: _Problem, terms: _Terms, R: np.ndarray, plate: float,
               step: np.ndarray, dh: float):
    """The piecewise-linear model at a step: each contact on the status and branch the step
    puts it on (:func:`_statuses`), each branch linearised there, so that the model's residual
    at the step is the piecewise model's own value. Returns (residual (n, 6), plate residual,
    the model, active, laws)."""
    active, laws = _statuses(terms, step, dh)
    _keep_plate_loaded(problem, terms, active)
    model = _model(problem.n, terms, active, laws, problem.correction)
    out, plate_out = model.residual(R, plate, step, dh)
    if problem.force is None:
        # under gap control the plates' total force is an outcome, not an equation: its
        # change under the step is no residual (counted, it rejected every full Newton step
        # of 25 pressed spheres, whose steps change that force: a quarter step a pass, 49
        # passes where 8 do)
        plate_out = 0.0
    return out, plate_out, model, active, laws


#: halvings of a step of the active-set passes towards the last one before they give up: of
#: the Newton step of the model at the last step's own branches (a descent direction of its
#: merit), and of a step from other branches (the start's)
_MODEL_HALVINGS, _OTHER_HALVINGS = 30, 8
#: the active-set passes stop when the model's merit is this share of its value at a zero step
#: (its residuals 1e-7 of theirs: the model's root, well below what the BEM will follow)
_MODEL_ROOT = 1e-14


#: when no pass lowers the model's merit, the last Newton step is tried with the BEM (False:
#: the step is zero, and the attempt ends: "the model sees no way down")
_NO_DESCENT_TRIAL = True
#: when not even the Newton step at the start's own branches lowers the model's merit (a
#: contact open at the start that any fraction of the step closes), the passes may start again
#: this many times from the branches the smallest tried fraction entered (0: give up there)
_ENTERED_BRANCHES = 2


def _newton_step(problem: _Problem, terms: _Terms, R: np.ndarray, plate: float,
                 scale: float, translate: bool = False, radius: float | None = None,
                 damped: list | None = None):
    """The model's step with an active set of contacts: a solved contact whose normal force
    the step would take below zero opens (its force goes, it has no stiffness), an open one
    that the step would close acts with its spring, and each contact's tangential law takes the
    branch (stick, or slide along the trial force) the predicted motion puts it on
    (:meth:`~thirdbody.network.stiffness.ModelStack.laws`); repeated until the set settles (a
    semismooth Newton step on the piecewise-linear model). Each pass must lower the model's
    merit (scaled by ``scale``, N) at its own branches (:func:`_piecewise`), else its step is
    halved towards the last one: on a saturating law (a contact that slid in the step, whose
    force stays μN until the motion takes its slip back) the undamped passes cycle between the
    plateau and beyond it. Under force control, while no contact presses the upper plate its
    open contacts stay active. When not even the step at the start's own branches descends
    while the step is still zero, the passes start again from the branches that the smallest
    tried fraction of it entered (at most :data:`_ENTERED_BRANCHES` times): among 36 touching
    spheres a pair contact open by 1.3e-14 m at the start closed at any fraction of the step,
    so the start's own Newton step was never a descent step, and the step came back zero ("no
    way down") on the first pass of the first compression step. ``radius``, ``damped``: the
    Levenberg-Marquardt steps of groups (:func:`_solve_model`). Returns (step, dh, model,
    active)."""
    n = problem.n
    step, dh = np.zeros((n, 6)), 0.0
    out, plate_out, model, active, laws = _piecewise(problem, terms, R, plate, step, dh)
    merit = start_merit = _merit(problem, out, plate_out, scale, translate)
    at_step = (out, plate_out, active, laws)       # the piecewise model at ``step``
    # a sliding contact starts on its stick branch (the elastic predictor from the start of
    # the step): on the slide branch it has no stiffness along its slip, so a particle whose
    # only way out is to roll back (a sphere under a plate that moved by more than the slip
    # distance) sees a singular model whose least-norm step never reverses the slip; the
    # passes below put it back on the slide branch if the step goes on along the slip
    start_laws = laws
    if _STICK_FIRST:
        start_laws = laws.where(terms.models.sliding & laws.slide, terms.models.elastic())
    # an open contact closer than its approach at the force scale starts active: a particle
    # pressed towards a neighbour it does not touch yet has no other support in the model (the
    # pass below opens it again if the step does not close it)
    start_active = terms.bem | (terms.sigma <= terms.reach)
    _keep_plate_loaded(problem, terms, start_active)
    used = (start_active, start_laws)
    own = np.array_equal(start_active, active) and _same(start_laws, laws)
    trial, trial_dh = _solve_model(problem, _model(n, terms, start_active, start_laws,
                                                          problem.correction),
                                   R, plate, translate, radius, damped)
    entered = 0
    for _ in range(2 * _ACTIVE_SET_PASSES):
        t = 1.0
        for _halving in range((_MODEL_HALVINGS if own else _OTHER_HALVINGS) + 1):
            cand = step + t * (trial - step)
            cand_dh = dh + t * (trial_dh - dh)
            out, plate_out, cand_model, cand_active, cand_laws = _piecewise(
                problem, terms, R, plate, cand, cand_dh)
            cand_merit = _merit(problem, out, plate_out, scale, translate)
            if cand_merit < merit or (t == 1.0 and cand_merit == merit == 0.0):
                break
            t *= 0.5
        else:
            if own:
                if entered < _ENTERED_BRANCHES and dh == 0.0 and not step.any() and not (
                        np.array_equal(cand_active, used[0]) and _same(cand_laws, used[1])):
                    # the smallest fraction of the step already changed the branches (a
                    # contact open at the start by rounding closes): the Newton step of the
                    # model on those branches
                    entered += 1
                    used = (cand_active, cand_laws)
                    trial, trial_dh = _solve_model(problem, cand_model, R, plate, translate,
                                                   radius, damped)
                    continue
                if _NO_DESCENT_TRIAL and dh == 0.0 and not step.any():
                    # the model's merit has a kink at the start along the step: the BEM
                    # decides (the trust region cuts the step until a trial descends)
                    step, dh = trial, trial_dh
                    out, plate_out, model, active, laws = _piecewise(problem, terms, R, plate,
                                                                     step, dh)
                    at_step = (out, plate_out, active, laws)
                break       # not even the step's own Newton step lowers the model's merit
            # the start's branches (or the last pass's) lead nowhere from here: the Newton
            # step of the model at the step's own branches, a descent direction of its merit
            used, own = (active, laws), True
            trial, trial_dh = _solve_model(problem, model, R, plate, translate, radius, damped)
            continue
        step, dh, merit = cand, cand_dh, cand_merit
        model, active, laws = cand_model, cand_active, cand_laws
        at_step = (out, plate_out, active, laws)
        if t == 1.0 and np.array_equal(cand_active, used[0]) and _same(cand_laws, used[1]):
            break           # the step's own branches: the piecewise model's root
        if merit <= _MODEL_ROOT * start_merit:
            break           # the piecewise model's root to rounding
        used, own = (cand_active, cand_laws), True
        trial, trial_dh = _solve_model(problem, cand_model, R, plate, translate, radius,
                                       damped)
    if _REST_UNTOUCHED:
        # a particle that no active term touches at the step has no stiffness in its model:
        # its minimum-norm step is zero. The passes' damping can leave it the motion of an
        # earlier pass on other branches (a spring of an open contact that pass closed), which
        # the merit does not see but the trust region's common factor does: in a dense potato
        # layer free neighbours turned by 2e-2 rad and held the pressed potato to 0.7 % of its
        # step, pass after pass, until the attempt stalled. A particle that a solved contact
        # touches at the start keeps its step, even where the step opens every contact it
        # has: a pressed sphere pushed out of its contacts by their force (its step is the
        # way out, and zeroing it stalled 25 pressed spheres at their first step)
        touched = np.zeros(n, dtype=bool)
        acting = active | terms.bem
        touched[terms.a[acting]] = True
        touched[terms.b[acting & terms.pair]] = True
        if step[~touched].any():
            step = step.copy()
            step[~touched] = 0.0
            out, plate_out, model, active, laws = _piecewise(problem, terms, R, plate, step, dh)
            at_step = (out, plate_out, active, laws)
    if _WAY_BACK:
        back = _way_back(problem, terms, R, plate, scale, translate, step, dh, at_step)
        if back is not None:
            step, model, active = back
    return step, dh, model, active


#: the step of a particle that no active term touches is zero (False: as the passes left it)
_REST_UNTOUCHED = True
#: a group of particles that the passes leave stranded on the plateau of contacts that slid in
#: the step takes the step that sticks them again (:func:`_way_back`; False: as the passes left
#: it)
_WAY_BACK = True
#: a particle is stranded when the model at the passes' step keeps more than this share of its
#: squared residual
_STRANDED = 0.25


def _way_back(problem: _Problem, terms: _Terms, R: np.ndarray, plate: float, scale: float,
              translate: bool, step: np.ndarray, dh: float, at_step: tuple):
    """The step back for groups that the active-set passes leave stranded, or None.

    A contact that slid in the step keeps μN until the motion has taken its slip back (the BEM
    solves the step as one increment from its start), so its law has a plateau as long as the
    slip. A particle that slid there (pushed by a neighbour that then moved away) and that
    only sliding contacts hold has no stiffness along its slip on the plateau; the passes'
    common halving of the step keeps it there (a half step back is still on the plateau, while
    the stick-first step of the other groups overshoots), and its least-norm step is zero, pass
    after pass. Measured: a 4 × 4 lattice of random radii apart by up to 3 µm (the closest
    pair touching), loaded with 0.025 N a sphere; a sphere pushed 2.55 µm sideways by its
    neighbour in the rotation-free phase was left sliding at both plates with 2μN unbalanced
    when the neighbour moved back, and every attempt failed there at a scaled residual of
    0.07. Here each such group (particles linked by active pair contacts in which some
    particle keeps more than :data:`_STRANDED` of its squared residual in the model at the
    passes' step, and has a sliding contact that slid in the step) takes the Newton step of
    the model with its sliding contacts on their stick branch (the elastic predictor from the
    start of the step), the other particles and the plate as the passes left them; kept
    where the piecewise model's merit at the combined step is lower. ``at_step``: the piecewise
    model at ``step`` (residual, plate residual, active set, laws), as the passes left it.
    Returns (step, model, active)."""
    models = terms.models
    if not models.sliding.any():
        return None
    slid = terms.bem & models.sliding & (np.abs(models.back).max(axis=1) > 0)
    if not slid.any():
        return None
    out, plate_out, active, laws = at_step
    merit = _merit(problem, out, plate_out, scale, translate)
    w = _scaled(problem, np.ones_like(R), 0.0, 1.0)[0]
    if translate:
        w = w * np.hstack([np.ones(3), np.zeros(3)])
    left, now = ((out * w) ** 2).sum(axis=1), ((R * w) ** 2).sum(axis=1)
    stranded = (left > _STRANDED * now) & (now > 0)
    holding = np.zeros(problem.n, dtype=bool)
    holding[terms.a[slid]] = True
    holding[terms.b[slid & terms.pair]] = True
    stranded &= holding
    if not stranded.any():
        return None
    pairs = active & terms.pair
    groups = _components(problem.n, list(zip(terms.a[pairs].tolist(),
                                             terms.b[pairs].tolist(), strict=True)))
    moving = np.zeros(problem.n, dtype=bool)
    for group in groups:
        if stranded[group].any():
            moving[group] = True
    mine = moving[terms.a] | (terms.pair & moving[np.maximum(terms.b, 0)])
    back_laws = laws.where(mine & models.sliding, models.elastic())
    back_active = np.where(mine, terms.bem | active, active)
    trial, _ = _solve_model(problem, _model(problem.n, terms, back_active, back_laws,
                                            problem.correction), R, plate, translate)
    combined = step.copy()
    combined[moving] = trial[moving]
    out, plate_out, model, active, _ = _piecewise(problem, terms, R, plate, combined, dh)
    if _merit(problem, out, plate_out, scale, translate) >= merit:
        return None
    return combined, model, active


#: a rejected trial that the trust region did not cut is not evaluated again at the quartered
#: radius (the same poses): the radius is quartered on until it cuts the step
_SKIP_REPEATS = True


#: the last attempt at a step lets the models learn their error from the BEM (:func:`_learn`)
_BROYDEN = True
#: a particle's model learns from a trial when its prediction of the residuals' change missed
#: by more than this share of the change
_BAD_MODEL = 0.3


def _contact_keys(contacts, n: int) -> list[set]:
    keys: list[set] = [set() for _ in range(n)]
    for c in contacts:
        keys[c.key[0]].add(c.key)
        if len(c.key) >= 3:
            keys[c.key[1]].add(c.key)
    return keys


def _learn(problem: _Problem, ev: _Evaluation, trial: _Evaluation, terms: _Terms,
           active: np.ndarray, laws: TangentialLaws, R: np.ndarray, R_trial: np.ndarray,
           predicted: np.ndarray, step: np.ndarray, rows: np.ndarray) -> bool:
    """Correct each particle's own block of the linear model by what a trial's BEM residuals
    showed (Broyden's good update of the 6 x 6 diagonal block, row by row as in Schubert's
    sparse update, in scaled unknowns: a rotation as the arc at the particle's size). ``R``,
    ``R_trial``: the (n, 6) residuals at the current poses and at the trial's.

    A contact's model is a few numbers from its last solve (Hertz's and Mindlin's stiffnesses of
    a circle, the curvatures at the first touch). Where the BEM contact is not that (a tilted
    potato's: elongated, nearly flat along one axis (radii 1.3 and 93 mm at one plate), or
    several spots), the model's derivatives are off by a factor of several, or of opposite
    sign where two plate contacts nearly cancel (dF_y/dφ_x −62 N/rad from the BEM against +38
    modelled), and the Newton iteration stalls. The residuals R(x + s) of a trial against the
    model's prediction give the model's error along s: E_k += (R(x + s) − R̂(s))_k ŝ_kᵀ / |ŝ_k|²
    for particle k, so that (J + E) s reproduces the BEM. The correction is kept over the
    passes of the attempt (the models are rebuilt every pass; their error is systematic). No
    update for a particle ``rows`` leaves out (converged), for one whose contact set or a
    contact's stick/slide state differs from the model's prediction (then the error is a
    change of set, not of derivative), or whose change the model predicted within
    :data:`_BAD_MODEL`; a particle whose contacts change loses its correction. Returns whether
    a correction changed."""
    n = problem.n
    before = _contact_keys(ev.contacts, n)
    after = _contact_keys(trial.contacts, n)
    for k in range(n):
        if before[k] != after[k]:
            problem.correction.pop((k, k), None)
    ok = [bool(rows[k]) and bool(before[k]) and before[k] == after[k] for k in range(n)]
    sliding = {c.key: c.model.sliding for c in trial.contacts}
    keys = [c.key for c in ev.contacts] + [None] * (len(terms) - len(ev.contacts))
    changed_state = np.asarray(active) != terms.bem
    for m, key in enumerate(keys):
        if key is not None and sliding.get(key) != bool(laws.slide[m]):
            changed_state[m] = True
    for m in np.flatnonzero(changed_state):
        ok[terms.a[m]] = False
        if terms.b[m] >= 0:
            ok[terms.b[m]] = False
    mismatch = R_trial - predicted
    change = R_trial - R
    # ŝ = (du, L dφ): |ŝ|² = s · (weight s); residuals scaled as (F, M / L)
    weight = np.hstack([np.ones((n, 3)), np.repeat(problem.sizes[:, None] ** 2, 3, 1)])
    changed = False
    for k in range(n):
        if not ok[k]:
            continue
        w = weight[k] ** -0.5
        if np.linalg.norm(w * mismatch[k]) <= _BAD_MODEL * np.linalg.norm(w * change[k]):
            continue
        denom = float(step[k] @ (weight[k] * step[k]))
        if not denom > 0:
            continue
        update = np.outer(mismatch[k], weight[k] * step[k]) / denom
        problem.correction[(k, k)] = problem.correction.get((k, k), 0.0) + update
        changed = True
    return changed


def _residual_vector(problem: _Problem, ev: _Evaluation) -> tuple[np.ndarray, float]:
    """(n, 6) residuals (forces N, moments N m) and the plate's force residual (N)."""
    R = np.hstack([ev.forces, ev.moments])
    plate = ev.plate_normal - problem.force if problem.force is not None else 0.0
    return R, plate


def _scaled(problem: _Problem, R: np.ndarray, plate: float, scale: float):
    w = np.hstack([np.ones((problem.n, 3)), np.repeat(1.0 / problem.sizes[:, None], 3, 1)])
    return R * w / scale, plate / scale


def _merit(problem: _Problem, R: np.ndarray, plate: float, scale: float,
           translate: bool = False) -> float:
    """Half the sum of the squared scaled residuals (``translate``: forces and plate only)."""
    Rs, ps = _scaled(problem, R, plate, scale)
    if translate:
        Rs = Rs[:, :3]
    return 0.5 * math.fsum(np.concatenate([(Rs * Rs).ravel(), [ps * ps]]))


#: the first phase of a step moves the particles (and the plate) without turning them until the
#: forces balance within this share of the force scale
_PHASE_ONE_TOL = 0.05
_PHASE_ONE_PASSES = 12


#: an attempt with the rotation-free phase is abandoned when, after that phase, the largest
#: residual of the last _STALL passes is not below half the best before them
#: (:func:`solve_cluster` then solves the step again without that phase)
_STALL = 15


def _stalled(log: list) -> bool:
    if len(log) <= _STALL:
        return False
    worst = [entry[0] for entry in log]
    return min(worst[-_STALL:]) > 0.5 * min(worst[:-_STALL])


def _force_residual(problem: _Problem, ev: _Evaluation, scale: float) -> float:
    R, plate = _residual_vector(problem, ev)
    Rs, ps = _scaled(problem, R, plate, scale)
    return max(float(np.abs(Rs[:, :3]).max()), abs(ps))


#: at trust radius 1: the largest rotation of a particle (rad), translation (in sizes), and
#: change of a contact's normal force (in its force, or the force scale if larger)
_ROTATION, _TRANSLATION, _FORCE = 0.05, 0.05, 1.0


def _limit(problem: _Problem, terms: _Terms, active: np.ndarray, scale: float,
           step: np.ndarray, dh: float, radius: float):
    """The step scaled as a whole (one factor for every particle and the plate: the direction
    and any symmetry are kept) so that at trust radius ρ no particle turns by more than
    ρ _ROTATION or moves by more than ρ _TRANSLATION sizes, and no contact's normal force
    changes by more than ρ _FORCE of itself or of the force scale. Returns (step, dh,
    clipped)."""
    factor = 1.0
    reach = _reach(step, problem.sizes)
    if reach > radius:
        factor = radius / reach
    d, _ = terms.approach_change(step, dh)
    change = np.where(terms.bem, np.abs(terms.kn * d), terms.kn * np.maximum(d - terms.sigma, 0.0))
    allowed = radius * _FORCE * np.maximum(terms.N, scale)
    over = np.asarray(active, dtype=bool) & (change > allowed)
    if over.any():
        factor = min(factor, float((allowed[over] / change[over]).min()))
    if factor < 1.0:
        return step * factor, dh * factor, True
    return step, dh, False


def _moved(centres, rotations, step):
    new_centres = centres + step[:, :3]
    new_rotations = [Rotation.from_rotvec(step[k, 3:]) * rotations[k]
                     for k in range(len(rotations))]
    return new_centres, new_rotations


def _converged(problem: _Problem, ev: _Evaluation, tol: float) -> tuple[bool, float]:
    R, plate = _residual_vector(problem, ev)
    scale = ev.scale
    if scale <= 0:
        # nothing touches: every particle is free and balanced; under force control the plate
        # carries nothing
        worst = 0.0 if problem.force is None else math.inf
        return worst <= tol, worst
    Rs, _ = _scaled(problem, R, 0.0, scale)
    worst = float(np.abs(Rs).max()) if Rs.size else 0.0
    if problem.force is not None:
        worst = max(worst, abs(plate) / problem.force)
    return worst <= tol, worst


# --- the solve -----------------------------------------------------------------------------
def solve_cluster(bodies: Sequence[Body], histories: Mapping | None = None, *, mu_up: float,
                  mu_low: float, mu_pp=0.0, gap: float | None = None,
                  force: float | None = None, gap_start: float | None = None,
                  plate_shift=(0.0, 0.0), box=None,
                  numerics: ClusterNumerics | None = None, guess=None,
                  retry: bool = True) -> ClusterResult:
    """The equilibrium of a cluster of particles between the plates (module docstring).

    Parameters
    ----------
    bodies : sequence of Body
        The particles at their poses at the start of the step.
    histories : mapping, optional
        The contact histories at the start of the step (:attr:`ClusterResult.histories` of the
        last step), by key; none for a first step.
    mu_up, mu_low : float
        Friction coefficients of the upper and the lower plate (>= 0).
    mu_pp : float, mapping or callable
        Particle-particle friction: one value, a mapping {(material_a, material_b): μ} (either
        order), or a function (material_a, material_b) -> μ.
    gap : float, optional
        Gap control: the plate gap h, m.
    force : float, optional
        Force control: the total normal force F_N of the upper plate, N (> 0); h is solved for.
        Exactly one of ``gap`` and ``force``.
    gap_start : float, optional
        The plate gap at the start of the step, m: the first guess under force control, and
        where a new upper contact started (default: ``gap``, or under force control the top of
        the cluster).
    plate_shift : (2,) array
        The upper plate's horizontal displacement in this step, m (default 0).
    box : (L_x, L_y), optional
        A periodic box in x and y, m.
    numerics : ClusterNumerics, optional
    guess : (translation, rotation, gap), optional
        A prediction of the step's motion: each particle's translation (n, 3) in m and rotation
        vector (n, 3) in rad (world frame, applied after its start rotation), in the order of
        ``bodies``, and the plate gap in m (None, or ignored under gap control). A run passes
        the last step's motion scaled by the ratio of the load increments (a secant predictor;
        :meth:`~thirdbody.network.run.NetworkEngine.step`). The first pass evaluates the
        contacts there instead of at the start poses; when that evaluation fails or its
        largest scaled residual is above :data:`GUESS_LIMIT`, the step starts from the start
        poses as without a guess (that pass is counted). Either way the answer is an
        equilibrium within ``numerics.tol``: a guess changes the passes, not what converged.
    retry : bool
        When the first attempt fails, try again without the rotation-free phase and then with
        models that learn from the BEM (the default); False raises the first attempt's error
        at once (a run that can still cut the step into halves does so instead).

    Returns
    -------
    ClusterResult

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    ClusterConvergenceError
        The equilibrium was not found; the message names the largest residual and the particle.
    """
    numerics = numerics or ClusterNumerics()
    bodies = list(bodies)
    if not bodies:
        raise ValueError("bodies: a cluster needs at least one particle")
    for b in bodies:
        if not isinstance(b, Body):
            raise TypeError("bodies must be thirdbody.network.Body objects")
    mu_up = _nonnegative(mu_up, "mu_up")
    mu_low = _nonnegative(mu_low, "mu_low")
    if not (callable(mu_pp) or isinstance(mu_pp, Mapping)):
        mu_pp = _nonnegative(mu_pp, "mu_pp")
    if (gap is None) == (force is None):
        raise ValueError("give exactly one of gap (m) and force (N)")
    if gap is not None:
        gap = float(gap)
        if not (math.isfinite(gap) and gap > 0):
            raise ValueError(f"gap must be a finite number > 0 m, got {gap!r}")
    if force is not None:
        force = float(force)
        if not (math.isfinite(force) and force > 0):
            raise ValueError(f"force must be a finite number > 0 N, got {force!r}")
    if box is not None:
        box = tuple(float(v) for v in box)
        if len(box) != 2 or not all(math.isfinite(v) and v > 0 for v in box):
            raise ValueError(f"box must be two lengths (L_x, L_y) > 0 m, got {box!r}")
    shift = np.asarray(plate_shift, dtype=float).reshape(-1)
    if shift.shape != (2,) or not np.isfinite(shift).all():
        raise ValueError(f"plate_shift must be a finite horizontal 2-vector, m, got "
                         f"{plate_shift!r}")
    histories = dict(histories or {})
    for key, hist in histories.items():
        if not isinstance(hist, ContactHistory) or hist.key != key:
            raise ValueError(f"histories[{key!r}] must be the ContactHistory of that key")
    tops = [float(b.centre[2] + b.shape.highest_point(b.rotation)[2]) for b in bodies]
    if gap_start is None:
        gap_start = gap if gap is not None else max(tops)
    predicted = _guess(guess, len(bodies))
    problem = _Problem(bodies, histories, mu_up, mu_low, _mu_function(mu_pp), gap, force,
                       gap_start, shift, box, numerics)
    h = gap if gap is not None else _first_gap(problem, float(gap_start))
    if predicted is not None:
        # the motion in the internal order; the gap only under force control
        order = problem.order
        predicted = (np.hstack([predicted[0][order], predicted[1][order]]),
                     h if gap is not None or predicted[2] is None else predicted[2])
    try:
        return _iterate(problem, h, phase_one=True, guess=predicted)
    except ClusterConvergenceError as first:
        if not retry:
            raise
        failed = problem.failed
        # the rotation-free first phase can leave the iteration in a state it does not leave
        # (before sliding contacts started the Newton step on their stick branch: a sphere
        # pressed into the groove of two others from touching, whose new contacts slid while
        # the lower spheres could not turn); the whole step again without it
        if problem.phase_one_used:
            try:
                return _iterate(problem, h, phase_one=False)
            except ClusterConvergenceError:
                failed = tuple(a + b for a, b in zip(failed, problem.failed, strict=True))
        if not _BROYDEN:
            problem.failed = failed
            raise first from None
        # last, with models that learn their error from the BEM (:func:`_learn`): a tilted
        # potato's contacts (elongated, nearly flat in one direction, several spots) are far
        # from the circles the models assume, and its iteration stalls without
        problem.failed = failed         # counted in the result of a later attempt
        try:
            return _iterate(problem, h, phase_one=True, learn=True)
        except ClusterConvergenceError:
            problem.failed = tuple(a + b for a, b in zip(failed, problem.failed, strict=True))
            # what the later attempts found beyond the contact model (a/R, spots facing
            # different ways) goes with the first attempt's residual
            if problem.beyond and problem.beyond not in str(first):
                raise ClusterConvergenceError(
                    f"{first} (later attempts{problem.beyond})") from None
            raise first from None


#: the largest scaled residual (:func:`_converged`) at a ``guess`` that the first pass keeps;
#: above it the step starts from the start poses. From the start poses a step begins at about
#: its load increment over the load (0.17-0.33 in the steps 3-6 of a 36-sphere touching
#: lattice's compression), from the secant guess at 0.024-0.043 there, and within the run's
#: tolerance (3e-3) at most sliding steps of ``make shear``
GUESS_LIMIT = 0.05


def _guess(guess, n: int):
    """``guess`` of :func:`solve_cluster` checked: (translation (n, 3), rotation (n, 3), gap
    or None) as floats, or None."""
    if guess is None:
        return None
    try:
        translation, rotation, gap = guess
    except (TypeError, ValueError):
        raise ValueError("guess must be (translation (n, 3) m, rotation vectors (n, 3) rad, "
                         "gap m or None)") from None
    out = []
    for name, value in (("translation", translation), ("rotation", rotation)):
        a = np.asarray(value, dtype=float)
        if a.shape != (n, 3) or not np.isfinite(a).all():
            raise ValueError(f"guess {name} must be a finite ({n}, 3) array, got shape "
                             f"{a.shape}")
        out.append(a)
    if gap is not None:
        gap = float(gap)
        if not (math.isfinite(gap) and gap > 0):
            raise ValueError(f"guess gap must be a finite number > 0 m or None, got {gap!r}")
    return out[0], out[1], gap


def _first_gap(problem: _Problem, h: float) -> float:
    """A first plate gap under force control: the given one if the upper plate presses some
    particle, else the gap at which the particles within reach of the upper plate carry F_N
    between them, each a Hertz contact with each plate in series (overlap top − h, half of it
    at each plate; radius: the shape's feature length). With one particle in reach this is
    the top less two Hertz approaches under F_N; with many it is not their sum's overload."""
    tops = [float(b.centre[2] + b.shape.highest_point(b.rotation)[2]) for b in problem.start]
    top = max(tops)
    if h < top:
        return h
    stiff = [4.0 / 3.0 * b.material.E_star * math.sqrt(b.shape.feature_length)
             for b in problem.start]

    def carried(gap: float) -> float:
        return math.fsum(k * (0.5 * (t - gap)) ** 1.5 for k, t in zip(stiff, tops, strict=True)
                         if t > gap)

    tallest = tops.index(top)
    delta = (problem.force / stiff[tallest]) ** (2.0 / 3.0)     # one plate's Hertz approach
    low, high = top - 2.0 * delta, top          # the tallest alone carries F_N at low
    for _ in range(60):
        mid = 0.5 * (low + high)
        if carried(mid) > problem.force:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)


def _iterate(problem: _Problem, h: float, phase_one: bool = True,
             learn: bool = False, guess=None) -> ClusterResult:
    """The Newton iteration with its trust region (module docstring). A step starts (if
    ``phase_one``) with a phase that holds the rotations: far from equilibrium (the first pass
    of a step: the plate moved, new contacts carry nothing yet) the model's moments are
    unreliable, since the geometric stiffness that decides which way a particle rolls scales
    with contact forces that are still wrong; so the particles and the plate first move until
    the forces balance within :data:`_PHASE_ONE_TOL` of the force scale, then everything
    moves. That phase can also lead astray (:func:`solve_cluster` retries without it); an
    attempt with it is abandoned when it stalls (:func:`_stalled`). ``learn``: each particle's
    model is corrected by what the trials showed (:func:`_learn`), the last attempt.
    ``guess``: the predicted (n, 6) motion in the internal order and the gap, where the first
    pass evaluates if its residual is below :data:`GUESS_LIMIT` (:func:`solve_cluster`)."""
    numerics = problem.numerics
    centres = np.array([b.centre for b in problem.start], dtype=float)
    rotations = [b.rotation for b in problem.start]
    ev = None
    carried = None          # the particles the guess moved (until strays are released)
    if guess is not None:
        try:
            ev = problem.evaluate(*_moved(centres, rotations, guess[0]), guess[1], None)
        except (ContactAtEdgeError, ConvergenceError, RuntimeError, ValueError):
            problem.guessed = (1, 0)
        else:
            if _converged(problem, ev, numerics.tol)[1] > GUESS_LIMIT:
                problem.guessed, ev = (1, ev.solves), None
            else:
                carried = np.abs(guess[0]).max(axis=1) > 0
    # a guess within the tolerance still takes one Newton step: without it the step would stop
    # wherever the guess fell within tol, where from the start poses the last pass lands far
    # below it (a flat ellipsoid sliding steadily went on dilating 1.3e-3 of its dilatancy a
    # step, against 5e-8 from the start poses)
    polish = ev is not None
    if ev is None:
        ev = problem.evaluate(centres, rotations, h, None)
    solves = ev.solves
    radius = numerics.radius
    merit_scale = ev.scale if ev.scale > 0 else (problem.force or 1.0)
    R, plate = _residual_vector(problem, ev)
    translate = phase_one and \
        _force_residual(problem, ev, ev.scale or merit_scale) > _PHASE_ONE_TOL
    problem.phase_one_used = translate
    problem.correction = {}
    phase_passes = phase_end = 0
    merit = _merit(problem, R, plate, merit_scale, translate)
    log = []
    model = None
    full = dh_full = None
    damped: list = []
    for _iteration in range(numerics.max_iterations):
        done, worst = _converged(problem, ev, numerics.tol)
        strays = _strays(problem, ev, carried) if done else []
        if strays:
            # converged, but with particles that only the guess moved and that nothing
            # touches: put them back where the step started them and go on from there
            log.append((worst, merit, radius, True))
            carried, polish, model = None, False, None
            ev = _released(problem, ev, strays)
            solves += ev.solves
            R, plate = _residual_vector(problem, ev)
            merit = _merit(problem, R, plate, merit_scale, translate)
            continue
        if done and not polish:
            log.append((worst, merit, radius, True))
            return _result(problem, ev, worst, len(log), solves, log)
        if problem.phase_one_used and not translate and _stalled(log[phase_end:]):
            problem.failed = (len(log), solves)
            raise ClusterConvergenceError(
                f"cluster equilibrium stalled after the rotation-free phase: largest scaled "
                f"residual {worst:.3e} > tol {numerics.tol:.1e} after {len(log)} passes"
                f"{_beyond_half_space(problem, ev)}")
        if translate and (phase_passes >= _PHASE_ONE_PASSES or _force_residual(
                problem, ev, ev.scale or merit_scale) <= _PHASE_ONE_TOL):
            translate = False
            phase_end = len(log)
            merit = _merit(problem, R, plate, merit_scale)
            radius = numerics.radius
            model = None
        t0 = time.perf_counter()
        if model is None:
            terms = _terms(problem, ev)
            damped = []
            full, dh_full, model, active = _newton_step(
                problem, terms, R, plate, merit_scale, translate,
                radius if _LEVENBERG_MARQUARDT else None, damped)
        if dh_full == 0.0 and not full.any():
            break           # the model sees no way down: the trial would be this state again
        step, dh, clipped = _limit(problem, terms, active, ev.scale or merit_scale, full,
                                   dh_full, radius)
        # a damped group's step depends on the radius: it counts as cut by the trust region,
        # and a new radius needs a new step
        clipped = clipped or bool(damped)
        out, plate_out, _, step_active, step_laws = _piecewise(problem, terms, R, plate,
                                                               step, dh)
        predicted = _merit(problem, out, plate_out, merit_scale, translate)
        problem.timings["newton"] += time.perf_counter() - t0
        trial_centres, trial_rotations = _moved(ev.centres, ev.rotations, step)
        last = {c.key: c for c in ev.contacts}
        try:
            trial = problem.evaluate(trial_centres, trial_rotations, ev.h + dh, last)
        except (ContactAtEdgeError, ConvergenceError, RuntimeError, ValueError) as exc:
            log.append((worst, merit, radius, False))
            radius *= 0.25
            if damped:
                model = None
            if radius < numerics.min_radius:
                problem.failed = (len(log), solves)
                raise ClusterConvergenceError(
                    f"cluster equilibrium: a contact could not be solved at the trial poses "
                    f"({exc}); residual {worst:.3e} > tol {numerics.tol:.1e}"
                    f"{_beyond_half_space(problem, ev)}") from exc
            continue
        solves += trial.solves
        phase_passes += translate
        R_trial, plate_trial = _residual_vector(problem, trial)
        learnt = False
        if learn:
            Rs = _scaled(problem, R, plate, ev.scale or merit_scale)[0]
            learnt = _learn(problem, ev, trial, terms, step_active, step_laws, R, R_trial, out,
                            step, np.abs(Rs).max(axis=1) > numerics.tol)
        merit_trial = _merit(problem, R_trial, plate_trial, merit_scale, translate)
        done_trial, _ = _converged(problem, trial, numerics.tol)
        fall = merit - merit_trial
        expected = merit - predicted
        accepted = done_trial or fall > 0
        log.append((worst, merit, radius, accepted))
        if accepted:
            ratio = fall / expected if expected > 0 else 0.0
            if ratio > 0.5 and clipped:
                radius = min(2.0 * radius, 4.0)
            elif ratio < 0.25:
                radius *= 0.5
            ev, R, plate, merit = trial, R_trial, plate_trial, merit_trial
            model = None
            polish = False
        elif polish and done:
            break           # the guess is within tol and its Newton step did not improve it
        else:
            radius *= 0.25
            if _SKIP_REPEATS and not learnt and not clipped:
                # the trust region did not cut this step, so at the quartered radius the trial
                # would be the same poses, evaluated and rejected again (the 12-sphere step
                # above spent 14 of its passes so): quarter on to the first radius that cuts it
                while radius >= numerics.min_radius and not _limit(
                        problem, terms, active, ev.scale or merit_scale, full, dh_full,
                        radius)[2]:
                    radius *= 0.25
            if radius < numerics.min_radius:
                break
            if learnt or damped:
                model = None        # the model learnt from the trial, or the damped step
                #                     depends on the radius: the step again
    done, worst = _converged(problem, ev, numerics.tol)
    if done:
        return _result(problem, ev, worst, len(log), solves, log)
    problem.failed = (len(log), solves)
    if not ev.contacts and problem.force is not None:
        raise ClusterConvergenceError(
            f"cluster equilibrium did not converge in {len(log)} passes: at the last poses "
            f"nothing carries F_N = {problem.force:.4g} N{_why_nothing_touches(problem, ev)}")
    k = int(np.argmax(np.abs(_scaled(problem, *_residual_vector(problem, ev), ev.scale or 1.0
                                     )[0]).max(axis=1)))
    raise ClusterConvergenceError(
        f"cluster equilibrium did not converge in {len(log)} passes: largest scaled residual "
        f"{worst:.3e} > tol {numerics.tol:.1e} (particle {problem.order[k]}: force "
        f"{np.linalg.norm(ev.forces[k]):.3e} N, moment {np.linalg.norm(ev.moments[k]):.3e} N m; "
        f"trust radius {radius:.1e} rad){_beyond_half_space(problem, ev)}")


def _plate_depth(body: Body, side: str, h: float) -> tuple[float, np.ndarray]:
    """(How far the rigid ``body`` reaches through the plate on ``side``, m (> 0: overlap),
    its extreme point towards that plate relative to its centroid, m), the upper plate at
    height ``h``."""
    extreme = (body.shape.lowest_point(body.rotation) if side == "lower"
               else body.shape.highest_point(body.rotation))
    z = float(body.centre[2] + extreme[2])
    return (-z if side == "lower" else z - h), extreme


def _why_nothing_touches(problem: _Problem, ev: _Evaluation) -> str:
    """The end of the error of a step left with no contact: whether the shapes still overlap a
    plate (then each overlap is below the surface's sag between cell centres: a contact
    smaller than a cell, or an extreme point between cells) or the plates have left them."""
    bodies = [problem.body(k, ev.centres, ev.rotations) for k in range(problem.n)]
    overlap = max(_plate_depth(b, side, ev.h)[0] for b in bodies for side in PLATES)
    if overlap > 0:
        return (f": the particles overlap the plates (by up to {overlap:.3g} m), but by less "
                f"than the surface's sag from their extreme point to the nearest cell centre, "
                f"so no cell touches (a contact smaller than a cell): more cells per particle "
                f"size (numerics.resolution) or a larger load step resolves it")
    return ": the plates have moved off every particle"


def _strays(problem: _Problem, ev: _Evaluation, carried: np.ndarray | None) -> list[int]:
    """The particles (internal order) that the step's guess moved and that no solved contact
    touches at ``ev``: nothing holds them where the prediction put them. A particle pushed in
    the last step and free in this one would otherwise go on moving by the predicted motion
    every step (a potato of ``make shear`` slid 20 µm a step for 38 steps after it parted
    from its neighbour, rising 12 nm a step)."""
    if carried is None or not carried.any():
        return []
    touched = np.zeros(problem.n, dtype=bool)
    for c in ev.contacts:
        touched[[c.key[0]] if isinstance(c.contact, PlateContact) else list(c.roles)] = True
    return [int(k) for k in np.flatnonzero(carried & ~touched)]


def _released(problem: _Problem, ev: _Evaluation, strays: list[int]) -> _Evaluation:
    """The contacts evaluated again with the ``strays`` back at the step's start poses (free
    particles are left where they were; one that now touches a neighbour is solved)."""
    centres = np.array(ev.centres, dtype=float)
    rotations = list(ev.rotations)
    for k in strays:
        centres[k] = problem.start[k].centre
        rotations[k] = problem.start[k].rotation
    return problem.evaluate(centres, rotations, ev.h, {c.key: c for c in ev.contacts})


def _beyond_half_space(problem: _Problem, ev: _Evaluation) -> str:
    """The end of a convergence error when the last poses' largest contact is past the
    half-space limit (a/R, :data:`HALF_SPACE_LIMIT`): the step asks for more than the contact
    model holds, and that is the likelier cause than the iteration (the 53 potatoes' step to
    14 % compression pressed the tallest with 73 N, its plate contacts at a/R ≈ 0.4)."""
    limit = problem.numerics.half_space_limit
    worst, where = 0.0, None
    tilt, tilted = 0.0, None
    for c in ev.contacts:
        ratio = c.contact.half_space_ratio
        if ratio > worst:
            worst, where = ratio, problem.user_key(c.key)
        spot = getattr(c.contact, "spot_tilt", 0.0)
        if spot > tilt:
            tilt, tilted = spot, problem.user_key(c.key)
    out = ""
    if worst > limit:
        out += (f"; contact {where} has a/R = {worst:.2g} > {limit:.2g}, out of the "
                f"half-space model's range: lower the load or the compression")
    if math.tan(tilt) > limit:
        out += (f"; contact {tilted} has a spot facing {math.degrees(tilt):.3g}° away from its "
                f"normal, kept in its frame (too close to be a contact of its own): its force "
                f"is taken along that normal")
    below = [(p.overlap, problem.user_key(p.roles)) for p in ev.potential if p.overlap > 0]
    if below:
        depth, key = max(below, key=lambda t: t[0])
        out += (f"; {len(below)} contact(s) overlap by less than their cells resolve (the "
                f"deepest, {key}, by {depth:.3g} m: the surface's sag from its extreme point to "
                f"the nearest cell centre is more), so their law jumps from nothing to a cell's "
                f"stiffness: more cells per particle size (numerics.resolution) or a larger "
                f"load step resolves them")
    problem.beyond = out or problem.beyond
    return out


# --- the result ----------------------------------------------------------------------------
def _result(problem: _Problem, ev: _Evaluation, worst: float, passes: int, solves: int,
            log) -> ClusterResult:
    n = problem.n
    numerics = problem.numerics
    order = problem.order
    bodies = [None] * n
    translation = np.zeros((n, 3))
    rotation = np.zeros((n, 3))
    forces = np.zeros((n, 3))
    moments = np.zeros((n, 3))
    for k in range(n):
        u = order[k]
        b = problem.body(k, ev.centres, ev.rotations)
        bodies[u] = b
        translation[u] = b.centre - problem.start[k].centre
        rotation[u] = (b.rotation * problem.start[k].rotation.inv()).as_rotvec()
        forces[u] = ev.forces[k]
        moments[u] = ev.moments[k]
    histories = {}
    reports = []
    touched = [[] for _ in range(n)]
    upper, lower = [], []
    for c in ev.contacts:
        s = c.contact
        key = problem.user_key(c.key)
        if isinstance(s, PlateContact):
            k = c.key[0]
            roles = (order[k], c.key[1])
            touched[order[k]].append(s.sliding)
            (upper if c.key[1] == "upper" else lower).append(s.force)
            reports.append(ContactReport(
                key=key, i=order[k], j=c.key[1], normal=s.normal, force=s.force,
                normal_force=s.normal_force, tangential_force=s.tangential_force,
                point=s.pressure_centroid, moment_i=s.moment, moment_j=np.zeros(3),
                approach=s.approach, area=s.area, stick_area=s.stick_area, spots=s.spots,
                slip=np.append(s.slip, 0.0), shift_increment=np.append(s.shift_increment, 0.0),
                sliding=s.sliding, state="slide" if s.sliding else "stick",
                half_space_ratio=s.half_space_ratio, mu=s.mu))
            ratio = s.half_space_ratio
        else:
            a, b = c.roles
            roles = (order[a], order[b])
            sliding = not bool(s.stick.any())
            touched[order[a]].append(sliding)
            touched[order[b]].append(sliding)
            i = key[0]
            flip = roles[0] != i                  # i is body b
            sign = -1.0 if flip else 1.0
            # the solved contact lies where its body a is; seen from i, near i: when i is body
            # b, placed at the image c_i − image L that meets a (key: c_j + image L meets c_i),
            # the point moves by image L
            point = s.pressure_centroid + (_shift(key[2], problem.box) if flip else 0.0)
            reports.append(ContactReport(
                key=key, i=i, j=key[1], normal=sign * s.normal, force=sign * s.force_on_a,
                normal_force=s.normal_force, tangential_force=sign * s.tangential_force,
                point=point, moment_i=s.moment_b if flip else s.moment_a,
                moment_j=s.moment_a if flip else s.moment_b, approach=s.approach,
                area=s.area, stick_area=s.stick_area, spots=s.spots, slip=sign * s.slip,
                shift_increment=sign * s.shift_increment, sliding=sliding,
                state="slide" if sliding else "stick", half_space_ratio=s.half_space_ratio,
                mu=s.mu, spot_tilt=s.spot_tilt))
            ratio = s.half_space_ratio
            if math.tan(s.spot_tilt) > numerics.half_space_limit:
                warnings.warn(HalfSpaceWarning(
                    f"contact {key}: a spot faces {math.degrees(s.spot_tilt):.3g}° away from "
                    f"the contact's normal (tan > {numerics.half_space_limit:.3g}): its force "
                    f"is taken along that normal, and friction carries the difference"),
                    stacklevel=3)
        if ratio > numerics.half_space_limit:
            warnings.warn(HalfSpaceWarning(
                f"contact {key}: contact radius / radius of curvature = {ratio:.3g} > "
                f"{numerics.half_space_limit:.3g}: out of the half-space model's range"),
                stacklevel=3)
        histories[key] = ContactHistory(key, roles, s)
    kinematics = []
    for u in range(n):
        slides = touched[u]
        if not slides:
            kinematics.append("free")
        elif all(slides):
            kinematics.append("slide")
        elif any(slides):
            kinematics.append("roll")
        elif np.linalg.norm(rotation[u]) > numerics.stick_rotation:
            kinematics.append("roll")
        else:
            kinematics.append("stick")
    reports.sort(key=lambda r: _sort_key(r.key))

    def total(vectors):
        if not vectors:
            return np.zeros(3)
        V = np.array(vectors)
        return np.array([math.fsum(V[:, d]) for d in range(3)])

    return ClusterResult(
        bodies=tuple(bodies), translation=translation, rotation=rotation,
        histories=dict(sorted(histories.items(), key=lambda kv: _sort_key(kv[0]))),
        gap=float(ev.h), plate_force=total(upper), lower_force=total(lower),
        contacts=tuple(reports), force_residual=forces, moment_residual=moments,
        residual=float(worst), force_scale=float(ev.scale), kinematics=tuple(kinematics),
        iterations=passes + problem.failed[0] + problem.guessed[0],
        bem_solves=solves + problem.failed[1] + problem.guessed[1],
        history=tuple(log),
        timings=dict(problem.timings), tol=numerics.tol)


def _sort_key(key: tuple):
    if len(key) == 2:
        return (key[0], 1, PLATES.index(key[1]), 0, 0, 0)
    return (key[0], 0, key[1], key[2][0], key[2][1], *key[3:])


def wrap(result_bodies: Sequence[Body], histories: Mapping, box) -> tuple[list[Body], dict]:
    """Move every centroid into the box [0, L_x) x [0, L_y) and rename the pair histories'
    keys to the images that then meet (the contacts and their histories are unchanged)."""
    box = (float(box[0]), float(box[1]))
    moved = []
    jumps = []
    for b in result_bodies:
        c = np.array(b.centre, dtype=float)
        m = [math.floor(c[0] / box[0]), math.floor(c[1] / box[1])]
        for k in (0, 1):
            c[k] -= m[k] * box[k]
            if c[k] >= box[k]:      # −1e-19 + L rounds to L: the particle is at 0, unmoved
                c[k], m[k] = 0.0, m[k] + 1
        moved.append(b.moved(centre=c))
        jumps.append(tuple(m))
    out = {}
    for key, hist in histories.items():
        if len(key) >= 3:
            i, j, image, *part = key
            # c_j + image L meets c_i; after the moves c_j' = c_j − m_j L, c_i' = c_i − m_i L
            new = (image[0] + jumps[j][0] - jumps[i][0], image[1] + jumps[j][1] - jumps[i][1])
            key = (i, j, new, *part)
            solved = hist.solved
            # the stored bodies move with their particles (same image relation)
            shift_a = np.array([-jumps[hist.roles[0]][0] * box[0],
                                -jumps[hist.roles[0]][1] * box[1], 0.0])
            solved = _translated(solved, shift_a)
            hist = ContactHistory(key, hist.roles, solved)
        else:
            i = key[0]
            shift = np.array([-jumps[i][0] * box[0], -jumps[i][1] * box[1], 0.0])
            hist = ContactHistory(key, hist.roles, _translated(hist.solved, shift))
        out[key] = hist
    return moved, out


def _translated(solved, shift: np.ndarray):
    """A solved contact with every world position moved by ``shift`` (m)."""
    from dataclasses import replace

    if isinstance(solved, PlateContact):
        return replace(solved, body=solved.body.moved(centre=solved.body.centre + shift),
                       pressure_centroid=solved.pressure_centroid + shift)
    return replace(solved, a=solved.a.moved(centre=solved.a.centre + shift),
                   b=solved.b.moved(centre=solved.b.centre + shift),
                   origin=solved.origin + shift,
                   pressure_centroid=solved.pressure_centroid + shift)
