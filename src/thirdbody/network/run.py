"""A layer whose particles touch each other: the load steps of a run, each one equilibrium of the
contact network (docs/methods/network.md, design notes §3c, issue 25).

:class:`~thirdbody.Simulation` uses this engine when it is given ``mu_pp`` (the friction
coefficient between particles; the ``[network]`` table of a configuration file). Each load step
is one :func:`~thirdbody.network.cluster.solve_cluster` from the poses, contact histories and
plate gap the last step left (:class:`NetworkState`, which is all a checkpoint holds), and its
result becomes the step's :class:`~thirdbody.records.LayerRecord`: the plates' totals, every
particle's variables (pose, turn, plate forces and contacts, state) and a row of the ``contact``
table per contact (:mod:`thirdbody.schema`, kind "contact").

**Sliding plates** (design notes §3d, :class:`~thirdbody.loading.Slide`): a step whose
:attr:`~thirdbody.loading.LoadStep.shift` is not zero moves the upper plate horizontally by it
(``plate_shift`` of :func:`solve_cluster`); the state carries the plate's position, its path
length and the gap at the end of the compression, and the step records them with the effective
friction (``mu_eff``, ``mu_eff_sliding``) and the dilatancy. Every step also records its energy
balance: the upper plate's work on the particles, the contacts' stored elastic energy and their
frictional dissipation, and the residual (:meth:`NetworkEngine._energy`).

Conventions as in :mod:`~thirdbody.network.cluster`: SI units, the lower plate at z = 0 and the
upper one at z = h. Horizontal positions in the records are the layer's (``x0``, ``y0`` as
placed, ``position`` the centroid's displacement since, not wrapped into a periodic box);
``contact_point`` is on particle i's side of the box in the layer's coordinates.

What a particle did (``state``, :func:`particle_state`): "unloaded" when it touches nothing;
"stick" when every contact has stick cells (it may still turn a little: a tilted particle
pressed between two stuck contacts turns as the plates approach, about dh sin φ / |AB| for
contacts A and B whose line leans φ from the vertical; the paper's model holds it fixed),
unless it turned in a step in which the plate slid: "roll", rolling without slip.
Rolling means turning (by more than ``stick_rotation`` in the step): "roll_upper" /
"roll_lower" when it touches only the plates and turns about the one whose contact sticks
while the other slides, "slide_lower" / "slide_upper" when it does so without turning (carried
by one plate, sliding on the other), "rotate" / "slide" when every contact slides and it turns
/ does not; "roll" / "slide" for the other particles with sticking and sliding contacts.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from .. import schema
from ..loading import LoadStep
from ..records import LayerRecord, StepRecord, _particle_names, _pose, _turn
from .body import Body
from .cluster import ClusterConvergenceError, ClusterNumerics, ClusterResult, solve_cluster, wrap

#: appended to the error of a failed first step of several particles (measured: the first step
#: of touching lattices fails far more often when the plate barely reaches some particles;
#: docs/methods/network.md)
FIRST_STEP_HINT = ("This is the first step from rest, where particles that the plate barely "
                   "reaches are the hardest to balance: a first step that presses the plate "
                   "further into the layer (a larger first force, `start` of a linear_ramp, or "
                   "fewer load steps) converges more often (docs/methods/network.md, \"What "
                   "the first load decides\")")

#: how many times a failed step is halved by default (down to 1/8 of it; measured: the first
#: sliding step of 100 touching spheres, 20 um, converges as 2.5 + 2.5 + 5 + 10 um, and the
#: later 20 um steps in 2-4 passes; docs/methods/network.md, "Cut steps")
CUTBACKS = 3

__all__ = ["CUTBACKS", "NetworkEngine", "NetworkState", "particle_state"]

#: ``contact_j`` of a plate contact
PLATE_INDEX = {"lower": -1, "upper": -2}


@dataclass
class NetworkState:
    """What a network run carries from one step to the next (a checkpoint is this).

    Attributes
    ----------
    bodies : list of Body
        Every particle at its pose at the end of the last step (in a periodic box: wrapped
        into [0, L_x) x [0, L_y)).
    histories : dict
        The contact histories (:attr:`ClusterResult.histories`).
    gap : float or None
        The plate gap at the end of the last step, m (None before the first step).
    displacement : (n, 3) array
        Each centroid's displacement since the start of the run, m (not wrapped).
    plate_shift : (2,) tuple
        The upper plate's horizontal displacement since the start of the run, m.
    sliding_distance : float
        The path length it has slid, m.
    slide_gap : float or None
        The plate gap at the end of the compression (the last step before the plate first
        slid), m; None until it slides.
    slide_direction : (2,) tuple or None
        Unit vector of the last sliding increment; None until the plate slides.
    last_step : _LastStep or None
        The last step's load increment and motion, from which the next step's first pass is
        predicted (:func:`_predicted`); None before the first step.
    """

    bodies: list
    histories: dict = field(default_factory=dict)
    gap: float | None = None
    displacement: np.ndarray | None = None
    # the sliding plate (defaults: a checkpoint written before sliding plates reads as a run
    # whose plate never slid)
    plate_shift: tuple = (0.0, 0.0)
    sliding_distance: float = 0.0
    slide_gap: float | None = None
    slide_direction: tuple | None = None
    # the secant predictor (a checkpoint written before it reads as a run without a last step)
    last_step: _LastStep | None = None


class _LastStep(NamedTuple):
    """What a step predicts the next one from: its load increment and the motion it caused."""

    kind: str               # LoadStep.kind
    value: float            # LoadStep.value at its end (N or the compression)
    normal: float           # the increment of value in the step
    shift: tuple            # the plate's horizontal increment, m
    translation: np.ndarray  # (n, 3) m, each particle's, unwrapped
    rotation: np.ndarray    # (n, 3) rad, world-frame rotation vectors
    gap: float              # the plate gap's change in the step, m


def _predicted(last: _LastStep | None, step: LoadStep, gap: float | None):
    """The ``guess`` of :func:`solve_cluster` for ``step``: the last step's motion and gap
    change times the ratio of the load increments (a secant predictor), when both steps load
    the same way: the same kind and, if the plate slides in either, both slide in the same
    direction at a fixed normal load; else None (a reversal, a change of direction or of
    kind, or the first two steps: the first starts from no gap). In a compression of touching
    spheres the guess starts the first pass about 7 times closer to the equilibrium than the
    start poses do (scaled residual 0.024-0.043 against 0.17-0.33)."""
    if (last is None or gap is None or not math.isfinite(last.gap)
            or last.kind != step.kind):
        return None
    normal = step.value - last.value
    shift, before = np.asarray(step.shift, dtype=float), np.asarray(last.shift, dtype=float)
    size, size_before = float(np.hypot(*shift)), float(np.hypot(*before))
    if size > 0 or size_before > 0:
        if not (size > 0 and size_before > 0 and normal == 0 and last.normal == 0
                and float(shift @ before) > 0.999 * size * size_before):
            return None
        ratio = size / size_before
    elif last.normal != 0 and normal / last.normal > 0:
        ratio = normal / last.normal
    else:
        return None
    return (ratio * last.translation, ratio * last.rotation,
            max(gap + ratio * last.gap, 0.5 * gap))


class _Sliding(NamedTuple):
    """The sliding plate at the end of a step (the :class:`NetworkState` fields of that name)."""

    plate_shift: tuple
    distance: float
    slide_gap: float | None
    direction: tuple | None

    @classmethod
    def after(cls, state: NetworkState, step: LoadStep) -> _Sliding:
        """The plate after ``step`` from ``state`` (before the step)."""
        dx, dy = (float(v) for v in step.shift)
        shift = (state.plate_shift[0] + dx, state.plate_shift[1] + dy)
        length = math.hypot(dx, dy)
        if length == 0:
            return cls(shift, state.sliding_distance, state.slide_gap, state.slide_direction)
        gap = state.slide_gap
        if gap is None:
            if state.gap is None:
                raise ValueError("the upper plate slides in the first load step: compress "
                                 "the layer first (Slide does)")
            gap = state.gap
        return cls(shift, state.sliding_distance + length, gap, (dx / length, dy / length))

    def along(self, result: ClusterResult) -> float:
        """μ_eff along the sliding, positive when the layer resists it: the upper plate's
        force on the particles along the last increment's direction, over F_N (NaN before
        the plate slides)."""
        if self.direction is None or not result.normal_force > 0:
            return math.nan
        e = self.direction
        driving = math.fsum([float(result.plate_force[0]) * e[0],
                             float(result.plate_force[1]) * e[1]])
        return driving / result.normal_force + 0.0

    def dilatancy(self, gap: float) -> float:
        """h − h_c, m: the gap's change since the end of the compression (NaN before)."""
        return math.nan if self.slide_gap is None else gap - self.slide_gap


