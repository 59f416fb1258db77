"""How the plates' load is shared among the particles of a layer (design notes §3b).

The particles interact only through the common plate gap h. Under force control h solves
Σ F_i(h) = F_N, each particle's force modelled from its last solves (its
:class:`~thirdbody.particle.compliance.Compliance`) and corrected by solving it at its modelled
share; under gap control h is prescribed. A particle shorter than h carries nothing. Sums are
exactly rounded (``math.fsum``), so the shares do not depend on the particles' order.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from ..loading import LoadStep
from ..particle.compliance import MIN_SHARE
from ..particle.statics import Evaluation, StaticsError
from ..state import LayerState

__all__ = ["LOST_LOAD_SHARE", "SHARE_TOL", "SHARE_TOL_STALLED", "LoadSharing"]

#: a particle that lost its load while turning stays out of the load sharing unless the new
#: gap presses it with more than this fraction of F_N (and more than where it stopped)
LOST_LOAD_SHARE = 1e-3
#: the layer's force balance is converged when no share is off by more than this fraction of
#: F_N (each share's stiffness times the offset of its plate gap from the common one)
SHARE_TOL = 1e-7
#: ... and accepted after 60 iterations if it stalled (at the normal solver's noise) below this;
#: the step records the largest share error it accepted (``share_error``)
SHARE_TOL_STALLED = 1e-5


class LoadSharing:
    """The normal equilibrium of every particle of a layer under a load step.

    ``members``: the particles' :class:`~thirdbody.particle.member.Member` objects (layer
    order); ``d0``: the plate gap at first contact of the tallest particle (m), from which gap
    control's compression ratio is measured. ``share_error`` is the largest share error
    (fraction of F_N) accepted since it was last reset.
    """

    def __init__(self, members: list, d0: float) -> None:
        self.members, self.d0 = members, d0
        self.share_error = 0.0

    def equilibrium(self, step: LoadStep, state: LayerState,
                     evs: list[Evaluation | None] | None,
                     excluded: frozenset[int] = frozenset()) -> list[Evaluation | None]:
        """Every particle's normal equilibrium under the step's load at its current orientation;
        ``evs`` are the evaluations so far in the step (kept where still valid); the
        ``excluded`` particles carry nothing (they lost their load while turning)."""
        rotations = [s.rotation for s in state.particles]
        members = self.members
        if step.kind == "compression":
            if evs is not None:             # h is fixed: a turn changes nobody else
                return [None if i in excluded else ev for i, ev in enumerate(evs)]
            h = self.d0 * (1.0 - step.value)
            if len(members) == 1:
                return [members[0].at_gap(rotations[0], h, state.particles[0])]
            out = [m.at_gap(r, h, s) if m.reach(r) > h else None
                   for m, r, s in zip(members, rotations, state.particles, strict=True)]
            if all(ev is None for ev in out):
                tallest = max(m.reach(r) for m, r in zip(members, rotations, strict=True))
                raise StaticsError(f"prescribed plate gap {h:.6g} m does not touch any particle "
                                   f"(the tallest is {tallest:.6g} m)")
            return out
        total = step.value
        if len(members) == 1:                   # it carries all: no gap search
            if evs is not None and evs[0] is not None and evs[0].force == total:
                return evs
            return [members[0].at_force(rotations[0], total)]
        return self.share_load(total, rotations, evs, excluded)

    def share_load(self, total: float, rotations, evs,
                    excluded: frozenset[int] = frozenset()) -> list[Evaluation | None]:
        """Force control of a layer: the plate gap h with Σ F_i(h) = ``total`` (N).

        Each iteration models every particle's force at gap h from its last two solves at its
        orientation (a power law, :meth:`~thirdbody.particle.member.Member.force_at`), finds h from
        the modelled sum (Brent), and solves each loaded particle at its modelled share, scaled so
        that the shares add up to ``total`` exactly. Sums are exactly rounded (``math.fsum``), so
        the result does not depend on the order of the particles. It stops when every loaded
        particle's plate gap h_i agrees with their force-weighted mean h so well that its share is
        off by at most ``SHARE_TOL`` F_N (1.5 F_i |h_i − h| / δ_i, δ_i its total approach; for Hertz
        contacts this is the force error) and no unloaded particle would carry more than 10
        ``MIN_SHARE`` of the load there (a margin over the ``MIN_SHARE`` below which a modelled
        share is dropped, so that a particle on the threshold cannot make the iteration cycle)."""
        members, n = self.members, len(self.members)
        reach = np.array([m.reach(r) for m, r in zip(members, rotations, strict=True)])
        evs = list(evs) if evs is not None else [None] * n
        active = [i for i in range(n) if i not in excluded]
        for i in excluded:
            evs[i] = None
        if not active:
            return evs
        best: tuple[float, list] | None = None
        for _ in range(60):
            # each particle's compliance, once per iteration (Brent evaluates it many times)
            models = {i: members[i].compliance(rotations[i]) for i in active}
            loaded = [i for i in range(n) if evs[i] is not None]
            if loaded and abs(math.fsum(evs[i].force for i in loaded) - total) <= 1e-12 * total:
                h = math.fsum(evs[i].force * evs[i].gap for i in loaded) / total
                # each share's error: its stiffness (Hertz, 1.5 F/δ) times its gap's offset
                error = max(1.5 * evs[i].force * abs(evs[i].gap - h)
                            / (total * members[i].points[-1][2])
                            if members[i].points[-1][2] > 0 else math.inf for i in loaded)
                if all(models[j].force_at(h) < 10 * MIN_SHARE * total
                       for j in active if evs[j] is None):
                    if error <= SHARE_TOL:
                        self.share_error = max(self.share_error, error)
                        return evs
                    if best is None or error < best[0]:
                        best = (error, list(evs))

            def excess(gap: float, models=models) -> float:
                return math.fsum(models[i].force_at(gap) for i in active) - total

            top = float(reach[active].max())
            depth = 1e-3 * top
            while excess(top - depth) < 0:
                depth *= 2.0
                if depth > top:
                    raise StaticsError("the plate gap for the normal force could not be found")
            h = brentq(excess, top - depth, top, xtol=1e-15 * top, rtol=1e-15)
            forces = np.array([models[i].force_at(h) if i in active else 0.0
                               for i in range(n)])
            forces[forces < MIN_SHARE * total] = 0.0
            forces *= total / math.fsum(forces)
            for i in range(n):
                evs[i] = (members[i].at_force(rotations[i], float(forces[i]))
                          if forces[i] > 0 else None)
        if best is not None and best[0] <= SHARE_TOL_STALLED:
            # stalled at the solvers' noise: accept, and record how far the shares are off
            self.share_error = max(self.share_error, best[0])
            return best[1]
        raise StaticsError("the plate gap for the normal force did not settle in 60 iterations"
                           + (f" (shares off by {best[0]:.2g} F_N)" if best else ""))

    def rebalance(self, step: LoadStep, state: LayerState, evs, candidates: set[int],
                   stops: dict[int, float]) -> tuple[list, set[int]]:
        """The equilibrium after a round of turns, without the particles that lost their load
        while turning (``candidates``), as long as the others really hold the plates above
        them: a candidate that the new gap presses harder than where it stopped (``stops``:
        its force there, N, which vanishes with the bisection tolerance; inf for a particle
        that lost its load within the tolerance of where it was) and with more than
        ``LOST_LOAD_SHARE`` F_N is put back; it lost its load
        against the others as they were at the round's start, and they may have turned too.
        With nobody else loaded, all are put back."""
        candidates = set(candidates)
        if step.kind == "compression":
            return self.equilibrium(step, state, evs, frozenset(candidates)), candidates
        total = step.value
        while True:
            out = self.equilibrium(step, state, evs, frozenset(candidates))
            loaded = [ev for ev in out if ev is not None]
            h = self.gap(out) if loaded else None
            wrong = {i for i in candidates
                     if h is None or self.members[i].force_at(state.particles[i].rotation, h)
                     > max(1.5 * stops.get(i, 0.0), LOST_LOAD_SHARE * total)}
            if not wrong:
                return out, candidates
            candidates -= wrong

    @staticmethod
    def gap(evs) -> float:
        """The plate gap (m) of the loaded particles' evaluations: their force-weighted mean
        (each one's own for a single one)."""
        loaded = [ev for ev in evs if ev is not None]
        if len(loaded) == 1:
            return loaded[0].gap
        total = math.fsum(ev.force for ev in loaded)
        return math.fsum(ev.force * ev.gap for ev in loaded) / total

