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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ._validate import positive, real

__all__ = ["ForceTable", "GapRamp", "HoldThenRamp", "LinearRamp", "LoadProgram", "LoadStep"]


@dataclass(frozen=True)
class LoadStep:
    """One load step: ``kind`` is ``"force"`` (``value`` = F_N, N) or ``"compression"``
    (``value`` = (d₀ − h)/d₀, dimensionless)."""

    kind: str
    value: float


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
