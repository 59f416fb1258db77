"""Particle shapes seen by the two plates: the abstract :class:`Shape` and frame helpers.

Conventions (design notes, docs/methods/design.md §2)
--------------------------
* World frame: x, y horizontal, z up. The plates are horizontal; the lower plate touches the
  particle from below, the upper plate from above.
* Body frame: the shape is defined with its volume centroid at the origin.
* An orientation (:mod:`thirdbody.orientation`) is a rotation ``R`` (a scipy ``Rotation``): a
  body-frame point ``p`` sits in the world at ``R p``, the centroid at the world origin. A plain
  number θ (radians) means the paper's rotation about +y by the right-hand rule,
  ``(x, y, z) -> (x cos θ + z sin θ, y, −x sin θ + z cos θ)``.
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

from thirdbody.orientation import OrientationLike, Rotation, as_rotation, key, matrix

if TYPE_CHECKING:
    from collections.abc import Callable

FloatArray = NDArray[np.float64]

__all__ = ["Shape", "rotate_to_body", "rotate_to_world"]

_CACHE_SIZE = 64

#: the half turn about +y: (x, y, z) -> (−x, y, −z); it swaps the roles of the two plates
_FLIP = np.diag([-1.0, 1.0, -1.0])


def rotate_to_world(points: ArrayLike, orientation: OrientationLike) -> FloatArray:
    """Map body-frame points (…, 3) to the world frame: ``R p`` (m in, m out)."""
    p = np.asarray(points, dtype=float)
    return p @ matrix(orientation).T


def rotate_to_body(points: ArrayLike, orientation: OrientationLike) -> FloatArray:
    """Inverse of :func:`rotate_to_world`: world-frame points (…, 3) to the body frame."""
    p = np.asarray(points, dtype=float)
    return p @ matrix(orientation)


def _ray_frame(orientation: OrientationLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Body-frame images of the world unit vectors x, y and z (up): the rows of ``R``."""
    m = matrix(orientation)
    return m[0].copy(), m[1].copy(), m[2].copy()


