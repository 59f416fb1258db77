"""A particle's normal force against the plate gap, modelled from its last solves, and its
share of a layer's load while it turns with the others held (their compliance models).
All quantities SI."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .statics import Evaluation

__all__ = ["MIN_SHARE", "Compliance", "share_while_turning"]

#: a particle whose modelled share is below this fraction of F_N counts as unloaded
MIN_SHARE = 1e-6


@dataclass(frozen=True)
class Compliance:
    """A particle's normal force against the plate gap at one orientation, modelled from its
    last solves there: ``points`` (force N, plate gap m, total approach m), ``reach`` the plate
    gap at first contact (m, from the scan), the material's E* (Pa) and the shape's size (m)."""

    points: tuple[tuple[float, float, float], ...]
    reach: float
    E_star: float
    size: float

    def force_at(self, gap: float) -> float:
        """The normal force (N) at plate gap ``gap`` (m): F^(2/3) linear in the gap (Hertz),
        through the last two solves when their forces differ by more than 0.1 % (a secant);
        otherwise through the last solve with the Hertz stiffness of its approach,
        F ∝ (δ + h₁ − h)^(3/2), δ the total approach measured from the lowest surface cells (a
        Newton step, free of the solver's noise); with no solve, Hertz for a radius ``size``
        from the scanned height."""
        pts = self.points
        if len(pts) == 2 and abs(pts[0][0] - pts[1][0]) > 1e-3 * pts[1][0] \
                and pts[0][1] != pts[1][1]:
            (F0, h0, _), (F1, h1, _) = pts
            slope = (F1 ** (2 / 3) - F0 ** (2 / 3)) / (h1 - h0)
            if slope < 0:
                value = F1 ** (2 / 3) + slope * (gap - h1)
                return value**1.5 if value > 0 else 0.0
        if pts and pts[-1][2] > 0 and pts[-1][0] > 0:
            F1, h1, d1 = pts[-1]
            value = (d1 + h1 - gap) / d1
            return F1 * value**1.5 if value > 0 else 0.0
        delta = self.reach - gap
        return (4.0 / 3.0 * self.E_star * math.sqrt(self.size) * (delta / 2) ** 1.5
                if delta > 0 else 0.0)


def share_while_turning(m, rotation, total: float, others: list[Compliance],
                        guess: float, twins: int = 1) -> Evaluation:
    """A particle at ``rotation`` under force control, the others held: its share F_i with
    n F_i + Σ_j F_j(h_i) = ``total`` (n = ``twins``: identical particles at the same
    orientation, each carrying F_i), the others' forces from their compliance models, by
    Illinois iterations on F_i in [0, total/n] (the residual grows with F_i). Unloaded
    (:meth:`Evaluation.unloaded`) when the others alone hold the plates above its top."""

    def rest(gap: float) -> float:
        return math.fsum(c.force_at(gap) for c in others)

    reach = m.reach(rotation)
    lo_f, lo_r = 0.0, rest(reach) - total
    if lo_r >= 0:
        return Evaluation.unloaded(rotation)
    hi_f = hi_r = None
    cap = total / twins
    F = min(max(guess, 1e-3 * cap), cap)
    best = None
    side = 0
    for _ in range(40):
        ev = m.at_force(rotation, F)
        r = twins * F + rest(ev.gap) - total
        best = ev
        if abs(r) <= 1e-9 * total:
            break
        if r > 0:
            hi_f, hi_r = F, r
            if side == 1:
                lo_r *= 0.5
            side = 1
        else:
            lo_f, lo_r = F, r
            if side == -1 and hi_r is not None:
                hi_r *= 0.5
            side = -1
        if hi_f is None:
            F = min(2.0 * F, cap)
        else:
            F = lo_f - lo_r * (hi_f - lo_f) / (hi_r - lo_r)
            if not lo_f < F < hi_f:
                F = 0.5 * (lo_f + hi_f)
        if F <= MIN_SHARE * total:
            return Evaluation.unloaded(rotation)
    return best
