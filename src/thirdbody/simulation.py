"""The quasi-static driver: deformable particles squeezed between two plates, step by step.

A run is a *layer* of particles (:class:`~thirdbody.layer.Layer`); a single particle is a layer
of one, through the same code. For each load step (docs/methods/design.md §3 and §3b, the paper's
eqs 6-11):

1. **Load.** Under force control the plate gap h is found with Σ F_i(h) = F_N (a monotone
   scalar root; particles shorter than h carry nothing); under gap control h is prescribed.
   Each loaded particle's normal contact at both plates is solved at its share F_i, every spot
   included (:mod:`thirdbody.particle.statics`); its pressure centroids give the force
   F'_i = F_i (r̄_up − r̄_low)/h its lower plate must exert for it to stay put.
2. **Turns.** A particle with |F'_i| > μ_min F_i turns (:mod:`thirdbody.particle.turning`) to
   its first stable orientation, or until it loses its load (then it stops where it last
   touched and carries nothing for the rest of the step), the others held at their
   orientations: at each orientation visited, its share under force control follows from the
   others' compliance (their last solves); under gap control h stays put. With
   unequal μ it rolls about the higher-friction interface's stick zone, with equal μ it rotates
   about its centroid (:func:`thirdbody.rigid.classify`); its tangential history restarts.
3. **Cascades.** A turn changes that particle's height, so under force control h and every
   share change and other particles may turn: steps 1-2 repeat until no particle turns.
4. **Partial slip.** Each loaded particle's interfaces solve the incremental partial-slip
   problem with ±F'_i, carrying that particle's previous traction.

Any failure inside a step (no stable orientation, a solver that does not converge, bad geometry,
two particles that a turn brings into contact) ends the run as a failed step:
:meth:`Simulation.run` returns the completed steps with a ``status`` saying why. All quantities
are SI; angles in the results are degrees.
"""

from __future__ import annotations

import copy
import math
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import asdict

import numpy as np

from . import checkpoint
from .layer import Layer, first_overlap
from .layer.sharing import LoadSharing
from .loading import LoadProgram, LoadStep
from .network.run import CUTBACKS
from .orientation import key
from .particle.member import Member
from .particle.model import Particle, Plates
from .particle.statics import Evaluation
from .particle.turning import TurnSettings, turn_particle, turn_task
from .records import (
    STATES,
    DatasetSpec,
    LayerRecord,
    StepMaps,
    StepRecord,
    has_maps,
    particle_record,
    step_maps,
    unloaded_record,
)
from .rigid import RigidState
from .state import LayerState, ParticleState

__all__ = ["STATES", "LayerState", "ParticleState", "Simulation", "SimulationError",
           "SimulationStoppedWarning", "StepMaps", "StepRecord"]

#: the finest grid allowed, cells per particle size (as numerics.resolution's range)
MAX_RESOLUTION = 4000.0
#: rounds of turns and rebalancing within one step before a cascade counts as not settling
MAX_CASCADE_ROUNDS = 25


class SimulationError(RuntimeError):
    """A step could not be completed (no stable orientation, a solver failure)."""


class SimulationStoppedWarning(RuntimeWarning):
    """A run stopped before its last step; the results hold the completed steps.

    Its own class so that a caller that reports the stop itself (the CLI, a sweep worker) can
    silence exactly this message and leave numpy's and everyone else's warnings visible."""