class _Energy(NamedTuple):
    """The energy terms of a (sub-)step, J (:meth:`NetworkEngine._energy`)."""

    work: float         # the upper plate's work on the particles
    stored0: float      # the contacts' elastic energy at the start
    stored: float       # ... and at the end
    dissipated: float   # their frictional dissipation in the step
    gap_change: float   # Δh, m


class _Part(NamedTuple):
    """A solved (sub-)step: its equilibrium and its energy terms."""

    result: ClusterResult
    energy: _Energy


#: the first step's work from first touch: ∫₀^δ F dδ = (2/5) F δ for F ∝ δ^(3/2) (Hertz)
_FROM_TOUCH = 0.4


def _balance(parts: list[_Energy], step: LoadStep, normal_force: float) -> dict:
    """The step's energy balance from the terms of its sub-steps (one when it was not cut):
    the plate's work and the dissipation summed, the elastic energy at the end, and the
    residual (W − (E_end − E_start) − D) over F_N (|Δs| + |Δh|), F_N at the end (NaN when that
    scale is zero)."""
    work = math.fsum(p.work for p in parts)
    dissipated = math.fsum(p.dissipated for p in parts)
    stored = parts[-1].stored
    scale = normal_force * (math.hypot(*step.shift) + abs(math.fsum(p.gap_change for p in parts)))
    residual = ((work - (stored - parts[0].stored0) - dissipated) / scale if scale > 0
                else math.nan)
    return dict(plate_work=work, elastic_energy=stored, dissipation=dissipated,
                energy_residual=residual)