def _broadcast_xy(x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    return xa, ya


class Shape(abc.ABC):
    """A rigid particle shape, seen through vertical rays at an orientation.

    Every method taking an ``orientation`` accepts a scipy ``Rotation`` or a number θ (rad, the
    paper's rotation about +y); see :mod:`thirdbody.orientation`.

    Subclasses implement :meth:`surfaces`, ``_lowest_point`` (uncached, given a ``Rotation``),
    :meth:`mirrored` and :attr:`size`, and call ``super().__init__()``. The default
    :meth:`highest_point` uses the identity ``highest(R) = F·lowest(F R)`` with F the half turn
    about y, ``(x, y, z) -> (−x, y, −z)``, which swaps top and bottom. Extreme points are cached
    per orientation (shapes are immutable).

    All lengths are in metres, angles in radians.
    """

    #: convex: the vertical gap between two convex bodies has a single minimum
    _convex = False

    def __init__(self) -> None:
        self._extreme_cache: dict[tuple, FloatArray] = {}

    # --- to implement -----------------------------------------------------------------------
    @abc.abstractmethod
    def surfaces(self, orientation: OrientationLike, x: ArrayLike,
                 y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest heights z (m) of the rotated body along vertical rays.

        Parameters
        ----------
        orientation:
            A ``Rotation`` (body -> world) or θ (rad) about +y.
        x, y:
            World horizontal coordinates (m) of the rays; any broadcastable shapes.

        Returns
        -------
        (z_low, z_up):
            Arrays of the broadcast shape: the lowest and the highest crossing of each ray with
            the body surface (for a non-convex body, the extreme ones), NaN where the ray misses.
        """

    @abc.abstractmethod
    def _lowest_point(self, rotation: Rotation) -> FloatArray:
        """Uncached world-frame lowest point (x, y, z) in metres."""

    @abc.abstractmethod
    def mirrored(self) -> Shape:
        """The shape mirrored in the body x coordinate (x -> −x).

        The mirrored shape at orientation −θ (about y) is the mirror image (world x -> −x) of
        this shape at orientation θ.
        """

    @property
    @abc.abstractmethod
    def size(self) -> float:
        """A characteristic length (m): the largest distance from the centroid to the surface."""

    # --- provided ---------------------------------------------------------------------------
    def _surfaces_rotated(self, rotation: Rotation, R: FloatArray, x: ArrayLike,
                          y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """:meth:`surfaces` at ``rotation`` whose matrix ``R`` (3, 3) the caller already has (the
        hot paths of the network solver keep both); the default ignores ``R``."""
        return self.surfaces(rotation, x, y)

    @property
    def centroid(self) -> FloatArray:
        """Volume centroid (m) in the body frame: zero by construction."""
        return np.zeros(3)

    @property
    def feature_length(self) -> float:
        """The smallest length (m) over which the surface's curvature changes much: a vertical
        scan of the footprint at a fraction of it sees every dip a plate can touch. Default: a
        sixteenth of :attr:`size`."""
        return self.size / 16.0

    def _cached(self, name: str, orientation: OrientationLike,
                fn: Callable[[Rotation], FloatArray]) -> FloatArray:
        rotation = as_rotation(orientation)
        k = (name, key(rotation))
        hit = self._extreme_cache.get(k)
        if hit is None:
            if len(self._extreme_cache) >= _CACHE_SIZE:
                self._extreme_cache.pop(next(iter(self._extreme_cache)))
            hit = np.asarray(fn(rotation), dtype=float)
            hit.setflags(write=False)
            self._extreme_cache[k] = hit
        return hit.copy()

    def lowest_point(self, orientation: OrientationLike) -> FloatArray:
        """World-frame point (x, y, z) in metres where the body reaches its lowest height.

        This is where the lower plate touches first. If several points share the minimum (for a
        shape symmetric in y turned about y, a pair at ±y), the one with y >= 0 is returned.
        """
        return self._cached("low", orientation, self._lowest_point)

    def _highest_point(self, rotation: Rotation) -> FloatArray:
        return _FLIP @ self.lowest_point(Rotation.from_matrix(_FLIP) * rotation)

    def highest_point(self, orientation: OrientationLike) -> FloatArray:
        """World-frame point (x, y, z) in metres where the body reaches its highest height."""
        return self._cached("high", orientation, self._highest_point)

    def height(self, orientation: OrientationLike) -> float:
        """Vertical extent (m) of the body: the plate gap at first contact of both plates."""
        return float(self.highest_point(orientation)[2] - self.lowest_point(orientation)[2])

    def gap_lower(self, orientation: OrientationLike, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Initial separation (m) between the lower plate at first contact and the body.

        ``z_low(x, y) − z_min`` at world coordinates (x, y) (m), >= 0, +inf where the ray misses
        the body. The plate touches at :meth:`lowest_point`, where the gap is zero.
        """
        z_low, _ = self.surfaces(orientation, x, y)
        gap = np.maximum(z_low - self.lowest_point(orientation)[2], 0.0)
        return np.where(np.isnan(z_low), np.inf, gap)

    def gap_upper(self, orientation: OrientationLike, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Initial separation (m) between the upper plate at first contact and the body.

        ``z_max − z_up(x, y)`` at world coordinates (x, y) (m), >= 0, +inf where the ray misses.
        """
        _, z_up = self.surfaces(orientation, x, y)
        gap = np.maximum(self.highest_point(orientation)[2] - z_up, 0.0)
        return np.where(np.isnan(z_up), np.inf, gap)

    def _radial_surface(self, directions: FloatArray) -> FloatArray:
        """Body-frame surface points (n, 3) along unit ``directions`` from the shape's centre.

        Used to tessellate star-shaped analytic shapes (:meth:`MeshShape.from_shape`). The centre
        may differ from the centroid. Shapes that cannot do this raise ``NotImplementedError``.
        """
        raise NotImplementedError(f"{type(self).__name__} has no radial parametrisation")
