"""The particle and the plates: what a simulation is about, with validated inputs."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .._validate import real
from ..material import Material
from ..shapes import Shape

__all__ = ["Particle", "Plates"]


@dataclass(frozen=True)
class Particle:
    """An elastic particle: a shape, its material and its initial orientation.

    Parameters
    ----------
    shape : thirdbody.shapes.Shape
        The geometry (body frame, metres, centroid at the origin).
    material : Material
        Young's modulus (Pa) and Poisson ratio of the particle; the plates are rigid.
    orientation_deg : float
        Initial rotation θ₀ about +y (right-hand rule), degrees.
    """

    shape: Shape
    material: Material
    orientation_deg: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.shape, Shape):
            raise TypeError(f"particle.shape must be a thirdbody.shapes.Shape, got "
                            f"{type(self.shape).__name__}")
        if not isinstance(self.material, Material):
            raise TypeError(f"particle.material must be a thirdbody.Material, got "
                            f"{type(self.material).__name__}")
        real("particle.orientation_deg (degrees)", self.orientation_deg, "(-inf, inf)",
             lambda x: True)

    @property
    def orientation(self) -> float:
        """Initial orientation θ₀ in radians."""
        return math.radians(self.orientation_deg)


@dataclass(frozen=True)
class Plates:
    """Two rigid horizontal plates with Coulomb friction coefficients (dimensionless, >= 0).

    ``mu_low`` defaults to ``mu_up``. The coefficients count as equal (rotation about the
    centroid rather than rolling) when they agree to ``mu_rtol``.
    """

    mu_up: float
    mu_low: float | None = None
    mu_rtol: float = 1e-9

    def __post_init__(self) -> None:
        real("plates.mu_up (friction coefficient)", self.mu_up, "[0, inf)", lambda x: x >= 0)
        if self.mu_low is None:
            object.__setattr__(self, "mu_low", float(self.mu_up))
        real("plates.mu_low (friction coefficient)", self.mu_low, "[0, inf)", lambda x: x >= 0)
        object.__setattr__(self, "mu_up", float(self.mu_up))
        object.__setattr__(self, "mu_low", float(self.mu_low))

    @property
    def mu_min(self) -> float:
        """The smaller coefficient: the most tangential force the pair can transmit is
        ``mu_min · F_N``."""
        return min(self.mu_up, self.mu_low)

    @property
    def equal(self) -> bool:
        return abs(self.mu_up - self.mu_low) <= self.mu_rtol * max(self.mu_up, self.mu_low)
