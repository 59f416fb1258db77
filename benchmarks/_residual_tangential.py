"""Independent Coulomb residual of a tangential (partial-slip) contact solution.

The tangential solvers (ours and the peers) each report their own convergence measure, and no
two of them mean the same thing. This module judges a solution from the returned traction and
pressure fields alone, with an elastic operator written here and nowhere else:

* tangential displacement (u_x, u_y) = K * (tau_x, tau_y), with K the Cerruti influence
  coefficients of a uniformly loaded square cell (FORMULAS.md):
  K_xx = [(1-nu) A + B]/(2 pi G), K_yy = [(1-nu) B + A]/(2 pi G), K_xy = K_yx = nu R/(2 pi G),
  applied as an exact linear (non-periodic) convolution by zero padding to 2N x 2N and
  ``numpy.fft`` real transforms. A and B reuse the cancellation-free asinh differences of
  ``_residual.py``; R is written here in a form without cancellation (see ``cerruti_r``);
* a periodic variant for Tamaas' doubly periodic problem: the continuous Cerruti symbol
  (I - nu q q^T/|q|^2)/(G |q|) on the discrete wavenumbers, mean (q = 0) mode dropped, with the
  Nyquist modes taken as Tamaas' real FFT takes them (the self-test checks it against Tamaas'
  own operator to round-off when Tamaas is installed);
* relative slip of the plate over the particle in the step, w = ds - du, with du = K (tau -
  tau_prev) and ds the plate's shift increment (the solver's, or estimated as the mean of du
  over the cells that stick, |tau| < (1 - 1e-3) mu p, when the solver does not report it; it is
  the only choice for the periodic operator, whose mean displacement is undefined);
* natural Coulomb residual max_i |tau_i - Pi_i(tau_i + w_i/k0)| / (mu max p), with Pi_i the
  projection on the friction disc |tau| <= mu p_i and k0 = K_xx(0) the cell's self-compliance.
  It is zero iff every cell either sticks (w_i = 0, |tau_i| <= mu p_i) or slips (|tau_i| =
  mu p_i, tau_i along w_i), and it also catches traction outside the contact (p_i = 0).

Sign conventions: tau is what the plate exerts on the particle, u the particle surface's
displacement parallel to the traction that causes it, the shift the plate's. A sign flip of the
whole solution (tau, u, s) leaves the residual unchanged.

It shares no code with ``thirdbody`` (nor with the peers), so it can referee all of them.

Run ``python benchmarks/_residual_tangential.py`` for the self-test.
"""

from __future__ import annotations

import os
import sys

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from _residual import _pair_term, love_phi  # noqa: E402

__all__ = ["cerruti_coefficients", "cerruti_r", "coulomb_residual", "self_compliance",
           "tangential_displacement"]

STICK_TOL = 1e-3  # cells with |tau| < (1 - STICK_TOL) mu p count as stuck when estimating ds


