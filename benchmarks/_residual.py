"""Independent KKT residual of a frictionless normal contact solution.

Every solver (ours and the peers) reports its own convergence measure, and no two of them mean
the same thing. This module judges a solution from the returned pressure field alone, with an
operator written here and nowhere else:

* displacement u = K * p, with K the exact Love (1929) influence coefficient of a uniformly
  loaded square cell, K_zz = Phi / (pi E*) (FORMULAS.md), applied as an exact linear
  (non-periodic) convolution by zero padding to 2N x 2N and ``numpy.fft`` real transforms;
* deformed separation s = gap + u - delta, with the approach delta taken as the mean of
  (gap + u) over the contact cells (p > 0);
* residual = max( max_contact |s|, max_open max(-s, 0) ) / delta.

It shares no code with ``thirdbody`` (nor with the peers), so it can referee all of them.

Run ``python benchmarks/_residual.py`` for the self-test (Hertz sphere).
"""

from __future__ import annotations

import itertools
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

__all__ = ["displacement", "kkt_residual", "love_phi"]


def _asinh_diff(u: np.ndarray, v: np.ndarray, du: np.ndarray) -> np.ndarray:
    """asinh(u) - asinh(v), given the exactly known difference du = u - v.

    When u and v have the same sign the direct difference cancels; there we use
    asinh(u) - asinh(v) = asinh(u sqrt(1+v^2) - v sqrt(1+u^2)) and write the argument as
    du (u+v) / (u sqrt(1+v^2) + v sqrt(1+u^2)), which has no cancellation.
    """
    su = np.sqrt(1.0 + u * u)
    sv = np.sqrt(1.0 + v * v)
    same = u * v > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = u * sv + v * su
        arg = np.where(same, du * (u + v) / np.where(same, denom, 1.0), 0.0)
    return np.where(same, np.arcsinh(arg), np.arcsinh(u) - np.arcsinh(v))


def _pair_term(c: np.ndarray, p: np.ndarray, q: np.ndarray, dpq: float) -> np.ndarray:
    """c * [asinh(p/|c|) - asinh(q/|c|)], with its c -> 0 limit (0) handled."""
    ac = np.abs(c)
    nz = ac > 0
    safe = np.where(nz, ac, 1.0)
    d = _asinh_diff(p / safe, q / safe, dpq / safe)
    return np.where(nz, c * d, 0.0)


def love_phi(x: np.ndarray, y: np.ndarray, a: float, b: float) -> np.ndarray:
    """Integral of 1/rho over the rectangle [-a, a] x [-b, b], seen from the point (x, y).

    Love's closed form (FORMULAS.md), written with asinh: for k != 0,
    ln[(m + rho(k, m)) / (n + rho(k, n))] = asinh(m/|k|) - asinh(n/|k|).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    k, el, m, n = x + a, x - a, y + b, y - b  # k, l, m, n of FORMULAS.md
    big_a = _pair_term(k, m, n, 2 * b) - _pair_term(el, m, n, 2 * b)
    big_b = _pair_term(m, k, el, 2 * a) - _pair_term(n, k, el, 2 * a)
    return big_a + big_b


_SPECTRA: dict[tuple[int, int, float, float], np.ndarray] = {}


def _kernel_spectrum(ny: int, nx: int, h: float, e_star: float) -> np.ndarray:
    key = (ny, nx, float(h), float(e_star))
    if key not in _SPECTRA:
        # wrap-around offsets on the 2N grid: index i <= N -> i h, i > N -> (i - 2N) h
        iy = np.arange(2 * ny)
        ix = np.arange(2 * nx)
        oy = np.where(iy <= ny, iy, iy - 2 * ny) * h
        ox = np.where(ix <= nx, ix, ix - 2 * nx) * h
        phi = love_phi(ox[None, :], oy[:, None], h / 2, h / 2)
        _SPECTRA.clear()  # keep one spectrum: the benchmark visits one size at a time
        _SPECTRA[key] = np.fft.rfft2(phi / (np.pi * e_star))
    return _SPECTRA[key]


def displacement(pressure: np.ndarray, h: float, e_star: float) -> np.ndarray:
    """Normal surface displacement (m, into the body) of cell pressures (Pa) on square cells h."""
    p = np.asarray(pressure, dtype=float)
    ny, nx = p.shape
    spec = _kernel_spectrum(ny, nx, h, e_star)
    padded = np.zeros((2 * ny, 2 * nx))
    padded[:ny, :nx] = p
    u = np.fft.irfft2(np.fft.rfft2(padded) * spec, s=padded.shape)
    return u[:ny, :nx]


def kkt_residual(pressure: np.ndarray, gap: np.ndarray, h: float, e_star: float,
                 force: float) -> dict:
    """KKT measures of a normal contact solution, from its pressure field only.

    Parameters
    ----------
    pressure : (N, N) cell pressures, Pa.
    gap : (N, N) initial separation at the cell centres, m.
    h : cell side, m.
    e_star : contact modulus E/(1 - nu^2) of the elastic body against a rigid plate, Pa.
    force : prescribed total force, N.

    Returns
    -------
    dict with
      residual        max(max_contact |s|, max_open max(-s, 0)) / delta
      contact_gap     max_contact |s| / delta
      penetration     max_open max(-s, 0) / delta
      complementarity sum(p |s|) / (sum(p) delta)   (pressure-weighted, informative)
      force_error     |h^2 sum p - force| / force
      negative_p      min(p) / max(p)
      approach        delta, m (mean of gap + u over the contact cells)
      n_contact       number of cells with p > 0
    """
    p = np.asarray(pressure, dtype=float)
    g = np.asarray(gap, dtype=float)
    if p.shape != g.shape:
        raise ValueError(f"pressure {p.shape} and gap {g.shape} differ in shape")
    u = displacement(p, h, e_star)
    contact = p > 0
    n_c = int(contact.sum())
    total = h * h * float(p.sum())
    out = {
        "force_error": abs(total - force) / force,
        "negative_p": float(p.min() / p.max()) + 0.0 if p.max() > 0 else float("nan"),
        "n_contact": n_c,
    }
    if n_c == 0:
        out.update(residual=float("inf"), contact_gap=float("inf"), penetration=float("inf"),
                   complementarity=float("inf"), approach=float("nan"))
        return out
    gu = g + u
    delta = float(gu[contact].mean())
    s = gu - delta
    scale = abs(delta) if delta != 0 else float(np.ptp(gu[contact]) or 1.0)
    cg = float(np.abs(s[contact]).max()) / scale
    pen = float(np.maximum(-s[~contact], 0.0).max()) / scale if n_c < p.size else 0.0
    out.update(
        residual=max(cg, pen),
        contact_gap=cg,
        penetration=pen,
        complementarity=float((p[contact] * np.abs(s[contact])).sum() / (p[contact].sum() * scale)),
        approach=delta,
    )
    return out


# ----------------------------------------------------------------------------------------------
# self-test


def _hertz_problem(n: int, length: float = 1e-3, force: float = 1.0, e_young: float = 210e9,
                   nu: float = 0.3):
    """The benchmark's Hertz problem: a = L/8 at W; apex at the window centre (a cell corner)."""
    e_star = e_young / (1 - nu**2)
    a = length / 8
    radius = 4 * e_star * a**3 / (3 * force)
    h = length / n
    c = (np.arange(n) + 0.5) * h - length / 2
    r2 = c[None, :] ** 2 + c[:, None] ** 2
    gap = r2 / (2 * radius)
    p0 = 3 * force / (2 * np.pi * a * a)
    p_hertz = p0 * np.sqrt(np.clip(1 - r2 / (a * a), 0.0, None))
    return gap, h, e_star, force, p_hertz, a, radius


