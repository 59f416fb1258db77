"""The network solver's measures of a state (:mod:`thirdbody.network.cluster`): the scaled
residuals and the convergence test, the merit the trust region minimises, the first phase's
force test, the stall test, the trust region's limit on a step, the open contacts' springs in
the Newton model and the models' learning from a trial (Broyden's update of a particle's
block), each on a state made up here with its answer worked out by hand from the documented
definitions (a force over the force scale, a moment over the force scale times the particle's
size, the plate's force error over F_N). Numbers are chosen so that each term is the largest
in turn and no two quantities the code could confuse (a size and its inverse, the force scale
and F_N) are equal."""

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from thirdbody.network import cluster

SIZES = np.array([1e-3, 4e-3])                  # the particles' sizes, m


def problem(force=None):
    return NS(n=2, sizes=SIZES, force=force)


def state(forces, moments, plate_normal=0.0, scale=2.0):
    return NS(forces=np.array(forces, dtype=float), moments=np.array(moments, dtype=float),
              plate_normal=plate_normal, scale=scale)


@pytest.mark.parametrize(("forces", "moments", "plate", "force", "worst"), [
    # a force: |F| / scale = 0.5 / 2
    ([[0.0, 0.5, 0.0], [0.1, 0.0, 0.0]], [[0.0] * 3, [0.0] * 3], 0.0, None, 0.25),
    # a negative force component counts by its size
    ([[0.0, 0.0, -0.75], [0.1, 0.0, 0.0]], [[0.0] * 3, [0.0] * 3], 0.0, None, 0.375),
    # the second particle's moment over its own size: 2e-3 N m / (4e-3 m 2 N)
    ([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], [[1e-4, 0.0, 0.0], [0.0, 0.0, -2e-3]], 0.0, None,
     0.25),
    # the first particle's: 4e-4 / (1e-3 2)
    ([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], [[0.0, -4e-4, 0.0], [0.0, 0.0, 1e-4]], 0.0, None,
     0.2),
    # under force control the plate's error over F_N = 3 N (not over the scale, 2 N)
    ([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], [[0.0] * 3, [0.0] * 3], 1.5, 3.0, 0.5),
    ([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], [[0.0] * 3, [0.0] * 3], 4.5, 3.0, 0.5),
    # a plate error below the particles' residuals
    ([[0.9, 0.0, 0.0], [0.0, 0.1, 0.0]], [[0.0] * 3, [0.0] * 3], 2.9, 3.0, 0.45),
])
def test_the_convergence_test_is_the_largest_scaled_residual(forces, moments, plate, force,
                                                             worst):
    ev = state(forces, moments, plate)
    done, value = cluster._converged(problem(force), ev, tol=worst)
    assert value == pytest.approx(worst, rel=1e-14)
    assert done                                 # at the tolerance: converged
    done, value = cluster._converged(problem(force), ev, tol=0.99 * worst)
    assert not done


def test_nothing_touching_is_converged_under_gap_control_only():
    ev = state([[0.0] * 3] * 2, [[0.0] * 3] * 2, 0.0, scale=0.0)
    assert cluster._converged(problem(), ev, tol=0.0) == (True, 0.0)     # at any tolerance
    done, worst = cluster._converged(problem(3.0), ev, tol=1e-6)
    assert not done and worst == np.inf


def test_the_merit_is_half_the_sum_of_the_squared_scaled_residuals():
    """Scale 2 N, F_N = 3 N: forces (0.2, −0.4, 0) and (0, 0, 0.6) N, moments 1e-3 N m on the
    1 mm particle and 4e-3 N m on the 4 mm one, the plate 0.8 N off:
    ½ [(0.1² + 0.2²) + 0.3² + 0.5² + 0.5² + 0.4²]; the first phase's (``translate``) without the
    moments."""
    R = np.array([[0.2, -0.4, 0.0, 1e-3, 0.0, 0.0], [0.0, 0.0, 0.6, 0.0, -4e-3, 0.0]])
    plate = 0.8
    moments = 0.5**2 + 0.5**2
    rest = 0.1**2 + 0.2**2 + 0.3**2 + 0.4**2
    assert cluster._merit(problem(3.0), R, plate, 2.0) == pytest.approx(
        0.5 * (rest + moments), rel=1e-14)
    assert cluster._merit(problem(3.0), R, plate, 2.0, translate=True) == pytest.approx(
        0.5 * rest, rel=1e-14)


