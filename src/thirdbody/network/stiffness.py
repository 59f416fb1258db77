"""A model of a solved contact's wrench as a function of the rigid motions of its two bodies:
what the network's Newton iteration (:mod:`~thirdbody.network.cluster`) predicts with, the BEM
being the corrector.

A contact between bodies a and b (b may be a plate) with unit normal n (from a to b) exerts on
a the force f = −N n + T at the pressure centroid x_p and the moment m n about the normal
(the tractions' twist), so that about a's centroid c_a

    M_a = (x_p − c_a) × f + m n,        F_b = −f,        M_b = −(x_p − c_b) × f − m n.

For virtual motions (du, dφ) of both bodies, the relative motion of b's material point at x_p
is dt = du_b + dφ_b × (x_p − c_b) − du_a − dφ_a × (x_p − c_a), the relative rotation
dψ = dφ_b − dφ_a, the approach changes by dδ = −n·dt and the tangential relative displacement is
ds = P dt (P = I − n nᵀ). The contact law, modelled from the last BEM solve:

* normal: dN = k_n dδ with k_n = 3N/(2δ) (Hertz: N ∝ δ^(3/2); δ the approach from first
  touch);
* tangential: Coulomb's law as an elastic predictor and a return to the friction cone: the trial
  force T + k ds must satisfy |T + k ds| <= μ(N + dN), else the contact slides with
  μ(N + dN) along the trial. The stiffness k is Mindlin's partial-slip one, k₀ c/a with
  k₀ = 8a/Σ(2 − ν_i)/G_i (Johnson 1985, §7.2) and c/a = √(A_stick/A) the stick zone's share
  (for Cattaneo-Mindlin c/a = (1 − Q/μN)^(1/3) and the tangent stiffness is k₀ (1 − Q/μN)^(1/3)),
  whichever way the predicted motion goes from the current iterate (the BEM solves the step
  as one increment from its start, so a motion back is less loading in the step, not an
  unloading: measured on a tilted potato at |T|/μN = 0.9, the residual's derivatives the
  same for ±1 nm and ±10⁻⁶ rad; Mindlin-Deresiewicz's k₀ after a reversal was the model's
  choice for a motion back until then, 2 to 6 times stiffer than the BEM); k₀ when a sliding
  contact's slip reverses. A sliding contact whose slip
  goes on keeps its force T, scaled by (N + dN)/N, turning with stiffness μN/|slip| across
  its slip. That is the BEM's own T, not μN along the mean slip: cell by cell the traction
  follows the local slip, so |T| falls short of μN and T turns off the mean slip by amounts
  that grow with the grid's detail (2 × 10⁻⁴ μN for the pairs of a hexagonal lattice of
  spheres at 60 cells per size). A model that jumped to μN along the slip at a zero step
  differed from the residual it linearised by that much, and Newton's iteration stalled
  there (scaled residual 2.2 × 10⁻⁵ > tol 10⁻⁵, steps of 10⁻¹³ m predicted to remove it);
  one
  whose slip reverses is the return to the cone of the elastic predictor from the start of
  the step, T + k₀ (ds + s_slip) with s_slip its slip in the step (the BEM solves the step as
  one increment, so the force stays μN until the reversal has taken the slip back). In
  partial slip the force also grows with N at a fixed shift (the contact grows): Cattaneo-
  Mindlin's dT/dN (:meth:`ContactModel._stick_normal`). The caller (the active set of
  :mod:`~thirdbody.network.cluster`) picks the branch from the predicted motion and
  linearises it there (:meth:`ModelStack.laws`);
* twist: dm = k_w n·dψ with Lubkin's (16/3) a³/Σ(1/G_i) times (c/a)³ (0 while sliding);

and the geometry of the rigid bodies (Montana's contact kinematics, to first order): relative to
a's material the contact point moves in the tangent plane by ξ = H⁺ (K_b P dt − n × dψ), with
K_a, K_b the curvature tensors of the two surfaces at the contact and H = K_a + K_b, and the
normal turns by dn = dφ_a × n + K_a ξ. So a particle that rolls about one contact while the
other slides has stiffness only from how its contacts migrate over its surface and how its
height changes: the moment the geometry leaves unbalanced drives it, as in the one-particle
turn.

All quantities SI, world frame; a contact's blocks are (6, 12) arrays (stacked over the
contacts in :class:`ModelStack`): rows (force, moment) on a or b, columns
(du_a, dφ_a, du_b, dφ_b).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["ContactModel", "ModelStack", "TangentialLaws", "cross", "cross_rows", "skew"]

#: a stick contact's tangential stiffness is its partial-slip tangent both ways (False: k0 for a
#: motion back from the current iterate, the former choice)
_TANGENT_BOTH_WAYS = True

#: a slip's tangential part below this share of the whole slip is taken as none (rounding)
_SLIP_ROUNDING = 1e-12
_I = np.eye(3)
_O = np.zeros((3, 3))


def skew(v) -> np.ndarray:
    """The matrix [v]× with [v]× w = v × w."""
    x, y, z = (float(c) for c in v)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def cross(u, v) -> np.ndarray:
    """u × v of two 3-vectors (np.cross costs ~30x more on a single pair: the Newton model
    takes hundreds of thousands of them per step of a dense layer)."""
    a, b, c = (float(x) for x in u)
    d, e, f = (float(x) for x in v)
    return np.array([b * f - c * e, c * d - a * f, a * e - b * d])


@dataclass(frozen=True)
class TangentialLaws:
    """Linearised branches of the tangential laws of m contacts (:meth:`ModelStack.laws`):
    T_model = T + stiffness ds + g dN + offset per contact, with ``stiffness`` (m, 3, 3), ``g``
    (m, 3) and ``offset`` (m, 3) world, SI; ``slide`` (m,) bool: the slide branch (else stick)."""

    stiffness: np.ndarray
    g: np.ndarray
    offset: np.ndarray
    slide: np.ndarray

    def where(self, mask: np.ndarray, other: TangentialLaws) -> TangentialLaws:
        """These laws with ``other``'s where ``mask`` (m,) is true."""
        return TangentialLaws(np.where(mask[:, None, None], other.stiffness, self.stiffness),
                              np.where(mask[:, None], other.g, self.g),
                              np.where(mask[:, None], other.offset, self.offset),
                              np.where(mask, other.slide, self.slide))