def _check_kernel() -> None:
    """Love's closed form against brute-force midpoint quadrature of 1/rho (and the self term)."""
    h = 1.0
    self_term = love_phi(np.array(0.0), np.array(0.0), h / 2, h / 2)
    assert abs(self_term - 4 * h * np.log(1 + np.sqrt(2))) < 1e-13, self_term
    m = 400
    t = (np.arange(m) + 0.5) / m * h - h / 2
    for (x, y) in [(1.0, 0.0), (1.0, 1.0), (2.0, -3.0), (0.5, 0.0), (17.0, 5.0)]:
        rho = np.hypot(x - t[None, :], y - t[:, None])
        quad = float((1.0 / rho).sum()) * (h / m) ** 2
        exact = float(love_phi(np.array(x), np.array(y), h / 2, h / 2))
        rel = abs(quad - exact) / exact
        tol = 1e-4 if x != 0.5 else 2e-2  # (0.5, 0): field point on the cell edge
        assert rel < tol, (x, y, quad, exact)
    # far field: Phi -> h^2 / r with stable cancellation
    x = np.array(3000.0)
    far = float(love_phi(x, np.array(0.0), h / 2, h / 2))
    assert abs(far * 3000.0 - 1.0) < 1e-7, far * 3000.0


def _self_test(sizes=(64, 128, 256), peers=True, tol=1e-8) -> None:
    _check_kernel()
    print("kernel: Love closed form agrees with quadrature")
    print(f"{'N':>5} {'source':<16} {'residual':>10} {'force err':>10} {'min/max p':>10}")
    hertz_res = []
    for n in sizes:
        gap, h, e_star, force, p_hertz, _, _ = _hertz_problem(n)
        r = kkt_residual(p_hertz, gap, h, e_star, force)
        hertz_res.append(r["residual"])
        print(f"{n:5d} {'Hertz analytic':<16} {r['residual']:10.2e} {r['force_error']:10.2e} "
              f"{r['negative_p']:10.2e}")
        if not peers:
            continue
        import _peers  # local module, next to this file

        for name, fn in _peers.SOLVERS.items():
            try:
                p, _, _ = fn(gap, h, e_star, force, tol)
            except Exception as exc:  # a missing peer must not stop the self-test
                print(f"{n:5d} {name:<16} failed: {type(exc).__name__}: {exc}")
                continue
            rr = kkt_residual(p, gap, h, e_star, force)
            print(f"{n:5d} {name:<16} {rr['residual']:10.2e} {rr['force_error']:10.2e} "
                  f"{rr['negative_p']:10.2e}")
            assert rr["residual"] < 1e-3 * r["residual"], (name, n, rr["residual"])
    assert all(b < a for a, b in itertools.pairwise(hertz_res)), hertz_res
    print("analytic Hertz residual falls with refinement (discretisation error);"
          " converged peers are far below it")


if __name__ == "__main__":
    import sys

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    _self_test()
