"""Parameter sweeps on dask.distributed: parsing the sweep file, case identity, a real
LocalCluster of 2 worker processes on loopback whose results equal the same cases run one by one
with ``thirdbody run``, the physics of the summary (a tilted ellipsoid turns to the rigid
equilibrium angle where μ < ξ(θ0) and sticks elsewhere), reruns that recompute nothing, a
failing case that does not stop the others, and a worker killed mid-sweep."""

import math
import os
import signal

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from conftest import local_client
from thirdbody import rigid
from thirdbody.cli import app
from thirdbody.io import open_results
from thirdbody.sweep import BEHAVIOURS, SweepError, case_id, load_sweep, parse_sweep, run_sweep

runner = CliRunner()

A, B, C = 1.0e-3, 0.8e-3, 0.6e-3
MUS = (0.3, 0.6)
THETAS = (-20.0, 35.0)

BASE = f"""
[particle]
shape = "ellipsoid"
semi_axes = [{A}, {B}, {C}]
E = 1.0e9
nu = 0.3
orientation_deg = 0.0

[plates]
mu_up = 0.5

[load]
program = "force_table"
forces = [0.5, 1.0]

[numerics]
resolution = 50.0
maps_every = 1
"""

SWEEP = """
base = "base.toml"

[axes]
plates.mu = [0.3, 0.6]
"particle.orientation_deg" = {start = -20, stop = 35, num = 2}
"""


def write_sweep(directory, sweep=SWEEP, base=BASE):
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "base.toml").write_text(base)
    (directory / "sweep.toml").write_text(sweep)
    return directory / "sweep.toml"


def without_times(ds):
    return ds.drop_vars([v for v in ds.data_vars if v.startswith("time_")])


# --- the sweep file ----------------------------------------------------------------------------
def test_axes_lists_ranges_and_nested_keys(tmp_path):
    path = write_sweep(tmp_path, sweep="""
base = "base.toml"
[axes]
plates.mu = [0.2, 0.4]
"particle.orientation_deg" = {start = -30, stop = 30, num = 4}
particle.E = {start = 1e9, stop = 3e9, step = 1e9}
[set]
"load.forces" = [1.0]
""")
    sweep = load_sweep(path)
    assert [a.key for a in sweep.axes] == ["plates.mu", "particle.orientation_deg", "particle.E"]
    assert [a.name for a in sweep.axes] == ["mu", "orientation_deg", "E"]
    assert sweep.axes[1].values == (-30.0, -10.0, 10.0, 30.0)
    assert sweep.axes[2].values == (1e9, 2e9, 3e9)
    cases = sweep.cases()
    assert len(cases) == 2 * 4 * 3 == math.prod(sweep.shape)
    first, last = cases[0], cases[-1]
    assert first.index == (0, 0, 0) and last.index == (1, 3, 2)
    # plates.mu sets both plates; [set] applies to every case; axis values land where they say
    assert first.config.plates.mu_up == 0.2 and first.config.plates.mu_low is None
    assert last.config.plates.mu_up == 0.4 and last.config.particle.E == 3e9
    assert last.config.particle.orientation_deg == 30.0
    assert all(c.config.load.forces == [1.0] for c in cases)
    assert len({c.case_id for c in cases}) == len(cases)


def test_integer_step_ranges_stay_integers(tmp_path):
    sweep = parse_sweep({"base": "fig3", "axes": {"particle": {"seed": {
        "start": 1, "stop": 7, "step": 3}}}})
    assert sweep.axes[0].values == (1, 4, 7)
    assert all(isinstance(v, int) for v in sweep.axes[0].values)


def test_base_can_be_a_bundled_example_or_a_table():
    from_example = parse_sweep({"base": "fig4a", "axes": {"plates.mu": [0.2]}})
    assert from_example.cases()[0].config.particle.orientation_deg == -41.0
    table = {"particle": {"shape": "sphere", "radius": 1e-3, "E": 1e9, "nu": 0.3},
             "plates": {"mu_up": 0.3}, "load": {"program": "force_table", "forces": [1.0]}}
    inline = parse_sweep({"base": table, "axes": {"particle.radius": [1e-3, 2e-3]}})
    assert [c.config.particle.geometry.radius for c in inline.cases()] == [1e-3, 2e-3]