@pytest.mark.parametrize(("plate_normal", "expected"), [(3.5, 0.3), (4.0, 0.5), (2.6, 0.3)])
def test_the_first_phase_measures_forces_and_the_plate_over_the_scale(plate_normal, expected):
    """The first phase's test: the largest of |F| over the scale (2 N) and the plate's error
    over the same scale, moments left out (the second particle's would be 2.5 over its size)."""
    ev = state([[0.2, -0.6, 0.0], [0.0, 0.1, 0.0]], [[0.0] * 3, [0.02, 0.0, 0.02]],
               plate_normal)
    assert cluster._force_residual(problem(3.0), ev, 2.0) == pytest.approx(expected, rel=1e-14)
    # under gap control the plate has no force to meet: the forces alone
    assert cluster._force_residual(problem(), ev, 2.0) == pytest.approx(0.3, rel=1e-14)


def test_an_attempt_stalls_when_its_last_passes_do_not_halve_the_best_before():
    window = cluster._STALL
    assert not cluster._stalled([(1.0,)] * window)        # too few passes to tell
    before = [(6.0,), (2.0,), (4.0,)]                     # best 2: half of it is 1
    assert cluster._stalled(before + [(1.2,)] * window)
    assert not cluster._stalled(before + [(1.2,)] * (window - 1) + [(1.0,)])
    assert not cluster._stalled(before + [(0.8,)] + [(1.2,)] * (window - 1))
    # only the best before the window counts, not the first
    assert not cluster._stalled([(2.0,), (2.0,), (6.0,)] + [(0.99,)] * window)


def terms(d, *, bem, kn, sigma, N, plate=(0.0, 0.0)):
    """Made-up terms whose approach changes by ``d`` under any step, and by ``plate`` times
    the plate's move dh (a contact with the upper plate: −1)."""
    d, plate = np.asarray(d, dtype=float), np.asarray(plate, dtype=float)
    return NS(approach_change=lambda step, dh: (d + plate * dh, None), bem=np.asarray(bem),
              kn=np.asarray(kn, dtype=float), sigma=np.asarray(sigma, dtype=float),
              N=np.asarray(N, dtype=float))


def test_the_trust_region_scales_the_whole_step_by_its_tightest_limit():
    """At radius ρ: a rotation up to 0.05 ρ rad, a translation up to 0.05 ρ sizes, a contact's
    normal force change up to ρ max(N, scale) (a solved contact: k_n |dδ|; an open one only
    past its separation: k_n (dδ − σ))."""
    rho = 0.5
    step = np.zeros((2, 6))
    step[0, 3:] = [0.03, 0.0, -0.04]                # |φ| = 0.05 rad: factor 0.025 / 0.05
    step[1, :3] = [0.0, 3e-5, 4e-5]                 # 5e-5 m = 0.0125 sizes of 4 mm: none
    dh = 2e-6
    quiet = terms([1e-7, 0.0], bem=[True, False], kn=[1e6, 1e6], sigma=[0.0, 1e-6],
                  N=[1.0, 0.0])
    out, out_dh, clipped = cluster._limit(problem(), quiet, np.array([True, True]), 2.0, step,
                                          dh, rho)
    assert clipped
    np.testing.assert_allclose(out, 0.5 * step, rtol=1e-14)
    assert out_dh == pytest.approx(0.5 * dh, rel=1e-14)
    # twice that turn, |φ| = 0.1 rad: factor 0.025 / 0.1 (the bound over the turn, not times it)
    out, out_dh, clipped = cluster._limit(problem(), quiet, np.array([True, True]), 2.0,
                                          2 * step, dh, rho)
    assert clipped
    np.testing.assert_allclose(out, 0.5 * step, rtol=1e-14)
    assert out_dh == pytest.approx(0.25 * dh, rel=1e-14)
    # the translation over the second particle's size: 2e-4 m = 0.05 sizes, factor 0.025/0.05
    moved = step.copy()
    moved[0, 3:] = 0.0
    moved[1, :3] = [0.0, 0.0, 2e-4]
    out, _, clipped = cluster._limit(problem(), quiet, np.array([True, True]), 2.0, moved,
                                     dh, rho)
    assert clipped
    np.testing.assert_allclose(out, 0.5 * moved, rtol=1e-14)
    # within every limit: unchanged
    small = 0.1 * moved
    out, out_dh, clipped = cluster._limit(problem(), quiet, np.array([True, True]), 2.0, small,
                                          dh, rho)
    assert not clipped and out is small and out_dh == dh
    # a solved contact: k_n |dδ| = 4 N against ρ max(N, scale) = 0.5 * 5 N = 2.5: factor 0.625
    loaded = terms([-4e-6, 0.0], bem=[True, False], kn=[1e6, 1e6], sigma=[0.0, 1e-6],
                   N=[5.0, 0.0])
    out, _, clipped = cluster._limit(problem(), loaded, np.array([True, True]), 2.0, small,
                                     dh, rho)
    assert clipped
    np.testing.assert_allclose(out, 0.625 * small, rtol=1e-14)
    # ... or the scale when N is below it: 0.5 * 2 N = 1 N of 4 N: 0.25
    light = terms([4e-6, 0.0], bem=[True, False], kn=[1e6, 1e6], sigma=[0.0, 1e-6],
                  N=[0.5, 0.0])
    out, _, _ = cluster._limit(problem(), light, np.array([True, True]), 2.0, small, dh, rho)
    np.testing.assert_allclose(out, 0.25 * small, rtol=1e-14)
    # an inactive contact does not limit
    out, _, clipped = cluster._limit(problem(), light, np.array([False, True]), 2.0, small,
                                     dh, rho)
    assert not clipped
    # an open contact: only the closing beyond its separation, k_n (3e-6 − 1e-6) = 2 N: 0.5
    closing = terms([0.0, 3e-6], bem=[True, False], kn=[1e6, 1e6], sigma=[0.0, 1e-6],
                    N=[0.0, 0.0])
    out, _, _ = cluster._limit(problem(), closing, np.array([True, True]), 2.0, small, dh, rho)
    np.testing.assert_allclose(out, 0.5 * small, rtol=1e-14)
    opening = terms([0.0, -3e-6], bem=[True, False], kn=[1e6, 1e6], sigma=[0.0, 1e-6],
                    N=[0.0, 0.0])
    assert not cluster._limit(problem(), opening, np.array([True, True]), 2.0, small, dh,
                              rho)[2]
    # the plate's move counts: coming down 4 µm onto a solved upper contact, k_n 4 µm = 4 N
    # against ρ max(N, scale) = 1 N: 0.25 of the step and of dh
    upper = terms([0.0, 0.0], bem=[True, False], kn=[1e6, 1e6], sigma=[0.0, 1e-6],
                  N=[0.5, 0.0], plate=[-1.0, 0.0])
    out, out_dh, clipped = cluster._limit(problem(), upper, np.array([True, True]), 2.0, small,
                                          -4e-6, rho)
    assert clipped and out_dh == pytest.approx(-1e-6, rel=1e-14)
    np.testing.assert_allclose(out, 0.25 * small, rtol=1e-14)


