"""What a run carries from one load step to the next, as plain data.

A step is a function of this state and the load: the driver reads it, updates it and hands it
back, a checkpoint is this state (with the records so far), and a worker process that turns a
particle receives and returns one :class:`ParticleState`. Nothing else survives between steps
but caches that change only the cost of a solve (the surfaces computed at an orientation).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["LayerState", "ParticleState", "WarmStart"]


@dataclass
class WarmStart:
    """A particle's solver memory: where its next solves start, not what they find (but a
    solver stops within its tolerance of the answer, so a resumed run must start where the
    uninterrupted one would).

    ``normal`` holds each plate's last normal solve (an
    :class:`~thirdbody.particle.interface.InterfaceNormal`, by side "lower", "upper"): its
    pressure starts the next solve at the same orientation and its approach bounds the next
    one's. ``points`` are (normal force N, plate gap m, total approach m) of the last two
    solves at the orientation ``points_key``: the model of the particle's compliance that the
    load sharing uses.
    """

    normal: dict[str, Any] = field(default_factory=dict)
    points: list[tuple[float, float, float]] = field(default_factory=list)
    points_key: tuple | None = None


@dataclass
class ParticleState:
    """Everything one particle carries from one step to the next.

    ``rotation`` is its orientation (scipy Rotation, body to world); ``position`` the
    horizontal displacement of its centroid and the slips its accumulated slip over each plate
    (2-vectors, m); ``history`` each interface's last tangential step and its window
    (``{"up"|"low": (Window, TangentialContact)}``); ``force_guess`` the last normal force (N)
    found under gap control; ``warm`` its solvers' :class:`WarmStart`.
    """

    rotation: Any
    position: np.ndarray = field(default_factory=lambda: np.zeros(2))
    slip_up: np.ndarray = field(default_factory=lambda: np.zeros(2))
    slip_low: np.ndarray = field(default_factory=lambda: np.zeros(2))
    history: dict[str, tuple] = field(default_factory=dict)
    force_guess: float | None = None
    warm: WarmStart = field(default_factory=WarmStart)


@dataclass
class LayerState:
    """Every particle's :class:`ParticleState`, in layer order."""

    particles: list[ParticleState]
