"""Particle shapes seen by the two plates: the abstract :class:`Shape` and frame helpers.

Conventions (DESIGN.md §2)
--------------------------
* World frame: x horizontal in the plane of rotation, y horizontal (the rotation axis), z up.
  The plates are horizontal; the lower plate touches the particle from below, the upper plate
  from above.
* Body frame: the shape is defined with its volume centroid at the origin.
* Orientation ``theta`` (radians in this module) is a rotation about +y by the right-hand rule:
  a body-frame point ``(x, y, z)`` sits in the world at
  ``(x cos θ + z sin θ, y, −x sin θ + z cos θ)``. The centroid stays at the world origin.
* Lengths are in metres.

The plates only need the shape through vertical rays: for each world point ``(x, y)`` of an
interface window, the lowest and highest heights where the vertical line through it meets the
rotated body (:meth:`Shape.surfaces`), and the extreme points that the plates touch first
(:meth:`Shape.lowest_point`, :meth:`Shape.highest_point`). The initial separations
:meth:`Shape.gap_lower` and :meth:`Shape.gap_upper` are what the contact solver consumes.
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from collections.abc import Callable

FloatArray = NDArray[np.float64]

__all__ = ["Shape", "rotate_to_body", "rotate_to_world"]

_CACHE_SIZE = 64


def rotate_to_world(points: ArrayLike, theta: float) -> FloatArray:
    """Map body-frame points (…, 3) to the world frame for orientation ``theta`` (rad).

    ``(x, y, z) -> (x cos θ + z sin θ, y, −x sin θ + z cos θ)``: a rotation about +y by the
    right-hand rule. Units are preserved (metres).
    """
    p = np.asarray(points, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty(np.broadcast_shapes(p.shape, (3,)))
    out[..., 0] = c * p[..., 0] + s * p[..., 2]
    out[..., 1] = p[..., 1]
    out[..., 2] = -s * p[..., 0] + c * p[..., 2]
    return out


def rotate_to_body(points: ArrayLike, theta: float) -> FloatArray:
    """Inverse of :func:`rotate_to_world`: world-frame points (…, 3) to the body frame."""
    return rotate_to_world(points, -theta)


def _ray_frame(theta: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Body-frame images of the world unit vectors x, y and z (up) at orientation ``theta``."""
    c, s = np.cos(theta), np.sin(theta)
    ex = np.array([c, 0.0, s])
    ey = np.array([0.0, 1.0, 0.0])
    ez = np.array([-s, 0.0, c])
    return ex, ey, ez


def _broadcast_xy(x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    return xa, ya


class Shape(abc.ABC):
    """A rigid particle shape, seen through vertical rays at an orientation ``theta``.

    Subclasses implement :meth:`surfaces`, ``_lowest_point`` (uncached), :meth:`mirrored` and
    :attr:`size`, and call ``super().__init__()``. The default :meth:`highest_point` uses the
    identity ``highest(θ) = M·lowest(θ + π)`` with ``M: (x, y, z) -> (−x, y, −z)``, because
    turning the body by π about y maps (x, z) to (−x, −z). Extreme points are cached per ``theta``
    (shapes are immutable).

    All lengths are in metres, angles in radians.
    """

    def __init__(self) -> None:
        self._extreme_cache: dict[tuple[str, float], FloatArray] = {}

    # --- to implement -----------------------------------------------------------------------
    @abc.abstractmethod
    def surfaces(self, theta: float, x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest heights z (m) of the rotated body along vertical rays.

        Parameters
        ----------
        theta:
            Orientation (rad), rotation about +y.
        x, y:
            World horizontal coordinates (m) of the rays; any broadcastable shapes.

        Returns
        -------
        (z_low, z_up):
            Arrays of the broadcast shape: the lowest and the highest crossing of each ray with
            the body surface (for a non-convex body, the extreme ones), NaN where the ray misses.
        """

    @abc.abstractmethod
    def _lowest_point(self, theta: float) -> FloatArray:
        """Uncached world-frame lowest point (x, y, z) in metres."""

    @abc.abstractmethod
    def mirrored(self) -> Shape:
        """The shape mirrored in the body x coordinate (x -> −x).

        The mirrored shape at orientation −θ is the mirror image (world x -> −x) of this shape at
        orientation θ.
        """

    @property
    @abc.abstractmethod
    def size(self) -> float:
        """A characteristic length (m): the largest distance from the centroid to the surface."""

    # --- provided ---------------------------------------------------------------------------
    @property
    def centroid(self) -> FloatArray:
        """Volume centroid (m) in the body frame: zero by construction."""
        return np.zeros(3)

    def _cached(self, key: str, theta: float, fn: Callable[[float], FloatArray]) -> FloatArray:
        k = (key, float(theta))
        hit = self._extreme_cache.get(k)
        if hit is None:
            if len(self._extreme_cache) >= _CACHE_SIZE:
                self._extreme_cache.pop(next(iter(self._extreme_cache)))
            hit = np.asarray(fn(float(theta)), dtype=float)
            hit.setflags(write=False)
            self._extreme_cache[k] = hit
        return hit.copy()

    def lowest_point(self, theta: float) -> FloatArray:
        """World-frame point (x, y, z) in metres where the body reaches its lowest height.

        This is where the lower plate touches first. If several points share the minimum (for a
        shape symmetric in y, a pair at ±y), the one with y >= 0 is returned.
        """
        return self._cached("low", theta, self._lowest_point)

    def _highest_point(self, theta: float) -> FloatArray:
        p = self.lowest_point(theta + np.pi)
        return np.array([-p[0], p[1], -p[2]])

    def highest_point(self, theta: float) -> FloatArray:
        """World-frame point (x, y, z) in metres where the body reaches its highest height."""
        return self._cached("high", theta, self._highest_point)

    def height(self, theta: float) -> float:
        """Vertical extent (m) of the body: the plate gap at first contact of both plates."""
        return float(self.highest_point(theta)[2] - self.lowest_point(theta)[2])

    def gap_lower(self, theta: float, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Initial separation (m) between the lower plate at first contact and the body.

        ``z_low(x, y) − z_min`` at world coordinates (x, y) (m), >= 0, +inf where the ray misses
        the body. The plate touches at :meth:`lowest_point`, where the gap is zero.
        """
        z_low, _ = self.surfaces(theta, x, y)
        gap = np.maximum(z_low - self.lowest_point(theta)[2], 0.0)
        return np.where(np.isnan(z_low), np.inf, gap)

    def gap_upper(self, theta: float, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Initial separation (m) between the upper plate at first contact and the body.

        ``z_max − z_up(x, y)`` at world coordinates (x, y) (m), >= 0, +inf where the ray misses.
        """
        _, z_up = self.surfaces(theta, x, y)
        gap = np.maximum(self.highest_point(theta)[2] - z_up, 0.0)
        return np.where(np.isnan(z_up), np.inf, gap)

    def _radial_surface(self, directions: FloatArray) -> FloatArray:
        """Body-frame surface points (n, 3) along unit ``directions`` from the shape's centre.

        Used to tessellate star-shaped analytic shapes (:meth:`MeshShape.from_shape`). The centre
        may differ from the centroid. Shapes that cannot do this raise ``NotImplementedError``.
        """
        raise NotImplementedError(f"{type(self).__name__} has no radial parametrisation")