def _halves(step: LoadStep, state: NetworkState, d0: float) -> tuple[LoadStep, LoadStep]:
    """``step`` from ``state`` as two equal halves: each moves the plate by half the shift,
    the first to the load value midway between the state's and the step's. The state's value
    is the last step's when it was of the same kind, else the state's own (the upper plate's
    normal force, N, or the compression (d₀ − h)/d₀)."""
    if state.last_step is not None and state.last_step.kind == step.kind:
        now = state.last_step.value
    elif step.kind == "force":
        now = -float(_upper_force(state.histories)[2])
    else:
        now = (d0 - state.gap) / d0
    half = tuple(0.5 * float(v) for v in step.shift)
    return (LoadStep(step.kind, now + 0.5 * (step.value - now), half),
            LoadStep(step.kind, step.value, half))


def _upper_force(histories: dict) -> np.ndarray:
    """The upper plate's total force on the particles in ``histories``' solved contacts, N
    (its z component is −F_N)."""
    upper = [h.solved.force for h in histories.values()
             if getattr(h.solved, "side", None) == "upper"]
    return np.array([math.fsum(f[d] for f in upper) for d in range(3)])


def _combined(results: list[ClusterResult]) -> ClusterResult:
    """The equilibrium at the end of the last of ``results`` (consecutive sub-steps), with
    the step's motion: translations summed, rotations composed, and each contact's slip and
    rigid shift increment summed over the sub-steps it was in; passes and BEM solves summed."""
    last = results[-1]
    if len(results) == 1:
        return last
    turn = Rotation.from_rotvec(results[0].rotation)
    for r in results[1:]:
        turn = Rotation.from_rotvec(r.rotation) * turn
    slips: dict = {}
    for r in results:
        for c in r.contacts:
            s, t = slips.get(c.key, (0.0, 0.0))
            slips[c.key] = (s + np.asarray(c.slip), t + np.asarray(c.shift_increment))
    contacts = tuple(dataclasses.replace(c, slip=slips[c.key][0],
                                         shift_increment=slips[c.key][1])
                     for c in last.contacts)
    return dataclasses.replace(
        last, translation=sum(r.translation for r in results),
        rotation=turn.as_rotvec().reshape(last.rotation.shape), contacts=contacts,
        iterations=sum(r.iterations for r in results),
        bem_solves=sum(r.bem_solves for r in results))