def test_the_first_gap_under_force_control_is_hertz_at_both_plates():
    """One sphere (R = 1 mm, E* = E/(1 − ν²)) whose top is below the plate: F_N through two
    Hertz contacts with rigid plates in series, F = (4/3) E* √R δ^(3/2) at each, so the first
    gap is the top less 2δ. Two equal spheres of the same top share F_N: δ at F_N/2. A plate
    already pressing on the top is kept."""
    import thirdbody as tb
    from thirdbody.network import Body
    from thirdbody.shapes import Sphere

    R, F = 1e-3, 2.5
    mat = tb.Material(2e9, 0.25)
    e_star = 2e9 / (1 - 0.25**2)

    def delta(force):
        return (force / (4 / 3 * e_star * math.sqrt(R))) ** (2 / 3)

    one = NS(start=[Body(Sphere(R), mat, centre=(0.0, 0.0, 1.5 * R))], force=F)
    top = 2.5 * R
    assert cluster._first_gap(one, 3 * R) == pytest.approx(top - 2 * delta(F), rel=1e-9)
    assert cluster._first_gap(one, 2.4 * R) == 2.4 * R
    two = NS(start=[Body(Sphere(R), mat, centre=(x, 0.0, 1.5 * R)) for x in (0.0, 3 * R)],
             force=F)
    assert cluster._first_gap(two, 3 * R) == pytest.approx(top - 2 * delta(F / 2), rel=1e-9)


def test_the_reach_of_a_step_is_its_furthest_move_in_trust_radii():
    """At radius 1 a particle may turn by 0.05 rad and move by 0.05 of its size: a turn of
    0.02 rad is 0.4, a move of 4e-4 m of the 4 mm particle 2.0, of the 1 mm one 8."""
    step = np.zeros((2, 6))
    step[0, 3:] = [0.0, 0.012, 0.016]                # |φ| = 0.02 rad
    step[1, :3] = [0.0, 4e-4, 0.0]
    assert cluster._reach(step, SIZES) == pytest.approx(2.0, rel=1e-14)
    assert cluster._reach(step[:1], SIZES[:1]) == pytest.approx(0.4, rel=1e-14)
    assert cluster._reach(step[::-1], SIZES) == pytest.approx(8.0, rel=1e-14)
    assert cluster._reach(np.zeros((0, 6)), SIZES[:0]) == 0.0


