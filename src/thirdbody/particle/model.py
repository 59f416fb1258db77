"""The particle and the plates: what a simulation is about, with validated inputs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import real
from ..material import Material
from ..orientation import Rotation, tilt
from ..shapes import Shape

__all__ = ["Particle", "Plates"]


@dataclass(frozen=True)
class Particle:
    """An elastic particle: a shape, its material and its initial orientation.

    The orientation is a tilt (``orientation_deg`` about the horizontal axis at azimuth
    ``tilt_axis_deg``, after a yaw of ``yaw_deg`` about the body's own z axis) or a unit
    ``quaternion`` (x, y, z, w), body to world; see :mod:`thirdbody.orientation`. Then
    ``azimuth_deg`` turns the particle about the world's vertical: R = R_z(azimuth) · R, so
    that turning a whole problem about z is one number.

    Parameters
    ----------
    shape : thirdbody.shapes.Shape
        The geometry (body frame, metres, centroid at the origin).
    material : Material
        Young's modulus (Pa) and Poisson ratio of the particle; the plates are rigid.
    orientation_deg : float
        Initial tilt angle, degrees; about +y by default (the paper's θ₀).
    tilt_axis_deg : float
        Azimuth of the tilt axis, degrees from +x towards +y (default 90: the +y axis).
    yaw_deg : float
        Rotation about the body's z axis before the tilt, degrees.
    quaternion : (4,) floats, optional
        The initial orientation as a quaternion (x, y, z, w), normalised here; instead of the
        tilt (which must then keep its defaults).
    azimuth_deg : float
        A last rotation about the world's vertical axis (+z, counter-clockwise seen from
        above), degrees, after the tilt or the quaternion. ``tilt(θ, φ, ψ)`` turned by α is
        ``tilt(θ, φ + α, ψ + α)``.
    """

    shape: Shape
    material: Material
    orientation_deg: float = 0.0
    tilt_axis_deg: float = 90.0
    yaw_deg: float = 0.0
    quaternion: tuple[float, float, float, float] | None = None
    azimuth_deg: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.shape, Shape):
            raise TypeError(f"particle.shape must be a thirdbody.shapes.Shape, got "
                            f"{type(self.shape).__name__}")
        if not isinstance(self.material, Material):
            raise TypeError(f"particle.material must be a thirdbody.Material, got "
                            f"{type(self.material).__name__}")
        for name in ("orientation_deg", "tilt_axis_deg", "yaw_deg", "azimuth_deg"):
            value = real(f"particle.{name} (degrees)", getattr(self, name), "(-inf, inf)",
                         lambda x: True)
            object.__setattr__(self, name, value)
        if self.quaternion is not None:
            if (self.orientation_deg, self.tilt_axis_deg, self.yaw_deg) != (0.0, 90.0, 0.0):
                raise ValueError("particle: give either a tilt (orientation_deg, tilt_axis_deg, "
                                 "yaw_deg) or a quaternion, not both")
            q = np.asarray(self.quaternion, dtype=float)
            if q.shape != (4,) or not np.all(np.isfinite(q)) or not np.linalg.norm(q) > 0:
                raise ValueError(f"particle.quaternion must be four finite numbers (x, y, z, w), "
                                 f"not all zero, got {self.quaternion!r}")
            object.__setattr__(self, "quaternion", tuple(float(v) for v in q / np.linalg.norm(q)))

    @property
    def orientation(self) -> Rotation:
        """Initial orientation (body -> world)."""
        if self.quaternion is not None:
            rotation = Rotation.from_quat(self.quaternion)
        else:
            rotation = tilt(self.orientation_deg, self.tilt_axis_deg, self.yaw_deg)
        if self.azimuth_deg == 0:
            return rotation
        return Rotation.from_rotvec([0.0, 0.0, np.radians(self.azimuth_deg)]) * rotation


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
