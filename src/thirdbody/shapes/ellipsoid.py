"""Ellipsoid and sphere with closed-form, cancellation-free vertical ray intersection."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from thirdbody.orientation import OrientationLike, Rotation, matrix
from thirdbody.shapes.base import FloatArray, Shape, _broadcast_xy

__all__ = ["Ellipsoid", "Sphere"]


class Ellipsoid(Shape):
    """Ellipsoid ``(x/A)² + (y/B)² + (z/C)² = 1`` in the body frame, centred at its centroid.

    Parameters
    ----------
    semi_axes:
        ``(A, B, C)`` in metres: A along body x (in the plane of rotation), B along y (the
        rotation axis), C along body z.

    At an orientation R the world-frame quadric is ``pᵀ M p = 1`` with ``M = R D Rᵀ``,
    ``D = diag(1/A², 1/B², 1/C²)``. The half-height is ``h = √((M⁻¹)_zz)`` and the lowest point
    is ``−M⁻¹ e_z / h``; the highest point is its mirror through the centroid. For the paper's
    tilt θ about y, ``h(θ) = √(A² sin²θ + C² cos²θ)`` and the lowest point is at
    ``(sinθ cosθ (A² − C²)/h, 0, −h)``.

    The gaps are computed without cancellation: the quadratic of the rotated ellipsoid is written
    for the height ``g`` above the lowest point, whose constant term is the exact positive form
    ``Q(Δx, Δy)`` of the 2x2 horizontal block of M (Δ measured from the lowest point), and the
    smaller root is taken as ``c/(−b + √(b² − ac))``. Near the apex the gap is therefore accurate to
    machine precision *relative to the gap itself*, not only relative to the particle size.
    """

    _convex = True

    def __init__(self, semi_axes: tuple[float, float, float] | ArrayLike) -> None:
        super().__init__()
        ax = np.asarray(semi_axes, dtype=float)
        if ax.shape != (3,) or not np.all(np.isfinite(ax)) or np.any(ax <= 0):
            raise ValueError(f"semi_axes must be three positive lengths (m), got {semi_axes!r}")
        self._axes = ax
        self._axes.setflags(write=False)

    @property
    def semi_axes(self) -> FloatArray:
        """``(A, B, C)`` in metres (body x, y, z)."""
        return self._axes.copy()

    @property
    def size(self) -> float:
        """Largest semi-axis (m)."""
        return float(self._axes.max())

    def __repr__(self) -> str:
        a, b, c = (float(v) for v in self._axes)
        return f"{type(self).__name__}(semi_axes=({a!r}, {b!r}, {c!r}))"

    @property
    def feature_length(self) -> float:
        """Smallest semi-axis (m): an ellipsoid has one lowest and one highest point."""
        return float(self._axes.min())

    def _quadric(self, orientation: OrientationLike) -> tuple[FloatArray, FloatArray]:
        """World-frame quadric ``M = R D Rᵀ`` (D = diag(1/A², 1/B², 1/C²)) and its inverse."""
        return self._quadric_of(matrix(orientation))

    def _quadric_of(self, R: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`_quadric` from the rotation matrix ``R`` (3, 3), body -> world."""
        M = (R / self._axes**2) @ R.T
        Minv = (R * self._axes**2) @ R.T
        return M, Minv

    def half_height(self, orientation: OrientationLike) -> float:
        """Half of the vertical extent (m) at an orientation: ``√((R diag(A², B², C²) Rᵀ)_zz)``."""
        _, Minv = self._quadric(orientation)
        return float(np.sqrt(Minv[2, 2]))

    def _lowest_point(self, rotation: Rotation) -> FloatArray:
        # the support point along −z of pᵀMp = 1: −M⁻¹e_z / √(e_zᵀ M⁻¹ e_z)
        _, Minv = self._quadric(rotation)
        h = np.sqrt(Minv[2, 2])
        return np.array([-Minv[0, 2] / h + 0.0, -Minv[1, 2] / h + 0.0, -h])

    def _highest_point(self, rotation: Rotation) -> FloatArray:
        return -self._lowest_point(rotation) + 0.0

    def _lower_gap_and_hit(
        self, orientation: OrientationLike, x: FloatArray, y: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Gap above the lowest point along rays at world (x, y), and the discriminant.

        With p* the lowest point, the ray (x, y, −h + g) meets the quadric where
        ``M_zz g² + 2 g (M_xz Δx + M_yz Δy − 1/h) + Q(Δx, Δy) = 0``, Δ measured from p*, and
        ``Q = M_xx Δx² + 2 M_xy Δx Δy + M_yy Δy² >= 0`` (p*ᵀMp* = 1 and Mp* = −e_z/h cancel
        the rest exactly).
        """
        M, Minv = self._quadric(orientation)
        return _gap_and_hit(M, Minv, np.sqrt(Minv[2, 2]), x, y)

    def surfaces(self, orientation: OrientationLike, x: ArrayLike,
                 y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest heights z (m) along vertical rays at world (x, y); NaN if missed.

        See :meth:`Shape.surfaces`. Closed form, accurate to machine precision.
        """
        return self._surfaces_of(matrix(orientation), x, y)

    def _surfaces_rotated(self, rotation: Rotation, R: FloatArray, x: ArrayLike,
                          y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self._surfaces_of(R, x, y)

    def _surfaces_of(self, R: FloatArray, x: ArrayLike,
                     y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """:meth:`surfaces` at the rotation matrix ``R`` (3, 3): one quadric for both
        surfaces."""
        xa, ya = _broadcast_xy(x, y)
        M, Minv = self._quadric_of(R)
        h = np.sqrt(Minv[2, 2])
        g_low, disc = _gap_and_hit(M, Minv, h, xa, ya)
        # Central symmetry: the upper surface at (x, y) is the lower one at (-x, -y), negated.
        g_up, _ = _gap_and_hit(M, Minv, h, -xa, -ya)
        hit = disc >= 0.0
        z_low = np.where(hit, -h + g_low, np.nan)
        z_up = np.where(hit, h - g_up, np.nan)
        return np.fmin(z_low, z_up), np.fmax(z_low, z_up)

    def gap_lower(self, orientation: OrientationLike, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """See :meth:`Shape.gap_lower`; closed form without cancellation near the apex."""
        xa, ya = _broadcast_xy(x, y)
        g, disc = self._lower_gap_and_hit(orientation, xa, ya)
        return np.where(disc >= 0.0, np.maximum(g, 0.0), np.inf)

    def gap_upper(self, orientation: OrientationLike, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """See :meth:`Shape.gap_upper`; closed form without cancellation near the apex."""
        xa, ya = _broadcast_xy(x, y)
        return self.gap_lower(orientation, -xa, -ya)

    def mirrored(self) -> Ellipsoid:
        """The ellipsoid is symmetric in x: an equal copy."""
        return Ellipsoid(self._axes)

    def implicit(self, points: ArrayLike) -> FloatArray:
        """Dimensionless implicit function ``√((x/A)² + (y/B)² + (z/C)²) − 1`` at body points.

        Negative inside, zero on the surface, positive outside; ``points`` has shape (…, 3) (m).
        """
        p = np.asarray(points, dtype=float)
        return np.sqrt(np.sum((p / self._axes) ** 2, axis=-1)) - 1.0

    def _radial_surface(self, directions: FloatArray) -> FloatArray:
        d = np.asarray(directions, dtype=float)
        return d / np.sqrt(np.sum((d / self._axes) ** 2, axis=-1, keepdims=True))


def _gap_and_hit(M: FloatArray, Minv: FloatArray, h, x: FloatArray,
                 y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:meth:`Ellipsoid._lower_gap_and_hit` from the quadric M, its inverse and the
    half-height h (m)."""
    dx = x + Minv[0, 2] / h
    dy = y + Minv[1, 2] / h
    qa = M[2, 2]
    qc = M[0, 0] * dx * dx + 2.0 * M[0, 1] * dx * dy + M[1, 1] * dy * dy
    qb = -1.0 / h + M[0, 2] * dx + M[1, 2] * dy
    disc = qb * qb - qa * qc
    root = np.sqrt(np.maximum(disc, 0.0))
    # For a ray that hits, both roots are >= 0, hence qb < 0 and -qb + root > 0.
    with np.errstate(divide="ignore", invalid="ignore"):
        gap = qc / (root - qb)
    return gap, disc


class Sphere(Ellipsoid):
    """Sphere of ``radius`` (m) centred at its centroid; every orientation looks the same."""

    def __init__(self, radius: float) -> None:
        super().__init__((radius, radius, radius))

    @property
    def radius(self) -> float:
        """Radius (m)."""
        return float(self._axes[0])

    def __repr__(self) -> str:
        return f"Sphere(radius={self.radius!r})"

    def mirrored(self) -> Sphere:
        """An equal copy."""
        return Sphere(self.radius)