@dataclass(frozen=True)
class ContactModel:
    """A contact's wrench and its model, from its last BEM solve (module docstring).

    Attributes
    ----------
    normal : (3,) array
        Unit normal from a to b.
    point : (3,) array
        Pressure centroid x_p, m.
    centre_a, centre_b : (3,) arrays
        The bodies' centroids (b: any point for a plate), m.
    normal_force : float
        N, N.
    tangential_force : (3,) array
        T on a, N.
    twist_moment : float
        m, N m.
    k_normal : float
        N/m.
    mu : float
    k_loading : float
        Tangential stiffness while loading further (Mindlin's k₀ c/a), N/m.
    k_stick : float
        k₀, N/m: unloading, or after a reversal.
    slip_direction : (3,) array or None
        The direction a sliding contact slides in (b over a), None if it has stick cells.
    k_across : float
        μN/|slip| of a sliding contact, N/m.
    k_twist : float
        N m/rad.
    curvature_a, curvature_b : (3, 3) arrays
        Curvature tensors on the tangent plane, world, 1/m.
    slipped : (3,) array or None
        A sliding contact's slip in the step (the mean slip increment of b over a, in the
        tangent plane), m: how far its shift must go back before it sticks again (the BEM
        solves one increment from the start of the step), None if it has stick cells.
    """

    normal: np.ndarray
    point: np.ndarray
    centre_a: np.ndarray
    centre_b: np.ndarray
    normal_force: float
    tangential_force: np.ndarray
    twist_moment: float
    k_normal: float
    mu: float
    k_loading: float
    k_stick: float
    slip_direction: np.ndarray | None
    k_across: float
    k_twist: float
    curvature_a: np.ndarray
    curvature_b: np.ndarray
    mid_a: np.ndarray | None = None
    mid_b: np.ndarray | None = None
    turn_a: np.ndarray | None = None
    turn_b: np.ndarray | None = None
    fraction: float = 1.0
    touch: np.ndarray | None = None
    slipped: np.ndarray | None = None

    def stepping(self, *, mid_a, mid_b, turn_a, turn_b, fraction: float) -> ContactModel:
        """The same model with the kinematics of the step's shift increment (the evaluation's
        :func:`~thirdbody.network.plate.solve_plate` and the cluster's pair shift): levers
        ``mid_a``, ``mid_b`` (m) at the middle of the step, the bodies' rotation vectors since
        the start of the step ``turn_a``, ``turn_b`` (rad), and the share of the motion the
        contact sees."""
        return replace(self, mid_a=np.asarray(mid_a, dtype=float),
                       mid_b=np.asarray(mid_b, dtype=float),
                       turn_a=np.asarray(turn_a, dtype=float),
                       turn_b=np.asarray(turn_b, dtype=float), fraction=float(fraction))

    @classmethod
    def of(cls, *, normal, point, centre_a, centre_b, normal_force, tangential_force,
           twist_moment, approach, area, stick_area, mu, slip, compliance, torsion,
           curvature_a, curvature_b, sliding) -> ContactModel:
        """The model of a solved contact.

        ``compliance`` is Σ(2 − ν_i)/G_i (1/Pa) and ``torsion`` Σ 1/G_i (1/Pa) over the elastic
        bodies; ``slip`` the mean slip increment of b over a (world, m); ``sliding``: no stick
        cell (with μ > 0)."""
        n = np.asarray(normal, dtype=float)
        P = _I - np.outer(n, n)
        N = float(normal_force)
        radius = math.sqrt(max(area, 0.0) / math.pi)
        k0 = 8.0 * radius / compliance
        kn = 1.5 * N / approach if approach > 0 else 0.0
        T = np.asarray(tangential_force, dtype=float)
        direction = None
        slipped = None
        across = 0.0
        share = 0.0
        if mu <= 0 or N <= 0:
            k0 = 0.0
        elif sliding:
            raw = np.asarray(slip, dtype=float)
            s = raw @ P
            length = float(np.linalg.norm(s))
            if length <= _SLIP_ROUNDING * float(np.linalg.norm(raw)):
                # a slip along the normal: what its projection leaves is rounding (2e-23 m of
                # a 3e-7 m slip with numpy 2.4), not a direction
                s, length = np.zeros(3), 0.0
            if length > 0:
                direction = s / length
            elif np.linalg.norm(T) > 0:
                direction = T / np.linalg.norm(T)
            else:
                direction = P @ np.array([1.0, 0.0, 0.0])
                direction /= np.linalg.norm(direction)
            across = k0 if length == 0 else min(mu * N / length, k0)
            slipped = s
        else:
            share = math.sqrt(max(stick_area, 0.0) / area) if area > 0 else 0.0
        kw = 16.0 / 3.0 * radius**3 / torsion * share**3
        return cls(n, np.asarray(point, dtype=float), np.asarray(centre_a, dtype=float),
                   np.asarray(centre_b, dtype=float), N, T, float(twist_moment), kn, float(mu),
                   k0 * share, k0, direction, across, kw,
                   np.asarray(curvature_a, dtype=float), np.asarray(curvature_b, dtype=float),
                   slipped=slipped)

    @classmethod
    def spring(cls, *, normal, point, centre_a, centre_b, stiffness: float,
               tangential: float = 0.0, mu: float = 0.0) -> ContactModel:
        """A contact that is open now: the normal stiffness (N/m) and tangential stick
        stiffness (N/m) it would have once closed, no force."""
        zero = np.zeros((3, 3))
        return cls(np.asarray(normal, dtype=float), np.asarray(point, dtype=float),
                   np.asarray(centre_a, dtype=float), np.asarray(centre_b, dtype=float), 0.0,
                   np.zeros(3), 0.0, float(stiffness), float(mu), float(tangential),
                   float(tangential), None, 0.0, 0.0, zero, zero)

    @property
    def sliding(self) -> bool:
        return self.slip_direction is not None

    def _stick_normal(self) -> np.ndarray:
        """dT/dN at a fixed shift of a contact in partial slip (3,): Cattaneo-Mindlin's
        T = μN [1 − (1 − u)^(3/2)] with u = s/s*, s* ∝ N^(2/3), gives
        dT/dN = μ [q − u (1 − q)^(1/3)] along T, q = |T|/(μN), u = 1 − (1 − q)^(2/3)
        (T/(3N) for a small load ratio: the stick stiffness grows with the contact radius)."""
        T = self.tangential_force
        size = float(np.linalg.norm(T))
        if size == 0 or self.normal_force <= 0 or self.mu <= 0:
            return np.zeros(3)
        q = min(size / (self.mu * self.normal_force), 1.0)
        u = 1.0 - (1.0 - q) ** (2.0 / 3.0)
        return self.mu * (q - u * (1.0 - q) ** (1.0 / 3.0)) * T / size


