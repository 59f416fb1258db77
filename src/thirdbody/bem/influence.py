"""Influence coefficients of a uniformly loaded rectangular surface cell on an elastic half-space.

Sign convention of this module (and of docs/methods/algorithms.md): z points into the elastic body,
pressure p > 0 is compressive, u_z > 0 is displacement into the body, tangential tractions act on
the body and u_x, u_y are parallel to them. A coefficient K_ab(x, y) is the displacement component
``a`` at field point (x, y) per unit uniform traction component ``b`` on the cell centred at the
origin with half-sides (a, b); units m/Pa.

Sources: Love (1929) for the normal block (integral of the Boussinesq point solution); the
tangential blocks integrate Cerruti's point solution (Johnson, *Contact Mechanics*, 1985, §3.2–3.3)
over the cell. All closed forms are written with ``X asinh(Y/|X|)`` terms, which are finite on the
cell's edge lines where the textbook logarithms read 0/0.
"""

from __future__ import annotations

import numpy as np

from .._citations import cites

_LOVE = ("Love, A. E. H. (1929). The stress produced in a semi-infinite solid by pressure on part "
         "of the boundary. Phil. Trans. R. Soc. A 228, 377-420.")


def _xasinh(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """X asinh(Y/|X|), continuous with value 0 on X = 0."""
    absX = np.abs(X)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = X * np.arcsinh(Y / absX)
    return np.where(absX > 0, out, 0.0)


def _corners(x, y, half_x: float, half_y: float):
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return x + half_x, x - half_x, y + half_y, y - half_y


def cell_integrals(x, y, half_x: float, half_y: float) -> tuple[np.ndarray, np.ndarray]:
    """The integrals (A, B) over the cell [-a, a] x [-b, b] seen from field point (x, y).

    ``A = ∫∫ Y²/ρ³``, ``B = ∫∫ X²/ρ³`` with (X, Y) the offset from the source point and
    ρ = |(X, Y)|; ``A + B = ∫∫ 1/ρ`` (m). Exact closed forms.
    """
    k, l, m, n = _corners(x, y, half_x, half_y)
    A = _xasinh(k, m) - _xasinh(k, n) - _xasinh(l, m) + _xasinh(l, n)
    B = _xasinh(m, k) - _xasinh(m, l) - _xasinh(n, k) + _xasinh(n, l)
    return A, B


def cell_integral_xy(x, y, half_x: float, half_y: float) -> np.ndarray:
    """R = ∫∫ X Y / ρ³ over the cell (m), odd in x and in y."""
    k, l, m, n = _corners(x, y, half_x, half_y)
    return np.hypot(k, n) - np.hypot(k, m) + np.hypot(l, m) - np.hypot(l, n)


@cites("love1929", _LOVE)
def normal(x, y, half_x: float, half_y: float, E_star: float) -> np.ndarray:
    """K_zz: normal displacement (m) per unit pressure (Pa) on the cell; Φ/(π E*)."""
    A, B = cell_integrals(x, y, half_x, half_y)
    return (A + B) / (np.pi * E_star)


def tangential(x, y, half_x: float, half_y: float, G: float, nu: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_xx, K_xy, K_yy): tangential displacement (m) per unit shear traction (Pa) on the cell.

    K_xx = [(1-ν)A + B]/(2πG), K_yy = [(1-ν)B + A]/(2πG), K_xy = K_yx = νR/(2πG) (the x-y
    coupling through Poisson's ratio). Normal-tangential coupling is not included (Goodman's
    approximation; it vanishes for ν = 0.5).
    """
    A, B = cell_integrals(x, y, half_x, half_y)
    R = cell_integral_xy(x, y, half_x, half_y)
    c = 1.0 / (2.0 * np.pi * G)
    return c * ((1 - nu) * A + B), c * nu * R, c * ((1 - nu) * B + A)


def coupling_integral(x, y, half_x: float, half_y: float) -> np.ndarray:
    """H_x = ∫∫ X/ρ² over the cell [-a, a] x [-b, b] seen from field point (x, y) (m), with
    (X, Y) the offset from the source point; odd in x, even in y. H_y is this function with
    the roles of x and y exchanged. Exact closed form, finite on the cell's edge lines and
    inside the cell."""
    k, l, m, n = _corners(x, y, half_x, half_y)

    def F(X, Y):
        # antiderivative of X/(X²+Y²) over the rectangle: ½ Y ln(X²+Y²) + X atan(Y/X)
        r2 = X * X + Y * Y
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = np.where(r2 > 0, 0.5 * Y * np.log(np.where(r2 > 0, r2, 1.0)), 0.0)
            t2 = np.where(X != 0, X * np.arctan(Y / np.where(X != 0, X, 1.0)), 0.0)
        return t1 + t2

    return F(k, m) - F(k, n) - F(l, m) + F(l, n)


def coupling(x, y, half_x: float, half_y: float, G: float, nu: float) -> np.ndarray:
    """K_zx: normal displacement (m, into the body) per unit shear traction τ_x (Pa) on the
    cell; by reciprocity K_xz = -K_zx (tangential displacement per unit pressure).

    ``(1-2ν) H_x / (4πG)`` with H_x = ∫∫ X/ρ² (:func:`coupling_integral`; Johnson 1985,
    eq. 3.86a). For a contact pair the factor is β/(πE*) instead, Dundurs' β
    (:class:`~thirdbody.bem.pair.ElasticPair`).
    """
    return (1 - 2 * nu) * coupling_integral(x, y, half_x, half_y) / (4 * np.pi * G)
