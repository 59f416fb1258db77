"""Orientations of a particle: 3-D rotations, with the paper's tilt about +y as a special case.

Conventions (docs/methods/design.md §2): x, y horizontal, z up. An orientation is the rotation ``R``
that takes a body-frame point ``p`` to its world position ``R p`` (the centroid stays at the
origin). It is a :class:`scipy.spatial.transform.Rotation`; everywhere an orientation is accepted, a
plain number θ (radians) also is, meaning the paper's rotation by θ about +y (right-hand rule):
``(x, y, z) -> (x cos θ + z sin θ, y, −x sin θ + z cos θ)``.

A user describes an orientation by a *tilt*: an angle about a horizontal axis whose azimuth is
measured from +x towards +y (the paper's θ is a tilt about the axis at azimuth 90°), optionally
after a yaw about the body's vertical axis; or by a unit quaternion (x, y, z, w), scalar last
as in scipy. :func:`decompose` gives the tilt back from any rotation (a swing-twist
decomposition about z).

Angles are radians in this module unless a name ends in ``_deg``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["OrientationLike", "Rotation", "Tilt", "about_y", "as_rotation", "decompose",
           "key", "matrix", "tilt", "turned"]

OrientationLike = Rotation | float | int


def about_y(theta: float) -> Rotation:
    """The paper's orientation: a rotation by ``theta`` (rad) about +y."""
    return Rotation.from_rotvec([0.0, float(theta), 0.0])


def as_rotation(orientation: OrientationLike) -> Rotation:
    """A :class:`Rotation` from a Rotation (returned as is) or a number θ (rad about +y)."""
    if isinstance(orientation, Rotation):
        if not orientation.single:
            raise ValueError("an orientation must be a single rotation, not a stack")
        return orientation
    if isinstance(orientation, bool) or not isinstance(orientation, int | float | np.floating
                                                         | np.integer):
        raise TypeError(f"an orientation is a scipy Rotation or an angle in rad about +y, got "
                        f"{type(orientation).__name__}")
    theta = float(orientation)
    if not math.isfinite(theta):
        raise ValueError(f"orientation angle must be finite, got {orientation!r}")
    return about_y(theta)


def matrix(orientation: OrientationLike) -> np.ndarray:
    """The 3x3 rotation matrix (body -> world) of an orientation."""
    return as_rotation(orientation).as_matrix()


def key(orientation: OrientationLike) -> tuple[float, float, float, float]:
    """A hashable key of an orientation (its quaternion with w >= 0), for caches.

    Two orientations share a key only if their quaternions are bitwise equal up to the overall
    sign, so cached geometry is never reused for a different rotation.
    """
    q = as_rotation(orientation).as_quat()
    if q[3] < 0 or (q[3] == 0 and next((v for v in q if v != 0), 0.0) < 0):
        q = -q
    return tuple(float(v) + 0.0 for v in q)        # + 0.0: no negative zeros in keys


def tilt(angle_deg: float, axis_azimuth_deg: float = 90.0, yaw_deg: float = 0.0) -> Rotation:
    """The orientation reached by a yaw about z, then a tilt about a horizontal axis.

    Parameters
    ----------
    angle_deg : float
        Tilt angle, degrees (right-hand rule about the axis).
    axis_azimuth_deg : float
        Azimuth of the tilt axis, degrees from +x towards +y; 90 (the default) is +y, the
        paper's axis, so ``tilt(θ)`` is the paper's orientation θ.
    yaw_deg : float
        Rotation about the body's vertical axis applied first, degrees.
    """
    for name, value in (("angle_deg", angle_deg), ("axis_azimuth_deg", axis_azimuth_deg),
                        ("yaw_deg", yaw_deg)):
        if not math.isfinite(float(value)):
            raise ValueError(f"{name} must be a finite angle in degrees, got {value!r}")
    az = math.radians(axis_azimuth_deg)
    angle = math.radians(angle_deg)
    swing = Rotation.from_rotvec([angle * math.cos(az), angle * math.sin(az), 0.0])
    if yaw_deg == 0:
        return swing
    return swing * Rotation.from_rotvec([0.0, 0.0, math.radians(yaw_deg)])


@dataclass(frozen=True)
class Tilt:
    """An orientation as a tilt after a yaw (see :func:`decompose`), degrees.

    ``vector_deg`` is the tilt's horizontal rotation vector (angle times the unit axis), which
    varies continuously with the orientation; for the paper's rotation θ about +y it is (0, θ).
    """

    angle_deg: float
    azimuth_deg: float
    yaw_deg: float
    vector_deg: tuple[float, float]


def decompose(orientation: OrientationLike) -> Tilt:
    """Split ``R = S · Y``: ``Y`` a yaw about the body's z axis, ``S`` a tilt about a horizontal
    axis taking z to the body's z axis ``b = R e_z`` (swing-twist decomposition).

    The tilt angle is the angle between ``b`` and +z (0 to 180°); its axis is ``e_z × b``.
    When ``b`` is (anti)parallel to z the axis is undefined and reported as +y (azimuth 90°).
    """
    R = as_rotation(orientation)
    b = R.apply([0.0, 0.0, 1.0])
    horizontal = math.hypot(b[0], b[1])
    angle = math.atan2(horizontal, b[2])
    if horizontal > 0:
        axis = np.array([-b[1], b[0], 0.0]) / horizontal
    else:
        axis = np.array([0.0, 1.0, 0.0])
    swing = Rotation.from_rotvec(angle * axis)
    yaw = (swing.inv() * R).as_rotvec()[2]
    vector = np.degrees(angle * axis[:2])
    return Tilt(math.degrees(angle), math.degrees(math.atan2(axis[1], axis[0])),
                math.degrees(yaw), (float(vector[0]) + 0.0, float(vector[1]) + 0.0))


def turned(orientation: OrientationLike, axis: Sequence[float], angle: float) -> Rotation:
    """The orientation after a further rotation by ``angle`` (rad) about the world axis
    ``axis`` (a unit 2-vector in the horizontal plane, or a 3-vector) through the centroid."""
    a = np.zeros(3)
    v = np.asarray(axis, dtype=float)
    a[: v.size] = v
    n = np.linalg.norm(a)
    if not n > 0:
        raise ValueError(f"turning axis must be a non-zero vector, got {axis!r}")
    return Rotation.from_rotvec(a * (float(angle) / n)) * as_rotation(orientation)
