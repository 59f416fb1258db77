"""Load programs: the sequence of normal loads (or plate gaps) a simulation steps through.

Every program is a small frozen dataclass whose ``schedule()`` is a list of :class:`LoadStep`.
A step is either force-controlled (the plates press with a total normal force F_N, N) or
gap-controlled (the plate separation h is prescribed, m, and F_N follows). Gap-controlled
programs are given as compression ratios c = (d₀ − h)/d₀, with d₀ the plate gap at first
contact of the particle in its initial orientation, so they do not depend on its size.

Programs
--------
* :class:`LinearRamp` — F_N from ``start`` to ``stop`` in ``steps`` equal increments.
* :class:`HoldThenRamp` — ``hold_steps`` steps at ``hold``, then a linear ramp to ``stop`` (the
  paper's Fig. 5: the particle finds a stable state at constant load, then is compressed).
* :class:`ForceTable` — an explicit list of forces.
* :class:`GapRamp` — displacement control: compression ratio from ``start`` to ``stop``.
* :class:`Slide` — compress (force or gap control), then slide the upper plate horizontally
  along a path of points, the normal force (or the gap) held. Needs a network run
  (``Simulation(..., mu_pp=...)``): only the network engine moves the plates sideways.

A step may move the upper plate horizontally: :attr:`LoadStep.shift` is its displacement
increment in the step (m, relative to the lower plate, which never moves).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ._validate import positive, real

__all__ = ["ForceTable", "GapRamp", "HoldThenRamp", "LinearRamp", "LoadProgram", "LoadStep",
           "Slide"]


@dataclass(frozen=True)
class LoadStep:
    """One load step: ``kind`` is ``"force"`` (``value`` = F_N, N) or ``"compression"``
    (``value`` = (d₀ − h)/d₀, dimensionless); ``shift`` is the upper plate's horizontal
    displacement increment in the step, (Δs_x, Δs_y) in m (the lower plate stays put)."""

    kind: str
    value: float
    shift: tuple[float, float] = (0.0, 0.0)

    @property
    def slides(self) -> bool:
        """The upper plate moves sideways in this step."""
        return self.shift != (0.0, 0.0)


#: the most load steps a program may have: a longer run would need ≥ 0.5 GiB of step records
#: and days of computing (≥ 20 ms a step), far beyond any sensible load history
MAX_STEPS = 100_000
_STEP_BYTES = 5 * 1024          # a step record in memory, about (its variables and their dict)
_STEP_SECONDS = 0.02            # the cheapest step measured (a sphere at resolution 20)


def _count(name: str, value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    if value > MAX_STEPS:
        raise ValueError(
            f"{name} = {value}: that many steps would need about "
            f"{value * _STEP_BYTES / 2**30:.3g} GiB for the step records alone and at least "
            f"{value * _STEP_SECONDS / 86400:.3g} days; at most {MAX_STEPS} steps are allowed")
    return int(value)


class LoadProgram:
    """Base class; its :meth:`schedule` lists the load steps in order."""

    def schedule(self) -> list[LoadStep]:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def slides(self) -> bool:
        """Some step moves the upper plate sideways (only network runs can)."""
        return any(s.slides for s in self.schedule())

    @property
    def max_force(self) -> float | None:
        """The largest prescribed normal force (N), or None for gap control."""
        forces = [s.value for s in self.schedule() if s.kind == "force"]
        return max(forces) if forces else None

    def __len__(self) -> int:
        return len(self.schedule())


@dataclass(frozen=True)
class LinearRamp(LoadProgram):
    """Normal force ramped linearly, N.

    Parameters
    ----------
    stop : float
        Final normal force F_N, N (> 0).
    steps : int
        Number of load steps (>= 1).
    start : float, optional
        First step's force, N (> 0, <= stop); default ``stop / steps``.
    """

    stop: float
    steps: int = 50
    start: float | None = None

    def __post_init__(self) -> None:
        positive("load.stop (final normal force, N)", self.stop)
        _count("load.steps", self.steps)
        if self.start is not None:
            real("load.start (first normal force, N)", self.start, f"(0, {self.stop}]",
                 lambda x: 0 < x <= self.stop)

    def schedule(self) -> list[LoadStep]:
        first = self.stop / self.steps if self.start is None else self.start
        return [LoadStep("force", float(f)) for f in np.linspace(first, self.stop, self.steps)]


@dataclass(frozen=True)
class HoldThenRamp(LoadProgram):
    """``hold_steps`` steps at the constant force ``hold`` (N), then ``ramp_steps`` equal
    increments up to ``stop`` (N)."""

    hold: float
    hold_steps: int
    stop: float
    ramp_steps: int

    def __post_init__(self) -> None:
        positive("load.hold (normal force during the hold, N)", self.hold)
        real("load.stop (final normal force, N)", self.stop, f"[{self.hold}, inf)",
             lambda x: x >= self.hold)
        _count("load.hold_steps", self.hold_steps)
        _count("load.ramp_steps", self.ramp_steps)

    def schedule(self) -> list[LoadStep]:
        ramp = np.linspace(self.hold, self.stop, self.ramp_steps + 1)[1:]
        return ([LoadStep("force", float(self.hold))] * self.hold_steps
                + [LoadStep("force", float(f)) for f in ramp])


@dataclass(frozen=True)
class ForceTable(LoadProgram):
    """An explicit list of normal forces, N (each > 0)."""

    forces: tuple[float, ...]

    def __init__(self, forces: Sequence[float]) -> None:
        values = tuple(positive(f"load.forces[{i}] (N)", f) for i, f in enumerate(forces))
        if not values:
            raise ValueError("load.forces must list at least one force (N)")
        object.__setattr__(self, "forces", values)

    def schedule(self) -> list[LoadStep]:
        return [LoadStep("force", f) for f in self.forces]


@dataclass(frozen=True)
class GapRamp(LoadProgram):
    """Displacement control: the plate gap h closes so that the compression ratio
    (d₀ − h)/d₀ goes linearly from ``start`` to ``stop`` (dimensionless, in (0, 0.5]) in
    ``steps`` steps; default ``start`` = ``stop / steps``."""

    stop: float
    steps: int = 50
    start: float | None = None

    def __post_init__(self) -> None:
        real("load.stop (final compression ratio)", self.stop, "(0, 0.5]",
             lambda x: 0 < x <= 0.5)
        _count("load.steps", self.steps)
        if self.start is not None:
            real("load.start (first compression ratio)", self.start, f"(0, {self.stop}]",
                 lambda x: 0 < x <= self.stop)

    def schedule(self) -> list[LoadStep]:
        first = self.stop / self.steps if self.start is None else self.start
        return [LoadStep("compression", float(c))
                for c in np.linspace(first, self.stop, self.steps)]


@dataclass(frozen=True)
class Slide(LoadProgram):
    """Compress the layer, then slide the upper plate sideways: a shear test.

    The first ``compress_steps`` steps press the plates together in equal increments up to
    the normal force ``force`` (N; force control) or the compression ratio ``compression``
    ((d₀ − h)/d₀; gap control): give exactly one of them. Then the upper plate moves
    horizontally along a path while that force (the gap is free: the layer may dilate) or that
    gap is held: from where it stands, s = (0, 0), through each point of ``points`` in turn
    ((s_x, s_y) in m, the plate's position relative to the lower plate), each segment in
    ``steps`` equal increments. A point back towards the start reverses the sliding; a list
    of points out and back is a cycle. ``distance`` (m, > 0) is the shorthand for one point:
    ``distance`` along the direction ``direction_deg`` (degrees from +x towards +y).

    Each sliding step's increment Δs = (Δs_x, Δs_y) is :attr:`LoadStep.shift`. Keep it small
    against the contacts: a step moves every contact's tangential history by Δs, and the
    equilibrium of a step larger than about 2 % of a particle's radius may not be found
    (docs/guide/sliding.md).

    Parameters
    ----------
    force : float, optional
        Normal force F_N, N (> 0).
    compression : float, optional
        Compression ratio (d₀ − h)/d₀ held while sliding, in (0, 0.5].
    distance : float, optional
        Sliding distance along ``direction_deg``, m (> 0). Exactly one of ``distance`` and
        ``points``.
    direction_deg : float
        Direction of ``distance``, degrees from +x towards +y.
    points : sequence of (s_x, s_y)
        The plate's path, m: the positions it slides through, in order, from (0, 0).
        Consecutive points must differ.
    steps : int
        Sliding steps per segment of the path (>= 1).
    compress_steps : int
        Steps of the compression (>= 1).
    """

    force: float | None = None
    compression: float | None = None
    distance: float | None = None
    direction_deg: float = 0.0
    points: tuple[tuple[float, float], ...] | None = None
    steps: int = 10
    compress_steps: int = 5

    def __post_init__(self) -> None:
        if (self.force is None) == (self.compression is None):
            raise ValueError("Slide: give exactly one of load.force (normal force held while "
                             "sliding, N) and load.compression (compression ratio held, in "
                             "(0, 0.5])")
        if self.force is not None:
            object.__setattr__(self, "force",
                               positive("load.force (normal force while sliding, N)",
                                        self.force))
        else:
            object.__setattr__(self, "compression", real(
                "load.compression (compression ratio held while sliding)", self.compression,
                "(0, 0.5]", lambda x: 0 < x <= 0.5))
        _count("load.steps", self.steps)
        _count("load.compress_steps", self.compress_steps)
        direction = real("load.direction_deg (degrees from +x)", self.direction_deg,
                         "(-inf, inf)", lambda x: True)
        object.__setattr__(self, "direction_deg", direction)
        if (self.distance is None) == (self.points is None):
            raise ValueError("Slide: give exactly one of load.distance (m, along "
                             "load.direction_deg) and load.points (the plate's path, "
                             "[[s_x, s_y], ...] in m)")
        if self.distance is not None:
            object.__setattr__(self, "distance",
                               positive("load.distance (sliding distance, m)", self.distance))
            return
        try:
            path = [tuple(float(v) for v in point) for point in self.points]
        except (TypeError, ValueError):
            raise ValueError(f"load.points must be a list of [s_x, s_y] pairs in m, got "
                             f"{self.points!r}") from None
        if not path:
            raise ValueError("load.points must list at least one point [s_x, s_y] (m)")
        last = (0.0, 0.0)
        for i, point in enumerate(path):
            if len(point) != 2 or not all(math.isfinite(v) for v in point):
                raise ValueError(f"load.points[{i}] must be two finite numbers [s_x, s_y] in "
                                 f"m, got {self.points[i]!r}")
            if point == last:
                where = "the start (0, 0)" if i == 0 else f"load.points[{i - 1}]"
                raise ValueError(f"load.points[{i}] = {list(point)} is {where} again: each "
                                 "point must differ from the one before")
            last = point
        object.__setattr__(self, "points", tuple(path))
        if len(path) * self.steps > MAX_STEPS:
            _count("load.steps x len(load.points)", len(path) * self.steps)

    @property
    def path(self) -> list[tuple[float, float]]:
        """The plate's path: the positions (s_x, s_y) it slides through in order, m (from
        (0, 0), which is not listed)."""
        if self.points is not None:
            return list(self.points)
        angle = math.radians(self.direction_deg)
        return [(self.distance * math.cos(angle), self.distance * math.sin(angle))]

    def schedule(self) -> list[LoadStep]:
        if self.force is not None:
            hold = LoadStep("force", float(self.force))
            press = [LoadStep("force", float(f)) for f in
                     np.linspace(self.force / self.compress_steps, self.force,
                                 self.compress_steps)]
        else:
            hold = LoadStep("compression", float(self.compression))
            press = [LoadStep("compression", float(c)) for c in
                     np.linspace(self.compression / self.compress_steps, self.compression,
                                 self.compress_steps)]
        out = list(press)
        start = np.zeros(2)
        for point in self.path:
            end = np.asarray(point, dtype=float)
            # each step's increment from the positions along the segment, so that the steps
            # of a segment sum to it as closely as floating point allows
            marks = [start + (end - start) * (k / self.steps) for k in range(self.steps + 1)]
            marks[-1] = end
            for a, b in itertools.pairwise(marks):
                out.append(LoadStep(hold.kind, hold.value,
                                    (float(b[0] - a[0]), float(b[1] - a[1]))))
            start = end
        _count("load.steps (the whole program)", len(out))
        return out