def cerruti_r(x: np.ndarray, y: np.ndarray, a: float, b: float) -> np.ndarray:
    """R = integral of X Y / rho^3 over the cell [-a, a] x [-b, b] seen from (x, y), m.

    FORMULAS.md gives R = rho(k,n) - rho(k,m) + rho(l,m) - rho(l,n), which cancels badly far
    from the cell (R ~ 4ab xy/r^3 while each term ~ r). Rationalising both differences gives
    R = 16 a b x y [1/(rho_km + rho_lm) + 1/(rho_kn + rho_ln)] / ((rho_km + rho_kn)(rho_lm +
    rho_ln)), which has no cancellation.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    k, el, m, n = x + a, x - a, y + b, y - b
    r_km, r_kn, r_lm, r_ln = np.hypot(k, m), np.hypot(k, n), np.hypot(el, m), np.hypot(el, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        inner = 1.0 / (r_km + r_lm) + 1.0 / (r_kn + r_ln)
        out = 16.0 * a * b * x * y * inner / ((r_km + r_kn) * (r_lm + r_ln))
    return np.where(x * y != 0, out, 0.0)


def cerruti_coefficients(x: np.ndarray, y: np.ndarray, a: float, b: float, G: float,
                         nu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_xx, K_xy, K_yy), m/Pa: tangential displacement at (x, y) per unit uniform shear
    traction on the cell [-a, a] x [-b, b] (Cerruti's point solution integrated over the cell).

    A = integral of Y^2/rho^3 and B = integral of X^2/rho^3 over the cell (A + B = Love's Phi).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    k, el, m, n = x + a, x - a, y + b, y - b
    big_a = _pair_term(k, m, n, 2 * b) - _pair_term(el, m, n, 2 * b)
    big_b = _pair_term(m, k, el, 2 * a) - _pair_term(n, k, el, 2 * a)
    c = 1.0 / (2.0 * np.pi * G)
    return (c * ((1.0 - nu) * big_a + big_b), c * nu * cerruti_r(x, y, a, b),
            c * ((1.0 - nu) * big_b + big_a))


def self_compliance(h: float, G: float, nu: float) -> float:
    """K_xx(0) = (2 - nu) h ln(1 + sqrt 2)/(pi G) of a square cell of side h, m/Pa."""
    return (2.0 - nu) * h * np.log1p(np.sqrt(2.0)) / (np.pi * G)


_SPECTRA: dict[tuple, tuple[np.ndarray, ...]] = {}


def _spectra(ny: int, nx: int, h: float, G: float, nu: float, periodic: bool):
    key = (ny, nx, float(h), float(G), float(nu), bool(periodic))
    if key in _SPECTRA:
        return _SPECTRA[key]
    if periodic:
        # continuous Cerruti symbol on the (x, y) layout that Tamaas uses: a real FFT along y
        # (the last axis there), with the Nyquist wavenumber of x negative as numpy's fftfreq
        qx = 2 * np.pi * np.fft.fftfreq(nx, d=h)
        qy = 2 * np.pi * np.fft.rfftfreq(ny, d=h)
        QX, QY = np.meshgrid(qx, qy, indexing="ij")
        q = np.hypot(QX, QY)
        safe = np.where(q > 0, q, 1.0)
        c = np.where(q > 0, 1.0 / (G * safe), 0.0)
        spectra = (c * (1 - nu * QX * QX / safe**2), -c * nu * QX * QY / safe**2,
                   c * (1 - nu * QY * QY / safe**2))
    else:
        # wrap-around offsets on the 2N grid: index i <= N -> i h, i > N -> (i - 2N) h
        iy = np.arange(2 * ny)
        ix = np.arange(2 * nx)
        oy = np.where(iy <= ny, iy, iy - 2 * ny) * h
        ox = np.where(ix <= nx, ix, ix - 2 * nx) * h
        blocks = cerruti_coefficients(ox[None, :], oy[:, None], h / 2, h / 2, G, nu)
        spectra = tuple(np.fft.rfft2(b) for b in blocks)
    _SPECTRA.clear()  # keep one operator: the benchmark visits one size at a time
    _SPECTRA[key] = spectra
    return spectra


def tangential_displacement(traction: np.ndarray, h: float, G: float, nu: float, *,
                            periodic: bool = False) -> np.ndarray:
    """Tangential surface displacement (2, N, N), m, of cell shear tractions (2, N, N), Pa.

    Fields are (ny, nx) arrays, components (x, y). Non-periodic: exact linear convolution with
    the cell coefficients. Periodic: window of side N h repeated in x and y, zero mean.
    """
    t = np.asarray(traction, dtype=float)
    _, ny, nx = t.shape
    sxx, sxy, syy = _spectra(ny, nx, h, G, nu, periodic)
    if periodic:
        fx = np.fft.rfft2(t[0].T)
        fy = np.fft.rfft2(t[1].T)
        ux = np.fft.irfft2(sxx * fx + sxy * fy, s=(nx, ny)).T
        uy = np.fft.irfft2(sxy * fx + syy * fy, s=(nx, ny)).T
        return np.stack([ux, uy])
    padded = np.zeros((2, 2 * ny, 2 * nx))
    padded[:, :ny, :nx] = t
    fx = np.fft.rfft2(padded[0])
    fy = np.fft.rfft2(padded[1])
    ux = np.fft.irfft2(sxx * fx + sxy * fy, s=(2 * ny, 2 * nx))[:ny, :nx]
    uy = np.fft.irfft2(sxy * fx + syy * fy, s=(2 * ny, 2 * nx))[:ny, :nx]
    return np.stack([ux, uy])


def coulomb_residual(traction: np.ndarray, pressure: np.ndarray, mu: float, h: float, G: float,
                     nu: float, *, shift=None, previous: np.ndarray | None = None,
                     previous_shift=None, force=None, periodic: bool = False) -> dict:
    """Coulomb measures of one incremental tangential step, from its fields only.

    Parameters
    ----------
    traction : (2, N, N) shear traction (tau_x, tau_y) of the plate on the particle, Pa.
    pressure : (N, N) the solver's own contact pressure, Pa (friction limit mu p).
    mu : friction coefficient.
    h : cell side, m. G : shear modulus, Pa. nu : Poisson's ratio.
    shift : (2,) total plate shift reported by the solver, m, or None (then estimated).
    previous, previous_shift : traction and shift of the previous converged step (history);
        None means a step from zero traction and zero shift.
    force : (2,) prescribed total tangential force, N, for the force error (optional).
    periodic : judge with the periodic operator (Tamaas) instead of the free-space one.

    Returns
    -------
    dict with
      residual       max_i |tau_i - Pi_i(tau_i + w_i/k0)| / (mu max p)
      stick_residual the same over the stuck cells only (there it is |w_i|/k0/(mu max p))
      slip_residual  the same over the slipping cells and outside the contact
      cone           max(|tau| - mu p, 0) / (mu max p)   (disc violation)
      force          (2,) h^2 sum tau, N;  force_error |force - prescribed| / |prescribed|
      shift          (2,) total shift used, m;  shift_estimated (bool)
      shift_from_stick (2,) the stick-cell estimate (whatever was used)
      n_stick, n_slip, stick_radius (m, from the stuck area), n_contact
    """
    tau = np.asarray(traction, dtype=float)
    p = np.asarray(pressure, dtype=float)
    if tau.shape != (2, *p.shape):
        raise ValueError(f"traction {tau.shape} must be (2, *pressure.shape), got {p.shape}")
    limit = mu * np.maximum(p, 0.0)
    tau_prev = np.zeros_like(tau) if previous is None else np.asarray(previous, dtype=float)
    s_prev = np.zeros(2) if previous_shift is None else np.asarray(previous_shift, dtype=float)
    du = tangential_displacement(tau - tau_prev, h, G, nu, periodic=periodic)
    norm = np.hypot(tau[0], tau[1])
    contact = p > 0
    stick = contact & (norm < (1.0 - STICK_TOL) * limit)
    slip = contact & ~stick
    est = du[:, stick].mean(axis=1) if stick.any() else np.full(2, np.nan)
    if shift is None or periodic:
        ds = est
        total_shift = s_prev + est
        estimated = True
    else:
        total_shift = np.asarray(shift, dtype=float)
        ds = total_shift - s_prev
        estimated = False
    k0 = self_compliance(h, G, nu)
    w = ds[:, None, None] - du
    trial = tau + w / k0
    tnorm = np.hypot(trial[0], trial[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(tnorm > limit, limit / np.where(tnorm > 0, tnorm, 1.0), 1.0)
    diff = np.hypot(*(tau - trial * factor))
    scale = float(limit.max())
    total = h * h * tau.reshape(2, -1).sum(axis=1)
    out = {
        "residual": float(diff.max() / scale),
        "stick_residual": float(diff[stick].max(initial=0.0) / scale),
        "slip_residual": float(diff[~stick].max(initial=0.0) / scale),
        "cone": float(np.maximum(norm - limit, 0.0).max() / scale),
        "force": total,
        "force_error": float("nan"),
        "shift": total_shift,
        "shift_estimated": estimated,
        "shift_from_stick": s_prev + est,
        "n_stick": int(stick.sum()),
        "n_slip": int(slip.sum()),
        "n_contact": int(contact.sum()),
        "stick_radius": float(np.sqrt(stick.sum() * h * h / np.pi)),
    }
    if force is not None:
        f = np.asarray(force, dtype=float)
        out["force_error"] = float(np.hypot(*(total - f)) / max(np.hypot(*f), 1e-300))
    return out


# ----------------------------------------------------------------------------------------------
# self-test


def _check_coefficients() -> None:
    """Closed forms against midpoint quadrature of Cerruti's point solution, and identities."""
    h, G, nu = 1.0, 1.0, 0.3
    m = 600
    t = (np.arange(m) + 0.5) / m * h - h / 2
    for (x, y) in [(1.0, 0.0), (1.0, 1.0), (2.0, -3.0), (-1.5, 0.75), (17.0, 5.0)]:
        dx = x - t[None, :]
        dy = y - t[:, None]
        rho = np.hypot(dx, dy)
        c = 1.0 / (2 * np.pi * G)
        w = (h / m) ** 2
        quad = (float((c * ((1 - nu) / rho + nu * dx * dx / rho**3)).sum() * w),
                float((c * nu * dx * dy / rho**3).sum() * w),
                float((c * ((1 - nu) / rho + nu * dy * dy / rho**3)).sum() * w))
        exact = [float(v) for v in cerruti_coefficients(np.array(x), np.array(y), h / 2, h / 2,
                                                        G, nu)]
        for q, e in zip(quad, exact, strict=True):
            assert abs(q - e) <= 1e-4 * abs(exact[0]), (x, y, quad, exact)
    # K_xx + K_yy = (2 - nu) Phi/(2 pi G); self term; parities; far field of R
    X, Y = np.meshgrid(np.arange(-5, 6) * 0.7, np.arange(-4, 5) * 0.9)
    kxx, kxy, kyy = cerruti_coefficients(X, Y, 0.5, 0.5, G, nu)
    phi = love_phi(X, Y, 0.5, 0.5)
    assert np.allclose(kxx + kyy, (2 - nu) * phi / (2 * np.pi * G), rtol=1e-14, atol=0)
    assert np.allclose(kxy, -kxy[:, ::-1], atol=1e-16) and np.allclose(kxy, -kxy[::-1], atol=1e-16)
    assert np.allclose(kxx, kxx[:, ::-1], rtol=1e-14) and np.allclose(kxx, kxx[::-1], rtol=1e-14)
    k00 = cerruti_coefficients(np.array(0.0), np.array(0.0), 0.5, 0.5, G, nu)[0]
    assert abs(k00 / self_compliance(1.0, G, nu) - 1) < 1e-14
    naive = (np.hypot(1e4 + 0.5, 3e3 - 0.5) - np.hypot(1e4 + 0.5, 3e3 + 0.5)
             + np.hypot(1e4 - 0.5, 3e3 + 0.5) - np.hypot(1e4 - 0.5, 3e3 - 0.5))
    far = float(cerruti_r(np.array(1e4), np.array(3e3), 0.5, 0.5))
    r = np.hypot(1e4, 3e3)
    assert abs(far / (1e4 * 3e3 / r**3) - 1) < 1e-6, far
    assert abs(naive / far - 1) < 1e-3  # the textbook form agrees, to its cancellation error


