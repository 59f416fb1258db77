"""Cut steps of network runs (:meth:`thirdbody.network.run.NetworkEngine.step`): a load step
after the first that does not converge is solved again as two halves, down to 1/2^cutbacks.

The failures are planted (the cluster solver raises at a chosen call), and the cut run is
checked against a run whose program lists the same sub-steps explicitly: the cut step's end
must be that run's end bit for bit (the same solves from the same states with the same
predictions), its motion, slips, passes and energy terms the sums over those steps, computed
here from the explicit run's records. The particle is the flat ellipsoid of test_sliding.py
(semi-axes 1 x 0.8 x 0.2 mm lying flat, μ_up 0.6, μ_low 0.3, 1 N): in its second sliding
step it tilts while its lower contact slides, so the cut step turns, slips and dissipates.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

import thirdbody as tb
from thirdbody.io import ConfigError, parse_config
from thirdbody.loading import LoadProgram, LoadStep
from thirdbody.network import run as network_run
from thirdbody.network.cluster import ClusterConvergenceError
from thirdbody.shapes import Ellipsoid

MAT = tb.Material(1e9, 0.3)
F = 1.0                                 # N
S = 5e-6                                # sliding increment, m
FLAT = tb.Particle(Ellipsoid((1e-3, 0.8e-3, 0.2e-3)), MAT)
SOLVE = network_run.solve_cluster       # the cluster solver, before any planted failure


@dataclasses.dataclass(frozen=True)
class Steps(LoadProgram):
    """An explicit schedule: (force in N, or compression, and the shift along x in m) per
    step."""

    steps: tuple
    kind: str = "force"

    def schedule(self) -> list[LoadStep]:
        return [LoadStep(self.kind, f, (s, 0.0)) for f, s in self.steps]


def _run(monkeypatch, steps, failing=(), cutbacks=3, kind="force", particle=FLAT):
    """Run ``particle`` (the flat ellipsoid, or a layer) through ``steps`` of ``kind``; the
    cluster solver's calls numbered in ``failing`` (from 1) raise. Returns (simulation,
    dataset, number of calls)."""
    calls = []

    def planted(*args, **kwargs):
        calls.append(1)
        if len(calls) in failing:
            raise ClusterConvergenceError("cluster equilibrium stalled (planted)")
        return SOLVE(*args, **kwargs)

    monkeypatch.setattr(network_run, "solve_cluster", planted)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = tb.Simulation(particle, tb.Plates(0.6, 0.3), Steps(tuple(steps), kind),
                            mu_pp=0.3, resolution=20, network_tol=1e-6, maps_every=0,
                            network_cutbacks=cutbacks)
        ds = sim.run()
    return sim, ds, len(calls)


def _rows(ds, k):
    """The contact rows of step k, by (i, j)."""
    at = np.flatnonzero(ds.contact_step.values == k)
    return {(int(ds.contact_i.values[r]), int(ds.contact_j.values[r])): r for r in at}


def _matrix(rotvec) -> np.ndarray:
    """Rodrigues' rotation matrix of a rotation vector (rad)."""
    r = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(r))
    if angle == 0:
        return np.eye(3)
    a = r / angle
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


#: the flat ellipsoid alone in a periodic box of 3 x 3 mm, 3 µm from its +x side: it crosses
#: the side while it slides (the run wraps it back after every (sub-)step)
BOX = 3e-3
EDGE = tb.Layer([tb.PlacedParticle(FLAT, (BOX / 2 - 3e-6, 0.0))], box=(BOX, BOX),
                periodic=True)