def soft_pair(seed=11):
    """A two-particle Newton matrix (scaled units) whose second particle has a soft turning
    mode (a singular value of 1e-4 of the stiffest), and a right-hand side."""
    rng = np.random.default_rng(seed)
    U = np.linalg.qr(rng.normal(size=(12, 12)))[0]
    s = np.linspace(2.0, 1.0, 12)
    J = U @ np.diag(s) @ U.T
    soft = np.zeros(12)
    soft[9] = 1.0                                     # the second particle's φ_x
    J = J - (J @ soft)[:, None] * soft[None, :] - soft[:, None] * (soft @ J)[None, :] \
        + (soft @ J @ soft) * np.outer(soft, soft)    # decoupled ...
    J += (1e-4 - J[9, 9]) * np.outer(soft, soft)      # ... and soft
    b = rng.normal(size=12) * 1e-6                    # N (forces, moments over sizes)
    col_scale = np.hstack([np.ones((2, 3)), np.repeat(1.0 / SIZES[:, None], 3, 1)])
    return J, b, col_scale


def test_the_damped_step_solves_the_shifted_normal_equations_at_the_trust_radius():
    """The Levenberg-Marquardt step x̂ of a group whose Newton step reaches past the radius
    solves (JᵀJ + λI) x̂ = Jᵀb for some λ > 0 (λ recovered here from x̂ itself) and reaches the
    radius; the stiff particle keeps nearly its Newton step, where the common factor would
    scale it by the soft particle's reach. Within the radius it is the Newton step."""
    J, b, col_scale = soft_pair()
    newton = np.linalg.solve(J, b)
    newton_step = newton.reshape(2, 6) * col_scale
    reach = cluster._reach(newton_step, SIZES)
    radius = 1e-3 * reach
    assert reach > 100 * radius                       # the soft particle's turn is huge
    x = cluster._damped(J, b, np.arange(12), col_scale, SIZES, radius)
    assert x.shape == (2, 6)
    assert cluster._reach(x, SIZES) == pytest.approx(radius, rel=1e-6)
    xs = (x / col_scale).ravel()                      # back to scaled unknowns
    g = J.T @ b - J.T @ J @ xs
    lam = float(g @ xs) / float(xs @ xs)
    assert lam > 0
    np.testing.assert_allclose(J.T @ J @ xs + lam * xs, J.T @ b, rtol=0,
                               atol=1e-9 * np.abs(J.T @ b).max())
    # the stiff particle: within a few per cent of its Newton step (the common factor would
    # have left it 1e-3 of it)
    np.testing.assert_allclose(x[0], newton_step[0], rtol=0,
                               atol=0.05 * np.abs(newton_step[0]).max())
    # a radius the Newton step is within: the Newton step itself
    wide = cluster._damped(J, b, np.arange(12), col_scale, SIZES, 2.0 * reach)
    np.testing.assert_allclose(wide, newton_step, rtol=1e-10, atol=0)
    # the rotation-free phase: only the translations are unknowns (keep), rotations stay 0
    keep = np.array([0, 1, 2, 6, 7, 8])
    part = cluster._damped(J[np.ix_(keep, keep)], b[keep], keep, col_scale, SIZES, radius)
    assert not part[:, 3:].any()
    np.testing.assert_allclose(part[:, :3].ravel(),
                               np.linalg.solve(J[np.ix_(keep, keep)], b[keep]), rtol=1e-10)


def model_of(blocks, n):
    """A linear model (:class:`cluster._Model`) of 6 x 6 blocks {(row, col): block}, no plate."""
    keys = list(blocks)
    return cluster._Model(rows=np.array([k[0] for k in keys]), cols=np.array([k[1] for k in keys]),
                          blocks=np.array([blocks[k] for k in keys]), constant=np.zeros((n, 6)),
                          h_col=np.zeros((n, 6)), h_row=np.zeros((n, 6)), h_diag=0.0,
                          plate_constant=0.0)