def _stack(values, shape: tuple) -> np.ndarray:
    """``values`` (a sequence of arrays of ``shape``) as one (m, *shape) float array."""
    return np.array(values, dtype=float).reshape((len(values), *shape))


def _dots(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise u_i · v_i (m,) of (m, k) arrays (as ``u[i] @ v[i]``, bit for bit)."""
    return np.matmul(u[:, None, :], v[:, :, None])[:, 0, 0]


def _apply(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise A_i v_i (m, r) of (m, r, k) and (m, k) arrays (as ``A[i] @ v[i]``)."""
    return np.matmul(A, v[:, :, None])[:, :, 0]


def _outer(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise u_i v_iᵀ (m, k, l)."""
    return u[:, :, None] * v[:, None, :]


def cross_rows(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise u_i × v_i (m, 3) (:func:`cross`'s arithmetic)."""
    a, b, c = u[:, 0], u[:, 1], u[:, 2]
    d, e, f = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([b * f - c * e, c * d - a * f, a * e - b * d], axis=1)


def _skews(v: np.ndarray) -> np.ndarray:
    """Row-wise [v_i]× (m, 3, 3)."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -v[:, 2], v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = v[:, 2], -v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -v[:, 1], v[:, 0]
    return out


def _vecmat(v: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Row-wise v_iᵀ A_i (m, k) of (m, r) and (m, r, k) arrays (as ``v[i] @ A[i]``)."""
    return np.matmul(v[:, None, :], A)[:, 0, :]


_PA = np.hstack([_O, _I, _O, _O])       # dφ_a of (du_a, dφ_a, du_b, dφ_b)
_UA = np.hstack([_I, _O, _O, _O])
_UB = np.hstack([_O, _O, _I, _O])
_DPSI = np.hstack([_O, -_I, _O, _I])    # the relative rotation dψ = dφ_b − dφ_a


def _relative_rows(ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """dt (m, 3, 12): b's material point at levers ``ra``, ``rb`` (m, 3) from the centroids
    relative to a's, for (du_a, dφ_a, du_b, dφ_b)."""
    count = len(ra)
    return np.concatenate([np.broadcast_to(-_I, (count, 3, 3)), _skews(ra),
                           np.broadcast_to(_I, (count, 3, 3)), -_skews(rb)], axis=2)


class ModelStack:
    """The models of m contacts stacked (arrays whose first axis runs over the contacts), all
    computed at once (module docstring): the rows of the approach ``approach_rows`` (m, 12) and
    of the shift increment ``tangential_rows`` (m, 3, 12), the blocks of everything but the
    tangential law ``base_a``, ``base_b`` (m, 6, 12), the wrenches of the current forces
    ``wrench_a``, ``wrench_b`` (m, 6), and at any predicted motion the tangential laws
    (:meth:`laws`) and their blocks (:meth:`law_blocks`). The Newton step
    (:mod:`~thirdbody.network.cluster`) stacks its contacts once and evaluates their laws at
    every pass of its active set, where one call per contact and pass cost more than the rest
    of the model (a 100-sphere lattice: 305,000 calls of the per-contact law in two load
    steps)."""

    def __init__(self, models: Sequence[ContactModel]) -> None:
        models = tuple(models)
        count = len(models)
        zero = np.zeros(3)

        def field(name: str, shape: tuple = (3,), default=None) -> np.ndarray:
            values = [getattr(c, name) for c in models]
            return _stack([default if v is None else v for v in values], shape)

        self.sliding = np.array([c.sliding for c in models], dtype=bool)
        self.normal_force = field("normal_force", ())
        self.mu = field("mu", ())
        self.k_stick = field("k_stick", ())
        self.k_loading = field("k_loading", ())
        self.k_across = field("k_across", ())
        self.k_normal = field("k_normal", ())
        self.tangential_force = field("tangential_force")
        #: the slip direction of a sliding contact (zero for one with stick cells)
        self.direction = field("slip_direction", default=zero)
        #: a sliding contact's slip in the step (zero for one with stick cells)
        self.back = _stack([c.slipped if c.sliding and c.slipped is not None else zero
                            for c in models], (3,))
        #: dT/dN at a fixed shift of a contact with stick cells (zero for a sliding one)
        self.stick_g = _stack([zero if c.sliding else c._stick_normal() for c in models], (3,))
        n = field("normal")
        point = field("point")
        centre_a, centre_b = field("centre_a"), field("centre_b")
        touch = _stack([c.point if c.touch is None else c.touch for c in models], (3,))
        curvature_a, curvature_b = field("curvature_a", (3, 3)), field("curvature_b", (3, 3))
        self.normal = n
        self.projector = P = _I - _outer(n, n)
        self.arm_a, self.arm_b = ra, rb = point - centre_a, point - centre_b
        self._skew_a, self._skew_b = _skews(ra), _skews(rb)
        # dδ (m, 12): the relative normal motion at the point of first touch (the closest
        # points of the undeformed surfaces; the pressure centroid if not known): by the
        # envelope theorem the closest points' own migration does not change the separation to
        # first order (the pressure centroid lies a fraction of a cell away, which matters
        # where the motions of a step nearly cancel in the approach: a rotation of the particle
        # against the plates' motion)
        self.approach_rows = -_vecmat(n, _relative_rows(touch - centre_a, touch - centre_b))
        # the contact point's migration over a ξ, the normal's turn dn and the levers' changes
        # (m, 3, 12) (module docstring)
        dt = _relative_rows(ra, rb)
        H = np.matmul(np.matmul(P, curvature_a + curvature_b), P)
        H_plus = np.linalg.pinv(H, rcond=1e-9, hermitian=True)
        skew_n = _skews(n)
        xi = np.matmul(H_plus, np.matmul(np.matmul(curvature_b, P), dt) -
                       np.matmul(skew_n, _DPSI))
        dn = np.matmul(P, np.matmul(-skew_n, _PA) + np.matmul(curvature_a, xi))
        d_ra = np.matmul(-self._skew_a, _PA) + xi
        d_rb = _UA - np.matmul(self._skew_a, _PA) + xi - _UB
        # the shift increment's change (m, 3, 12). Without the step's kinematics ds = P dt.
        # With them (:meth:`ContactModel.stepping`): the evaluated increment is
        # Δs = f P [Δc_b + Δφ_b × r̄_b − Δc_a − Δφ_a × r̄_a] with r̄ = ½(r₀ + r) the levers at
        # the middle of the step, so ds = f P [dt(r̄) + ½ Δφ_b × dr_b − ½ Δφ_a × dr_a], dr the
        # levers' change (the contact point migrates)
        stepping = np.array([c.mid_a is not None for c in models], dtype=bool)
        middle = _relative_rows(field("mid_a", default=zero), field("mid_b", default=zero)) + \
            0.5 * (np.matmul(_skews(field("turn_b", default=zero)), d_rb) -
                   np.matmul(_skews(field("turn_a", default=zero)), d_ra))
        self.tangential_rows = np.where(stepping[:, None, None],
                                        field("fraction", ())[:, None, None] *
                                        np.matmul(P, middle), np.matmul(P, dt))
        self._dN_rows = self.k_normal[:, None] * self.approach_rows
        # the blocks of everything but the tangential law (m, 6, 12): the normal force's
        # change, the rigid geometry (the normal turns, the point migrates, T stays in the
        # tangent plane) and the twist
        N, T = self.normal_force, self.tangential_force
        twist = field("twist_moment", ())
        f = (-N)[:, None] * n + T
        df = -_outer(n, self._dN_rows) - N[:, None, None] * dn - _outer(n, _vecmat(T, dn))
        dm = field("k_twist", ())[:, None] * _vecmat(n, np.broadcast_to(_DPSI, (count, 3, 12)))
        skew_f = _skews(f)
        dMa = np.matmul(-skew_f, d_ra) + np.matmul(self._skew_a, df) + _outer(n, dm) + \
            twist[:, None, None] * dn
        dMb = np.matmul(skew_f, d_rb) - np.matmul(self._skew_b, df) - _outer(n, dm) - \
            twist[:, None, None] * dn
        self.base_a = np.concatenate([df, dMa], axis=1)
        self.base_b = np.concatenate([-df, dMb], axis=1)
        # the wrenches (m, 6) of the current force and twist on a and b
        moment = twist[:, None] * n
        self.wrench_a = np.concatenate([f, cross_rows(ra, f) + moment], axis=1)
        self.wrench_b = np.concatenate([-f, -cross_rows(rb, f) - moment], axis=1)

    def laws(self, ds: np.ndarray, dN: np.ndarray) -> TangentialLaws:
        """Each contact's branch of the tangential law at its predicted tangential displacement
        ``ds`` (m, 3) and normal force change ``dN`` (m,), linearised there (module docstring;
        ``tests/test_network_stiffness.py`` holds the same law written per contact):

        * no friction (μ = 0 or k₀ = 0): no tangential force, the slide branch;
        * a sliding contact whose slip goes on: its force T (N + dN)/N, stiffness μN/|slip|
          across its slip (``k_across``);
        * otherwise the return to the cone of the elastic predictor
          T + k (ds + s_slip) + g dN (k the partial-slip tangent of a contact with stick cells,
          k₀ after a sliding contact's reversal; s_slip a sliding contact's slip in the step,
          g its dT/dN in partial slip): stick inside μ(N + dN), else the slide branch along the
          predictor, turning with stiffness μN k/|predictor| across it."""
        P, T, N, mu = self.projector, self.tangential_force, self.normal_force, self.mu
        frictionless = (mu <= 0) | (self.k_stick <= 0)
        limit = mu * np.maximum(N + dN, 0.0)
        d = self.direction
        along = self.sliding & (_dots(ds, d) >= 0)
        # a contact with stick cells: the tangent of its partial slip, whichever way the step
        # goes (the BEM solves the step as one increment from its start, so a motion back
        # from the current iterate is less loading in the step, not an unloading; measured
        # on a tilted potato at |T|/muN = 0.9: dR/dx the same for +-1 nm, +-1e-6 rad)
        loading = ~self.sliding & (_TANGENT_BOTH_WAYS | (_dots(ds, T) > 0))
        k = np.where(loading, self.k_loading, self.k_stick)
        g = self.stick_g
        # a sliding contact's force is the return to the cone of the elastic predictor from
        # the start of the step, T₀ + k₀ Δs = T + k₀ s_slip: the BEM solves one increment
        # from there, so a reversal first takes back the step's slip at μN before it unloads
        back = self.back
        trial = T + k[:, None] * (ds + back) + g * dN[:, None]
        size = np.sqrt(_dots(trial, trial))
        stick = (size <= limit) | (size == 0)
        safe = np.where(stick, 1.0, size)
        u = trial / safe[:, None]
        muN = mu * N
        across = (muN / safe * k)[:, None, None] * (P - _outer(u, u))
        stiffness = np.where(stick[:, None, None], k[:, None, None] * P, across)
        gain = np.where(stick[:, None], g, mu[:, None] * u)
        offset = np.where(stick[:, None], k[:, None] * back,
                          muN[:, None] * u - _apply(across, ds) - T)
        stiffness = np.where(along[:, None, None],
                             self.k_across[:, None, None] * (P - _outer(d, d)), stiffness)
        # the BEM's force, not μN d: the model must equal the residual it linearises at ds = 0
        # (a contact without load is frictionless, its law zeroed below)
        per_N = 1.0 / np.where(N > 0, N, 1.0)
        gain = np.where(along[:, None], T * per_N[:, None], gain)
        offset = np.where(along[:, None], 0.0, offset)
        off = frictionless[:, None]
        return TangentialLaws(np.where(off[:, :, None], 0.0, stiffness),
                              np.where(off, 0.0, gain), np.where(off, 0.0, offset),
                              frictionless | along | ~stick)

    def elastic(self) -> TangentialLaws:
        """The stick branch of each sliding contact's law (where a Newton step starts it): the
        elastic predictor from the start of the step, T + k₀ (ds + s_slip) (module docstring);
        for a contact with stick cells, from its current force, T + k₀ ds."""
        k = self.k_stick
        return TangentialLaws(k[:, None, None] * self.projector, np.zeros((len(k), 3)),
                              k[:, None] * self.back, np.zeros(len(k), dtype=bool))

    def law_blocks(self, laws: TangentialLaws):
        """The (m, 6, 12) blocks of the laws' dT and the (m, 6) wrenches of their offsets, on a
        and on b: (on_a, on_b, offset_a, offset_b)."""
        dT = np.matmul(laws.stiffness, self.tangential_rows) + _outer(laws.g, self._dN_rows)
        on_a = np.concatenate([dT, np.matmul(self._skew_a, dT)], axis=1)
        on_b = -np.concatenate([dT, np.matmul(self._skew_b, dT)], axis=1)
        c = laws.offset
        return (on_a, on_b, np.concatenate([c, cross_rows(self.arm_a, c)], axis=1),
                -np.concatenate([c, cross_rows(self.arm_b, c)], axis=1))