# (planted failing calls, the cut run's schedule, the explicit schedule, the cut step, the
# explicit steps it is made of[, the load's kind, the particle])
CASES = {
    # the second compression step (F/2 -> F) in halves: to 3F/4, then to F
    "compression": ((2,), [(F / 2, 0), (F, 0), (F, S)],
                    [(F / 2, 0), (0.75 * F, 0), (F, 0), (F, S)], 1, (1, 2)),
    # the second sliding step, where it tilts while the lower contact slides, in halves
    "sliding": ((3,), [(F, 0), (F, S), (F, S), (F, S)],
                [(F, 0), (F, S), (F, S / 2), (F, S / 2), (F, S)], 2, (2, 3)),
    # the second compression step's second half fails again: a half, then quarters
    "second": ((2, 4), [(F / 2, 0), (F, 0), (F, S)],
               [(F / 2, 0), (0.75 * F, 0), (0.875 * F, 0), (F, 0), (F, S)], 1, (1, 2, 3)),
    # its first half fails again: quarters, then the second half whole
    "deeper": ((3, 4), [(F, 0), (F, S), (F, S), (F, S)],
               [(F, 0), (F, S), (F, S / 4), (F, S / 4), (F, S / 2), (F, S)], 2, (2, 3, 4)),
    # gap control: the compression 0.004 -> 0.008 in halves, then slid
    "gap": ((2,), [(0.004, 0), (0.008, 0), (0.008, S)],
            [(0.004, 0), (0.006, 0), (0.008, 0), (0.008, S)], 1, (1, 2), "compression"),
    # the second sliding step halved while the particle crosses the periodic box's side
    "periodic": ((3,), [(F, 0), (F, S), (F, S), (F, S)],
                 [(F, 0), (F, S), (F, S / 2), (F, S / 2), (F, S)], 2, (2, 3), "force", EDGE),
}


# function scope: mutmut picks the tests that call a function when they run, and a cached
# fixture would credit every call to the first test (its surviving mutants were false)
@pytest.fixture(params=list(CASES))
def cut_and_explicit(request):
    failing, cut, explicit, k, parts, *how = CASES[request.param]
    with pytest.MonkeyPatch.context() as mp:
        start = time.perf_counter()
        sim, ds, _ = _run(mp, cut, failing, 3, *how)
        wall = time.perf_counter() - start
        assert 0 < float(ds.time_total.values[k]) < wall
        assert sim.status == "complete", sim.status
        ref_sim, ref, _ = _run(mp, explicit, (), 3, *how)
    if how and how[-1] is EDGE:                     # it crosses the side in the cut step
        x = ds.position.isel(particle=0).values[:, 0] + BOX / 2 - 3e-6
        assert x[k - 1] < BOX / 2 < x[k]
        assert ref_sim.status == "complete", ref_sim.status
    return ds, ref, k, list(parts)


def test_a_cut_step_ends_where_its_sub_steps_listed_in_the_program_end(cut_and_explicit):
    ds, ref, k, parts = cut_and_explicit
    end = parts[-1]
    assert int(ds.network_substeps.values[k]) == len(parts)
    assert (ds.network_substeps.values[np.arange(ds.sizes["step"]) != k] == 1).all()
    assert (ref.network_substeps.values == 1).all()
    # the end state, bit for bit
    for name in ("plate_gap", "total_force", "plate_force", "plate_shift", "sliding_distance",
                 "mu_eff_sliding", "network_residual", "elastic_energy"):
        assert np.array_equal(ds[name].values[k], ref[name].values[end], equal_nan=True), name
    for name in ("quaternion", "centroid_height", "plate_normal_force", "stick_area"):
        assert np.array_equal(ds[name].isel(step=k).values, ref[name].isel(step=end).values,
                              equal_nan=True), name
    mine, theirs = _rows(ds, k), _rows(ref, end)
    assert mine.keys() == theirs.keys() and mine
    for key in mine:
        for name in ("contact_force", "contact_point", "contact_state",
                     "contact_stick_area"):
            assert np.array_equal(ds[name].values[mine[key]], ref[name].values[theirs[key]])


