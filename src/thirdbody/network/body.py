"""A rigid body's pose in a network of touching particles: shape, material, rotation, centre.

Conventions (docs/methods/design.md §2, §3c): x, y horizontal, z up, SI units. A body-frame
point ``p`` sits in the world at ``centre + rotation.apply(p)``; the body frame has the shape's
volume centroid at its origin, so ``centre`` is the world position of the centroid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..material import Material
from ..orientation import Rotation, as_rotation
from ..shapes import Shape

__all__ = ["Body"]


@dataclass(frozen=True, eq=False)
class Body:
    """A particle placed in the world: what a particle-particle contact needs to know of it.

    Attributes
    ----------
    shape : Shape
        The particle's geometry (body frame, centroid at the origin), m.
    material : Material
        Its elastic constants (E in Pa, ν).
    rotation : Rotation
        Body -> world rotation (a scipy ``Rotation``; a number θ means θ rad about +y).
    centre : (3,) array
        World position of the centroid, m.
    """

    shape: Shape
    material: Material
    rotation: Rotation = field(default_factory=Rotation.identity)
    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        if not isinstance(self.shape, Shape):
            raise TypeError(f"Body.shape must be a thirdbody Shape, got "
                            f"{type(self.shape).__name__}")
        if not isinstance(self.material, Material):
            raise TypeError(f"Body.material must be a thirdbody Material, got "
                            f"{type(self.material).__name__}")
        try:
            rotation = as_rotation(self.rotation)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"Body.rotation: {exc}") from None
        try:
            centre = np.array(self.centre, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            centre = np.full(0, np.nan)
        if centre.shape != (3,) or not np.isfinite(centre).all():
            raise ValueError(f"Body.centre must be three finite coordinates (m), got "
                             f"{self.centre!r}")
        centre.setflags(write=False)
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "centre", centre)

    @cached_property
    def matrix(self) -> np.ndarray:
        """The rotation's 3 x 3 matrix (body -> world), computed once (read-only)."""
        m = self.rotation.as_matrix()
        m.setflags(write=False)
        return m

    @property
    def size(self) -> float:
        """Radius of the bounding sphere about the centroid, m (:attr:`Shape.size`)."""
        return float(self.shape.size)

    def moved(self, rotation: Rotation | None = None, centre=None) -> Body:
        """The same body at another pose (either part kept when not given)."""
        return Body(self.shape, self.material,
                    self.rotation if rotation is None else rotation,
                    self.centre if centre is None else centre)

    def transformed(self, rotation: Rotation, translation=(0.0, 0.0, 0.0)) -> Body:
        """The body after the rigid motion x -> rotation x + translation of the whole world."""
        rotation = as_rotation(rotation)
        return Body(self.shape, self.material, rotation * self.rotation,
                    rotation.apply(np.array(self.centre)) + np.asarray(translation, dtype=float))

    def to_world(self, points) -> np.ndarray:
        """World coordinates (m) of body-frame points (..., 3)."""
        return self.rotation.apply(np.asarray(points, dtype=float).reshape(-1, 3)).reshape(
            np.shape(points)) + self.centre

    def __repr__(self) -> str:
        c = ", ".join(f"{v:.6g}" for v in self.centre)
        angle = math.degrees(float(np.linalg.norm(self.rotation.as_rotvec())))
        return f"Body({self.shape!r}, {self.material!r}, turned {angle:.3g} deg, centre=({c}))"