class NetworkEngine:
    """The load steps of a layer of touching particles.

    Parameters
    ----------
    layer : Layer
        The particles at their initial poses, resting on the lower plate.
    plates : Plates
        μ_up and μ_low.
    mu_pp : float, mapping or callable
        Friction between particles (:func:`solve_cluster`).
    box : (L_x, L_y), optional
        A periodic box, m: the layer's centroids must lie in [−L_x/2, L_x/2) x [−L_y/2, L_y/2)
        (where :meth:`Layer.random` places them).
    cells : list of float
        Each particle's BEM cell size, m.
    tol : float
        Equilibrium tolerance of each step (:attr:`ClusterNumerics.tol`).
    solver_tol : float
        Tolerance of the BEM solves.
    d0 : float
        The gap at which the tallest particle first touches, m (compression control).
    cutbacks : int
        How many times a step after the first that does not converge is halved (0: never;
        :meth:`step`).
    energy_tol : float, optional
        A step after the first whose energy residual (:func:`_balance`) exceeds it in
        magnitude is solved again in halves too, within the same ``cutbacks`` (None: never).
    """

    def __init__(self, layer, plates, mu_pp, box, cells: list[float], tol: float,
                 solver_tol: float, d0: float, cutbacks: int = CUTBACKS,
                 energy_tol: float | None = None) -> None:
        self.layer, self.plates, self.mu_pp = layer, plates, mu_pp
        self.cutbacks = int(cutbacks)
        self.energy_tol = energy_tol
        self.d0 = d0
        self.box = None if box is None else (float(box[0]), float(box[1]))
        # the cluster's coordinates: the layer's, moved so that a box starts at the origin
        self.origin = np.zeros(3) if self.box is None else np.array(
            [-self.box[0] / 2, -self.box[1] / 2, 0.0])
        if self.box is not None:
            xy = layer.positions
            inside = ((xy >= -np.array(self.box) / 2) & (xy < np.array(self.box) / 2)).all(1)
            if not inside.all():
                i = int(np.flatnonzero(~inside)[0])
                raise ValueError(
                    f"box (network.box) = ({self.box[0]:.4g}, {self.box[1]:.4g}) m: particle {i} "
                    f"at ({xy[i, 0]:.4g}, {xy[i, 1]:.4g}) m lies outside it (centroids must lie "
                    f"in [-L/2, L/2) on each axis)")
        if self.box is not None and not (getattr(layer, "periodic", False)
                                         and layer.box == self.box):
            from ..layer.placement import _first_overlap_across

            shapes = [p.particle.shape for p in layer]
            rotations = [p.particle.orientation for p in layer]
            centres = np.array([(*p.xy, p.height) for p in layer])
            hit = _first_overlap_across(shapes, rotations, centres, self.box)
            if hit is not None:
                raise ValueError(f"box (network.box): particles {hit[0]} and {hit[1]} overlap "
                                 f"through a side of the periodic box (near x = {hit[2]:.4g} m, "
                                 f"y = {hit[3]:.4g} m): move them apart or enlarge the box")
        self.numerics = ClusterNumerics(cell_size=list(cells), tol=tol, solver_tol=solver_tol)

    def initial_state(self) -> NetworkState:
        """Every particle at its initial orientation, resting on the lower plate or at its
        height ``z``."""
        bodies = []
        for placed in self.layer:
            p = placed.particle
            rotation = p.orientation
            centre = np.array([placed.xy[0], placed.xy[1], placed.height]) - self.origin
            bodies.append(Body(p.shape, p.material, rotation, centre))
        return NetworkState(bodies, {}, None, np.zeros((len(bodies), 3)))

    def step(self, k: int, step: LoadStep, state: NetworkState) -> LayerRecord:
        """Solve load step ``k`` from ``state`` (replaced in place by the step's end). Raises
        :class:`~thirdbody.network.cluster.ClusterConvergenceError` (or ValueError for bad
        geometry) when the step cannot be solved; ``state`` is then unchanged.

        A step after the first that does not converge is solved again as two halves, each
        half that fails as two halves again, down to 1/2^``cutbacks`` of the step
        (:meth:`_parts`); the step's record is then its end, with the motion, slips and
        energies summed over the sub-steps and ``network_substeps`` saying how many there
        were; the next step is predicted from the last sub-step (:func:`_predicted`)."""
        t0 = time.perf_counter()
        sliding = _Sliding.after(state, step)           # refuses a slide before any load
        trial = copy.copy(state)                        # its fields are replaced, not changed
        try:
            parts = self._parts(step, trial, 0)
        except ClusterConvergenceError as exc:
            if state.gap is None and len(state.bodies) > 1:
                raise ClusterConvergenceError(f"{exc}. {FIRST_STEP_HINT}") from exc
            if state.gap is not None and self.cutbacks > 0:
                raise ClusterConvergenceError(
                    f"{exc} (the step was also cut into halves, down to 1/{2 ** self.cutbacks} "
                    f"of it: network.cutbacks = {self.cutbacks})") from exc
            raise
        result = _combined([p.result for p in parts])
        starts = [b.rotation for b in state.bodies]
        displacement = state.displacement + result.translation
        energy = _balance([p.energy for p in parts], step, result.normal_force)
        record = self._record(k, step, result, starts, displacement, sliding, energy,
                              time.perf_counter() - t0, state.histories, state.plate_shift)
        record.values["network_substeps"] = len(parts)
        # the next step is predicted from the last sub-step, the latest motion (measured: from
        # the whole step, whose first sub-steps took the stick-slide transition, the second
        # sliding step of 100 touching spheres failed; from its last sub-step it took 3 passes)
        state.__dict__.update(trial.__dict__)
        return record

    def _parts(self, step: LoadStep, state: NetworkState, level: int) -> list[_Part]:
        """Solve ``step`` from ``state`` and advance ``state`` to its end (:meth:`_advance`);
        if it does not converge, or its energy residual exceeds ``energy_tol``, and ``level``
        < ``cutbacks``, solve its two halves (:func:`_halves`) one after the other instead.
        The whole step and the deepest sub-steps get every attempt of :func:`solve_cluster`;
        the sub-steps between give up after the first (``retry=False``), since halving them
        again is cheaper than its retries. Returns the solved (sub-)steps in order. Raises
        ClusterConvergenceError when a (sub-)step at the deepest level fails (``state`` may
        then be partly advanced: :meth:`step` passes a copy)."""
        if step.kind == "force":
            load = {"force": step.value, "gap_start": state.gap}
        else:
            load = {"gap": self.d0 * (1.0 - step.value)}
        try:
            result = solve_cluster(state.bodies, state.histories, mu_up=self.plates.mu_up,
                                   mu_low=self.plates.mu_low, mu_pp=self.mu_pp, box=self.box,
                                   plate_shift=step.shift, numerics=self.numerics,
                                   guess=_predicted(state.last_step, step, state.gap),
                                   retry=level == 0 or level >= self.cutbacks, **load)
        except ClusterConvergenceError:
            if state.gap is None or level >= self.cutbacks:
                raise
            first, second = _halves(step, state, self.d0)
            return self._parts(first, state, level + 1) + self._parts(second, state, level + 1)
        part = _Part(result, self._energy(step, state, result))
        if (self.energy_tol is not None and state.gap is not None and level < self.cutbacks
                and abs(_balance([part.energy], step, result.normal_force)["energy_residual"])
                > self.energy_tol):
            # converged, but its forces did not change linearly over it (a contact went from
            # stick to slide, or a particle was reached, within the step): halves
            first, second = _halves(step, state, self.d0)
            return self._parts(first, state, level + 1) + self._parts(second, state, level + 1)
        self._advance(state, step, result)
        return [part]

    def _advance(self, state: NetworkState, step: LoadStep, result: ClusterResult) -> None:
        """Replace ``state``'s fields by the end of ``step`` (solved as ``result``)."""
        bodies, histories = list(result.bodies), dict(result.histories)
        if self.box is not None:
            bodies, histories = wrap(bodies, histories, self.box)
        sliding = _Sliding.after(state, step)
        state.last_step = self._last_step(step, state, result)
        state.bodies, state.histories, state.gap = bodies, histories, result.gap
        state.displacement = state.displacement + result.translation
        (state.plate_shift, state.sliding_distance, state.slide_gap,
         state.slide_direction) = sliding

    @staticmethod
    def _last_step(step: LoadStep, state: NetworkState, result: ClusterResult) -> _LastStep:
        """What the next step predicts from: ``step`` taken from ``state`` (before it), ending
        at ``result``."""
        previous = (0.0 if state.last_step is None or state.last_step.kind != step.kind
                    else state.last_step.value)
        # kept from the first step too, for its load value (its gap change is unknown: NaN)
        return _LastStep(step.kind, step.value, step.value - previous,
                         tuple(float(v) for v in step.shift), result.translation,
                         result.rotation,
                         math.nan if state.gap is None else result.gap - state.gap)

    # --- the step's energy --------------------------------------------------------------------
    def _energy(self, step: LoadStep, state: NetworkState, result: ClusterResult) -> _Energy:
        """The step's energy terms (design notes §3d; the balance is :func:`_balance`): the
        upper plate's work on the particles W = F̄ · Δu (trapezoid: F̄ the mean of its force
        on them at the start and the end of the step, Δu = (Δs_x, Δs_y, Δh); so W = F_T·Δs −
        F_N·Δh with F_T the plate's tangential force on them), the stored elastic energy E of
        every contact at the start and at the end, and their frictional dissipation D in the
        step (:func:`_contact_energy`). The step's start is the state's histories (the first
        step: no contact, the gap d₀).

        The first step starts from rest, before any force: there the trapezoid's ½ F Δh is
        replaced by Hertz's ⅖ f (t − h) for each particle's upper contact, f its force at the
        end and t − h the plate's travel from where that particle first touched it (t its
        height at rest, h the gap at the end): the work of a force that grows as the approach
        to the power 3/2 (every smooth, non-conforming contact from first touch, Hertz 1882).
        It is exact for one particle (the trapezoid left a residual of 0.1 of F_N Δh there)
        and for particles that share the load without pressing each other."""
        start = [h.solved for h in state.histories.values()]
        force0 = _upper_force(state.histories)
        gap0 = self.d0 if state.gap is None else state.gap
        move = np.array([*step.shift, result.gap - gap0], dtype=float)
        if state.gap is None:
            work = math.fsum(_FROM_TOUCH * float(h.solved.force[2])
                             * (result.gap - self.layer[i].top)
                             for (i, side, *_), h in result.histories.items()
                             if side == "upper")
        else:
            mean = 0.5 * (force0 + np.asarray(result.plate_force, dtype=float))
            work = math.fsum(mean * move)
        ends = [_contact_energy(h.solved) for h in result.histories.values()]
        return _Energy(work=work,
                       stored0=math.fsum(_contact_energy(c)[0] for c in start),
                       stored=math.fsum(e[0] for e in ends),
                       dissipated=math.fsum(e[1] for e in ends), gap_change=float(move[2]))

    # --- the step's records ------------------------------------------------------------------
    def _record(self, k: int, step: LoadStep, result: ClusterResult, starts, displacement,
                sliding: _Sliding, energy: dict, seconds: float, state_histories: dict,
                state_shift) -> LayerRecord:
        n = len(result.bodies)
        plate = {i: {} for i in range(n)}
        touching = [[] for _ in range(n)]          # each particle's loaded contacts
        for c in result.contacts:
            if c.normal_force <= 0:
                continue
            touching[c.i].append(c)
            if isinstance(c.j, str):
                plate[c.i][c.j] = c
            else:
                touching[c.j].append(c)
        degree, neighbours = _neighbours(touching, result.contacts)
        records = []
        for i, body in enumerate(result.bodies):
            records.append(self._particle(k, step, i, body, result, starts[i], plate[i],
                                          touching[i], displacement[i]))
        loaded = [i for i in range(n) if records[i].state != "unloaded"]
        m = max(len(loaded), 1)
        both = [i for i in loaded if "upper" in plate[i] and "lower" in plate[i]]
        total = result.normal_force
        for r in records:
            r.values["load_share"] = r.normal_force / total if total > 0 else 0.0
        states = [records[i].state for i in loaded]
        values = dict(
            load_value=step.value, load_kind=step.kind, total_force=total,
            plate_gap=result.gap, compression=(self.d0 - result.gap) / self.d0,
            loaded=len(loaded),
            fraction_stick=states.count("stick") / m,
            fraction_roll=sum(s in ("roll_upper", "roll_lower", "roll") for s in states) / m,
            fraction_rotate=states.count("rotate") / m,
            fraction_slide=sum(s in schema.SLIDING for s in states) / m,
            particle_contacts=neighbours,
            coordination=(math.fsum(degree[i] for i in loaded) / len(loaded)
                          if loaded else math.nan),
            both_plates_force=math.fsum(plate[i]["upper"].normal_force for i in both),
            # the particles' force on the upper plate: the lower plate's on them at balance
            plate_force=(float(-result.plate_force[0]) + 0.0,
                         float(-result.plate_force[1]) + 0.0),
            plate_moment=schema.VARIABLES["plate_moment"].blank(),
            plate_shift=sliding.plate_shift, sliding_distance=sliding.distance,
            mu_eff_sliding=sliding.along(result), dilatancy=sliding.dilatancy(result.gap),
            **energy,
            network_residual=result.residual, network_iterations=result.iterations,
            share_error=0.0, time_total=seconds)
        for var in schema.by_kind("step"):
            if var.derive is not None:
                values[var.name] = var.derive(values)
        for var in schema.by_kind("particle"):
            if var.derive is not None:
                for r in records:
                    r.values[var.name] = var.derive(r.values)
        rows = [self._row(k, c, result.histories[c.key].solved,
                          _travel(state_histories.get(c.key), result.histories[c.key],
                                  c.i, state_shift, sliding.plate_shift))
                for c in result.contacts]
        return LayerRecord(k, step.kind, records, values, contacts=rows)

    def _particle(self, k: int, step: LoadStep, i: int, body: Body, result: ClusterResult,
                  start, plate: dict, mine: list, displacement) -> StepRecord:
        values = {name: schema.VARIABLES[name].blank() for name in _particle_names()}
        kind = result.kinematics[i]
        sides = ("upper", "lower")
        mu = {"upper": self.plates.mu_up, "lower": self.plates.mu_low}
        others = [c for c in mine if not isinstance(c.j, str)]
        turned = bool(np.linalg.norm(result.rotation[i]) > self.numerics.stick_rotation)
        state = particle_state(kind, turned, [c.state for c in mine],
                               {s: c.state for s, c in plate.items()}, bool(others),
                               step.slides)
        turn = _turn(body.rotation, start)
        values.update(**_pose(body.rotation), **turn, state=state,
                      turned=turned,
                      position=(float(displacement[0]), float(displacement[1])),
                      centroid_height=float(body.centre[2]),
                      translation=tuple(float(v) for v in result.translation[i]))
        if state == "unloaded":
            return StepRecord(k, step.kind, values, gap=result.gap)

        def per_side(get, blank):
            return tuple(get(plate[s], s) if s in plate else blank for s in sides)

        forces = per_side(lambda c, s: c.normal_force, 0.0)
        lower = plate.get("lower")
        values.update(
            normal_force=max(forces), plate_normal_force=forces,
            tangential_force=(0.0, 0.0) if lower is None else
            (float(lower.tangential_force[0]), float(lower.tangential_force[1])),
            ratio=per_side(lambda c, s: float(np.linalg.norm(c.tangential_force))
                           / (mu[s] * c.normal_force) if mu[s] > 0 else math.nan, math.nan),
            centroid=per_side(lambda c, s: (float(c.point[0] - body.centre[0]),
                                            float(c.point[1] - body.centre[1])),
                              (math.nan, math.nan)),
            approach=per_side(lambda c, s: c.approach, math.nan),
            contact_area=per_side(lambda c, s: c.area, 0.0),
            stick_area=per_side(lambda c, s: c.stick_area, 0.0),
            spots=per_side(lambda c, s: c.spots, 0),
            force_residual=float(np.linalg.norm(result.force_residual[i])) / result.force_scale,
            moment_residual=float(np.linalg.norm(result.moment_residual[i]))
            / (result.force_scale * body.size),
            turn_evaluations=result.iterations)
        return StepRecord(k, step.kind, values, gap=result.gap)

    def _row(self, k: int, c, solved, travel: tuple[float, float]) -> dict:
        image = (0, 0) if isinstance(c.j, str) else tuple(int(v) for v in c.key[2])
        stored, dissipated = _contact_energy(solved)
        return {
            "contact_step": k, "contact_i": int(c.i),
            "contact_j": PLATE_INDEX[c.j] if isinstance(c.j, str) else int(c.j),
            "contact_image": image,
            "contact_normal": tuple(float(v) for v in c.normal),
            "contact_force": tuple(float(v) for v in c.force),
            "contact_normal_force": float(c.normal_force),
            "contact_point": tuple(float(v) for v in np.asarray(c.point) + self.origin),
            "contact_approach": float(c.approach),
            "contact_total_area": float(c.area), "contact_stick_area": float(c.stick_area),
            "contact_spots": int(c.spots),
            "contact_slip": tuple(float(v) for v in c.slip),
            "contact_shift_increment": tuple(float(v) for v in c.shift_increment),
            "contact_rolling_i": travel[0], "contact_rolling_j": travel[1],
            "contact_state": c.state,
            "contact_half_space_ratio": float(c.half_space_ratio),
            "contact_spot_tilt": math.degrees(c.spot_tilt),
            "contact_mu": float(c.mu),
            "contact_elastic_energy": stored, "contact_dissipation": dissipated,
        }