def test_a_cut_step_reports_the_whole_step_summed_over_its_sub_steps(cut_and_explicit):
    ds, ref, k, parts = cut_and_explicit
    end = parts[-1]
    # the centroid's motion summed; the turn is from the pose before the step to the pose
    # after it (angle between the recorded quaternions), not the last sub-step's
    move = sum(ref.translation.isel(step=j, particle=0).values for j in parts)
    assert ds.translation.isel(step=k, particle=0).values == pytest.approx(move, rel=1e-12,
                                                                         abs=1e-22)
    q0, q1 = (ds.quaternion.isel(step=j, particle=0).values for j in (k - 1, k))
    angle = 2 * math.degrees(math.acos(min(1.0, abs(float(q0 @ q1)))))
    assert float(ds.rotation_angle.isel(step=k, particle=0)) == pytest.approx(angle, rel=1e-6,
                                                                              abs=1e-9)
    assert ds.position.isel(step=k).values == pytest.approx(
        ref.position.isel(step=end).values, rel=1e-12, abs=1e-24)
    # what it did is what it did over the whole step: the flat ellipsoid's second sliding step
    # tilts it about its sticking upper contact while the lower one slides (roll_upper),
    # though in the last sub-step alone it may no longer turn (slide_lower)
    turned = bool(ds.turned.isel(step=k, particle=0))
    assert turned == (math.radians(angle) > 1e-3)           # ClusterNumerics.stick_rotation
    if ds.plate_shift.values[k][0] > ds.plate_shift.values[k - 1][0]:
        names = ds.state.attrs["flag_meanings"].split()
        assert turned and names[int(ds.state.isel(step=k, particle=0))] == "roll_upper"
    # passes and the energy terms summed; the balance over the whole step, from the records
    assert int(ds.network_iterations.values[k]) == sum(int(ref.network_iterations.values[j])
                                                       for j in parts)
    work = math.fsum(float(ref.plate_work.values[j]) for j in parts)
    lost = math.fsum(float(ref.dissipation.values[j]) for j in parts)
    assert float(ds.plate_work.values[k]) == pytest.approx(work, rel=1e-12)
    assert float(ds.dissipation.values[k]) == pytest.approx(lost, rel=1e-12)
    stored0 = float(ref.elastic_energy.values[parts[0] - 1])
    dh = float(ref.plate_gap.values[parts[-1]] - ref.plate_gap.values[parts[0] - 1])
    shift = ref.plate_shift.values[parts[-1]] - ref.plate_shift.values[parts[0] - 1]
    scale = float(ref.total_force.values[parts[-1]]) * (math.hypot(*shift) + abs(dh))
    residual = (work - (float(ref.elastic_energy.values[parts[-1]]) - stored0) - lost) / scale
    assert float(ds.energy_residual.values[k]) == pytest.approx(residual, rel=1e-9, abs=1e-15)
    # each contact's slip and rigid shift increment summed over the sub-steps
    mine = _rows(ds, k)
    # how far each contact travelled over both surfaces: from its start to its end, known for
    # every contact that existed before the step
    before = _rows(ds, k - 1)
    for key, row in mine.items():
        rolled = [float(ds[n].values[row]) for n in ("contact_rolling_i", "contact_rolling_j")]
        assert all(math.isfinite(r) and r >= 0 for r in rolled) == (key in before), key
    for key, row in mine.items():
        for name in ("contact_slip", "contact_shift_increment"):
            total = sum(ref[name].values[_rows(ref, j)[key]] for j in parts)
            assert ds[name].values[row] == pytest.approx(total, rel=1e-12, abs=1e-24), name


def test_the_step_after_a_cut_one_ends_where_the_explicit_run_does(cut_and_explicit):
    # it is predicted from the cut step's last sub-step, as the explicit run's next step is
    # from its last step: the same solve, bit for bit
    ds, ref, _, _ = cut_and_explicit
    for name in ("plate_gap", "plate_force", "mu_eff_sliding", "elastic_energy",
                 "network_iterations"):
        assert np.array_equal(ds[name].values[-1], ref[name].values[-1], equal_nan=True), name
    assert np.array_equal(ds.quaternion.isel(step=-1).values, ref.quaternion.isel(step=-1).values)