def test_only_groups_of_touching_particles_take_the_damped_step():
    """Particles 0 and 1 linked by a contact (an off-diagonal block) and a lone particle 2, each
    with a soft turning mode whose Newton step reaches far past the radius: the pair takes the
    damped step of the radius (and is reported), the lone particle keeps its Newton step (the
    trust region's common factor limits it later); without a radius nothing is damped."""
    J, b, col_scale = soft_pair()
    sizes = np.array([1e-3, 4e-3, 1e-3])
    scale = np.hstack([np.ones((3, 3)), np.repeat(1.0 / sizes[:, None], 3, 1)])
    # unscale the scaled matrix: blocks in N per m (forces) and N m per rad (moments)
    physical = J / np.outer(np.hstack([scale[0], scale[1]]), np.hstack([scale[0], scale[1]]))
    lone = physical[6:, 6:] * np.outer(scale[1], scale[1]) / np.outer(scale[2], scale[2])
    blocks = {(0, 0): physical[:6, :6], (0, 1): physical[:6, 6:], (1, 0): physical[6:, :6],
              (1, 1): physical[6:, 6:], (2, 2): lone}
    R = -np.vstack([b.reshape(2, 6), b[6:]]) / scale
    problem = NS(n=3, sizes=sizes, force=None)
    free, _ = cluster._solve_model(problem, model_of(blocks, 3), R, 0.0)
    reach = cluster._reach(free[:2], sizes[:2])
    radius = 1e-3 * reach
    assert cluster._reach(free[2:], sizes[2:]) > 100 * radius
    damped = []
    step, dh = cluster._solve_model(problem, model_of(blocks, 3), R, 0.0, radius=radius,
                                    damped=damped)
    assert dh == 0.0 and damped == [[0, 1]]
    assert cluster._reach(step[:2], sizes[:2]) == pytest.approx(radius, rel=1e-6)
    np.testing.assert_allclose(step[:2], cluster._damped(J, b, np.arange(12), col_scale,
                                                         sizes[:2], radius), rtol=1e-9)
    np.testing.assert_array_equal(step[2], free[2])
    # the model's own solve: the Newton step of each group (the pair's from numpy)
    np.testing.assert_allclose(free[:2], np.linalg.solve(J, b).reshape(2, 6) * col_scale,
                               rtol=1e-9)


def no_descent(monkeypatch, entered_branches: bool):
    """A one-particle model whose merit rises along every nonzero step (a kink at the start):
    ``_piecewise`` and the solves are stand-ins that record what the active-set passes ask.
    With ``entered_branches`` any nonzero step changes the state of the particle's only
    contact from that of the last solve's model (open after the first solve, closed after the
    second, ...): branches other than those the step was solved on."""
    calls = []
    trial = np.full((1, 6), 1e-6)
    laws = NS(slide=np.array([False]), g=np.zeros((1, 3)))

    def piecewise(problem, terms, R, plate, step, dh):
        moved = bool(step.any())
        out = R * (1.0 + 1e6 * float(np.abs(step).sum()))
        closed = not (moved and entered_branches and len(calls) % 2 == 1)
        active = np.array([closed])
        return out, 0.0, ("model at", moved, closed), active, laws

    def solve_model(problem, model, R, plate, translate=False, radius=None, damped=None):
        calls.append(model)
        return trial * len(calls), 0.0

    monkeypatch.setattr(cluster, "_piecewise", piecewise)
    monkeypatch.setattr(cluster, "_solve_model", solve_model)
    monkeypatch.setattr(cluster, "_model", lambda *args: "start model")
    monkeypatch.setattr(cluster, "_STICK_FIRST", False)
    problem = NS(n=1, sizes=SIZES[:1], force=None, correction=None)
    terms = NS(bem=np.array([True]), sigma=np.array([0.0]), reach=np.array([1.0]),
               a=np.array([0]), b=np.array([-1]), pair=np.array([False]),
               upper=np.array([False]), models=NS(sliding=np.array([False])))
    R = np.array([[0.1, 0.0, 0.0, 0.0, 0.0, 0.0]])
    step, dh, model, _ = cluster._newton_step(problem, terms, R, 0.0, 1.0)
    assert dh == 0.0                                  # gap control: the plate stays
    return calls, trial, step, model


@pytest.mark.parametrize("switch", [True, False])
def test_a_step_the_model_sees_no_descent_along_is_left_to_the_bem(monkeypatch, switch):
    """No fraction of the Newton step lowers the model's merit: with the switch the passes
    return that step (the BEM and the trust region judge it), without it a zero step (the
    attempt then ends: "no way down")."""
    monkeypatch.setattr(cluster, "_NO_DESCENT_TRIAL", switch)
    monkeypatch.setattr(cluster, "_ENTERED_BRANCHES", 0)
    calls, trial, step, model = no_descent(monkeypatch, entered_branches=False)
    assert calls == ["start model"]                   # one solve: nothing else to try
    if switch:
        np.testing.assert_array_equal(step, trial)
        assert model == ("model at", True, True)      # the model at the returned step
    else:
        assert not step.any()