def _check_against_thirdbody(n: int = 96) -> float:
    """Our non-periodic displacement against thirdbody's operator on a random traction."""
    import thirdbody
    from thirdbody.bem.operator import tangential_operator

    thirdbody.set_workers(1)
    rng = np.random.default_rng(1)
    worst = 0.0
    for nu in (0.0, 0.3, 0.5):
        G = 80e9
        h = 1e-3 / n
        t = rng.standard_normal((2, n, n)) * 1e6
        ours = tangential_displacement(t, h, G, nu)
        theirs = tangential_operator((n, n), (h, h), G, nu)(t)
        err = float(np.abs(ours - theirs).max() / np.abs(theirs).max())
        worst = max(worst, err)
        assert err < 1e-12, (nu, err)
    return worst


def _check_against_tamaas(n: int = 32) -> float | None:
    """Our periodic displacement against Tamaas' periodic Westergaard operator (round-off)."""
    try:
        import tamaas as tm
    except ImportError:
        return None
    rng = np.random.default_rng(2)
    worst = 0.0
    for nu in (0.0, 0.3, 0.5):
        E, L = 3.0, 2.0
        model = tm.ModelFactory.createModel(tm.model_type.surface_2d, [L, L], [n, n])
        model.E = E
        model.nu = nu
        t = rng.standard_normal((2, n, n))
        # Tamaas' arrays are (x, y) with component c along axis c
        model.traction[..., 0] = t[0].T
        model.traction[..., 1] = t[1].T
        model.traction[..., 2] = 0.0
        model.solveNeumann()
        theirs = np.stack([np.array(model.displacement[..., c]).T for c in (0, 1)])
        ours = tangential_displacement(t, L / n, E / (2 * (1 + nu)), nu, periodic=True)
        err = float(np.abs(ours - theirs).max() / np.abs(theirs).max())
        worst = max(worst, err)
        assert err < 1e-12, (nu, err)
    return worst


