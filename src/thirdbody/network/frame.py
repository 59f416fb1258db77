"""The contact frame of two bodies, and their surfaces seen from it along vertical rays.

A particle-particle contact is solved in its own frame (docs/methods/design.md §3c): the
rotation ``F`` takes the common normal n (from body a to body b) to +z, and the origin is a world
point o near the contact (the midpoint of the closest points). A world point x has frame coordinates
``F (x − o)``; in that frame body a lies below, body b above, and the gap along a vertical ray
is the lowest height of b minus the highest height of a, both from :meth:`Shape.surfaces`.

Two frames are used. The narrow phase only needs the vertical: :func:`contact_frame` is the
smallest rotation taking n to +z. The contact's lattice also needs tangent axes, and those are
tied to the bodies (:func:`pair_frame`): t₁ is the tangential part of the sum of both bodies'
x axes. So a rotation of the whole pair turns the lattice with it (the gaps, hence every scalar
of the solution, do not change), exchanging a and b mirrors the lattice (the frame of (b, a) is
that of (a, b) turned half a turn about t₁), and a pair spinning rigidly about n carries its
lattice along.
"""

from __future__ import annotations

import math

import numpy as np

from ..orientation import Rotation

__all__ = ["contact_frame", "gap_in_frame", "heights_in_frame", "pair_frame",
           "smallest_rotation"]

_Z = np.array([0.0, 0.0, 1.0])


def unit(vector, name: str = "normal") -> np.ndarray:
    """``vector`` (3,) scaled to unit length, or ValueError naming ``name``."""
    v = np.asarray(vector, dtype=float).reshape(-1)
    length = float(np.linalg.norm(v)) if v.shape == (3,) else math.nan
    if not (math.isfinite(length) and length > 0):
        raise ValueError(f"{name} must be a finite non-zero 3-vector, got {vector!r}")
    return v / length


def smallest_rotation(u, v) -> Rotation:
    """The rotation about u × v taking the unit vector u to the unit vector v (a half turn about
    an axis ⟂ u, x if it can, when v = −u)."""
    # np.cross(u, v), spelt out (the same operations, without its overhead on 3-vectors)
    axis = np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                     u[0] * v[1] - u[1] * v[0]], dtype=float)
    s = float(np.linalg.norm(axis))
    c = float(np.dot(u, v))
    if s < 1e-300:
        if c > 0:
            return Rotation.identity()
        perp = np.cross(u, [0.0, 1.0, 0.0])
        if np.linalg.norm(perp) < 0.5:
            perp = np.cross(u, [0.0, 0.0, 1.0])
        return Rotation.from_rotvec(math.pi * perp / np.linalg.norm(perp))
    return Rotation.from_rotvec(axis / s * math.atan2(s, c))


def contact_frame(normal) -> Rotation:
    """World -> contact-frame rotation F with F n = +z: the smallest rotation taking the unit
    normal ``n`` (3,) to +z (about n × z; a half turn about x when n = −z)."""
    return smallest_rotation(unit(normal), _Z)


def pair_frame(a, b, normal) -> Rotation:
    """World -> contact-frame rotation of the pair (a, b) with unit normal ``normal`` from a to b:
    rows t₁, t₂ = n × t₁, n, with t₁ the normalised tangential part of the sum of both bodies'
    body-x axes (their y axes if that sum is nearly normal; the smallest rotation's axes if both
    are)."""
    n = unit(normal)
    for k in (0, 1):
        axis = a.rotation.apply(np.eye(3)[k]) + b.rotation.apply(np.eye(3)[k])
        t1 = axis - (axis @ n) * n
        length = float(np.linalg.norm(t1))
        if length > 0.1:
            t1 /= length
            t2 = np.cross(n, t1)
            return Rotation.from_matrix(np.stack([t1, t2, n]))
    return contact_frame(n)


class Seen:
    """A body seen from a frame: its centroid in frame coordinates (m) and its body -> frame
    rotation (a ``Rotation`` and its matrix), worked out once for many rays.

    ``frame`` is the world -> frame rotation, ``origin`` (3,) the frame origin in the world, m;
    ``matrix`` is ``frame``'s matrix if the caller has it.
    """

    __slots__ = ("centre", "matrix", "rotation", "shape")

    def __init__(self, body, frame: Rotation, origin, matrix: np.ndarray | None = None) -> None:
        F = frame.as_matrix() if matrix is None else matrix
        # F @ v is bit for bit frame.apply(v)
        self.centre = F @ (np.asarray(body.centre, dtype=float) - np.asarray(origin, dtype=float))
        self.rotation = frame * body.rotation
        self.matrix = self.rotation.as_matrix()
        self.shape = body.shape

    def heights(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Lowest and highest heights (m) along the vertical rays at frame coordinates x, y (m);
        NaN where a ray misses."""
        c = self.centre
        z_low, z_up = self.shape._surfaces_rotated(self.rotation, self.matrix,
                                                   np.asarray(x) - c[0], np.asarray(y) - c[1])
        return z_low + c[2], z_up + c[2]


def heights_in_frame(body, frame: Rotation, origin, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest heights (m) of ``body`` along vertical rays of the frame.

    ``frame`` is the world -> frame rotation, ``origin`` (3,) the frame origin in the world;
    ``x``, ``y`` are frame coordinates (m). NaN where the ray misses the body.
    """
    return Seen(body, frame, origin).heights(x, y)


def seen_gap(a: Seen, b: Seen, x, y) -> np.ndarray:
    """:func:`gap_in_frame` of two bodies already seen from the frame."""
    _, z_up = a.heights(x, y)
    z_low, _ = b.heights(x, y)
    gap = z_low - z_up
    return np.where(np.isnan(gap), np.inf, gap)


def gap_in_frame(a, b, frame: Rotation, origin, x, y) -> np.ndarray:
    """Vertical gap (m) from body a (below) to body b (above) at frame coordinates (x, y): the
    lowest height of b minus the highest height of a; +inf where a ray misses either body,
    negative where the undeformed bodies overlap."""
    F = frame.as_matrix()
    return seen_gap(Seen(a, frame, origin, F), Seen(b, frame, origin, F), x, y)
