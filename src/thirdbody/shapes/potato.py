"""The "potato": an ellipsoid whose radius is modulated by a few smooth sine waves.

The paper's particle of section 3 is generated "by superposition of ellipsoid and sine waves
with comparable wavelength and amplitude" and is symmetric about the plane of rotation. This
module gives a precise, reproducible version of that recipe.

Definition
----------
Let ``d`` be a unit direction (body frame) seen from the *wave centre* ``c``. The surface is the
radial graph ``q = c + r(d) d`` with

    r(d) = r_ell(d) · m(d),
    r_ell(d) = 1 / √(d_x²/A² + d_y²/B² + d_z²/C²)         (the ellipsoid's radius),
    m(d) = 1 + Σ_k a_k sin(k_k (d · e_k) + φ_k),           e_k = (cos β_k, 0, sin β_k).

Each wave is a plane wave in the direction ``e_k`` evaluated on the unit sphere of directions:
``a_k`` is its relative amplitude, ``k_k`` its angular wavenumber (radians per unit of d·e, so
the wave runs through ``k_k/π`` periods across the sphere), ``β_k`` the angle of ``e_k`` in the
body xz-plane (from +x towards +z) and ``φ_k`` its phase. Because every ``e_k`` has no y
component, ``m`` depends on ``d_y`` only through ``|d| = 1``: the potato is symmetric about the
xz-plane (y -> −y). ``r`` is an analytic function of the unit vector ``d``, so the surface is C∞
everywhere, including the poles (no spherical-angle singularity).

The body frame has its origin at the volume centroid, computed by Gauss quadrature over the
directions (the wave centre ``c`` is :attr:`Potato.wave_centre`, generally a small offset from
the centroid, in the xz-plane).

Validity: the total relative amplitude ``Σ|a_k|`` must not exceed 1/2 (so ``r >= r_ell/2``), and
the surface must be star-shaped with respect to the centroid with a margin: at every surface
point the cosine between the outward normal and the direction from the centroid must be at least
``min_star_cosine`` (checked on a dense quadrature grid). Shapes violating either are refused.

Non-convexity: the waves may make the surface locally concave, so the gap to a plate can have
several local minima (several potential contact spots); :meth:`Potato.lower_minima` lists them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize, minimize_scalar

from thirdbody.orientation import OrientationLike, Rotation, as_rotation
from thirdbody.shapes._roots import IntArray, extreme_roots
from thirdbody.shapes.base import FloatArray, Shape, _broadcast_xy, _ray_frame

__all__ = ["MAX_TOTAL_AMPLITUDE", "Potato", "Wave"]

#: Upper bound of the summed relative wave amplitudes Σ|a_k|.
MAX_TOTAL_AMPLITUDE = 0.5

_CHUNK_RAYS = 8192


@dataclass(frozen=True)
class Wave:
    """One radial modulation wave of a :class:`Potato`.

    Attributes
    ----------
    amplitude:
        Relative amplitude ``a`` (dimensionless, a fraction of the ellipsoid radius).
    wavenumber:
        Angular wavenumber ``k`` (rad per unit of ``d·e``; dimensionless), >= 0.
    direction:
        Angle ``β`` (rad) of the wave vector ``e = (cos β, 0, sin β)`` in the body xz-plane,
        measured from +x towards +z.
    phase:
        Phase ``φ`` (rad).
    """

    amplitude: float
    wavenumber: float
    direction: float
    phase: float


def _as_wave(w: Wave | Sequence[float]) -> Wave:
    if isinstance(w, Wave):
        return w
    vals = tuple(float(v) for v in w)
    if len(vals) != 4:
        raise ValueError(f"a wave is (amplitude, wavenumber, direction, phase), got {w!r}")
    return Wave(*vals)


def draw_waves(
    seed: int | np.random.Generator | None,
    n_waves: int = 3,
    amplitude: float = 0.05,
    wavenumber_range: tuple[float, float] = (2.0, 4.0),
) -> tuple[Wave, ...]:
    """Draw the waves of a random potato.

    ``rng = numpy.random.default_rng(seed)`` draws one array ``u = rng.uniform(size=(n_waves,
    4))``; wave ``k`` then has amplitude ``amplitude·(0.5 + 0.5 u[k,0])``, wavenumber uniform in
    ``wavenumber_range`` (``u[k,1]``), direction ``π u[k,2]`` and phase ``2π u[k,3]``.
    """
    if n_waves < 0:
        raise ValueError(f"n_waves must be >= 0, got {n_waves}")
    k_lo, k_hi = wavenumber_range
    u = np.random.default_rng(seed).uniform(size=(n_waves, 4))
    return tuple(
        Wave(
            amplitude=float(amplitude * (0.5 + 0.5 * row[0])),
            wavenumber=float(k_lo + (k_hi - k_lo) * row[1]),
            direction=float(np.pi * row[2]),
            phase=float(2.0 * np.pi * row[3]),
        )
        for row in u
    )


class Potato(Shape):
    """Ellipsoid modulated by smooth sine waves (see the module docstring for the definition).

    Parameters
    ----------
    semi_axes:
        ``(A, B, C)`` (m) of the underlying ellipsoid along body x, y, z.
    waves:
        Explicit waves, each a :class:`Wave` or a tuple ``(amplitude, wavenumber, direction,
        phase)``. When given, ``seed``, ``n_waves``, ``amplitude`` and ``wavenumber_range`` are
        ignored.
    seed:
        Seed of the random waves (see :func:`draw_waves`). ``None`` draws fresh entropy; the
        drawn waves are in :attr:`waves`, so a shape can always be rebuilt exactly from them.
    n_waves, amplitude, wavenumber_range:
        Number of random waves, their nominal relative amplitude (each is drawn in
        ``[amplitude/2, amplitude]``) and the range of their angular wavenumbers.
    min_star_cosine:
        Required lower bound of the cosine between the surface normal and the direction from
        the centroid (star-shapedness with margin).

    Raises
    ------
    ValueError
        If ``Σ|a_k| > MAX_TOTAL_AMPLITUDE`` or the surface is not star-shaped about its centroid
        with the required margin.
    """

    def __init__(
        self,
        semi_axes: tuple[float, float, float] | ArrayLike,
        waves: Iterable[Wave | Sequence[float]] | None = None,
        *,
        seed: int | np.random.Generator | None = None,
        n_waves: int = 3,
        amplitude: float = 0.05,
        wavenumber_range: tuple[float, float] = (2.0, 4.0),
        min_star_cosine: float = 0.05,
    ) -> None:
        super().__init__()
        ax = np.asarray(semi_axes, dtype=float)
        if ax.shape != (3,) or not np.all(np.isfinite(ax)) or np.any(ax <= 0):
            raise ValueError(f"semi_axes must be three positive lengths (m), got {semi_axes!r}")
        if waves is None:
            wv = draw_waves(seed, n_waves, amplitude, wavenumber_range)
        else:
            wv = tuple(_as_wave(w) for w in waves)
        for w in wv:
            if not all(math.isfinite(v) for v in (w.amplitude, w.direction, w.phase)):
                raise ValueError(f"wave parameters must be finite, got {w!r}")
            if not (math.isfinite(w.wavenumber) and w.wavenumber >= 0.0):
                raise ValueError(f"wavenumber must be finite and >= 0, got {w!r}")
        total = sum(abs(w.amplitude) for w in wv)
        if total > MAX_TOTAL_AMPLITUDE:
            raise ValueError(
                f"total relative wave amplitude {total:.3g} exceeds {MAX_TOTAL_AMPLITUDE}: "
                "the potato would not stay a star-shaped perturbation of its ellipsoid"
            )
        self._axes = ax
        self._axes.setflags(write=False)
        self._waves = wv
        self._min_star_cosine = float(min_star_cosine)
        self._amp = np.array([w.amplitude for w in wv])
        self._k = np.array([w.wavenumber for w in wv])
        self._phase = np.array([w.phase for w in wv])
        self._ex = np.cos([w.direction for w in wv])
        self._ez = np.sin([w.direction for w in wv])
        self._k_max = float(self._k.max()) if wv else 0.0
        # Generating-frame bound of the surface radius: r_ell <= max(A,B,C), m <= 1 + Σ|a|.
        self._r_bound = float(ax.max() * (1.0 + total) * (1.0 + 1e-9))
        self._centre = np.zeros(3)  # overwritten by _analyse (centroid in the wave-centre frame)
        self._analyse()

    # --- the radial function ------------------------------------------------------------------
    def _modulation(self, dx: FloatArray, dz: FloatArray) -> FloatArray:
        """m = 1 + Σ a sin(k (dx cos β + dz sin β) + φ); in place, one temporary per wave (it
        is the hot loop of every ray cast)."""
        m = np.ones(np.broadcast_shapes(np.shape(dx), np.shape(dz)))
        for a, k, ex, ez, ph in zip(
            self._amp, self._k, self._ex, self._ez, self._phase, strict=True
        ):
            arg = np.asarray(dx * ex, dtype=float)
            arg += dz * ez
            arg *= k
            arg += ph
            np.sin(arg, out=arg)
            arg *= a
            m += arg
        return m

    def radius(self, directions: ArrayLike) -> FloatArray:
        """Radial function ``r(d)`` (m) for unit directions (…, 3) seen from the wave centre."""
        d = np.asarray(directions, dtype=float)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        quad = np.sum((d / self._axes) ** 2, axis=-1)
        return self._modulation(d[..., 0], d[..., 2]) / np.sqrt(quad)

    def _tangential_grad_log_r(self, d: FloatArray) -> FloatArray:
        """Tangential gradient of log r on the unit sphere at unit directions d (…, 3)."""
        inv2 = 1.0 / self._axes**2
        md = d * inv2
        grad = -md / np.sum(d * md, axis=-1, keepdims=True)
        m = self._modulation(d[..., 0], d[..., 2])
        gm = np.zeros_like(d)
        for a, k, ex, ez, ph in zip(
            self._amp, self._k, self._ex, self._ez, self._phase, strict=True
        ):
            c = a * k * np.cos(k * (d[..., 0] * ex + d[..., 2] * ez) + ph)
            gm[..., 0] += c * ex
            gm[..., 2] += c * ez
        grad += gm / m[..., None]
        return grad - np.sum(grad * d, axis=-1, keepdims=True) * d

    def _analyse(self) -> None:
        """Centroid, volume, size, star-shapedness check and ray-sampling parameters."""
        n_mu = max(64, 8 * math.ceil(self._k_max))
        n_phi = 2 * n_mu
        mu, w_mu = np.polynomial.legendre.leggauss(n_mu)
        phi = 2.0 * np.pi * np.arange(n_phi) / n_phi
        sin_t = np.sqrt(1.0 - mu**2)
        d = np.stack(
            [
                sin_t[:, None] * np.cos(phi)[None, :],
                sin_t[:, None] * np.sin(phi)[None, :],
                np.broadcast_to(mu[:, None], (n_mu, n_phi)),
            ],
            axis=-1,
        )
        weights = w_mu[:, None] * (2.0 * np.pi / n_phi)
        r = self.radius(d)
        volume = float(np.sum(weights * r**3) / 3.0)
        moment = np.sum((weights * r**4)[..., None] * d, axis=(0, 1)) / 4.0
        g = moment / volume
        g[1] = 0.0  # exact by the xz-symmetry
        gs = self._tangential_grad_log_r(d)
        slope = np.sqrt(1.0 + np.sum(gs * gs, axis=-1))
        rel = r[..., None] * d - g
        dist = np.linalg.norm(rel, axis=-1)
        cosine = (r - d @ g + gs @ g) / (dist * slope)
        worst = float(cosine.min())
        if worst < self._min_star_cosine:
            raise ValueError(
                "potato is not star-shaped about its centroid with the required margin: "
                f"min cos(normal, radius) = {worst:.3g} < {self._min_star_cosine}; "
                "reduce the wave amplitudes or wavenumbers"
            )
        self._centre = g
        self._volume = volume
        self._size = float(dist.max())
        r_min = float(r.min())
        self._r_min = r_min
        self._r_ratio = float(r.max()) / r_min
        # |grad F| for F = |q|/r(q/|q|) - 1 is sqrt(1 + |grad_S log r|²)/r; 1.25 covers the
        # sampling of the maximum.
        self._lipschitz = 1.25 * float(np.max(slope / r))
        h_target = min(r_min, 2.0 * np.pi * r_min / max(self._k_max, 1.0)) / 8.0
        self._n_samples = max(64, math.ceil(2.0 * self._r_bound / h_target) + 1)

    # --- properties ---------------------------------------------------------------------------
    @property
    def semi_axes(self) -> FloatArray:
        """``(A, B, C)`` (m) of the underlying ellipsoid."""
        return self._axes.copy()

    @property
    def waves(self) -> tuple[Wave, ...]:
        """The modulation waves (drawn from the seed or given explicitly)."""
        return self._waves

    @property
    def wave_centre(self) -> FloatArray:
        """Body-frame position (m) of the centre of the radial parametrisation."""
        return 0.0 - self._centre

    @property
    def volume(self) -> float:
        """Volume (m³)."""
        return self._volume

    @property
    def size(self) -> float:
        """Largest distance (m) from the centroid to the surface (dense sampling)."""
        return self._size

    @property
    def feature_length(self) -> float:
        """Half the shortest surface wavelength, π r_min / k_max, or the smallest semi-axis if
        shorter (m)."""
        return float(min(np.pi * self._r_min / max(self._k_max, 1.0), self._axes.min()))

    def __repr__(self) -> str:
        a, b, c = (float(v) for v in self._axes)
        return f"Potato(semi_axes=({a!r}, {b!r}, {c!r}), waves={list(self._waves)!r})"

    def implicit(self, points: ArrayLike) -> FloatArray:
        """Dimensionless implicit function ``|q|/r(q/|q|) − 1`` at body-frame points (…, 3) (m).

        ``q`` is the point relative to the wave centre. Negative inside, zero on the surface,
        positive outside; near the surface it is the relative radial distance.
        """
        q = np.asarray(points, dtype=float) + self._centre
        return self._implicit_q(q[..., 0], q[..., 1], q[..., 2])

    def _implicit_q(self, qx: FloatArray, qy: FloatArray, qz: FloatArray) -> FloatArray:
        a, b, c = (float(v) for v in self._axes)
        n = np.sqrt(qx * qx + qy * qy + qz * qz)
        with np.errstate(divide="ignore", invalid="ignore"):
            m = self._modulation(qx / n, qz / n)
        ell = np.asarray((qx / a) ** 2, dtype=float)
        ell += (qy / b) ** 2
        ell += (qz / c) ** 2
        np.sqrt(ell, out=ell)
        ell /= m
        ell -= 1.0
        return ell

    def mirrored(self) -> Potato:
        """The potato mirrored in body x: every wave direction β becomes π − β."""
        waves = [Wave(w.amplitude, w.wavenumber, np.pi - w.direction, w.phase) for w in self._waves]
        return Potato(self._axes, waves, min_star_cosine=self._min_star_cosine)

    def _radial_surface(self, directions: FloatArray) -> FloatArray:
        d = np.asarray(directions, dtype=float)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return self.radius(d)[..., None] * d - self._centre

    # --- vertical rays ------------------------------------------------------------------------
    def surfaces(self, orientation: OrientationLike, x: ArrayLike,
                 y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lowest and highest crossing heights z (m) of vertical rays at world (x, y).

        See :meth:`Shape.surfaces`. Each ray is sampled on its chord through a bounding sphere,
        brackets of the first and last crossing are refined to ~4 ulp of the particle size
        (vectorised Illinois iterations); a sampled near-miss is searched for a thin sliver of
        body between samples. NaN where the ray misses.
        """
        xa, ya = _broadcast_xy(x, y)
        shape = xa.shape
        xf, yf = xa.ravel(), ya.ravel()
        z_low = np.full(xf.size, np.nan)
        z_up = np.full(xf.size, np.nan)
        t1, t2, w = _ray_frame(orientation)
        # Ray in the wave-centre frame: q(Z) = x t1 + y t2 + g + Z w (x t1 + y t2 is ⟂ w).
        zc = -float(w @ self._centre)
        g_perp = self._centre + zc * w
        px = xf[:, None] * t1 + yf[:, None] * t2 + g_perp[None, :]
        rho2 = np.sum(px * px, axis=1)
        inside = rho2 < self._r_bound**2
        sel = np.flatnonzero(inside)
        half = np.sqrt(self._r_bound**2 - rho2[sel])
        xtol = 4.0 * np.finfo(float).eps * self._r_bound
        for start in range(0, sel.size, _CHUNK_RAYS):
            part = sel[start : start + _CHUNK_RAYS]
            base = px[part]
            hp = half[start : start + _CHUNK_RAYS]

            def fun(idx: IntArray, z: FloatArray, base: FloatArray = base) -> FloatArray:
                dz = z - zc
                return self._implicit_q(
                    base[idx, 0] + dz * w[0], base[idx, 1] + dz * w[1], base[idx, 2] + dz * w[2]
                )

            lo, hi = extreme_roots(fun, zc - hp, zc + hp, self._n_samples, self._lipschitz, xtol)
            z_low[part] = lo
            z_up[part] = hi
        return z_low.reshape(shape), z_up.reshape(shape)

    # --- extreme points -----------------------------------------------------------------------
    def _lowest_z(self, rotation: Rotation, alpha: FloatArray, beta: FloatArray) -> FloatArray:
        """World (x, y, z) (m) of the surface point in direction (α, β) from the wave centre.

        The direction is ``normalise(tan α · x̂ + tan β · ŷ − ẑ)`` in world axes (a gnomonic
        chart of the lower hemisphere), which is smooth where the lowest point lies.
        """
        t1, ey, w = _ray_frame(rotation)
        u, v = np.tan(alpha), np.tan(beta)
        norm = np.sqrt(1.0 + u * u + v * v)
        d = (u[..., None] * t1 + v[..., None] * ey - w) / norm[..., None]
        r = self.radius(d)
        x = r * u / norm - t1 @ self._centre
        y = r * v / norm - ey @ self._centre
        z = -r / norm - w @ self._centre
        return np.stack([x, y, z], axis=-1)

    def _find_lower_minima(self, rotation: Rotation) -> FloatArray:
        # turned about y only, the body's symmetry plane is the world xz-plane (y = 0)
        _, ey, _ = _ray_frame(rotation)
        planar = bool(np.all(ey == np.array([0.0, 1.0, 0.0])))
        n = max(121, 2 * math.ceil(8.0 * self._k_max) + 1)
        # The lowest point is seen from the wave centre within atan(r_max/r_min) of straight down
        # (for an ellipsoid, atan((A² − C²)/(2AC)) at worst); keep a factor 2 of margin.
        amax = min(1.55, math.atan(2.0 * self._r_ratio))
        grid = np.linspace(-amax, amax, n)
        step = grid[1] - grid[0]
        al, be = np.meshgrid(grid, grid, indexing="ij")
        zg = self._lowest_z(rotation, al, be)[..., 2]
        core = zg[1:-1, 1:-1]
        is_min = np.ones(core.shape, dtype=bool)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if di or dj:
                    is_min &= core <= zg[1 + di : n - 1 + di, 1 + dj : n - 1 + dj]
        ii, jj = np.nonzero(is_min)
        order = np.argsort(core[ii, jj])[:16]
        scale = self._size

        def z_of(p: FloatArray) -> float:
            return float(self._lowest_z(rotation, np.array(p[0]), np.array(p[1]))[2])

        found: list[FloatArray] = []
        for i, j in zip(ii[order] + 1, jj[order] + 1, strict=True):
            x0 = np.array([grid[i], grid[j]])
            simplex = x0 + np.array([[0.0, 0.0], [step, 0.0], [0.0, step]])
            res = minimize(
                z_of,
                x0,
                method="Nelder-Mead",
                options={
                    "initial_simplex": simplex,
                    "xatol": 1e-11,
                    "fatol": 1e-15 * scale,
                    "maxiter": 4000,
                },
            )
            a_opt, b_opt = float(res.x[0]), float(res.x[1])
            pt = self._lowest_z(rotation, np.array(a_opt), np.array(b_opt))
            if planar and abs(pt[1]) < 1e-6 * scale:
                # On the symmetry plane: polish in one dimension with y = 0 exactly.
                res1 = minimize_scalar(
                    lambda a: z_of(np.array([a, 0.0])),
                    bounds=(a_opt - 2.0 * step, a_opt + 2.0 * step),
                    method="bounded",
                    options={"xatol": 1e-12},
                )
                pt = self._lowest_z(rotation, np.array(float(res1.x)), np.array(0.0))
                pt[1] = 0.0
            if all(np.linalg.norm(pt[:2] - q[:2]) > 1e-5 * scale for q in found):
                found.append(pt)
        pts = np.array(found).reshape(-1, 3)
        # A surface point may be a local minimum of height yet hidden above another part of the
        # body (an overhang): keep only those on the lower envelope, which a plate can touch.
        z_low, _ = self.surfaces(rotation, pts[:, 0], pts[:, 1])
        pts = pts[np.abs(z_low - pts[:, 2]) <= 1e-9 * scale]
        return pts[np.lexsort((-pts[:, 1], pts[:, 2]))]

    def lower_minima(self, orientation: OrientationLike) -> FloatArray:
        """Local minima of the lower surface height at an orientation (Rotation or θ in rad).

        Array (n, 3) of world points (x, y, z) in metres, sorted by z (lowest first). A non-convex
        potato may have several: each is a potential contact spot of the lower plate. Turned
        about y, minima off the symmetry plane come in pairs (±y). Minima hidden from the plate
        by an overhang are left out. The upper plate's spots are the lower ones of the
        orientation turned by a half turn about y, mapped by (x, y, z) -> (−x, y, −z).
        """
        return self._cached("minima", as_rotation(orientation), self._find_lower_minima)

    def _lowest_point(self, rotation: Rotation) -> FloatArray:
        minima = self.lower_minima(rotation)
        if minima.shape[0] == 0:  # pragma: no cover - the global minimum is always kept
            raise RuntimeError(f"no lowest point found for {rotation.as_quat()!r}")
        p = minima[0].copy()
        _, ey, _ = _ray_frame(rotation)
        if np.all(ey == np.array([0.0, 1.0, 0.0])):
            p[1] = abs(p[1])    # of a ±y pair of equal minima, the one at y >= 0
        return p