def _cattaneo_case(n: int, nu: float, ratio: float = 0.5, mu: float = 0.3):
    """Cattaneo-Mindlin traction and Hertz pressure sampled at the cell centres (a = L/8)."""
    from thirdbody.reference import mindlin

    E, L, P = 210e9, 1e-3, 1.0
    e_star = E / (1 - nu**2)
    a = L / 8
    radius = 4 * e_star * a**3 / (3 * P)
    h = L / n
    c = (np.arange(n) + 0.5) * h - L / 2
    r = np.hypot(c[None, :], c[:, None])
    cm = mindlin.cattaneo_mindlin(ratio * mu * P, P, mu, radius, E, nu)
    p = cm.peak_pressure * np.sqrt(np.clip(1 - (r / a) ** 2, 0, None))
    tau = np.stack([np.asarray(cm.traction(r)), np.zeros_like(r)])
    return tau, p, mu, h, E / (2 * (1 + nu)), cm


def _self_test() -> None:
    _check_coefficients()
    print("Cerruti coefficients: closed forms agree with quadrature, identities hold")
    err = _check_against_thirdbody()
    print(f"non-periodic displacement vs thirdbody's operator: max rel. difference {err:.1e}")
    err = _check_against_tamaas()
    print("periodic displacement vs Tamaas' Westergaard operator: "
          + ("tamaas not installed" if err is None else f"max rel. difference {err:.1e}"))
    print(f"{'N':>5} {'nu':>4} {'source':<28} {'residual':>9} {'stick':>9} {'slip':>9} "
          f"{'F err':>8}")
    import thirdbody

    thirdbody.set_workers(1)
    for nu in (0.0, 0.5):
        previous = None
        for n in (64, 128, 256):
            tau, p, mu, h, G, cm = _cattaneo_case(n, nu)
            res = coulomb_residual(tau, p, mu, h, G, nu, shift=(cm.shift, 0.0),
                                   force=(cm.tangential_force, 0.0))
            print(f"{n:5d} {nu:4.1f} {'Cattaneo-Mindlin sampled':<28} {res['residual']:9.2e} "
                  f"{res['stick_residual']:9.2e} {res['slip_residual']:9.2e} "
                  f"{res['force_error']:8.1e}")
            if previous is not None and nu == 0.0:
                assert res["stick_residual"] < previous, "discretisation error must fall"
            previous = res["stick_residual"]
            # a converged thirdbody solution of the same discrete problem is far below it
            grid = thirdbody.Grid(n, h)
            mat = thirdbody.Material(2 * G * (1 + nu), nu)
            gap = grid.paraboloid(4 * mat.E_star * (1e-3 / 8) ** 3 / 3.0)
            normal = thirdbody.solve_normal(gap, grid, mat, force=1.0)
            t = thirdbody.solve_tangential(normal, mu, force=(cm.tangential_force, 0.0))
            rr = coulomb_residual(t.traction, normal.pressure, mu, h, G, nu, shift=t.shift,
                                  force=(cm.tangential_force, 0.0))
            re = coulomb_residual(t.traction, normal.pressure, mu, h, G, nu,
                                  force=(cm.tangential_force, 0.0))
            print(f"{n:5d} {nu:4.1f} {'thirdbody (shift reported)':<28} {rr['residual']:9.2e} "
                  f"{rr['stick_residual']:9.2e} {rr['slip_residual']:9.2e} "
                  f"{rr['force_error']:8.1e}")
            print(f"{n:5d} {nu:4.1f} {'thirdbody (shift estimated)':<28} {re['residual']:9.2e} "
                  f"{re['stick_residual']:9.2e} {re['slip_residual']:9.2e} "
                  f"{re['force_error']:8.1e}")
            assert rr["residual"] < 1e-6 and re["residual"] < 1e-6, (rr, re)
            assert rr["residual"] < 1e-3 * res["residual"]
    # the residual sees a wrong solution: a converged traction perturbed by 1e-6 mu p0 in one
    # stick cell, and the same traction rotated by 1e-3 rad in every slip cell
    tau, p, mu, h, G, cm = _cattaneo_case(128, 0.5)
    grid = thirdbody.Grid(128, h)
    mat = thirdbody.Material(2 * G * 1.5, 0.5)
    normal = thirdbody.solve_normal(grid.paraboloid(4 * mat.E_star * (1e-3 / 8) ** 3 / 3.0),
                                    grid, mat, force=1.0)
    t = thirdbody.solve_tangential(normal, mu, force=(cm.tangential_force, 0.0), tol=1e-10)
    good = coulomb_residual(t.traction, normal.pressure, mu, h, G, 0.5)["residual"]
    bad = t.traction.copy()
    bad[0, 64, 64] += 1e-6 * mu * cm.peak_pressure
    kicked = coulomb_residual(bad, normal.pressure, mu, h, G, 0.5)["residual"]
    c, s = np.cos(1e-3), np.sin(1e-3)
    turned = t.traction.copy()
    turned[0] = np.where(t.slip, c * t.traction[0] - s * t.traction[1], t.traction[0])
    turned[1] = np.where(t.slip, s * t.traction[0] + c * t.traction[1], t.traction[1])
    rotated = coulomb_residual(turned, normal.pressure, mu, h, G, 0.5)["residual"]
    print(f"converged {good:.1e}; one stick cell off by 1e-6 mu p0: {kicked:.1e}; "
          f"slip directions turned by 1e-3: {rotated:.1e}")
    assert good < 1e-9 and kicked > 1e-7 and rotated > 1e-4, (good, kicked, rotated)


if __name__ == "__main__":
    _self_test()