@pytest.mark.parametrize("entered", [0, 1, 2])
def test_branches_entered_at_the_start_get_their_own_newton_step(monkeypatch, entered):
    """A step whose every fraction changes a contact's state from the one it was solved on:
    the passes solve the model on the entered branches again, at most ``_ENTERED_BRANCHES``
    times, while the step is still zero."""
    monkeypatch.setattr(cluster, "_NO_DESCENT_TRIAL", False)
    monkeypatch.setattr(cluster, "_ENTERED_BRANCHES", entered)
    calls, _, step, _ = no_descent(monkeypatch, entered_branches=True)
    # each re-solve on the branches the smallest fraction entered: open, closed, open, ...
    assert calls == ["start model"] + [("model at", True, k % 2 == 1) for k in range(entered)]
    assert not step.any()


def test_the_damped_step_leaves_modes_without_stiffness_alone():
    """Edge cases of the damped step: a mode below 1e-7 of the stiffest takes no step (as in
    the undamped solve), a matrix of zeros gives no step, and a radius below what even the
    largest shift reaches gives that shift's step: next to nothing, along Jᵀb (steepest
    descent)."""
    J, b, col_scale = soft_pair()
    U, s, Vt = np.linalg.svd(J)
    s[-1] = 0.4 * cluster._RCOND * s[0]               # below the cut: no step along it
    weak = U @ np.diag(s) @ Vt
    expected = Vt[:-1].T @ ((U[:, :-1].T @ b) / s[:-1])
    wide = cluster._damped(weak, b, np.arange(12), col_scale, SIZES, 1e30)
    np.testing.assert_allclose((wide / col_scale).ravel(), expected, rtol=1e-9,
                               atol=1e-12 * np.abs(expected).max())
    assert not cluster._damped(np.zeros((12, 12)), b, np.arange(12), col_scale, SIZES,
                               1e-3).any()
    tiny = cluster._damped(J, b, np.arange(12), col_scale, SIZES, 1e-300)
    scaled = (tiny / col_scale).ravel()
    gradient = J.T @ b
    assert 0 < np.linalg.norm(scaled) < 1e-6 * np.linalg.norm(np.linalg.solve(J, b))
    assert scaled @ gradient == pytest.approx(np.linalg.norm(scaled) * np.linalg.norm(gradient),
                                              rel=1e-6)


#: an open contact's point (m) and the centres of its bodies a and b (m): off the line of the
#: centres, so that its force has a moment about each
POINT, CENTRE_A, CENTRE_B = (np.array([2e-4, -1e-4, 0.0]), np.array([0.0, 0.0, -1e-3]),
                             np.array([-3e-4, 0.0, 1e-3]))


def open_contact(roles, sigma, mu, radius=2e-3, E_star=3e9, compliance=4e-9):
    """An open contact of the Newton model (normal +z at POINT, between CENTRE_A and
    CENTRE_B)."""
    return cluster._Potential(roles, sigma, np.array([0.0, 0.0, 1.0]), POINT, CENTRE_A,
                              CENTRE_B, E_star, radius, compliance, mu)


