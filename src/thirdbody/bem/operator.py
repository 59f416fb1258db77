"""Non-periodic convolution of surface tractions with influence coefficients (DC-FFT).

The kernel is tabulated on a padded grid in wrap-around order and transformed once; each product
zero-pads the field, multiplies spectra and keeps the first ``ny x nx`` block, which is the exact
linear (non-periodic) convolution. Kernel spectra are real because every kernel block is even or
odd in both x and y, so only their real parts are stored.

Reference: Liu, S., Wang, Q., Liu, G. (2000). A versatile method of discrete convolution and FFT
(DC-FFT) for contact analyses. Wear 243, 101-111.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from functools import cached_property

import numpy as np
import scipy.fft as sfft

try:        # scipy's own pocketfft binding: the transforms below without the dispatch layers
    from scipy.fft._pocketfft import pypocketfft as _pocket
except ImportError:         # pragma: no cover - another scipy layout: the public functions
    _pocket = None

from .._citations import cites
from . import influence

_DCFFT = ("Liu, S., Wang, Q., Liu, G. (2000). A versatile method of discrete convolution and FFT "
          "(DC-FFT) for contact analyses. Wear 243, 101-111.")

# One thread by default: the contact windows are small, and on a 2-core machine two threads
# made every transform slower, most of all on small windows; a sweep or a layer runs its
# cases in parallel processes.
#: cells added to a window for its periodic preconditioner (a margin against wrap-around)
_PRECONDITION_PAD = 8
_workers: int = int(os.environ.get("THIRDBODY_WORKERS", "0")) or 1
#: operators kept per kind. A dense network has a window shape and a spacing per contact (each
#: particle's own cell size): a few hundred contacts cycling through 32 slots missed every time
#: (55 % of the tangential operators were rebuilt in a 36-sphere lattice). An operator of a
#: 32 x 32 window holds about 0.1 MB.
_OPERATORS = 1024
#: and at most this many bytes of their arrays per kind: the tangential operator of a 512 x 512
#: window holds 12 MB when built, so 1024 of them would not fit in memory
_OPERATOR_BYTES = 256 * 2**20


def _nbytes(obj, depth: int = 2) -> int:
    """The bytes of the numpy arrays an operator holds (in its attributes, to ``depth``)."""
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if depth == 0:
        return 0
    if isinstance(obj, (tuple, list)):
        return sum(_nbytes(v, depth - 1) for v in obj)
    fields = getattr(obj, "__dict__", None)
    return 0 if fields is None else sum(_nbytes(v, depth - 1) for v in fields.values())


class _Cache:
    """The operators built last, by their arguments: at most :data:`_OPERATORS` of them and
    :data:`_OPERATOR_BYTES` of arrays (measured when built), the least recently used dropped
    first (an operator larger than the whole budget is built, then dropped at once)."""

    def __init__(self, build) -> None:
        self.build = build
        self.items: OrderedDict = OrderedDict()
        self.nbytes = 0

    def __call__(self, *key):
        hit = self.items.get(key)
        if hit is not None:
            self.items.move_to_end(key)
            return hit[0]
        op = self.build(*key)
        size = _nbytes(op)
        self.items[key] = (op, size)
        self.nbytes += size
        while len(self.items) > _OPERATORS or self.nbytes > _OPERATOR_BYTES:
            self.nbytes -= self.items.popitem(last=False)[1][1]
        return op


def set_workers(n: int) -> None:
    """Number of threads the FFTs use (default 1, or ``$THIRDBODY_WORKERS``)."""
    global _workers
    if int(n) < 1:
        raise ValueError(f"workers must be >= 1, got {n!r}")
    _workers = int(n)


def get_workers() -> int:
    """Number of threads the FFTs use."""
    return _workers


def _padded(n: int) -> int:
    return sfft.next_fast_len(2 * n - 1, real=True)


def _tabulate(kernel, ny: int, nx: int, dy: float, dx: float,
              parities: tuple[tuple[int, int], ...]) -> tuple[np.ndarray, ...]:
    """Kernel blocks on the padded grid in wrap-around order.

    Only the quadrant of non-negative offsets is evaluated; the rest follows from each block's
    parity ``(sign under x -> -x, sign under y -> -y)``. Entries that no kept output uses are 0.
    """
    py, px = _padded(ny), _padded(nx)
    X, Y = np.meshgrid(np.arange(nx) * dx, np.arange(ny) * dy, indexing="xy")
    blocks = []
    for quad, (sx, sy) in zip(kernel(X, Y), parities, strict=True):
        full = np.zeros((py, px))
        full[:ny, :nx] = quad
        full[:ny, px - nx + 1:] = sx * quad[:, :0:-1]
        full[py - ny + 1:, :] = sy * full[ny - 1:0:-1, :]
        blocks.append(full)
    return tuple(blocks)


def _zero_padded(field: np.ndarray, shape: tuple[int, ...], dtype) -> np.ndarray:
    """``field`` (..., n₁, n₂) in the corner of zeros of the trailing ``shape`` (1 or 2 axes; what
    ``scipy.fft`` does with ``n``/``s`` larger than the input)."""
    out = np.zeros(field.shape[:-len(shape)] + shape, dtype=dtype)
    if len(shape) == 1:
        out[..., :field.shape[-1]] = field
    else:
        out[..., :field.shape[-2], :field.shape[-1]] = field
    return out


class _Transform:
    """Zero-padded real 2-D FFT pair that skips the transforms of all-zero padding rows.

    The windows of a contact are small (tens of cells), so a transform costs less than
    ``scipy.fft``'s dispatch (backend lookup, argument checks, padding): the pocketfft binding
    behind it is called directly, with the arguments ``scipy.fft`` would pass (bit for bit
    the same result; 2 to 3 times faster on 8 to 24 cell windows)."""

    def __init__(self, ny: int, nx: int) -> None:
        self.ny, self.nx = ny, nx
        self.py, self.px = _padded(ny), _padded(nx)

    def forward(self, field: np.ndarray) -> np.ndarray:
        # rows first (only the ny data rows are non-zero), then columns over the padded length
        if _pocket is None:     # pragma: no cover
            rows = sfft.rfft(field, n=self.px, axis=-1, workers=_workers)
            return sfft.fft(rows, n=self.py, axis=-2, workers=_workers, overwrite_x=True)
        field = np.asarray(field, dtype=float)
        if field.shape[-1] < self.px:
            field = _zero_padded(field, (self.px,), float)
        rows = _pocket.r2c(field, (-1,), True, 0, None, _workers)
        if rows.shape[-2] < self.py:
            rows = _zero_padded(rows, (self.py, rows.shape[-1]), complex)
        return _pocket.c2c(rows, (-2,), True, 0, rows, _workers)

    def inverse(self, spectrum: np.ndarray) -> np.ndarray:
        if _pocket is None:     # pragma: no cover
            cols = sfft.ifft(spectrum, axis=-2, workers=_workers, overwrite_x=True)
            cols = cols[..., : self.ny, :]
            out = sfft.irfft(cols, n=self.px, axis=-1, workers=_workers)
            return out[..., : self.nx]
        spectrum = np.asarray(spectrum, dtype=complex)
        cols = _pocket.c2c(spectrum, (-2,), False, 2, spectrum, _workers)
        out = _pocket.c2r(cols[..., : self.ny, :], (-1,), self.px, False, 2, None, _workers)
        return out[..., : self.nx]

    def kernel_spectrum(self, kernel: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(sfft.rfft2(kernel, workers=_workers).real)


_STANLEY_KATO = ("Stanley, H. M., Kato, T. (1997). An FFT-based method for rough surface contact. "
                 "J. Tribol. 119, 481-485 (the half-space's Fourier response 2/(E*|k|)).")


def _folded(py: int, px: int, spacing: tuple[float, float], aliases: int, response):
    """Σ_m response(ξx_m, ξy_m, |ξ_m|) sinc(θx_m/2) sinc(θy_m/2) on the ``rfft2`` layout of a
    ``(py, px)`` periodic grid, θ_m = θ + 2πm, ξ_m = θ_m / (dx, dy), |mx|, |my| <= aliases.
    ``response`` returns a tuple of arrays (one per kernel block)."""
    dx, dy = spacing
    ty = 2 * np.pi * sfft.fftfreq(py)[:, None]
    tx = 2 * np.pi * sfft.rfftfreq(px)[None, :]
    total = None
    with np.errstate(divide="ignore", invalid="ignore"):
        for my in range(-aliases, aliases + 1):
            ay = ty + 2 * np.pi * my
            for mx in range(-aliases, aliases + 1):
                ax = tx + 2 * np.pi * mx
                xi_x, xi_y = ax / dx, ay / dy
                cell = np.sinc(ax / (2 * np.pi)) * np.sinc(ay / (2 * np.pi))
                terms = [t * cell for t in response(xi_x, xi_y, np.hypot(xi_x, xi_y))]
                total = terms if total is None else [a + b for a, b in zip(total, terms,
                                                                           strict=True)]
    return total


@cites("lattice_symbol", _STANLEY_KATO)
def boussinesq_symbol(py: int, px: int, spacing: tuple[float, float], E_star: float,
                      aliases: int = 1) -> np.ndarray:
    """Fourier symbol of the cell-to-centre normal influence on an infinite lattice, m/Pa.

    The displacement at cell centres from uniform cell pressures is the lattice sampling of the
    continuous response û(ξ) = 2/(E*|ξ|) p̂(ξ), with p̂ the transform of a uniform unit pressure on
    one cell, dx dy sinc(ξx dx/2) sinc(ξy dy/2). Sampling folds the continuous spectrum, so at the
    discrete frequency θ (rad per cell)

        K̂(θ) = Σ_m 2/(E* |ξ_m|) sinc(θx_m/2) sinc(θy_m/2),  θ_m = θ + 2πm,  ξ_m = θ_m / (dx, dy)

    summed over |mx|, |my| <= ``aliases`` (the folded terms alternate and fall off as 1/m²: one
    ring leaves the near-field coefficients within 3 % of Love's, three within 0.3 %). Returned
    on the ``rfft2`` layout of a ``(py, px)`` periodic grid; the θ = 0 entry (the unbounded mean
    response) is ``inf``.

    Unlike the transform of the tabulated kernel on a zero-padded window, this symbol does not
    depend on the window: it is the free half-space's, at every wavelength.
    """
    (total,) = _folded(py, px, spacing, aliases, lambda kx, ky, k: (2.0 / (E_star * k),))
    total[0, 0] = np.inf
    return total


@cites("lattice_symbol", _STANLEY_KATO)
def cerruti_symbol(py: int, px: int, spacing: tuple[float, float], G: float, nu: float,
                   aliases: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fourier symbols (xx, xy, yy) of the cell-to-centre tangential influence on an infinite
    lattice, m/Pa: as :func:`boussinesq_symbol`, with the continuous Cerruti response

        Ĝ_ij(ξ) = (δ_ij − ν ξ_i ξ_j / |ξ|²) / (G |ξ|)

    (the transform of Johnson's (1985) eq. 3.86a point solution, since the transform of
    x_i x_j / r³ is 2π (δ_ij − ξ_i ξ_j/|ξ|²)/|ξ|). The θ = 0 entries are ``inf`` (xx, yy) and 0.
    """
    def response(kx, ky, k):
        c = 1.0 / (G * k)
        return (c * (1 - nu * kx * kx / (k * k)), -c * nu * kx * ky / (k * k),
                c * (1 - nu * ky * ky / (k * k)))

    sxx, sxy, syy = _folded(py, px, spacing, aliases, response)
    sxx[0, 0], sxy[0, 0], syy[0, 0] = np.inf, 0.0, np.inf
    return sxx, sxy, syy


def _periodic_size(shape: tuple[int, int]) -> tuple[int, int]:
    """The preconditioner's periodic grid for a window: ``_PRECONDITION_PAD`` more cells per
    direction, rounded up to fast FFT lengths."""
    return tuple(sfft.next_fast_len(n + _PRECONDITION_PAD, real=True) for n in shape)


def _periodic_apply(field: np.ndarray, size: tuple[int, int], combine) -> np.ndarray:
    """Transform ``field`` (..., ny, nx) on the periodic grid ``size``, let ``combine`` act on
    its spectrum in place, and return the window's part of the inverse transform."""
    ny, nx = field.shape[-2:]
    if _pocket is None:     # pragma: no cover
        spec = sfft.rfft2(field, s=size, workers=_workers)
        combine(spec)
        return sfft.irfft2(spec, s=size, workers=_workers)[..., :ny, :nx]
    # as scipy.fft's rfft2 / irfft2 with s=size (_Transform's docstring)
    field = np.asarray(field, dtype=float)
    if (ny, nx) != tuple(size):
        field = _zero_padded(field[..., :size[0], :size[1]], tuple(size), float)
    axes = (field.ndim - 2, field.ndim - 1)
    spec = _pocket.r2c(field, axes, True, 0, None, _workers)
    combine(spec)
    return _pocket.c2r(spec, axes, size[1], False, 2, None, _workers)[..., :ny, :nx]


@cites("dcfft", _DCFFT)
class NormalOperator:
    """u_z = K_zz * p on a ``(ny, nx)`` window: pressure (Pa) to normal displacement (m).

    Obtain through :func:`normal_operator`, which caches one instance per
    (shape, spacing, E*). Displacement is positive away from the plate (into the particle).
    """

    def __init__(self, shape: tuple[int, int], spacing: tuple[float, float], E_star: float):
        ny, nx = shape
        dx, dy = spacing
        self.shape, self.spacing, self.E_star = (ny, nx), (dx, dy), E_star
        self._t = _Transform(ny, nx)
        (k,) = _tabulate(lambda X, Y: (influence.normal(X, Y, dx / 2, dy / 2, E_star),),
                         ny, nx, dy, dx, ((1, 1),))
        self.spectrum = self._t.kernel_spectrum(k)
        #: self-influence K_zz(0) in m/Pa
        self.self_term = float(k[0, 0])

    def __call__(self, pressure: np.ndarray) -> np.ndarray:
        spec = self._t.forward(pressure)
        spec *= self.spectrum
        return self._t.inverse(spec)

    @cached_property
    def _preconditioner(self) -> tuple[tuple[int, int], np.ndarray]:
        size = _periodic_size(self.shape)
        return size, 1.0 / boussinesq_symbol(*size, self.spacing, self.E_star)

    def precondition(self, residual: np.ndarray) -> np.ndarray:
        """Approximate inverse of this operator, pressure (Pa) from a displacement field (m):
        the field is convolved, periodically on the window plus ``_PRECONDITION_PAD`` cells,
        with the inverse of :func:`boussinesq_symbol`. The inverse kernel falls off as 1/r³, so
        the wrap-around leaves the CG's convergence as on a grid padded to twice the window,
        with transforms 4x smaller."""
        size, inv = self._preconditioner
        return _periodic_apply(residual, size, lambda spec: spec.__imul__(inv))


@cites("dcfft", _DCFFT)
class TangentialOperator:
    """(u_x, u_y) = K * (τ_x, τ_y) on a ``(ny, nx)`` window: traction (Pa) to displacement (m).

    Fields have shape ``(2, ny, nx)``. The x-y coupling through ν is included; the
    normal-tangential coupling is not (Goodman approximation). Obtain through
    :func:`tangential_operator`.
    """

    def __init__(self, shape: tuple[int, int], spacing: tuple[float, float], G: float, nu: float):
        ny, nx = shape
        dx, dy = spacing
        self.shape, self.spacing, self.G, self.nu = (ny, nx), (dx, dy), G, nu
        self._t = _Transform(ny, nx)
        kxx, kxy, kyy = _tabulate(
            lambda X, Y: influence.tangential(X, Y, dx / 2, dy / 2, G, nu), ny, nx, dy, dx,
            ((1, 1), (-1, -1), (1, 1)))
        self.spectra = tuple(self._t.kernel_spectrum(k) for k in (kxx, kxy, kyy))
        #: self-influence (K_xx(0), K_yy(0)) in m/Pa
        self.self_terms = (float(kxx[0, 0]), float(kyy[0, 0]))

    @cached_property
    def _preconditioner(self) -> tuple[tuple[int, int], tuple[np.ndarray, ...]]:
        size = _periodic_size(self.shape)
        sxx, sxy, syy = cerruti_symbol(*size, self.spacing, self.G, self.nu)
        with np.errstate(invalid="ignore"):
            det = sxx * syy - sxy * sxy
            inverse = (syy / det, -sxy / det, sxx / det)
        inverse[0][0, 0] = inverse[1][0, 0] = inverse[2][0, 0] = 0.0
        return size, (*inverse, 1.0 / sxx)

    def precondition(self, residual: np.ndarray, scalar: bool = False) -> np.ndarray:
        """Approximate inverse of this operator, traction (Pa) from a displacement field (m),
        ``(2, ny, nx)`` (or ``(1, ny, nx)`` with ``scalar``: x only, ν's x-y coupling dropped):
        the inverse of :func:`cerruti_symbol`, applied periodically on the window plus
        ``_PRECONDITION_PAD`` cells, as :meth:`NormalOperator.precondition`."""
        size, (ixx, ixy, iyy, ix) = self._preconditioner

        def combine(spec: np.ndarray) -> None:
            if scalar:
                spec[0] *= ix
            else:
                fx, fy = spec[0].copy(), spec[1]
                spec[0] = ixx * fx + ixy * fy
                spec[1] = ixy * fx + iyy * fy

        return _periodic_apply(residual, size, combine)

    def __call__(self, traction: np.ndarray) -> np.ndarray:
        sx, sy = self._t.forward(traction)
        sxx, sxy, syy = self.spectra
        out = np.empty((2, *sx.shape), dtype=sx.dtype)
        np.multiply(sxx, sx, out=out[0])
        out[0] += sxy * sy
        np.multiply(sxy, sx, out=out[1])
        out[1] += syy * sy
        return self._t.inverse(out)


@cites("dcfft", _DCFFT)
class CouplingOperator:
    """The normal-tangential coupling on a ``(ny, nx)`` window of a contact pair.

    ``normal(τ)``: u_z = K_zx * τ_x + K_zy * τ_y, the normal displacement (m, into the particle,
    away from the plate) of shear tractions (2, ny, nx) in Pa; ``tangential(p)``: (u_x, u_y) =
    -(K_zx * p, K_zy * p), the tangential displacement (m) of a pressure (Pa), by reciprocity
    (K_xz = -K_zx). K_zx = β H_x/(πE*) (:func:`~thirdbody.bem.influence.coupling_integral`),
    K_zy the same with x and y exchanged. Both blocks are odd in one direction, so their spectra
    are imaginary; only the imaginary parts are stored. Obtain through :func:`coupling_operator`.
    """

    def __init__(self, shape: tuple[int, int], spacing: tuple[float, float], factor: float):
        ny, nx = shape
        dx, dy = spacing
        self.shape, self.spacing, self.factor = (ny, nx), (dx, dy), factor
        self._t = _Transform(ny, nx)

        def blocks(X, Y):
            return (factor * influence.coupling_integral(X, Y, dx / 2, dy / 2),
                    factor * influence.coupling_integral(Y, X, dy / 2, dx / 2))

        kzx, kzy = _tabulate(blocks, ny, nx, dy, dx, ((-1, 1), (1, -1)))
        self.spectra = tuple(1j * np.ascontiguousarray(sfft.rfft2(k, workers=_workers).imag)
                             for k in (kzx, kzy))

    def normal(self, traction: np.ndarray) -> np.ndarray:
        """Normal displacement (m, away from the plate) of the shear tractions (2, ny, nx)."""
        sx, sy = self._t.forward(traction)
        sx *= self.spectra[0]
        sx += self.spectra[1] * sy
        return self._t.inverse(sx)

    def tangential(self, pressure: np.ndarray) -> np.ndarray:
        """Tangential displacement (2, ny, nx), m, of a pressure field (ny, nx), Pa."""
        spec = self._t.forward(pressure)
        out = np.stack([-self.spectra[0] * spec, -self.spectra[1] * spec])
        return self._t.inverse(out)


_coupling_cached = _Cache(CouplingOperator)


def coupling_operator(shape: tuple[int, int], spacing: tuple[float, float],
                      factor: float) -> CouplingOperator:
    """Cached :class:`CouplingOperator` for a ``(ny, nx)`` window of cells ``(dx, dy)`` (m);
    ``factor`` is β/(πE*) (:attr:`~thirdbody.bem.pair.ElasticPair.coupling_modulus`)."""
    return _coupling_cached(tuple(int(s) for s in shape), tuple(float(s) for s in spacing),
                            float(factor))


_normal_cached = _Cache(NormalOperator)
_tangential_cached = _Cache(TangentialOperator)


def normal_operator(shape: tuple[int, int], spacing: tuple[float, float],
                    E_star: float) -> NormalOperator:
    """Cached :class:`NormalOperator` for a ``(ny, nx)`` window of cells ``(dx, dy)`` (m)."""
    return _normal_cached(tuple(int(s) for s in shape), tuple(float(s) for s in spacing),
                          float(E_star))


def tangential_operator(shape: tuple[int, int], spacing: tuple[float, float], G: float,
                        nu: float) -> TangentialOperator:
    """Cached :class:`TangentialOperator` for a ``(ny, nx)`` window of cells ``(dx, dy)`` (m)."""
    return _tangential_cached(tuple(int(s) for s in shape), tuple(float(s) for s in spacing),
                              float(G), float(nu))


def surface_displacements(shape: tuple[int, int], spacing: tuple[float, float], pair,
                          pressure: np.ndarray, traction: np.ndarray,
                          normal_traction: np.ndarray) -> tuple[np.ndarray, ...]:
    """The surface displacements of one coupled load state on a ``(ny, nx)`` window, m, sharing
    the forward transforms (9 instead of 12): ``K_zz * p``; the normal displacement of
    ``normal_traction`` (2, ny, nx), Pa (K_zx * τ_x + K_zy * τ_y, the shear a normal solve saw);
    and the tangential displacement (2, ny, nx) of ``traction`` and the pressure,
    K_tt * τ − (K_zx, K_zy) * p. ``pair`` is an :class:`~thirdbody.bem.pair.ElasticPair`."""
    K = normal_operator(shape, spacing, pair.E_star)
    T = tangential_operator(shape, spacing, pair.G, pair.nu)
    C = coupling_operator(shape, spacing, pair.coupling_modulus)
    t = K._t
    sp = t.forward(pressure)
    sx, sy = t.forward(traction)
    nx_, ny_ = t.forward(normal_traction)
    sxx, sxy, syy = T.spectra
    cx, cy = C.spectra
    normal = t.inverse(np.stack([K.spectrum * sp, cx * nx_ + cy * ny_]))
    tangential = t.inverse(np.stack([sxx * sx + sxy * sy - cx * sp,
                                     sxy * sx + syy * sy - cy * sp]))
    return normal[0], normal[1], tangential