def _neighbours(touching: list, contacts) -> tuple[list[int], int]:
    """Each particle's number of contacts (``touching``: its loaded contacts) and the number of
    touching particle pairs carrying load. A neighbour touched on contacts facing different
    ways (keys (i, j, image) and (i, j, image, s)) counts once, as a plate touched on several
    spots does."""
    degree = [len({c.key[:3] for c in t}) for t in touching]
    pairs = {c.key[:3] for c in contacts if not isinstance(c.j, str) and c.normal_force > 0}
    return degree, len(pairs)


def particle_state(kinematics: str, turned: bool, contact_states: list[str],
                   plate_states: dict[str, str], touches_particles: bool,
                   slid: bool = False) -> str:
    """What a particle of a network run did in a step (``state``, :data:`thirdbody.schema.STATES`).

    ``kinematics`` is the cluster's word for it (:attr:`ClusterResult.kinematics`: "free",
    "stick", "roll", "slide"); ``turned`` whether it turned by more than ``stick_rotation`` in
    the step; ``contact_states`` the state ("stick" or "slide") of each of its loaded
    contacts; ``plate_states`` those of its plate contacts by side ("upper", "lower");
    ``touches_particles`` whether any loaded contact is with another particle; ``slid``
    whether the upper plate moved sideways in the step.

    Rolling means turning. "unloaded": it touches nothing; "stick": no contact slides
    (whatever it turned under compression: a tilted particle pressed between two stuck
    contacts turns a little as the plates approach), but "roll" when it turned while the
    plate slid (rolling without slip: a sphere under the sliding plate). Every contact
    sliding: "rotate" if it turns, else "slide". A
    particle touching only the two plates, one contact sticking and the other sliding:
    "roll_upper" / "roll_lower" when it turns about the sticking one (the paper's states,
    eqs 4-5), "slide_lower" / "slide_upper" when it does not turn: carried by the plate whose
    contact sticks, it slides on the other one (named by where it slides: "slide_lower"
    sticks to the upper plate and slides on the lower). Any other particle with contacts that
    stick and contacts that slide (touching particles, or one plate): "roll" when it turns,
    "slide" when it does not.
    """
    if kinematics == "free":
        return "unloaded"
    if kinematics == "stick" or all(c == "stick" for c in contact_states):
        return "roll" if turned and slid else "stick"
    if kinematics == "slide":                       # every contact slides
        return "rotate" if turned else "slide"
    up, low = plate_states.get("upper"), plate_states.get("lower")
    if touches_particles or up is None or low is None:
        return "roll" if turned else "slide"
    if up == "stick" and low == "slide":
        return "roll_upper" if turned else "slide_lower"
    if low == "stick" and up == "slide":
        return "roll_lower" if turned else "slide_upper"
    return "roll" if turned else "slide"