@pytest.mark.parametrize(("scale", "force", "used"), [(0.5, 5.0, 0.5), (0.0, 5.0, 5.0)])
def test_an_open_contact_is_a_spring_of_hertz_stiffness_at_the_force_scale(scale, force, used):
    """Each open contact enters the model as a spring with Hertz's tangent stiffness at the
    force scale N (the mean contact force, or F_N when nothing touches yet): δ = (9 N² /
    (16 E*² R))^(1/3), k = 3N/(2δ), and Mindlin's k₀ = 8 √(Rδ)/C (C the pair's compliance
    Σ (2 − ν)/G) with friction, none without; its separation σ and Hertz approach (``reach``)
    are kept, its force on a is −N n with N = −k σ (the spring must first close by σ), on b
    the opposite, and a plate is particle −1, flagged when it is the upper one. Numbers chosen
    so that no factor of the formulas cancels (a force scale below 1 N, E* of 3 GPa)."""
    R, E, C = 2e-3, 3e9, 4e-9                     # radius m, E* Pa, compliance 1/Pa
    potential = [open_contact((0, "upper"), 3e-7, 0.4, R, E, C),
                 open_contact((1, 2), 5e-7, 0.0, R, E, C)]
    ev = NS(scale=scale, contacts=[], potential=potential)
    terms = cluster._terms(NS(force=force), ev)
    delta = (9 * used**2 / (16 * E**2 * R)) ** (1 / 3)
    k = 1.5 * used / delta
    assert terms.a.tolist() == [0, 1] and terms.b.tolist() == [-1, 2]
    assert terms.upper.tolist() == [True, False]
    assert not terms.bem.any()
    assert terms.kn == pytest.approx([k, k], rel=1e-13)
    assert terms.reach == pytest.approx([delta, delta], rel=1e-13)
    assert terms.sigma.tolist() == [3e-7, 5e-7]
    assert terms.N.tolist() == [0.0, 0.0]
    assert terms.models.k_stick == pytest.approx([8 * math.sqrt(R * delta) / C, 0.0],
                                                 rel=1e-13)
    expected = np.array([[0.0, 0.0, k * 3e-7], [0.0, 0.0, k * 5e-7]])
    assert terms.wrench_a[:, :3] == pytest.approx(expected, rel=1e-13)
    assert terms.wrench_b[:, :3] == pytest.approx(-expected, rel=1e-13)
    # moments about each body's centre: (point − centre) × force, by hand for f = (0, 0, f_z)
    for row, fz in zip((0, 1), expected[:, 2], strict=True):
        for wrench, centre, sign in ((terms.wrench_a, CENTRE_A, 1.0),
                                     (terms.wrench_b, CENTRE_B, -1.0)):
            arm = POINT - centre
            by_hand = sign * np.array([arm[1] * fz, -arm[0] * fz, 0.0])
            assert wrench[row, 3:] == pytest.approx(by_hand, rel=1e-13, abs=1e-30)


def test_without_a_force_scale_no_open_contact_enters_the_model():
    """Under gap control with nothing touching there is no force scale: the open contacts are
    left out (nothing to size their springs by)."""
    ev = NS(scale=0.0, contacts=[], potential=[open_contact((0, "lower"), 1e-7, 0.3)])
    assert len(cluster._terms(NS(force=None), ev)) == 0


class _Stack(NS):
    """Made-up model terms: the solved contacts' particles and which are solved."""

    def __len__(self) -> int:
        return len(self.a)


def learning_case(*, slide=(False, False, False), after=None, rows=(True, True)):
    """Two particles (sizes 1 and 4 mm): particle 0 on the lower plate, 1 under the upper one,
    and a pair contact (0, 1) solved with 1 as a and 0 as b; a trial step whose residuals the
    model mispredicted. Returns the arguments of ``_learn`` and its problem."""
    keys = [(0, "lower"), (1, "upper"), (0, 1, (0, 0))]
    contacts = [NS(key=k, model=NS(sliding=False)) for k in keys]
    trial = [NS(key=k, model=NS(sliding=False)) for k in (keys if after is None else after)]
    problem = NS(n=2, sizes=SIZES, correction={})
    # the pair's roles (1, 0): particle 0 is its b
    terms = _Stack(a=np.array([0, 1, 1]), b=np.array([-1, -1, 0]),
                   bem=np.array([True, True, True]))
    R = np.array([[0.1, 0.2, -0.3, 1e-4, 2e-4, 0.0], [0.0, -0.5, 0.4, 0.0, 3e-3, -1e-3]])
    predicted = np.array([[0.05, 0.1, -0.1, 0.0, 1e-4, 0.0], [0.0, -0.2, 0.1, 0.0, 1e-3, 0.0]])
    R_trial = np.array([[0.3, -0.1, 0.2, 2e-4, -1e-4, 5e-5], [0.2, 0.1, -0.3, 1e-3, 0.0, 2e-3]])
    step = np.array([[1e-6, -2e-6, 0.5e-6, 1e-3, 0.0, -2e-3],
                     [-3e-6, 1e-6, 2e-6, 0.0, 4e-4, 1e-4]])
    args = (problem, NS(contacts=contacts), NS(contacts=trial), terms,
            np.array([True, True, True]), NS(slide=np.array(slide)), R, R_trial, predicted,
            step, np.array(rows))
    return problem, args


def broyden(k, R_trial, predicted, step):
    """Broyden's good update of particle k's block in the scaled unknowns (du, L dφ), by hand:
    (mismatch) (W s)ᵀ / (s · W s) with W = diag(1, 1, 1, L², L², L²)."""
    W = np.array([1.0, 1.0, 1.0] + [SIZES[k] ** 2] * 3)
    mismatch = R_trial[k] - predicted[k]
    return np.outer(mismatch, W * step[k]) / float(step[k] @ (W * step[k]))