def test_without_cutbacks_a_step_that_fails_ends_the_run(monkeypatch):
    sim, ds, calls = _run(monkeypatch, CASES["sliding"][1], (3,), cutbacks=0)
    assert sim.status.startswith("failed: step 2 "), sim.status
    assert "cut into halves" not in sim.status
    assert calls == 3 and ds.sizes["step"] == 2


def test_only_the_whole_step_and_the_deepest_cut_get_the_solvers_retries(monkeypatch):
    # the sub-steps between give up after the first attempt: halving is cheaper than retries
    def run(failing, cutbacks):
        retries = []
        monkeypatch.setattr(network_run, "solve_cluster", _planted_at(failing, retries))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = tb.Simulation(FLAT, tb.Plates(0.6, 0.3), Steps(tuple(CASES["sliding"][1])),
                                mu_pp=0.3, resolution=20, network_tol=1e-6, maps_every=0,
                                network_cutbacks=cutbacks)
            sim.run()
        return sim.status, retries

    # every call from the third fails: the whole step, its first half, its first quarter...
    status, retries = run(set(range(3, 99)), 3)
    assert "down to 1/8 of it" in status
    assert retries == [True, True, True, False, False, True]
    # the second half cut as deep as the first: with cutbacks = 2 its first quarter is the
    # deepest level (the whole step, its first half converging, its second half, a quarter)
    status, retries = run({3} | set(range(5, 99)), 2)
    assert status.startswith("failed: step 2 ") and "down to 1/4 of it" in status
    assert retries == [True, True, True, False, False, True]


def test_the_solver_without_retries_raises_its_first_attempts_error(monkeypatch):
    from thirdbody.network import cluster

    attempts = []

    def stalls(problem, h, **kwargs):
        problem.phase_one_used = True           # so that the retry without it is tried too
        attempts.append(kwargs.get("phase_one"))
        raise ClusterConvergenceError(f"attempt {len(attempts)} stalled (planted)")

    monkeypatch.setattr(cluster, "_iterate", stalls)
    body = tb.network.Body(FLAT.shape, MAT, FLAT.orientation, np.array([0.0, 0.0, 0.2e-3]))
    for retry, count in ((False, 1), (True, 3)):
        attempts.clear()
        with pytest.raises(ClusterConvergenceError, match="attempt 1 stalled"):
            cluster.solve_cluster([body], mu_up=0.6, mu_low=0.3, force=F, retry=retry,
                                  numerics=cluster.ClusterNumerics(resolution=20))
        assert len(attempts) == count


@pytest.mark.parametrize("cutbacks", [1, 2, 3])
def test_a_step_that_fails_at_every_cut_names_the_depth_and_leaves_the_run_as_it_was(
        monkeypatch, cutbacks):
    # every call from the third fails: the step, its first half, that half's first half...
    sim, ds, calls = _run(monkeypatch, CASES["sliding"][1], range(3, 100), cutbacks=cutbacks)
    assert sim.status.startswith("failed: step 2 "), sim.status
    assert f"down to 1/{2 ** cutbacks} of it: network.cutbacks = {cutbacks}" in sim.status
    assert calls == 3 + cutbacks and ds.sizes["step"] == 2
    # what it completed is the run without the failure
    _, ref, _ = _run(monkeypatch, CASES["sliding"][1][:2])
    assert np.array_equal(ds.plate_gap.values, ref.plate_gap.values)


def test_a_failed_sub_step_leaves_the_state_as_it_was_before_the_step(monkeypatch):
    # the whole step fails, its first half converges, its second half fails at the deepest
    # level: the state the step started from is unchanged, so the step solved again (here
    # without the planted failure) ends as in a run that never failed
    steps = CASES["sliding"][1][:3]
    sim, _, _ = _run(monkeypatch, steps, ())
    expected = sim.records[-1].values["plate_gap"]
    engine, state = sim.network, sim.network.initial_state()
    for k, step in enumerate(sim.schedule[:2]):
        engine.step(k, step, state)
    before = copy.copy(state)
    monkeypatch.setattr(engine, "cutbacks", 1)
    monkeypatch.setattr(network_run, "solve_cluster", _failing_after(1))
    with pytest.raises(ClusterConvergenceError, match="down to 1/2 of it"):
        engine.step(2, sim.schedule[2], state)
    for name in ("bodies", "histories", "gap", "displacement", "plate_shift",
                 "sliding_distance", "slide_gap", "last_step"):
        assert getattr(state, name) is getattr(before, name), name
    monkeypatch.setattr(network_run, "solve_cluster", SOLVE)
    assert engine.step(2, sim.schedule[2], state).values["plate_gap"] == expected


