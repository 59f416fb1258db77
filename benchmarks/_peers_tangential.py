"""The same tangential (partial-slip) contact problem, solved by two peer libraries.

Problem: an elastic half-space (Young's modulus E, Poisson ratio nu) whose surface is a window of
N x N square cells of side ``h`` (m), ``gap`` (N, N) the initial separation at the cell centres
(m), pressed by a rigid flat with normal force ``P`` (N) and then loaded tangentially with total
force ``Q`` (N, along x) with Coulomb friction ``mu`` (friction disc |tau| <= mu p). Arrays are
(ny, nx): rows along y, columns along x; tractions are (2, ny, nx) = (tau_x, tau_y) in Pa, what
the plate exerts on the particle.

=================  ==========================================  ===============================
peer               problem it solves                            output converted here
=================  ==========================================  ===============================
tamaas 2.9         PERIODIC window, normal and tangential       traction[..., 0:2] (x, y layout)
                   together from zero (no history):            transposed to (y, x); pressure
                   ``PolonskyKeerTan.solve([Q/L^2, 0, P/L^2])``  traction[..., 2]; no shift
aspher 0.1.3       free-space window (FFT, zero padded),        qx, qy, pressure reshaped as
                   incremental load history, Goodman            given (gap passed (y, x), its
                   decoupling: ``FrictionSolver``                x is our x); delta_t = shift
=================  ==========================================  ===============================

Each peer's own tolerance means something else; the benchmark calibrates it against the
independent residual of ``_residual_tangential``.
"""

from __future__ import annotations

import os
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from _peers import _cached, _capture_fd  # noqa: E402

__all__ = ["AspherFriction", "solve_tamaas"]


def _check(gap: np.ndarray) -> np.ndarray:
    g = np.ascontiguousarray(gap, dtype=np.float64)
    if g.ndim != 2 or g.shape[0] != g.shape[1] or not np.isfinite(g).all():
        raise ValueError(f"gap must be a finite square (N, N) array, got shape {g.shape}")
    return g


# ----------------------------------------------------------------------------------------------
# Tamaas


def solve_tamaas(gap, h, E, nu, mu, P, Q, max_iter: int, tol: float = 0.0):
    """Tamaas ``PolonskyKeerTan`` (Coulomb) on a periodic ``model_type.surface_2d`` model.

    Calls: ``ModelFactory.createModel(model_type.surface_2d, [L, L], [N, N])``, ``model.E = E``,
    ``model.nu = nu``; ``PolonskyKeerTan(model, -gap^T, tol, mu)``, ``max_iter``;
    ``solve([Q/L^2, 0, P/L^2])`` (mean tractions over the window: x, y, normal). It solves the
    normal and the tangential problem together, from zero, in one call; at nu = 0.5 they are
    uncoupled and the problem is the Goodman one the other solvers solve (but periodic).

    Tamaas' arrays are (x, y) with traction component c along axis c, so the gap is passed
    transposed and the fields are transposed back.

    Its own error (the returned value) stalls near 1e-13 for this problem (it scales with the
    square of the strain, ~(p/E)^2) long before the solution has converged, and stopping at a
    tolerance above that floor leaves the loads off by up to tens of percent. So ``tol`` is
    0 here and the knob is ``max_iter``: Tamaas runs exactly that many iterations.
    """
    import tamaas as tm

    g = _check(gap)
    n = g.shape[0]
    length = n * h

    def build():
        model = tm.ModelFactory.createModel(tm.model_type.surface_2d, [length, length], [n, n])
        model.E = float(E)
        model.nu = float(nu)
        return model

    model = _cached(("tamaas", n, float(h), float(E), float(nu)), build)
    model.traction[...] = 0.0
    solver = tm.PolonskyKeerTan(model, np.ascontiguousarray(-g.T), float(tol), float(mu))
    solver.max_iter = int(max_iter)
    level = tm.get_log_level()
    tm.set_log_level(tm.LogLevel.error)
    try:
        # its iteration-table header goes to stdout whatever the log level: keep it out
        with _capture_fd(1), _capture_fd(2):
            t0 = time.perf_counter()
            error = float(solver.solve([Q / length**2, 0.0, P / length**2]))
            wall = time.perf_counter() - t0
    finally:
        tm.set_log_level(level)
    tr = np.array(model.traction, dtype=float)
    traction = np.stack([tr[..., 0].T, tr[..., 1].T])
    pressure = np.ascontiguousarray(tr[..., 2].T)
    return traction, pressure, {
        "time_total": wall,
        "iterations": int(max_iter),
        "converged": None,
        "peer_error": error,
        "settings": {"tol": tol, "max_iter": int(max_iter), "model": "surface_2d (periodic)"},
    }


