"""The same normal contact problem, solved by three peer libraries.

Problem (identical for every function): a rigid flat plate pressed, frictionless, onto an elastic
half-space whose surface is a non-periodic (free-boundary) window of N x N square cells of side
``h`` (m). ``gap`` (N, N), m, >= 0, is the initial separation at the cell centres; ``E_star``
(Pa) is the contact modulus (rigid plate: E* = E/(1-nu^2)); ``force`` (N) is the prescribed
total load. Pressure is uniform over each cell (exact Love influence coefficients, zero-padded
convolution).

Each ``solve_<peer>(gap, h, E_star, force, tol, **options)`` returns
``(pressure, approach, info)``:

* ``pressure`` - (N, N) float array, Pa, cell values, >= 0, with h^2 * sum(p) == force;
* ``approach`` - rigid approach delta in m (s = gap + u - delta is zero in contact), or None;
* ``info``     - dict with at least ``iterations`` (int or None) and ``converged`` (the peer's
  own flag), plus the peer's own error measures and the native settings used.

``tol`` is handed to the peer in ITS OWN sense (see each docstring): the peers' tolerances do not
mean the same thing, nor what ``_residual.kkt_residual`` measures. Calibrate against that
independent residual instead of comparing ``tol`` values.

Operators are cached per (N, h, E*), as thirdbody caches its kernel spectra, so a repeated
solve of the same size measures the solve and not the set-up.

Peer conventions converted here:

=================  ==================================  =================================
peer               input                               output
=================  ==================================  =================================
tamaas 2.9         heights = -gap; mean pressure       traction = cell pressure (Pa);
                   W/L^2; model.E = E*, nu = 0 set      approach not reported (computed
                   BEFORE registerNonPeriodic           from its own dcfft displacement)
contactmechanics   heights = -gap; external_force = W  forces per pixel (N) -> / h^2;
                   (N, total); young = E* (contact      offset = approach
                   modulus); physical_sizes = N h
aspher             gap as is; p_nominal = W/L^2;        pressure (Pa); approach
                   domain_size = N h; E_star = E*
=================  ==================================  =================================
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

__all__ = ["SOLVERS", "peer_versions", "solve_aspher", "solve_contactmechanics", "solve_tamaas"]

_CACHE: dict[tuple, object] = {}


def _cached(key: tuple, build):
    if key not in _CACHE:
        # one size at a time is enough: drop other entries of the same peer
        for k in [k for k in _CACHE if k[0] == key[0]]:
            del _CACHE[k]
        _CACHE[key] = build()
    return _CACHE[key]


def _check(gap: np.ndarray, h: float, e_star: float, force: float) -> np.ndarray:
    g = np.ascontiguousarray(gap, dtype=np.float64)
    if g.ndim != 2 or g.shape[0] != g.shape[1]:
        raise ValueError(f"gap must be a square (N, N) array, got shape {g.shape}")
    if not np.isfinite(g).all():
        raise ValueError("gap must be finite")
    if not (h > 0 and e_star > 0 and force > 0):
        raise ValueError("h, E_star and force must be > 0")
    return g


@contextlib.contextmanager
def _capture_fd(fd: int):
    """Collect what C++ code writes to a file descriptor (Tamaas logs to stderr)."""
    out: list[str] = []
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        sys.stderr.flush()
        sys.stdout.flush()
        saved = os.dup(fd)
        try:
            os.dup2(tmp.fileno(), fd)
            yield out
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            out.append(tmp.read().decode(errors="replace"))


# ----------------------------------------------------------------------------------------------
# Tamaas


def solve_tamaas(gap, h, E_star, force, tol, *, max_iter: int = 20000):
    """Tamaas ``PolonskyKeerRey`` on its non-periodic ``dcfft`` Boussinesq operator.

    Calls: ``ModelFactory.createModel(model_type.basic_2d, [L, L], [N, N])``; ``model.E = E*``,
    ``model.nu = 0`` (so Tamaas' E/(1-nu^2) is E*); ``ModelFactory.registerNonPeriodic(model,
    "dcfft")``; ``PolonskyKeerRey(model, -gap, tol)``; ``solver.setIntegralOperator("dcfft")``;
    ``solver.solve(W / L^2)`` (mean pressure over the window).

    Pitfalls (checked with Tamaas 2.9.0):

    * without ``setIntegralOperator("dcfft")`` the solver silently stays PERIODIC;
    * the dcfft operator reads E and nu when it is registered: setting them afterwards leaves a
      wrong modulus in it. Set them first (then the operator equals Love's coefficients to
      round-off);
    * ``model.displacement`` is not the non-periodic displacement after the solve; the approach
      is computed here from ``model.operators["dcfft"]`` (one extra convolution).

    ``tol`` is Tamaas' own PK error (a complementarity measure); its solve returns the final
    error. The iteration count is read from Tamaas' log (stderr, at info level).
    """
    import tamaas as tm

    g = _check(gap, h, E_star, force)
    n = g.shape[0]
    length = n * h

    def build():
        model = tm.ModelFactory.createModel(tm.model_type.basic_2d, [length, length], [n, n])
        model.E = float(E_star)
        model.nu = 0.0
        tm.ModelFactory.registerNonPeriodic(model, "dcfft")  # after E, nu: see docstring
        return model

    model = _cached(("tamaas", n, float(h), float(E_star)), build)
    model.traction[...] = 0.0
    solver = tm.PolonskyKeerRey(model, np.ascontiguousarray(-g), float(tol))
    solver.setIntegralOperator("dcfft")
    solver.max_iter = int(max_iter)
    level = tm.get_log_level()
    tm.set_log_level(tm.LogLevel.info)
    try:
        with _capture_fd(2) as log:
            error = float(solver.solve(force / (length * length)))
    finally:
        tm.set_log_level(level)
    text = "".join(log)
    rows = re.findall(r"^\s*(\d+)\s+[-+0-9.eE]+\s+[-+0-9.eE]+\s*$", text, flags=re.M)
    iterations = int(rows[-1]) if rows else None
    p = np.array(model.traction, dtype=float).reshape(n, n)
    u = np.zeros((n, n))
    model.operators["dcfft"](model.traction, u)
    contact = p > 0
    approach = float((g + u)[contact].mean()) if contact.any() else None
    return p, approach, {
        "iterations": iterations,
        "converged": bool(error <= tol),
        "peer_error": error,
        "settings": {"tol": tol, "max_iter": max_iter, "operator": "dcfft"},
        "approach_source": "mean of gap + u over contact, u from Tamaas' dcfft operator",
    }


# ----------------------------------------------------------------------------------------------
# ContactMechanics


def solve_contactmechanics(gap, h, E_star, force, tol, *, max_iter: int = 20000,
                           pentol: float | None = None, forcetol: float | None = None,
                           thermotol: float | None = None):
    """ContactMechanics ``constrained_conjugate_gradients`` on ``FreeFFTElasticHalfSpace``.

    Calls: ``FreeFFTElasticHalfSpace((N, N), E*, (L, L))`` (its ``young`` IS the contact
    modulus; it pads to 2N x 2N internally) and ``constrained_conjugate_gradients(substrate,
    -gap, external_force=W, pentol=..., forcetol=..., thermotol=..., maxiter=...)``. Its
    unknowns are per-pixel FORCES (N, compressive > 0 in ``result.jac``): pressure =
    ``jac / h^2``; ``result.offset`` is the approach.

    Its stopping rule is absolute: rms and max penetration and the last displacement change
    < ``pentol`` (m), tensile force outside contact < ``forcetol`` (N per pixel; default 1e-5 N,
    meaningless at these scales), relative change of force/offset < ``thermotol``. The relative
    ``tol`` given here is mapped to ``pentol = tol * ptp(gap)``, ``forcetol = tol * force /
    N^2`` and ``thermotol = tol`` unless given explicitly.
    """
    from ContactMechanics import FreeFFTElasticHalfSpace
    from ContactMechanics.Optimization import constrained_conjugate_gradients

    g = _check(gap, h, E_star, force)
    n = g.shape[0]
    length = n * h
    substrate = _cached(
        ("contactmechanics", n, float(h), float(E_star)),
        lambda: FreeFFTElasticHalfSpace((n, n), float(E_star), (length, length)),
    )
    g_ref = float(np.ptp(g)) or 1.0
    settings = {
        "pentol": tol * g_ref if pentol is None else pentol,
        "forcetol": tol * force / (n * n) if forcetol is None else forcetol,
        "thermotol": tol if thermotol is None else thermotol,
        "maxiter": int(max_iter),
    }
    res = constrained_conjugate_gradients(substrate, -g, external_force=float(force), **settings)
    p = np.asarray(res.jac, dtype=float).reshape(n, n) / (h * h)
    return p, float(res.offset), {
        "iterations": int(res.nit),
        "converged": bool(res.success),
        "message": str(res.message),
        "max_pen": float(res.maxcv["max_pen"]) if "maxcv" in res else None,
        "settings": settings,
    }


# ----------------------------------------------------------------------------------------------
# ASPHER


def solve_aspher(gap, h, E_star, force, tol, *, max_iter: int = 20000,
                 precond: str = "fourier", nested: bool = False):
    """ASPHER ``ContactSolver(backend="fft")`` with its ``"fourier"`` preconditioner.

    Calls: ``aspher.ContactSolver(grid_size=N, domain_size=N h, E_star=E*, backend="fft")`` (the
    exact zero-padded Love convolution; the library's default backend is an approximate
    H-matrix and must not be used here) and ``solver.solve(gap, p_nominal=W / L^2, tol=tol,
    max_iter=..., precond="fourier")``; ``precond="fourier"`` is the |q| preconditioner applied
    as a 13-tap stencil on the contact set, ``"fourier-fft"`` the full-grid FFT version.
    ``nested=True`` uses ``aspher.solve_nested(..., backend="fft")`` instead (coarse-to-fine
    warm start; N must be 64 * 2^k).

    ``tol`` is ASPHER's certified tolerance: Frank-Wolfe gap / (P g_ref) and max penetration /
    g_ref, with g_ref = max(gap) - min(gap) over the WINDOW (not the approach), and the load.
    """
    import aspher

    g = _check(gap, h, E_star, force)
    n = g.shape[0]
    length = n * h
    p_nominal = force / (length * length)
    if nested:
        res = aspher.solve_nested(grid_size=n, gap=g, p_nominal=p_nominal, domain_size=length,
                                  E_star=float(E_star), backend="fft", tol=float(tol),
                                  max_iter=int(max_iter))
    else:
        solver = _cached(
            ("aspher", n, float(h), float(E_star)),
            lambda: aspher.ContactSolver(grid_size=n, domain_size=length, E_star=float(E_star),
                                         backend="fft"),
        )
        res = solver.solve(g, p_nominal=p_nominal, tol=float(tol), max_iter=int(max_iter),
                           precond=precond)
    p = np.asarray(res.pressure, dtype=float).reshape(n, n)
    return p, float(res.approach), {
        "iterations": int(res.iterations),
        "converged": bool(res.converged),
        "status": str(res.status),
        "fw_error": float(res.fw_error),
        "penetration_error": float(res.penetration_error),
        "g_ref": float(res.g_ref),
        "matvec_count": int(res.matvec_count),
        "settings": {"tol": tol, "backend": "fft", "precond": precond, "nested": nested},
    }


SOLVERS = {
    "tamaas": solve_tamaas,
    "contactmechanics": solve_contactmechanics,
    "aspher": solve_aspher,
}


def peer_versions() -> dict[str, str]:
    """Installed versions of the peers (from package metadata), 'missing' if absent."""
    from importlib import metadata

    out = {}
    for dist in ("tamaas", "contactmechanics", "aspher"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "missing"
    return out