def _planted_at(failing, retries):
    """A solver whose calls numbered in ``failing`` (from 1) raise; each call's ``retry``
    is appended to ``retries``."""
    def planted(*args, **kwargs):
        retries.append(kwargs["retry"])
        if len(retries) in failing:
            raise ClusterConvergenceError("cluster equilibrium stalled (planted)")
        return SOLVE(*args, **kwargs)

    return planted


def _failing_after(good):
    """A solver whose first call fails, the next ``good`` calls solve and the rest fail."""
    calls = []

    def planted(*args, **kwargs):
        calls.append(1)
        if 1 < len(calls) <= 1 + good:
            return SOLVE(*args, **kwargs)
        raise ClusterConvergenceError("cluster equilibrium stalled (planted)")

    return planted


def test_the_energy_residual_of_a_step_that_neither_moves_nor_slides_is_nan():
    held = network_run._Energy(work=0.0, stored0=1e-6, stored=1e-6, dissipated=0.0,
                               gap_change=0.0)
    assert math.isnan(network_run._balance([held, held], LoadStep("force", F), F)
                      ["energy_residual"])


def test_halves_split_the_load_from_the_state_when_the_last_step_was_of_another_kind():
    side = SimpleNamespace(side="upper", force=np.array([0.1, 0.0, -2.0]))
    lower = SimpleNamespace(side="lower", force=np.array([0.0, 0.0, 2.0]))
    pair = SimpleNamespace(force=np.array([0.0, 0.0, -5.0]))      # a pair contact: no side
    histories = {1: SimpleNamespace(solved=side), 2: SimpleNamespace(solved=lower),
                 3: SimpleNamespace(solved=pair)}
    state = SimpleNamespace(last_step=SimpleNamespace(kind="compression", value=0.1),
                            histories=histories, gap=0.9e-3)
    first, second = network_run._halves(LoadStep("force", 3.0, (4e-6, -2e-6)), state, 1e-3)
    assert first == LoadStep("force", 2.5, (2e-6, -1e-6))        # from 2 N (the upper plate)
    assert second == LoadStep("force", 3.0, (2e-6, -1e-6))
    state.last_step = SimpleNamespace(kind="force", value=2.0)
    first, _ = network_run._halves(LoadStep("compression", 0.2), state, 1e-3)
    assert first.value == pytest.approx(0.15)                     # from (d0 - h)/d0 = 0.1
    state.last_step = SimpleNamespace(kind="force", value=1.0)    # the same kind: its value
    first, _ = network_run._halves(LoadStep("force", 3.0), state, 1e-3)
    assert first == LoadStep("force", 2.0)


@pytest.mark.parametrize("value", [-1, 9, 2.0, True])
def test_cutbacks_out_of_range_name_the_field(value):
    with pytest.raises(ValueError, match=r"network_cutbacks \(network.cutbacks\) must be an "
                                         r"integer in \[0, 8\]"):
        tb.Simulation(FLAT, tb.Plates(0.5), tb.LinearRamp(stop=F, steps=1), mu_pp=0.3,
                      network_cutbacks=value)


def test_the_network_table_takes_cutbacks_and_refuses_a_bad_one():
    cfg = {"particle": {"shape": "sphere", "radius": 1e-3, "E": 1e9, "nu": 0.3},
           "plates": {"mu_up": 0.5}, "network": {"mu_pp": 0.3, "cutbacks": 1},
           "load": {"program": "linear_ramp", "stop": F, "steps": 1}}
    assert parse_config(cfg).build()[3]["network_cutbacks"] == 1
    cfg["network"]["cutbacks"] = 9
    with pytest.raises(ConfigError, match=r"network\.cutbacks"):
        parse_config(cfg)
    del cfg["network"]["cutbacks"]
    assert parse_config(cfg).build()[3]["network_cutbacks"] == network_run.CUTBACKS


