"""Coulomb's law on the cells of a window: the friction discs |τ| <= μp and the natural residual.

Tractions τ are (k, ny, nx) arrays in Pa (k = 2: (τ_x, τ_y); k = 1: τ_x alone, where the disc is
the box |τ_x| <= μp), exerted by the plate on the particle; the slip w is the plate's relative
tangential motion over the particle's surface in the step, m, in the same layout.
"""

from __future__ import annotations

import numpy as np


def project_on_discs(traction: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Each cell's traction (Pa) pulled back radially onto its friction disc of radius
    ``limit`` = μp (Pa) where it lies outside, unchanged inside."""
    norm = np.sqrt((traction * traction).sum(axis=0))     # |τ_x| in the scalar problem
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(norm > limit, limit / np.where(norm > 0, norm, 1.0), 1.0)
    return traction * factor


def coulomb_residual(traction: np.ndarray, slip_increment: np.ndarray, pressure: np.ndarray,
                     mu: float, self_compliance: float) -> float:
    """Natural residual of Coulomb's law, dimensionless: max over cells of
    |τ − Π(τ + w/k₀)| / (μ max p), with Π the projection on the friction disc and k₀ the
    self-compliance (m/Pa). Zero iff every cell obeys stick (w = 0, |τ| <= μp) or slip
    (|τ| = μp, τ along w) exactly; see :class:`~thirdbody.bem.tangential.TangentialContact`."""
    trial = traction + slip_increment / self_compliance
    norm = np.sqrt((trial * trial).sum(axis=0))
    limit = mu * pressure
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(norm > limit, limit / np.where(norm > 0, norm, 1.0), 1.0)
    diff = traction - trial * factor
    scale = mu * float(pressure.max())
    return float(np.sqrt((diff * diff).sum(axis=0)).max() / scale) if scale > 0 else 0.0