class Simulation:
    """Particles between two plates under a load program.

    Parameters
    ----------
    particle : Particle or Layer
        One particle (results along ``step``, as for the paper's figures), or a
        :class:`~thirdbody.layer.Layer` (results along ``step`` and ``particle``).
    plates : Plates
    load : LoadProgram
        See :mod:`thirdbody.loading`. For a layer the force is the total F_N on each plate, and
        compression ratios are relative to d₀ = the tallest particle's height. A program that
        slides the upper plate (:class:`~thirdbody.loading.Slide`) needs ``mu_pp``.
    resolution : float
        Cells per particle size (the largest centroid-to-surface distance): each particle's cell
        size is ``shape.size / resolution`` (m). Ignored if ``cell_size`` is given.
    cell_size : float, optional
        Cell size Δ, m, for every particle.
    tol : float
        Tolerance of the normal and tangential solvers (dimensionless residuals).
    angle_step_deg, angle_tol_deg : float
        Turning: march step and the bisection tolerance on the final orientation, degrees.
    maps_every : int
        Store the pressure/traction/status maps every k-th step (and always the last one);
        0 stores none.
    classification : {"statics", "paper"}
        How a both-interfaces-exceeded demand is read with unequal μ
        (:func:`thirdbody.rigid.classify`).
    twist_tol : float
        Largest twisting moment about z left unbalanced, relative to max(μ) F_N a (a the contact
        radius); above it the particle's twist relative to the plates is solved for (``inf``:
        never). The tilting couple's lever arms never twist (F' is parallel to the offset of the
        pressure centroids); the tractions of non-symmetric or multi-spot contacts can.
    coupling : bool
        Normal-tangential coupling for ν < 0.5 (default False: Goodman's approximation, the
        paper's model). Each evaluation of the particle alternates the normal solves with the
        tangential solves under the demand F' they imply until both stop changing
        (Panagiotopoulos' process, :func:`thirdbody.bem.solve_coupled`); the shear's normal
        displacement then moves the pressure centroids and so the turning load. A material
        with ν = 0.5 gives the uncoupled results exactly.
    workers : int
        Processes that turn the particles of a layer in parallel (the turns of one round are
        independent: each holds the others as they were at the round's start); 1 runs
        everything in this process. The results do not depend on it.
    mu_pp : float, optional
        Friction coefficient between particles (>= 0). Given, the particles may touch each
        other: every load step is the equilibrium of the contact network, every contact
        (particle-plate and particle-particle) resolved by the BEM
        (:mod:`thirdbody.network.run`, docs/methods/network.md); the results gain the
        ``contact`` table. Not given (the default), the paper's layer model: particles share
        the plates' load but may not touch (a touch ends the run).
    box : (L_x, L_y), optional
        With ``mu_pp``: a periodic box in x and y, m, centred on the origin (the layer's
        centroids inside it); contacts act across its sides. Default: the layer's box if it
        was generated periodic (``Layer.random(..., periodic=True)``), else none.
    network_tol : float
        With ``mu_pp``: the equilibrium tolerance of each step (the largest force residual over
        the mean contact force, moments over it times the particle's size, the plate force over
        F_N). ``tol`` stays the BEM solvers' tolerance.
    network_cutbacks : int
        With ``mu_pp``: how many times a load step after the first that does not converge is
        cut into halves (each half that fails into halves again), 0–8; the step's record is its
        end (``network_substeps`` says how many sub-steps it took). 0: a step that fails ends
        the run at once.
    network_energy_tol : float, optional
        With ``mu_pp``: a load step after the first whose energy residual
        (``energy_residual``: the plate's work less the change of elastic energy and the
        dissipation, over F_N (|Δs| + |Δh|)) exceeds it in magnitude is cut into halves as
        well, within ``network_cutbacks``, so that each step's balance closes within it or the
        step is at its deepest cut (e.g. 0.01). Default None: never.
    """

    #: fewest cells across the contact at the largest load that :meth:`preflight` accepts
    MIN_CONTACT_CELLS = 8

    def __init__(self, particle: Particle | Layer, plates: Plates, load: LoadProgram, *,
                 resolution: float = 80.0, cell_size: float | None = None,
                 tol: float = 1e-8, angle_step_deg: float = 1.0, angle_tol_deg: float = 0.01,
                 maps_every: int = 5, classification: str = "statics",
                 twist_tol: float = 1e-3, workers: int = 1, coupling: bool = False,
                 mu_pp: float | None = None, box: tuple[float, float] | None = None,
                 network_tol: float = 1e-6, network_cutbacks: int = CUTBACKS,
                 network_energy_tol: float | None = None) -> None:
        from ._validate import positive, real

        if isinstance(particle, Layer):
            self.layer, self.single = particle, False
        elif isinstance(particle, Particle):
            self.layer, self.single = Layer.of(particle), True
        else:
            raise TypeError("particle must be a thirdbody.Particle or a thirdbody.Layer")
        if not isinstance(plates, Plates):
            raise TypeError("plates must be a thirdbody.Plates")
        if not isinstance(load, LoadProgram):
            raise TypeError("load must be a load program from thirdbody.loading")
        if classification not in ("statics", "paper"):
            raise ValueError(f"classification must be 'statics' or 'paper', got "
                             f"{classification!r}")
        if isinstance(maps_every, bool) or not isinstance(maps_every, int) or maps_every < 0:
            raise ValueError(f"maps_every must be an integer >= 0, got {maps_every!r}")
        self.plates, self.load = plates, load
        self._resolution_key = "resolution (numerics.resolution)"
        if cell_size is not None:
            self._resolution_key = "cell_size (numerics.cell_size)"
            cells = [positive("cell_size (m)", cell_size)] * len(self.layer)
            finest = max(p.particle.shape.size for p in self.layer) / cells[0]
            if finest > MAX_RESOLUTION:
                # refused from an estimate, before a surface is computed: the particle's
                # surface grids alone would hold ~10 arrays of finest² doubles
                raise ValueError(
                    f"cell_size (numerics.cell_size) = {cell_size:.3g} m gives {finest:.3g} "
                    f"cells per particle size (about {10 * 8 * finest**2 / 2**30:.3g} GiB for "
                    f"the surface grids alone); at most {MAX_RESOLUTION} are allowed, i.e. "
                    f"cell_size >= "
                    f"{max(p.particle.shape.size for p in self.layer) / MAX_RESOLUTION:.3g} m")
        else:
            res = positive("resolution (cells per particle size)", resolution)
            if res > MAX_RESOLUTION:
                raise ValueError(f"resolution (numerics.resolution) = {res:.6g} cells per "
                                 f"particle size: at most {MAX_RESOLUTION} are allowed")
            cells = [p.particle.shape.size / res for p in self.layer]
        self.tol = positive("tol", tol)
        self.angle_step = math.radians(positive("angle_step_deg (degrees)", angle_step_deg))
        self.angle_tol = math.radians(positive("angle_tol_deg (degrees)", angle_tol_deg))
        self.maps_every = maps_every
        self.classification = classification
        self.twist_tol = math.inf if twist_tol == math.inf else real(
            "twist_tol", twist_tol, "[0, inf]", lambda x: x >= 0)
        self.schedule: list[LoadStep] = load.schedule()
        if not isinstance(coupling, bool):
            raise ValueError(f"coupling must be true or false, got {coupling!r}")
        self.coupling = coupling
        self.members = [Member(p.particle, plates, c, self.tol, self.twist_tol, coupling)
                        for p, c in zip(self.layer, cells, strict=True)]
        self.cell_size = cells[0]
        self.resolution = self.layer[0].particle.shape.size / self.cell_size
        # the gap at which the upper plate first touches the layer (a stacked particle's top
        # is its height above the lower plate plus its highest point)
        self.d0 = max(max(m.d0 for m in self.members), max(p.top for p in self.layer))
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
        self.workers = workers
        self.sharing = LoadSharing(self.members, self.d0)
        self._settings = TurnSettings(plates, classification, self.angle_step, self.angle_tol,
                                      self.d0)
        self._pool = None
        self.sharing.share_error = 0.0
        self.mu_pp, self.box, self.network = None, None, None
        if mu_pp is not None and box is None and getattr(self.layer, "periodic", False):
            box = self.layer.box                # Layer.random(..., periodic=True)
        if mu_pp is None and self.load.slides:
            raise ValueError(
                f"load ({type(load).__name__}) slides the upper plate sideways, which only the "
                "network engine can do: give mu_pp (network.mu_pp, the friction between "
                "particles; a single particle is a network of one)")
        if mu_pp is None and box is not None:
            raise ValueError("box (network.box) needs mu_pp (network.mu_pp): a periodic box is "
                             "a property of a network of touching particles")
        stacked = [i for i, p in enumerate(self.layer) if p.stacked]
        if mu_pp is None and stacked:
            raise ValueError(
                f"particle {stacked[0]} is placed above the lower plate (z = "
                f"{self.layer[stacked[0]].z:.6g} m): only a network run, which holds a particle "
                f"by its neighbours, can load it; give mu_pp (network.mu_pp)")
        if mu_pp is None and network_energy_tol is not None:
            raise ValueError("network_energy_tol (network.energy_tol) needs mu_pp "
                             "(network.mu_pp): only the network engine cuts steps")
        if mu_pp is not None:
            from .network.run import NetworkEngine

            self.mu_pp = real("mu_pp (network.mu_pp, friction between particles)", mu_pp,
                              "[0, inf)", lambda x: x >= 0)
            if box is not None:
                box = tuple(positive("box (network.box, m)", v) for v in box)
                if len(box) != 2:
                    raise ValueError(f"box (network.box) must be two lengths (L_x, L_y) in m, "
                                     f"got {box!r}")
            self.box = box
            self.network_tol = positive("network_tol (network.tol)", network_tol)
            if (isinstance(network_cutbacks, bool)
                    or not isinstance(network_cutbacks, (int, np.integer))
                    or not 0 <= network_cutbacks <= 8):
                raise ValueError(f"network_cutbacks (network.cutbacks) must be an integer in "
                                 f"[0, 8], got {network_cutbacks!r}")
            self.network_cutbacks = int(network_cutbacks)
            self.network_energy_tol = None if network_energy_tol is None else real(
                "network_energy_tol (network.energy_tol)", network_energy_tol, "(0, 1)",
                lambda x: 0 < x < 1)
            if coupling:
                raise ValueError("coupling (numerics.coupling) is not available with mu_pp "
                                 "(network.mu_pp): the network's contacts are uncoupled")
            self.network = NetworkEngine(self.layer, plates, self.mu_pp, box, cells,
                                         self.network_tol, self.tol, self.d0,
                                         self.network_cutbacks, self.network_energy_tol)
        self.records: list = []
        self.maps: list = []
        self.status = "not run"

    # --- the single particle's view ----------------------------------------------------------
    @property
    def particle(self) -> Particle:
        """The first (for a single-particle run: the) particle."""
        return self.layer[0].particle

    @property
    def statics(self):
        """The first particle's :class:`~thirdbody.particle.statics.PairStatics`."""
        return self.members[0].statics

    @property
    def interfaces(self):
        """The first particle's two :class:`~thirdbody.particle.interface.Interface` objects."""
        return self.members[0].interfaces

    # --- inputs, for the results file ------------------------------------------------------
    def _particle_inputs(self, particle: Particle) -> dict:
        mat = particle.material
        return {
            "shape": repr(particle.shape),
            "E": mat.E, "nu": mat.nu, "orientation_deg": particle.orientation_deg,
            "tilt_axis_deg": particle.tilt_axis_deg, "yaw_deg": particle.yaw_deg,
            **({"azimuth_deg": particle.azimuth_deg} if particle.azimuth_deg else {}),
            "quaternion": [float(v) for v in particle.orientation.as_quat()],
        }

    def inputs(self) -> dict:
        """The run's inputs as plain data (stored as attributes of the results)."""
        common = {
            "mu_up": self.plates.mu_up, "mu_low": self.plates.mu_low,
            "load": {"program": type(self.load).__name__, **asdict(self.load)},
            "cell_size": self.cell_size, "resolution": self.resolution, "tol": self.tol,
            "angle_step_deg": math.degrees(self.angle_step),
            "angle_tol_deg": math.degrees(self.angle_tol),
            "maps_every": self.maps_every, "classification": self.classification,
            "twist_tol": self.twist_tol, "d0": self.d0,
            **({"coupling": 1} if self.coupling else {}),
            **({"mu_pp": self.mu_pp, "network_tol": self.network_tol,
                "network_cutbacks": self.network_cutbacks,
                **({"network_energy_tol": self.network_energy_tol}
                   if self.network_energy_tol is not None else {})} if self.network else {}),
            **({"box": list(self.box)} if self.box is not None else {}),
        }
        if self.single:
            return {**self._particle_inputs(self.particle), **common}
        particles = [{**self._particle_inputs(p.particle), "x": p.xy[0], "y": p.xy[1],
                      **({"z": p.z} if p.stacked else {}), "cell_size": m.cell_size}
                     for p, m in zip(self.layer, self.members, strict=True)]
        return {"particles": particles, **common}

    # --- the physics of one step -------------------------------------------------------------
    def _stable(self, ev: Evaluation) -> bool:
        return ev.demand <= self.plates.mu_min

    def _classify(self, ev: Evaluation) -> RigidState:
        return self._settings.classify(ev)

    def preflight(self) -> int:
        """Solve the largest load at the initial orientations once and check the resolution.
        Returns the smallest checked contact's extent in cells (a network run, with ``mu_pp``:
        nothing is solved beforehand, 0).

        Raises ValueError (naming ``resolution``) when a contact at the largest load spans
        fewer than :attr:`MIN_CONTACT_CELLS` cells: the solution would not be resolved. In a
        layer, the particles carrying at least a tenth of the load (or the most loaded one)
        are checked.
        Raises :class:`SimulationError` when that load cannot be solved at all.
        """
        if self.network is not None:
            # a network's load path is not one particle's: its contacts are not known before
            # the steps are solved (the cluster solver checks each contact as it solves it)
            return 0
        step = max(self.schedule, key=lambda s: s.value)
        state = self._initial_state()           # a throwaway: the run starts afresh
        for m, s in zip(self.members, state.particles, strict=True):
            m.bind(s.warm)
        try:
            evs = self.sharing.equilibrium(step, state, None)
        except Exception as exc:
            raise SimulationError(f"the largest load cannot be solved: {exc}") from exc
        smallest, which = None, 0
        total = math.fsum(ev.force for ev in evs if ev is not None)
        biggest = max(ev.force for ev in evs if ev is not None)
        for k, ev in enumerate(evs):
            # in a layer, the particles that carry a tenth of the load or more (the lightly
            # loaded ones have small contacts whatever the grid, and matter little)
            if ev is None or (ev.force < 0.1 * total and ev.force < biggest):
                continue
            extent = 0
            for sol in (ev.up, ev.low):
                c = sol.contact.contact
                rows, cols = np.flatnonzero(c.any(axis=1)), np.flatnonzero(c.any(axis=0))
                extent = max(extent, rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1)
            if smallest is None or extent < smallest:
                smallest, which = extent, k
        if smallest < self.MIN_CONTACT_CELLS:
            member = self.members[which]
            res = member.particle.shape.size / member.cell_size
            needed = res * self.MIN_CONTACT_CELLS / max(smallest, 1)
            where = "" if self.single else f" of particle {which}"
            if self._resolution_key.startswith("cell_size"):
                raise ValueError(
                    f"cell_size (numerics.cell_size) = {member.cell_size:.4g} m is too coarse "
                    f"({res:.4g} cells per particle size): the contact{where} at the largest "
                    f"load spans {smallest} cells; use at most "
                    f"{member.particle.shape.size / needed:.3g} m")
            raise ValueError(
                f"resolution (numerics.resolution) = {res:.4g} cells per particle size is too "
                f"coarse: the contact{where} at the largest load spans {smallest} cells; use "
                f"at least {needed:.0f}")
        return int(smallest)

    def _initial_state(self):
        if self.network is not None:
            return self.network.initial_state()
        return LayerState([ParticleState(p.particle.orientation) for p in self.layer])

    def step(self, k: int, state: LayerState):
        """Run load step ``k`` from ``state`` (updated in place). Returns (record, maps or
        None): a :class:`LayerRecord` (for a single particle too) and the step's per-particle
        list of :class:`StepMaps` (None for a particle not loaded).
        Raises on failure; a step that ends with two particles touching returns its record
        with ``error`` set (the run then stops)."""
        step = self.schedule[k]
        if self.network is not None:
            return self.network.step(k, step, state), None
        n = len(self.members)
        t_start = time.perf_counter()
        self.sharing.share_error = 0.0
        clock0 = [(m.statics.normal_time, m.statics.geometry_time) for m in self.members]
        starts = [s.rotation for s in state.particles]
        for m, s in zip(self.members, state.particles, strict=True):
            m.begin_step(s)
        evs = self.sharing.equilibrium(step, state, None)
        first = list(evs)
        kinds = [RigidState.STICK] * n
        balanced = [False] * n
        counts = [1 if ev is not None else 0 for ev in evs]
        settled: dict[int, tuple] = {}
        excluded: set[int] = set()
        stops: dict[int, float] = {}
        for _ in range(MAX_CASCADE_ROUNDS):
            # a turn that ended at a balance (or where the particle lost its load) is not
            # repeated for a change of its share alone
            unstable = [i for i, ev in enumerate(evs) if ev is not None
                        and not self._stable(ev) and settled.get(i) != key(ev.rotation)]
            if not unstable:
                break
            starts_round = {i: state.particles[i].rotation for i in unstable}
            lost = self._turns(unstable, step, state, evs, kinds, balanced, counts, settled)
            for i in lost:
                moved = (state.particles[i].rotation * starts_round[i].inv()).magnitude()
                # it lost its load within the bisection tolerance of where it was: it is at
                # the edge, and stays out whatever the others' new share presses on it
                stops[i] = math.inf if moved < self.angle_tol else evs[i].force
            evs, excluded = self.sharing.rebalance(step, state, evs, excluded | lost, stops)
        else:
            raise SimulationError(f"the layer did not settle: particles still turned after "
                                  f"{MAX_CASCADE_ROUNDS} rounds of turns and load sharing")
        t_tan = []
        tangential: list[dict | None] = []
        for m, ev, s in zip(self.members, evs, state.particles, strict=True):
            t0 = time.perf_counter()
            if ev is None:
                s.history.clear()
                tangential.append(None)
            else:
                tangential.append(m.tangential(ev, s))
            t_tan.append(time.perf_counter() - t0)
        gap = self.sharing.gap(evs)
        records = []
        for i, (m, ev, s) in enumerate(zip(self.members, evs, state.particles, strict=True)):
            if ev is None:
                r = unloaded_record(k, step, gap, s, starts[i], kinds[i] is not RigidState.STICK,
                                    m.lowest(s.rotation))
            else:
                r = particle_record(k, step, self.plates, first[i] or ev, ev, kinds[i],
                                    balanced[i], starts[i], tangential[i], s, counts[i])
            normal0, geometry0 = clock0[i]
            r.values.update(time_normal=m.statics.normal_time - normal0,
                            time_geometry=m.statics.geometry_time - geometry0,
                            time_tangential=t_tan[i])
            records.append(r)
        total = time.perf_counter() - t_start
        want_maps = self.maps_every and (k % self.maps_every == 0
                                         or k == len(self.schedule) - 1)
        maps = [step_maps(k, ev, t) if want_maps and ev is not None else None
                for ev, t in zip(evs, tangential, strict=True)]
        record = LayerRecord.from_particles(k, step, gap, self.d0, records, self.layer, total,
                                            self.sharing.share_error)
        if n > 1:
            record.error = self._clearance(state, evs)
        return record, (maps if want_maps else None)

    def _twins(self, unstable: list[int], evs) -> list[list[int]]:
        """The unstable particles in groups of twins: the same shape, material and cells, at the
        same orientation under the same load and couple (equal bit for bit). Twins turn alike,
        so each group turns once, its members together (a regular array of identical grains
        would otherwise turn in lockstep against each other as they were at the round's
        start, and undo each other's turns for ever). Groups are in order of their first
        member; every other particle is a group of one."""
        groups: dict[tuple, list[int]] = {}
        for i in unstable:
            m, ev = self.members[i], evs[i]
            twin = (repr(m.particle.shape), m.particle.material, m.cell_size,
                    key(ev.rotation), ev.force, ev.gap, tuple(ev.demand_force))
            groups.setdefault(twin, []).append(i)
        return list(groups.values())

    def _turns(self, unstable: list[int], step: LoadStep, state: LayerState, evs, kinds,
               balanced, counts, settled) -> set[int]:
        """Turn every particle of ``unstable`` to its first stable orientation, each with the
        others held as they were at the start of the round (so the order does not matter, and
        the turns can run in parallel processes), twins (:meth:`_twins`) together: their
        share follows from F_i · (twins) + Σ others = F_N; integrate their kinematics. Returns
        the particles that lost their load on the way (a layer): each stops where it last
        touched and carries nothing for the rest of the step (its share there vanishes with the
        bisection tolerance; the others take it)."""
        members = self.members
        for i in unstable:
            if kinds[i] is RigidState.STICK:
                kinds[i] = self._classify(evs[i])
        groups = self._twins(unstable, evs)
        held = None
        if step.kind == "force" and len(members) > 1:
            held = [m.compliance(s.rotation) for m, s in zip(members, state.particles,
                                                             strict=True)]
        before = {g[0]: (state.particles[g[0]].position.copy(),
                         state.particles[g[0]].slip_up.copy(),
                         state.particles[g[0]].slip_low.copy()) for g in groups}
        tasks = [(self._settings, members[g[0]], evs[g[0]], state.particles[g[0]], step,
                  None if held is None else [c for j, c in enumerate(held) if j not in g],
                  len(g))
                 for g in groups]
        if self._pool is not None and len(tasks) > 1:
            results = list(self._pool.map(turn_task, tasks))
        else:
            results = [turn_particle(*task) for task in tasks]
        lost = set()
        for group, (particle, turn, times) in zip(groups, results, strict=True):
            first = group[0]
            moved = [new - old for new, old in zip((particle.position, particle.slip_up,
                                                    particle.slip_low), before[first],
                                                   strict=True)]
            for i in group:
                if i == first:
                    state.particles[i] = particle
                else:
                    twin = state.particles[i]
                    twin.rotation = particle.rotation
                    twin.position = twin.position + moved[0]
                    twin.slip_up = twin.slip_up + moved[1]
                    twin.slip_low = twin.slip_low + moved[2]
                    twin.history.clear()
                    twin.warm = copy.deepcopy(particle.warm)
                members[i].bind(state.particles[i].warm)
                if self._pool is not None and len(tasks) > 1 and i == first:
                    members[i].statics.add_time(*times)     # solved in another process
                evs[i] = turn.final
                balanced[i] = turn.balanced
                counts[i] = turn.evaluations if counts[i] <= 1 else counts[i] + turn.evaluations
                if turn.balanced and not turn.lost_load:
                    settled[i] = key(turn.final.rotation)       # a balance of the couple
                if turn.lost_load and len(members) > 1:
                    lost.add(i)
        return lost

    def _clearance(self, state: LayerState, evs) -> str | None:
        """None, or a message naming two particles whose solids overlap after the step."""
        rotations = [s.rotation for s in state.particles]
        centres = []
        for p, m, s, ev in zip(self.layer, self.members, state.particles, evs, strict=True):
            lift = -(ev.low.plate if ev is not None else m.lowest(s.rotation))
            centres.append((p.xy[0] + s.position[0], p.xy[1] + s.position[1], lift))
        hit = first_overlap([m.particle.shape for m in self.members], rotations,
                            np.array(centres))
        if hit is None:
            return None
        i, j, x, y = hit
        return (f"particles {i} and {j} touch (near x = {x:.4g} m, y = {y:.4g} m): the layer "
                "model has no particle-particle contact")

    # --- the run -------------------------------------------------------------------------
    def steps(self, state: LayerState | None = None, start: int = 0,
              ) -> Iterator[tuple[object, object, LayerState]]:
        """Run the load steps from ``start``; yields (record, maps or None, state) per step.

        Raises :class:`SimulationError` when a step cannot be completed, whatever the cause
        (after yielding the step that brought two particles into contact).
        """
        state = state or self._initial_state()
        if self.workers > 1 and len(self.members) > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
            self._pool = ProcessPoolExecutor(self.workers,
                                             mp_context=multiprocessing.get_context(method))
        try:
            for k in range(start, len(self.schedule)):
                step = self.schedule[k]
                try:
                    record, maps = self.step(k, state)
                except Exception as exc:
                    reason = str(exc) or type(exc).__name__
                    raise SimulationError(f"step {k} ({step.kind} {step.value:.6g}): "
                                          f"{reason}") from exc
                yield record, maps, state
                error = getattr(record, "error", None)
                if error:
                    raise SimulationError(f"step {k} ({step.kind} {step.value:.6g}): {error}")
        finally:
            if self._pool is not None:
                self._pool.shutdown(cancel_futures=True)
                self._pool = None

    def run(self, progress: Callable | None = None,
            checkpoint: Callable[[Simulation, LayerState], None] | None = None,
            resume_from: bytes | None = None):
        """Run every load step and return the history as an :class:`xarray.Dataset`.

        ``progress`` is called with each completed record; ``checkpoint`` with the simulation
        and its state after each step (to save :meth:`snapshot`). ``resume_from`` is a
        snapshot: the run continues after its last completed step and ends exactly as an
        uninterrupted one. A step that cannot be completed stops the run: the dataset then
        holds the completed steps, its ``status`` attribute says why, and a warning is issued.
        """
        state, start = None, 0
        if resume_from is not None:
            state, start = self.restore(resume_from)
        else:
            self.records, self.maps = [], []
        self.status = "running"
        try:
            for record, maps, current in self.steps(state, start):
                self.records.append(record)
                if has_maps(maps):          # not a step with no particle loaded
                    self.maps.append(maps)
                if progress is not None:
                    progress(record)
                if checkpoint is not None:
                    checkpoint(self, current)
            self.status = "complete"
        except SimulationError as exc:
            self.status = f"failed: {exc}"
            warnings.warn(f"simulation stopped: {exc}", SimulationStoppedWarning, stacklevel=2)
        return self.dataset()

    def snapshot(self, state: LayerState, *, history: bool = True) -> bytes:
        """Everything needed to continue after the last completed step (pickled): the inputs,
        ``state`` and, with ``history``, the records and maps so far
        (:func:`thirdbody.checkpoint.snapshot`)."""
        return checkpoint.snapshot(self.inputs(), state,
                                   (self.records, self.maps) if history else None)

    def restore(self, blob: bytes) -> tuple[LayerState, int]:
        """Load a :meth:`snapshot` (its records and maps become this run's); returns (state,
        index of the next step). The snapshot must come from a run with the same inputs."""
        state, self.records, self.maps = checkpoint.restore(blob, self.inputs())
        return state, len(self.records)

    def dataset(self, records: list | None = None, maps: list | None = None,
                frame: tuple[int, int, int, int] | None = None, raw: bool = False):
        """The records and maps collected so far as an :class:`xarray.Dataset` (or the given
        ``records`` and ``maps``; maps on the lattice cells ``frame`` = (i0, j0, nx, ny) if
        given, else on the union of their windows; ``raw``: a dict of the variables, see
        :func:`~thirdbody.records.to_dataset`)."""
        records = self.records if records is None else records
        maps = self.maps if maps is None else maps
        return self.dataset_spec().build(records, maps, self.status, frame=frame, raw=raw)

    def dataset_spec(self) -> DatasetSpec:
        """What :meth:`dataset` needs besides the records and maps (picklable)."""
        return DatasetSpec(self.layer, [m.cell_size for m in self.members], self.inputs())