def test_a_cut_step_turns_by_its_sub_steps_composed_and_predicts_from_the_last(monkeypatch):
    # the cut step's rotation is R2 R1 (checked with Rodrigues' matrices of the halves' own
    # rotation vectors); the next step is predicted from the last half's motion, the latest
    sim, _, _ = _run(monkeypatch, CASES["sliding"][1][:2], ())
    engine, state = sim.network, sim.network.initial_state()
    for k, step in enumerate(sim.schedule):
        engine.step(k, step, state)
    results = []
    monkeypatch.setattr(network_run, "solve_cluster", _recording(_failing_after(2), results))
    record = engine.step(2, LoadStep("force", F, (S, 0.0)), state)
    assert record.values["network_substeps"] == 2 and len(results) == 2
    first, second = results
    whole = network_run._combined(results)
    for i in range(len(state.bodies)):
        expected = _matrix(second.rotation[i]) @ _matrix(first.rotation[i])
        assert _matrix(whole.rotation[i]) == pytest.approx(expected, abs=1e-15)
    assert whole.bem_solves == first.bem_solves + second.bem_solves
    assert np.linalg.norm(first.rotation) > 1e-4 and np.linalg.norm(second.rotation) > 1e-4
    # these two nearly commute (both tilt about y); two large turns about x, then z, do not
    about_x = dataclasses.replace(first, rotation=np.array([[0.3, 0.0, 0.0]]))
    about_z = dataclasses.replace(second, rotation=np.array([[0.0, 0.0, 0.5]]))
    turned = network_run._combined([about_x, about_z]).rotation[0]
    assert _matrix(turned) == pytest.approx(_matrix([0, 0, 0.5]) @ _matrix([0.3, 0, 0]),
                                            abs=1e-14)
    last = state.last_step
    assert (last.kind, last.value, last.normal, last.shift) == ("force", F, 0.0, (S / 2, 0.0))
    assert np.array_equal(last.translation, second.translation)
    assert np.array_equal(last.rotation, second.rotation)


def _recording(solve, results):
    """``solve``, keeping every result it returns in ``results``."""
    def recorded(*args, **kwargs):
        result = solve(*args, **kwargs)
        results.append(result)
        return result

    return recorded


def test_identical_particles_stay_identical_through_a_cut_step(monkeypatch):
    # a tie: two identical flat ellipsoids, 3 mm apart in a periodic box of 6 x 6 mm (nothing
    # touches across it), the second sliding step cut into halves; both move, turn and carry
    # load alike, each half of F_N, to rounding (their different x put 1e-17 into components
    # that are zero even in the uncut run; cut, 1.2e-15 of a unit quaternion)
    pair = tb.Layer([tb.PlacedParticle(FLAT, (x, 0.0)) for x in (-1.5e-3, 1.5e-3)],
                    box=(6e-3, 6e-3), periodic=True)
    steps = [(2 * F, 0), (2 * F, S), (2 * F, S)]
    sim, ds, _ = _run(monkeypatch, steps, (3,), particle=pair)
    assert sim.status == "complete", sim.status
    assert int(ds.network_substeps.values[2]) == 2
    def both(name):
        return (ds[name].isel(step=2, particle=p).values for p in (0, 1))

    a, b = both("quaternion")
    assert a == pytest.approx(b, abs=1e-13)
    a, b = both("translation")
    assert a == pytest.approx(b, abs=1e-12 * S)
    for name in ("plate_normal_force", "rotation_angle"):
        a, b = both(name)
        assert a == pytest.approx(b, rel=1e-12), name
    a, b = both("state")
    assert a == b
    assert ds.load_share.isel(step=2).values == pytest.approx([0.5, 0.5], abs=1e-12)