def _travel(start, end, i: int, shift0, shift1) -> tuple[float, float]:
    """How far the contact point travelled over particle i's surface and over the other body's
    (particle j, or the plate) in the step, m: each the distance between the pressure
    centroid's positions in that body's own frame at the start (``start``, the contact's
    history before the step; None for a contact new in the step: NaN) and at the end
    (``end``), from the bodies' rigid poses (a straight line: the chord of the path over the
    surface). The upper plate's frame moves with its horizontal shift (``shift0`` before the
    step, ``shift1`` after, m); the lower plate's is the world's. A contact that rolls
    without slipping travels as far over both bodies; one that slides travels over them by
    amounts that differ by its slip."""
    if start is None:
        return math.nan, math.nan
    before, after = start.solved, end.solved

    def local(body, point) -> np.ndarray:
        return body.rotation.inv().apply(np.asarray(point, dtype=float) - body.centre)

    def distance(a, b) -> float:
        return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))

    p0, p1 = before.pressure_centroid, after.pressure_centroid
    if isinstance(end.key[1], str):             # a plate: (particle, plate)
        on_particle = distance(local(after.body, p1), local(before.body, p0))
        move = np.zeros(2)
        if end.key[1] == "upper":
            move = np.asarray(shift1, dtype=float) - np.asarray(shift0, dtype=float)
        return on_particle, distance(np.asarray(p1)[:2] - move, np.asarray(p0)[:2])
    on_a = distance(local(after.a, p1), local(before.a, p0))
    on_b = distance(local(after.b, p1), local(before.b, p0))
    return (on_a, on_b) if end.roles[0] == i else (on_b, on_a)


def _contact_energy(solved) -> tuple[float, float]:
    """A solved contact's stored elastic energy ½ Σ (p u_n + τ·u_t) ΔA and the frictional
    dissipation of its last step Σ τ·w ΔA, J (p, τ its pressure and traction, u_n, u_t the
    elastic displacements they cause, w the cells' slip increment in the step; τ and w are
    what the plate, or body b, exerts on the particle, or body a, and its slip over it, so
    that τ·w >= 0 cell by cell). Both are sums over the contact's window, in its own frame."""
    normal, tangential = solved.normal_solution, solved.tangential_solution
    area = normal.grid.cell_area
    stored = math.fsum((normal.pressure * normal.displacement).ravel())
    dissipated = 0.0
    if tangential is not None:
        stored += math.fsum((tangential.traction * tangential.displacement).ravel())
        dissipated = math.fsum((tangential.traction * tangential.slip_increment).ravel())
    return 0.5 * stored * area, dissipated * area