# ----------------------------------------------------------------------------------------------
# ASPHER


class AspherFriction:
    """ASPHER ``FrictionSolver`` on the free-space FFT operator, one normal step then tangential
    steps with history.

    Calls: ``FrictionSolver(grid_size=N, domain_size=L, E_star=E/(1-nu^2), nu=nu,
    model=CoulombFriction(mu))`` (cached per size and material), ``set_gap(gap)`` (resets the
    history), ``step(p_bar=P/L^2)``, then ``step(q_bar=(Qx/L^2, Qy/L^2), tol_tangential=tol)``
    (TOTAL force) or ``step(delta_t=(sx, sy), ...)`` (TOTAL shift). A step that does not converge
    leaves the driver's state unchanged and returns no ``delta_t``.

    ``tol`` is ASPHER's tangential tolerance (its projection residual, scaled by its own step
    length rho and the largest friction limit). Its acceptance test ``kkt_tol`` stays at its
    default (1e-2): with ``tol_kkt = tol`` it refuses even steps that meet our residual.
    """

    def __init__(self, gap, h, E, nu, mu, P, tol_normal: float = 1e-8):
        import aspher

        self.gap = _check(gap)
        n = self.gap.shape[0]
        self.n, self.h, self.L, self.P = n, float(h), n * float(h), float(P)
        self.tol_normal = float(tol_normal)
        e_star = E / (1 - nu * nu)
        self.solver = _cached(
            ("aspher", n, float(h), float(E), float(nu), float(mu)),
            lambda: aspher.FrictionSolver(grid_size=n, domain_size=self.L, E_star=float(e_star),
                                          nu=float(nu), model=aspher.CoulombFriction(float(mu))))
        self.reset()

    def reset(self) -> None:
        """Clear the history and redo the normal step (timed in ``self.normal_time``)."""
        self.solver.set_gap(self.gap)
        t0 = time.perf_counter()
        r = self.solver.step(p_bar=self.P / self.L**2, tol_normal=self.tol_normal)
        self.normal_time = time.perf_counter() - t0
        if not r.converged:
            raise RuntimeError(f"aspher normal step failed: {r.status_reason}")
        self.normal_iterations = int(r.normal_iters)
        self.pressure = np.asarray(self.solver.pressure, dtype=float).reshape(self.n, self.n)

    def step(self, Q=None, shift=None, tol: float = 1e-8, max_iter: int = 20000):
        """One tangential step to the TOTAL force ``Q`` (N, (Qx, Qy)) or shift (m)."""
        kw = {"tol_tangential": float(tol), "max_iter": int(max_iter)}
        if (Q is None) == (shift is None):
            raise ValueError("give exactly one of Q and shift")
        if Q is not None:
            kw["q_bar"] = (float(Q[0]) / self.L**2, float(Q[1]) / self.L**2)
        else:
            kw["delta_t"] = (float(shift[0]), float(shift[1]))
        t0 = time.perf_counter()
        r = self.solver.step(**kw)
        wall = time.perf_counter() - t0
        n = self.n
        traction = np.stack([np.asarray(r.qx, dtype=float).reshape(n, n),
                             np.asarray(r.qy, dtype=float).reshape(n, n)])
        shift_out = None if r.delta_t is None else np.asarray(r.delta_t, dtype=float)
        return traction, shift_out, {
            "time": wall,
            "iterations": int(r.tangential_iters),
            "converged": bool(r.converged),
            "status": str(r.status_reason),
            "peer_error": float(r.proj_residual),
            "kkt_tol": float(r.kkt_tol),
            "n_stick": int(r.n_stick),
            "n_slip": int(r.n_slip),
            "settings": {"tol_tangential": float(tol), "max_iter": int(max_iter)},
        }
