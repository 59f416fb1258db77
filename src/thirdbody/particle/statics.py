"""Statics of the particle between the plates at one orientation: the normal contact at both
plates under a normal force (or a plate gap), the couple of the two pressure centroids, and the
tangential force that keeps the particle from turning.

Moment balance about the centroid (docs/methods/design.md §3, the paper's eqs 6-9, generalised to
any orientation). The upper plate pushes down with F_N at its pressure centroid r̄_up, the lower one
up at r̄_low: their couple is ``F_N e_z × d`` with the horizontal offset ``d = r̄_up − r̄_low``.
The tangential forces T_up = −T_low at the two plates, a distance h apart, add ``h e_z × T_up``.
Balance gives

    F' := T_low = F_N d / h,

the force (N) the lower plate must exert on the particle (the upper plate exerts −F'). F' is
parallel to d, so the tangential forces have no twisting moment about z through their lever
arms. When |F'| > μ F_N the particle turns about the horizontal axis ``e_z × F'/|F'|`` (right-hand
rule), the way the couple pushes it; for the paper's tilt about +y, F'_x = M_p / h (eq 9).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..loading import LoadStep
from ..material import Material
from ..orientation import Rotation, key
from ..shapes import Shape
from .interface import Interface, InterfaceNormal, remap
from .surface import Surfaces, scan_stride

__all__ = ["Evaluation", "PairStatics", "StaticsError"]

_SURFACES_CACHED = 6


class StaticsError(RuntimeError):
    """The normal problem at an orientation has no acceptable solution (the plates met, a
    prescribed gap that does not touch the particle, a gap the force search cannot meet)."""


@dataclass(frozen=True)
class Evaluation:
    """The normal equilibrium of the particle at one orientation (SI units).

    Attributes
    ----------
    rotation : Rotation
        The orientation (body -> world).
    force : float
        Normal force F_N on each plate, N (0: unloaded, :meth:`unloaded`).
    gap : float
        Plate separation h, m.
    up, low : InterfaceNormal
        The normal solves at the upper and lower plate.
    demand_force : (2,) array
        F' = F_N (r̄_up − r̄_low)/h, N: the force of the lower plate on the particle that keeps
        it from turning.
    shear : dict or None
        With normal-tangential coupling: the tangential steps at both plates ("up", "low")
        under ±F' (capped at μ_min F_N) that the pressures were solved with; None uncoupled.
    coupling_passes : int
        Normal-tangential passes of the coupled evaluation (0 uncoupled).
    """

    rotation: Rotation
    force: float
    gap: float
    up: InterfaceNormal | None
    low: InterfaceNormal | None
    demand_force: np.ndarray
    shear: dict | None = None
    coupling_passes: int = 0

    @classmethod
    def unloaded(cls, rotation: Rotation) -> Evaluation:
        """The particle at ``rotation`` with no load (the plates do not press it: in a layer,
        the others hold the plates above it): no contact, no couple."""
        return cls(rotation, 0.0, math.nan, None, None, np.zeros(2))

    @property
    def demand(self) -> float:
        """|F'| / F_N: the friction coefficient the particle needs to stay put (0 unloaded)."""
        if self.force == 0:
            return 0.0
        return float(math.hypot(*self.demand_force)) / self.force

    @property
    def direction(self) -> np.ndarray:
        """Unit vector of F' (zero vector if F' = 0)."""
        n = math.hypot(*self.demand_force)
        return self.demand_force / n if n > 0 else np.zeros(2)

    @property
    def axis(self) -> np.ndarray:
        """Unit horizontal axis the couple turns the particle about, e_z × F'/|F'| (2,)."""
        fx, fy = self.direction
        return np.array([-fy, fx])

    def drive(self, reference: Evaluation) -> float:
        """F'·(unit F' of ``reference``)/F_N: the couple along the turn that ``reference``
        started; it changes sign where the particle would turn back."""
        if self.force == 0:
            return 0.0
        return float(self.demand_force @ reference.direction) / self.force


