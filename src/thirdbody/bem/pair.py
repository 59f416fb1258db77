"""The elastic constants of a contact pair: what the boundary-element solvers need to know.

A contact between two half-spaces is governed by combined compliances, not by either body's
material alone (Johnson, *Contact Mechanics*, 1985, §5.1; Dundurs 1969):

* normal: 1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂;
* tangential: the Cerruti blocks add, K_xx = Σ[(1 − ν_i)A + B]/(2πG_i), which is exactly one
  body with 1/G = Σ 1/G_i and ν = G Σ ν_i/G_i;
* normal–tangential coupling: the bodies sit on opposite sides of the interface, so their
  coupling terms subtract; in units of the normal compliance it is Dundurs' second parameter

      β = [(1 − 2ν₁)/G₁ − (1 − 2ν₂)/G₂] / [2 (1 − ν₁)/G₁ + 2 (1 − ν₂)/G₂],

  and the coupling influence coefficient is K_zx = β H_x/(π E*) (docs/methods/algorithms.md: for one
  body (1 − 2ν)/(4πG) = β/(πE*)). β = 0 for two equal materials or for ν = 0.5 against a rigid body:
  Goodman's approximation (no coupling) is then exact.

Today the particle meets rigid plates (:meth:`ElasticPair.rigid_plate`); :meth:`ElasticPair.of`
takes two materials for an elastic counter-face.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .._citations import cites

_DUNDURS = ("Dundurs, J. (1969). Discussion of 'Edge-bonded dissimilar orthogonal elastic "
            "wedges under normal and shear loading'. J. Appl. Mech. 36, 650-652.")


@cites("dundurs1969", _DUNDURS)
@dataclass(frozen=True)
class ElasticPair:
    """Combined elastic constants of the two bodies at an interface (body 1: the particle).

    Attributes
    ----------
    E_star : float
        Contact modulus E* (Pa), 1/E* = Σ (1 − ν_i²)/E_i.
    G : float
        Combined shear modulus (Pa), 1/G = Σ 1/G_i.
    nu : float
        Combined Poisson's ratio of the tangential blocks, G Σ ν_i/G_i.
    beta : float
        Dundurs' β of the pair (dimensionless, |β| <= 0.5): the strength of the normal-tangential
        coupling, with the sign of body 1 (the particle, on the side the traction acts on).
    """

    E_star: float
    G: float
    nu: float
    beta: float

    def __post_init__(self) -> None:
        for name in ("E_star", "G"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"ElasticPair.{name} must be a finite number > 0 Pa, "
                                 f"got {value!r}")
        if not (isinstance(self.nu, int | float) and -1.0 < self.nu <= 0.5):
            raise ValueError(f"ElasticPair.nu must lie in (-1, 0.5], got {self.nu!r}")
        if not (isinstance(self.beta, int | float) and abs(self.beta) <= 0.5 + 1e-12):
            raise ValueError(f"ElasticPair.beta (Dundurs) must lie in [-0.5, 0.5], "
                             f"got {self.beta!r}")

    @classmethod
    def rigid_plate(cls, material) -> ElasticPair:
        """An elastic body (``material``: E, ν) against a rigid plate: E* = E/(1 − ν²), G and ν
        of the body, β = (1 − 2ν)/(2(1 − ν)) (0.29 at ν = 0.3, 0.5 at ν = 0, 0 at ν = 0.5)."""
        E, nu = float(material.E), float(material.nu)
        # the single-body formulas as Material writes them, so the moduli are the same floats
        return cls(E_star=E / (1.0 - nu**2), G=E / (2.0 * (1.0 + nu)), nu=nu,
                   beta=(1.0 - 2.0 * nu) / (2.0 * (1.0 - nu)))

    @classmethod
    def of(cls, body, counter=None) -> ElasticPair:
        """The pair of two isotropic bodies (objects with ``E`` in Pa and ``nu``); ``counter``
        None is rigid."""
        bodies = [(float(body.E), float(body.nu))]
        if counter is not None:
            bodies.append((float(counter.E), float(counter.nu)))
        shear = [E / (2.0 * (1.0 + nu)) for E, nu in bodies]
        normal = sum((1.0 - nu * nu) / E for E, nu in bodies)
        tangential = sum(1.0 / G for G in shear)
        nu = sum(nu / G for (_, nu), G in zip(bodies, shear, strict=True)) / tangential
        signs = (1.0, -1.0)
        top = sum(s * (1.0 - 2.0 * nu_i) / G
                  for s, (_, nu_i), G in zip(signs, bodies, shear, strict=False))
        bottom = sum(2.0 * (1.0 - nu_i) / G for (_, nu_i), G in zip(bodies, shear, strict=True))
        return cls(E_star=1.0 / normal, G=1.0 / tangential, nu=nu, beta=top / bottom)

    @property
    def coupled(self) -> bool:
        """Whether the normal and tangential problems interact (β ≠ 0)."""
        return self.beta != 0.0

    @property
    def coupling_modulus(self) -> float:
        """β/(π E*), m/Pa per unit length: the factor of H_x in K_zx
        (docs/methods/algorithms.md)."""
        return self.beta / (math.pi * self.E_star)
