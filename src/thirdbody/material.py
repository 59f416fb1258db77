"""Elastic constants of the particle."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic particle material against rigid plates.

    Parameters
    ----------
    E : float
        Young's modulus in Pa, E > 0.
    nu : float
        Poisson's ratio, -1 < nu <= 0.5.
    """

    E: float
    nu: float

    def __post_init__(self) -> None:
        E, nu = self.E, self.nu
        if not isinstance(E, int | float) or not math.isfinite(E) or E <= 0:
            raise ValueError(
                f"Material.E (Young's modulus) must be a finite number > 0 Pa, got {E!r}")
        if not isinstance(nu, int | float) or not math.isfinite(nu) or not -1.0 < nu <= 0.5:
            raise ValueError(f"Material.nu (Poisson's ratio) must lie in (-1, 0.5], got {nu!r}")
        object.__setattr__(self, "E", float(E))
        object.__setattr__(self, "nu", float(nu))

    @property
    def E_star(self) -> float:
        """Plane-strain contact modulus against a rigid plate, E/(1 - nu^2), in Pa."""
        return self.E / (1.0 - self.nu**2)

    @property
    def G(self) -> float:
        """Shear modulus E/(2(1 + nu)), in Pa."""
        return self.E / (2.0 * (1.0 + self.nu))