class PairStatics:
    """The normal problem of the particle at any orientation: both plates, one lattice.

    Parameters
    ----------
    shape : Shape
    material : Material
    spacing : float
        Cell size Δ, m.
    tol : float
        Normal solver tolerance.
    coupling : bool
        Normal-tangential coupling (ν < 0.5): each evaluation alternates the normal solves at
        both plates with the tangential solves under the demand they imply (``shear_solver``,
        set by the particle that owns the statics), until the pressures and F' stop changing.
    """

    #: relative change of the pressures and of F'/F_N that ends the coupled passes
    COUPLING_TOL = 1e-6
    #: budget of coupled passes per evaluation
    COUPLING_PASSES = 40
    #: tolerance of the first pass's tangential solves (None: every pass at the full one)
    COUPLING_LOOSE: float | None = 1e-4
    #: the later passes' tangential solves: this fraction of the last pass's change
    COUPLING_FORCING = 1e-2

    def __init__(self, shape: Shape, material: Material, spacing: float, tol: float,
                 coupling: bool = False) -> None:
        self.shape, self.material, self.spacing, self.tol = shape, material, spacing, tol
        self.coupling = bool(coupling) and (1.0 - 2.0 * material.nu) != 0.0
        self.shear_solver: Callable[[Evaluation, dict | None, float | None], dict] | None = None
        self.interfaces = {"up": Interface("upper", material, spacing, tol),
                           "low": Interface("lower", material, spacing, tol)}
        self.stride = scan_stride(shape, spacing)
        self._surfaces: OrderedDict[tuple, Surfaces] = OrderedDict()
        self._retired_time = 0.0
        self.normal_time = 0.0

    def add_time(self, normal: float, geometry: float) -> None:
        """Count wall time (s) spent on this particle's normal solves and geometry elsewhere
        (in a worker process that turned it)."""
        self.normal_time += normal
        self._retired_time += geometry

    @property
    def geometry_time(self) -> float:
        """Wall time (s) spent on vertical rays so far."""
        return self._retired_time + sum(s.geometry_time for s in self._surfaces.values())

    def surfaces(self, rotation: Rotation) -> Surfaces:
        """The particle's surfaces at ``rotation`` (cached for the last few orientations)."""
        k = key(rotation)
        hit = self._surfaces.get(k)
        if hit is None:
            hit = Surfaces(self.shape, rotation, self.spacing, self.stride)
            self._surfaces[k] = hit
            if len(self._surfaces) > _SURFACES_CACHED:
                _, old = self._surfaces.popitem(last=False)
                self._retired_time += old.geometry_time
        else:
            self._surfaces.move_to_end(k)
        return hit

    def evaluate(self, rotation: Rotation, step: LoadStep, d0: float,
                 force_guess: float | None = None) -> Evaluation:
        """The normal equilibrium at ``rotation`` under a load step (force, or compression
        relative to ``d0``, the plate gap at first contact in the initial orientation, m)."""
        if step.kind == "force":
            return self.at_force(rotation, step.value)
        return self.at_gap(rotation, d0 * (1.0 - step.value), force_guess)

    def at_force(self, rotation: Rotation, force: float) -> Evaluation:
        """Both plates pressing with ``force`` (N)."""
        surfaces = self.surfaces(rotation)
        geometry = self.geometry_time
        start = time.perf_counter()
        up = self.interfaces["up"].solve_normal(surfaces, force=force)
        low = self.interfaces["low"].solve_normal(surfaces, force=force)
        self.normal_time += time.perf_counter() - start - (self.geometry_time - geometry)
        ev = self._evaluation(rotation, force, up, low)
        if self.coupling and self.shear_solver is not None:
            ev = self._coupled(ev, surfaces)
        return ev

    def _coupled(self, ev: Evaluation, surfaces: Surfaces) -> Evaluation:
        """The Panagiotopoulos passes of one evaluation (see
        :func:`thirdbody.bem.solve_coupled`): shear under the current demand, then both
        normal solves with that shear, until the pressures change by less than
        ``COUPLING_TOL`` of their maximum and F'/F_N by less than ``COUPLING_TOL``."""
        from ..bem import ConvergenceError

        change = math.inf
        warm = None
        for passes in range(1, self.COUPLING_PASSES + 1):
            # inexact passes: the tangential halves only as accurately as the pressures have
            # settled (the first to COUPLING_LOOSE, then COUPLING_FORCING times the last
            # change); the shear returned with the evaluation at the full tolerance
            loose = None if self.COUPLING_LOOSE is None else \
                self.COUPLING_LOOSE if passes == 1 else self.COUPLING_FORCING * change
            shear = self.shear_solver(ev, warm, loose)
            warm = {side: (getattr(ev, side).window, shear[side]) for side in shear}
            geometry = self.geometry_time
            start = time.perf_counter()
            sols = {side: self.interfaces[side].solve_normal(
                surfaces, force=ev.force, traction=(getattr(ev, side).window,
                                                    shear[side].traction))
                for side in ("up", "low")}
            self.normal_time += time.perf_counter() - start - (self.geometry_time - geometry)
            new = self._evaluation(ev.rotation, ev.force, sols["up"], sols["low"])
            change = float(np.abs(new.demand_force - ev.demand_force).max()) / ev.force
            for side in ("up", "low"):
                a, b = getattr(new, side), getattr(ev, side)
                p_old = remap(b.contact.pressure, b.window, a.window)
                change = max(change, float(np.abs(a.contact.pressure - p_old).max())
                             / float(a.contact.pressure.max()))
            ev = new
            if change <= self.COUPLING_TOL:
                return replace(ev, shear=self.shear_solver(ev, warm), coupling_passes=passes)
        raise ConvergenceError(f"normal-tangential coupling of the particle did not converge "
                               f"in {self.COUPLING_PASSES} passes (last change {change:.1e})")

    def _evaluation(self, rotation: Rotation, force: float, up: InterfaceNormal,
                    low: InterfaceNormal) -> Evaluation:
        h = up.plate - low.plate
        if not h > 0:
            raise StaticsError(f"the plates met (gap h = {h:.3g} m): the load is too large for "
                               "the half-space approximation")
        offset = np.subtract(up.centroid, low.centroid)
        return Evaluation(rotation, force, h, up, low, force * offset / h)

    def at_gap(self, rotation: Rotation, gap: float,
               force_guess: float | None = None) -> Evaluation:
        """The normal force (N) for which the plates are ``gap`` (m) apart, by a secant search
        on log F against the log of the total approach (which grows like F^(2/3))."""
        surfaces = self.surfaces(rotation)
        reach = surfaces.reference[1] - surfaces.reference[0]   # plate gap at first contact
        target = reach - gap                # total approach δ_up + δ_low, m
        if not target > 0:
            raise StaticsError(f"prescribed plate gap {gap:.6g} m does not touch the particle "
                               f"(height {reach:.6g} m at this orientation)")
        # Hertz-like first guess: δ_total ≈ 2 (9 F² / (16 E*² R))^(1/3) with R ~ size
        F = force_guess or (target / 2) ** 1.5 * 4 / 3 * self.material.E_star * \
            math.sqrt(self.shape.size)
        points: list[tuple[float, float]] = []
        for _ in range(40):
            ev = self.at_force(rotation, F)
            total = ev.up.contact.approach + ev.low.contact.approach
            if abs(total - target) <= 1e-7 * target:
                return ev
            points.append((math.log(F), math.log(max(total, 1e-300))))
            if len(points) >= 2 and points[-1][1] != points[-2][1]:
                (x0, y0), (x1, y1) = points[-2:]
                slope = min(max((y1 - y0) / (x1 - x0), 0.2), 2.0)
            else:
                slope = 2.0 / 3.0
            F = math.exp(points[-1][0] + (math.log(target) - points[-1][1]) / slope)
        raise StaticsError(f"could not find the normal force for the plate gap {gap:.6g} m")
