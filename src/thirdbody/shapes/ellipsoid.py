"""Ellipsoid and sphere with closed-form, cancellation-free vertical ray intersection."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from thirdbody.shapes.base import FloatArray, Shape, _broadcast_xy

__all__ = ["Ellipsoid", "Sphere"]


class Ellipsoid(Shape):
    """Ellipsoid ``(x/A)² + (y/B)² + (z/C)² = 1`` in the body frame, centred at its centroid.

    Parameters
    ----------
    semi_axes:
        ``(A, B, C)`` in metres: A along body x (in the plane of rotation), B along y (the
        rotation axis), C along body z.

    At orientation θ the half-height is ``h(θ) = √(A² sin²θ + C² cos²θ)`` and the lowest point is
    at world ``(sinθ cosθ (A² − C²)/h, 0, −h)``; the highest point is its mirror through the
    centroid.

    The gaps are computed without cancellation: the quadratic of the rotated ellipsoid is written
    for the height ``g`` above the lowest point, whose constant term is the exact positive form
    ``Δx² (cos²θ/A² + sin²θ/C²) + y²/B²`` (Δx measured from the lowest point), and the smaller
    root is taken as ``c/(−b + √(b² − ac))``. Near the apex the gap is therefore accurate to
    machine precision *relative to the gap itself*, not only relative to the particle size.
    """

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

    def half_height(self, theta: float) -> float:
        """Half of the vertical extent (m) at orientation ``theta`` (rad)."""
        a, _, c = self._axes
        return float(np.hypot(a * np.sin(theta), c * np.cos(theta)))

    def _lowest_point(self, theta: float) -> FloatArray:
        a, _, c = self._axes
        h = self.half_height(theta)
        x = np.sin(theta) * np.cos(theta) * (a * a - c * c) / h
        return np.array([x, 0.0, -h])

    def _highest_point(self, theta: float) -> FloatArray:
        return -self._lowest_point(theta) + 0.0

    def _lower_gap_and_hit(
        self, theta: float, x: FloatArray, y: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Gap above the lowest point along rays at world (x, y), and the discriminant."""
        a_, b_, c_ = self._axes
        s, c = np.sin(theta), np.cos(theta)
        h = self.half_height(theta)
        x_star = s * c * (a_ * a_ - c_ * c_) / h
        dx = x - x_star
        qa = (s / a_) ** 2 + (c / c_) ** 2
        qc = dx * dx * ((c / a_) ** 2 + (s / c_) ** 2) + (y / b_) ** 2
        qb = -1.0 / h + dx * (s * c * (1.0 / c_**2 - 1.0 / a_**2))
        disc = qb * qb - qa * qc
        root = np.sqrt(np.maximum(disc, 0.0))
        # For a ray that hits, both roots are >= 0, hence qb < 0 and -qb + root > 0.
        with np.errstate(divide="ignore", invalid="ignore"):
            gap = qc / (root - qb)
        return gap, disc

    def surfaces(self, theta: float, x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest heights z (m) along vertical rays at world (x, y); NaN if missed.

        See :meth:`Shape.surfaces`. Closed form, accurate to machine precision.
        """
        xa, ya = _broadcast_xy(x, y)
        h = self.half_height(theta)
        g_low, disc = self._lower_gap_and_hit(theta, xa, ya)
        # Central symmetry: the upper surface at (x, y) is the lower one at (-x, -y), negated.
        g_up, _ = self._lower_gap_and_hit(theta, -xa, -ya)
        hit = disc >= 0.0
        z_low = np.where(hit, -h + g_low, np.nan)
        z_up = np.where(hit, h - g_up, np.nan)
        return np.fmin(z_low, z_up), np.fmax(z_low, z_up)

    def gap_lower(self, theta: float, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """See :meth:`Shape.gap_lower`; closed form without cancellation near the apex."""
        xa, ya = _broadcast_xy(x, y)
        g, disc = self._lower_gap_and_hit(theta, xa, ya)
        return np.where(disc >= 0.0, np.maximum(g, 0.0), np.inf)

    def gap_upper(self, theta: float, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """See :meth:`Shape.gap_upper`; closed form without cancellation near the apex."""
        xa, ya = _broadcast_xy(x, y)
        return self.gap_lower(theta, -xa, -ya)

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