@pytest.mark.parametrize("sweep, words", [
    ({"axes": {"plates.mu": [0.2]}}, ["base", "required"]),
    ({"base": "no_such_file", "axes": {"plates.mu": [0.2]}}, ["no_such_file"]),
    ({"base": "fig4a"}, ["axes", "required"]),
    ({"base": "fig4a", "axes": {"plates.mu": []}}, ["axes.plates.mu", "empty"]),
    ({"base": "fig4a", "axes": {"plates.mu": [0.2, 0.2]}}, ["repeated"]),
    ({"base": "fig4a", "axes": {"plates.mu": {"start": 0.1, "stop": 0.3, "num": 3,
                                              "step": 0.1}}}, ["exactly one of num and step"]),
    ({"base": "fig4a", "axes": {"plates.mu": {"start": 0.3, "stop": 0.1, "step": 0.1}}},
     ["step"]),
    ({"base": "fig4a", "axes": {"plates.mu": 0.2}}, ["axes.plates.mu", "list"]),
    ({"base": "fig4a", "axes": {"plates.mu": [0.2]}, "sett": {}}, ["sett"]),
    ({"base": "fig4a", "axes": {"plates.mu": [0.2]}, "set": {"plates.mu": 0.1}},
     ["both an axis and in [set]"]),
])
def test_bad_sweep_files_name_the_key(sweep, words):
    with pytest.raises(SweepError) as info:
        parse_sweep(sweep).cases()
    for word in words:
        assert word in str(info.value)


def test_invalid_case_values_name_the_case_and_the_key():
    with pytest.raises(SweepError) as info:
        parse_sweep({"base": "fig4a", "axes": {"plates.mu": [0.2, -0.1],
                                               "particle.nuu": [0.3]}}).cases()
    message = str(info.value)
    assert "particle.nuu" in message and "unknown key" in message
    with pytest.raises(SweepError) as info:
        parse_sweep({"base": "fig4a", "axes": {"plates.mu": [0.2, -0.1]}}).cases()
    message = str(info.value)
    assert "plates.mu = -0.1" in message and "plates.mu_up" in message
    assert "must be >= 0" in message                 # the allowed range
    assert "plates.mu = 0.2" not in message          # only the bad case is reported


def test_case_id_is_the_hash_of_the_resolved_configuration():
    def one(**axes):
        return parse_sweep({"base": "fig4a", "axes": axes}).cases()[0]

    assert one(**{"plates.mu": [0.3]}).case_id == one(**{"plates.mu_up": [0.3]}).case_id
    # an explicit default value resolves to the same configuration, hence the same case
    assert (one(**{"numerics.tol": [1e-8]}).case_id
            == one(**{"numerics.angle_tol_deg": [0.01]}).case_id)
    assert one(**{"plates.mu": [0.3]}).case_id != one(**{"plates.mu": [0.31]}).case_id
    case = one(**{"plates.mu": [0.3]})
    assert case.case_id == case_id(case.config) and len(case.case_id) == 16