def test_a_trial_the_model_mispredicted_corrects_each_particle_s_block_by_broyden():
    """Both particles' predictions missed (by more than _BAD_MODEL of the change): each gets
    Broyden's update of its own 6 x 6 block, and a second trial adds to it. (The learning
    attempt's converged answers do not pin the update: only these definitions do.)"""
    problem, args = learning_case()
    R_trial, predicted, step = args[7], args[8], args[9]
    assert cluster._learn(*args)
    assert set(problem.correction) == {(0, 0), (1, 1)}
    for k in (0, 1):
        assert problem.correction[(k, k)] == pytest.approx(
            broyden(k, R_trial, predicted, step), rel=1e-12)
    assert cluster._learn(*args)
    assert problem.correction[(1, 1)] == pytest.approx(
        2 * broyden(1, R_trial, predicted, step), rel=1e-12)


@pytest.mark.parametrize(("case", "learns"), [
    # particle 1 converged: only 0 learns
    ({"rows": (True, False)}, {0}),
    # the pair contact slid in the trial, the model had it stick: neither of its particles
    ({"slide": (False, False, True)}, set()),
    # the lower contact is predicted to slide and it did not: particle 0 does not learn
    ({"slide": (True, False, False)}, {1}),
    # the trial lost the upper contact: particle 1's set changed
    ({"after": [(0, "lower"), (0, 1, (0, 0))]}, {0}),
])
def test_a_particle_learns_only_from_a_trial_that_kept_its_contacts_and_their_states(case,
                                                                                     learns):
    problem, args = learning_case(**case)
    assert cluster._learn(*args) == bool(learns)
    assert {k for k, _ in problem.correction} == learns


def test_a_changed_contact_set_drops_the_particle_s_correction():
    """A correction learnt before is dropped when the particle's contacts change."""
    problem, args = learning_case(after=[(0, "lower"), (0, 1, (0, 0))])
    problem.correction[(1, 1)] = np.ones((6, 6))
    problem.correction[(0, 0)] = np.ones((6, 6))
    cluster._learn(*args)
    assert (1, 1) not in problem.correction
    assert (problem.correction[(0, 0)] != 1.0).any()        # kept, and updated


@pytest.mark.parametrize(("miss", "learns"), [(0.0, set()), (0.99, set()), (1.01, {1})])
def test_a_particle_whose_change_the_model_predicted_well_learns_nothing(miss, learns):
    """Particle 0 predicted exactly; particle 1 missed by ``miss`` times _BAD_MODEL of its
    change (scaled: forces, moments over the size): below 1, nothing to learn."""
    problem, args = learning_case()
    R, R_trial, predicted = args[6], args[7], args[8].copy()
    predicted[0] = R_trial[0]
    predicted[1] = R_trial[1] - miss * cluster._BAD_MODEL * (R_trial[1] - R[1])
    assert cluster._learn(*args[:8], predicted, *args[9:]) == bool(learns)
    assert {k for k, _ in problem.correction} == learns


@pytest.mark.parametrize(("still", "learns"), [(0, {1}), (1, {0})])
def test_a_particle_that_did_not_move_learns_nothing_and_the_others_still_do(still, learns):
    """A particle whose step is zero has no direction to learn along (s · W s = 0); the
    other particle's update goes on."""
    problem, args = learning_case()
    step = args[9].copy()
    step[still] = 0.0
    assert cluster._learn(*args[:9], step, *args[10:])
    assert {k for k, _ in problem.correction} == learns


def test_the_learning_threshold_weighs_moments_by_the_particle_s_size():
    """The comparison of the miss with the change is in the scaled residuals (forces, moments
    over the size): particle 1 (4 mm) missed only its moment about x, by 1.5 times the
    threshold in the scaled norm, which the unscaled norm (moments in N m, 250 times smaller
    here) would see as far below it."""
    problem, args = learning_case()
    R, R_trial, predicted = args[6], args[7], args[8].copy()
    predicted[0] = R_trial[0]
    scaled = np.array([1.0, 1.0, 1.0] + [1 / SIZES[1]] * 3)
    threshold = cluster._BAD_MODEL * np.linalg.norm(scaled * (R_trial[1] - R[1]))
    miss = np.zeros(6)
    miss[3] = 1.5 * threshold * SIZES[1]             # a moment, N m
    predicted[1] = R_trial[1] - miss
    assert np.linalg.norm(miss) < cluster._BAD_MODEL * np.linalg.norm(R_trial[1] - R[1])
    assert cluster._learn(*args[:8], predicted, *args[9:])
    assert set(problem.correction) == {(1, 1)}