def test_cli_refuses_a_bad_sweep_with_exit_2_and_writes_nothing(tmp_path):
    path = write_sweep(tmp_path / "in", sweep=SWEEP.replace("0.6]", "-0.6]"))
    result = runner.invoke(app, ["sweep", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "plates.mu_up" in result.output and "-0.6" in result.output
    assert not (tmp_path / "out").exists()
    result = runner.invoke(app, ["sweep", str(write_sweep(tmp_path / "in")), "-o",
                                 str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:1",
                                 "--workers", "2"])
    assert result.exit_code == 2 and "--workers" in result.output


def test_cli_unreachable_scheduler_exits_2_and_writes_nothing(tmp_path):
    path = write_sweep(tmp_path / "in")
    result = runner.invoke(app, ["sweep", str(path), "-o", str(tmp_path / "out"), "--scheduler",
                                 "tcp://127.0.0.1:9", "--connect-timeout", "1"])
    assert result.exit_code == 2
    assert "cannot reach the Dask scheduler tcp://127.0.0.1:9" in result.output
    assert not (tmp_path / "out").exists()


def test_cli_dry_run_lists_the_cases(tmp_path):
    path = write_sweep(tmp_path / "in")
    result = runner.invoke(app, ["sweep", str(path), "-o", str(tmp_path / "out"), "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "4 cases (2 x 2)" in result.output
    assert not (tmp_path / "out").exists()


# --- on a real cluster -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def client():
    yield from local_client(2)


@pytest.fixture(scope="module")
def one_by_one(tmp_path_factory):
    """Each case of SWEEP run by itself with `thirdbody run` from a config written by hand."""
    root = tmp_path_factory.mktemp("one_by_one")
    results = {}
    for mu in MUS:
        for theta in THETAS:
            text = (BASE.replace("mu_up = 0.5", f"mu_up = {mu}")
                    .replace("orientation_deg = 0.0", f"orientation_deg = {theta}"))
            (root / "run.toml").write_text(text)
            out = root / f"mu{mu}_theta{theta}"
            result = runner.invoke(app, ["run", str(root / "run.toml"), "-o", str(out),
                                         "--no-plots"])
            assert result.exit_code == 0, result.output
            results[mu, theta] = open_results(out / "results.nc")
    return results


@pytest.fixture(scope="module")
def swept(tmp_path_factory, client):
    root = tmp_path_factory.mktemp("sweep")
    sweep = load_sweep(write_sweep(root / "in"))
    report = run_sweep(sweep, root / "out", client=client)
    return sweep, report, root / "out"


@pytest.mark.slow
def test_sweep_on_two_workers_equals_the_cases_run_one_by_one(swept, one_by_one):
    _, report, out = swept
    assert report.computed == 4 and report.skipped == 0 and not report.failures
    workers = {r["worker"] for r in report.records.values()}
    assert len(workers) == 2                         # both worker processes ran cases
    for case in report.cases:
        mu, theta = case.values["plates.mu"], case.values["particle.orientation_deg"]
        ds = open_results(out / "cases" / case.filename)
        expected = one_by_one[mu, theta]
        xr.testing.assert_identical(without_times(ds).drop_attrs(), without_times(
            expected).drop_attrs())
        assert ds.attrs["inputs"] == expected.attrs["inputs"]
        assert ds.attrs["config"] == expected.attrs["config"]
        assert case.case_id in ds.attrs["sweep_case"]


# the flat ellipsoid of the bundled shear example, slid 5 µm and back in 2.5 µm steps, at three
# μ_low
SLIDING_SWEEP = """
base = "shear_ellipsoid"

[axes]
plates.mu_low = [0.3, 0.4, 0.5]

[set]
"load.points" = [[5.0e-6, 0.0], [0.0, 0.0]]
"load.steps" = 2
"numerics.resolution" = 20.0
"""


@pytest.mark.slow
def test_a_sweep_of_sliding_cases_on_two_workers_equals_them_run_one_by_one(tmp_path, client):
    """Sliding runs (the network engine, a contact table, μ_eff, the energy balance) are as
    deterministic across worker processes as the particle runs: each case's file is the one
    `thirdbody run` writes for its configuration."""
    sweep = load_sweep(write_sweep(tmp_path / "in", sweep=SLIDING_SWEEP, base=""))
    report = run_sweep(sweep, tmp_path / "out", client=client)
    assert report.computed == 3 and not report.failures
    # one worker runs two cases one after the other: nothing may carry over between runs
    assert len({r["worker"] for r in report.records.values()}) == 2
    for case in report.cases:
        (tmp_path / "case.toml").write_text(case.config.to_toml())
        alone = tmp_path / f"alone_{case.case_id}"
        result = runner.invoke(app, ["run", str(tmp_path / "case.toml"), "-o", str(alone),
                                     "--no-plots"])
        assert result.exit_code == 0, result.output
        expected = open_results(alone / "results.nc")
        ds = open_results(tmp_path / "out" / "cases" / case.filename)
        assert ds.sizes["contact"] > 0 and np.isfinite(ds.mu_eff_sliding.values[2:]).all()
        xr.testing.assert_identical(without_times(ds).drop_attrs(),
                                    without_times(expected).drop_attrs())
        assert ds.attrs["config"] == expected.attrs["config"]
    assert np.isfinite(report.summary["steady_mu_eff"].values).all()


@pytest.mark.slow
def test_the_summary_shows_the_rigid_turning_criterion(swept, one_by_one):
    """μ = 0.3 < ξ(θ0) for both tilts: the ellipsoid rotates to the rigid equilibrium angle;
    μ = 0.6 > ξ(θ0): it sticks. Checks the values land on the right sweep coordinates."""
    _, _, out = swept
    s = xr.open_dataset(out / "summary.nc", engine="h5netcdf").load()
    assert s.behaviour.dims == ("mu", "orientation_deg")
    assert s.attrs["failed"] == 0
    for mu in MUS:
        for theta in THETAS:
            at = {"mu": mu, "orientation_deg": theta}
            xi = rigid.ellipsoid_xi(A, C, math.radians(theta))
            behaviour = BEHAVIOURS[int(s.behaviour.sel(at))]
            rotation = float(s.total_rotation.sel(at))
            if mu < xi:
                eq = math.degrees(rigid.ellipsoid_equilibrium_angle(A, C, math.radians(theta),
                                                                    mu))
                assert behaviour == "rotate"
                assert abs(rotation - (eq - theta)) < 0.2
                assert float(s.first_turn_force.sel(at)) == 0.5
            else:
                assert behaviour == "stick" and rotation == 0.0
                assert np.isnan(float(s.first_turn_force.sel(at)))
            expected = one_by_one[mu, theta]
            np.testing.assert_array_equal(s.orientation.sel(at).values,
                                          expected.orientation.values)
            assert float(s.final_ratio_low.sel(at)) == float(
                expected.ratio.sel(interface="lower", particle=0)[-1])
    csv = (out / "summary.csv").read_text().splitlines()
    assert len(csv) == 5 and csv[0].startswith("plates.mu,particle.orientation_deg,case")
    assert (out / "state_map.png").stat().st_size > 10_000


@pytest.mark.slow
def test_a_rerun_recomputes_nothing(swept, monkeypatch):
    sweep, _, out = swept
    files = sorted((out / "cases").glob("*.nc"))
    stamps = [f.stat().st_mtime_ns for f in files]
    import dask.distributed

    def no_cluster(*args, **kwargs):
        raise AssertionError("a rerun of a finished sweep must not start a cluster")

    monkeypatch.setattr(dask.distributed, "LocalCluster", no_cluster)
    report = run_sweep(sweep, out, plots=False)
    assert report.computed == 0 and report.skipped == 4
    assert [f.stat().st_mtime_ns for f in files] == stamps
    result = runner.invoke(app, ["sweep", str(out.parent / "in" / "sweep.toml"), "-o", str(out),
                                 "--no-plots"])
    assert result.exit_code == 0, result.output
    assert "0 run, 4 already done" in result.output


def test_a_failing_case_is_recorded_and_the_others_go_on(tmp_path, client):
    sweep = load_sweep(write_sweep(tmp_path / "in", sweep="""
base = "base.toml"
[axes]
"numerics.resolution" = [12.0, 50.0]
[set]
"plates.mu" = 0.6
"particle.orientation_deg" = 35.0
"""))
    report = run_sweep(sweep, tmp_path / "out", client=client, plots=False)
    bad, good = report.cases
    assert list(report.failures) == [bad.case_id]
    assert "too coarse" in report.failures[bad.case_id]
    error = (tmp_path / "out" / "cases" / f"{bad.case_id}.error.txt").read_text()
    assert "resolution" in error and "Traceback" in error
    assert report.records[good.case_id]["status"] == "complete"
    s = report.summary
    assert BEHAVIOURS[int(s.behaviour.sel(resolution=12.0))] == "error"
    assert BEHAVIOURS[int(s.behaviour.sel(resolution=50.0))] == "stick"
    # the rerun retries the failed case only
    again = run_sweep(sweep, tmp_path / "out", client=client, plots=False)
    assert again.computed == 1 and again.skipped == 1


def test_cli_runs_on_an_existing_cluster_and_leaves_it_as_it_was(tmp_path, client):
    path = write_sweep(tmp_path / "in", sweep="""
base = "base.toml"
[axes]
"particle.orientation_deg" = [35.0]
[set]
"plates.mu" = 0.6
""")
    before = client.run(os.getpid)
    result = runner.invoke(app, ["sweep", str(path), "-o", str(tmp_path / "out"), "--scheduler",
                                 client.scheduler.address, "--no-plots"])
    assert result.exit_code == 0, result.output
    assert "1 cases: 1 run, 0 already done, 0 not complete" in result.output
    # no terminal here: a plain line for the case, then what comes next
    assert "[1/1] case " in result.output and "elapsed" in result.output
    assert "writing the summary\n" in result.output
    assert client.run(os.getpid) == before          # same workers, still running
    s = open_results(tmp_path / "out" / "summary.nc")
    assert BEHAVIOURS[int(s.behaviour.sel(orientation_deg=35.0))] == "stick"


@pytest.mark.slow
def test_a_worker_killed_mid_sweep_does_not_stop_it(tmp_path, one_by_one):
    """SIGKILL one busy worker process after the first case completes: dask reschedules its
    case (the nanny restarts the worker) and every result equals the uninterrupted one."""
    from dask.distributed import Client, LocalCluster

    sweep = load_sweep(write_sweep(tmp_path / "in"))
    killed = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=":0") as cluster, Client(cluster) as c:
        pids = c.run(os.getpid)

        def progress(record, done, total):
            if killed:
                return
            busy = [w for w, keys in c.processing().items() if keys]
            if busy:
                killed.append(pids[busy[0]])
                os.kill(pids[busy[0]], signal.SIGKILL)

        report = run_sweep(sweep, tmp_path / "out", client=c, plots=False, progress=progress)
        assert killed, "no worker was busy after the first case: nothing was tested"
        assert killed[0] not in c.run(os.getpid).values()
    assert not report.failures and report.computed == 4
    for case in report.cases:
        ds = open_results(tmp_path / "out" / "cases" / case.filename)
        expected = one_by_one[case.values["plates.mu"], case.values["particle.orientation_deg"]]
        xr.testing.assert_identical(without_times(ds).drop_attrs(),
                                    without_times(expected).drop_attrs())


# --- resuming a case in process ----------------------------------------------------------------
def _sweep_of(tmp_path, mus):
    return load_sweep(write_sweep(tmp_path / "in", sweep=f"""
base = "base.toml"
[axes]
"plates.mu" = {list(mus)}
[set]
"particle.orientation_deg" = 35.0
"load.forces" = [0.5, 0.75, 1.0]
"""))


def _interrupt_after_first_step(case, base_dir, path):
    from thirdbody import Simulation
    from thirdbody.io.config import parse_config
    from thirdbody.io.results import run_to_file

    particle, plates, load, numerics = parse_config(case.data, base_dir=base_dir).build()
    sim = Simulation(particle, plates, load, **numerics)
    sim.preflight()

    def progress(record):
        if record.step == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_file(sim, path, progress=progress)
    assert open_results(path).sizes["step"] == 1


@pytest.mark.slow      # CI budget: the results tests resume partial files in the default run
def test_run_case_resumes_a_partial_file_to_the_uninterrupted_result(tmp_path):
    from thirdbody.sweep import run_case

    sweep = _sweep_of(tmp_path, [0.6])
    case = sweep.cases()[0]
    fresh, partial = tmp_path / "fresh", tmp_path / "partial"
    fresh.mkdir()
    partial.mkdir()
    record = run_case(case.data, sweep.base_dir, str(fresh), case.case_id)
    assert record["status"] == "complete" and not record["resumed"]
    _interrupt_after_first_step(case, sweep.base_dir, partial / case.filename)
    record = run_case(case.data, sweep.base_dir, str(partial), case.case_id)
    assert record["status"] == "complete" and record["resumed"] and record["steps"] == 3
    xr.testing.assert_identical(without_times(open_results(partial / case.filename)),
                                without_times(open_results(fresh / case.filename)))
    # a second attempt on the finished file (its first worker died before reporting back)
    # reuses it: computed in this sweep, not "already done" before it
    mtime = (fresh / case.filename).stat().st_mtime_ns
    again = run_case(case.data, sweep.base_dir, str(fresh), case.case_id)
    assert again["status"] == "complete" and again["reused"] and not again.get("skipped")
    assert (fresh / case.filename).stat().st_mtime_ns == mtime


@pytest.mark.slow
def test_run_case_restarts_a_partial_file_it_cannot_continue(tmp_path):
    """A partial file whose inputs differ (another version, another case) is not resumed: the
    case starts afresh and ends as an uninterrupted run."""
    from thirdbody.sweep import run_case

    sweep = _sweep_of(tmp_path, [0.5, 0.6])
    other, case = sweep.cases()
    fresh, partial = tmp_path / "fresh", tmp_path / "partial"
    fresh.mkdir()
    partial.mkdir()
    run_case(case.data, sweep.base_dir, str(fresh), case.case_id)
    _interrupt_after_first_step(other, sweep.base_dir, partial / case.filename)
    record = run_case(case.data, sweep.base_dir, str(partial), case.case_id)
    assert record["status"] == "complete" and not record["resumed"]
    xr.testing.assert_identical(without_times(open_results(partial / case.filename)),
                                without_times(open_results(fresh / case.filename)))
