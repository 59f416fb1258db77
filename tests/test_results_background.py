"""Saving each step in a child process while the run computes the next (``run_to_file(...,
background=True)``, what ``thirdbody run`` does; issue 15): the file is the same as when saving
in the run's own process, an interrupted run leaves every step it had computed, a run killed
outright leaves the steps it had sent to the child, and a failing or dying child stops the run
with its error instead of losing steps in silence."""

import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import pytest
import xarray as xr

import thirdbody.io.results as results
from test_results_append import layer_sim, potato_sim, steps_on_disk, stop_after
from thirdbody.io import open_results, run_to_file


def _timers(ds):
    return [v for v in ds.data_vars if v.startswith("time_")]


def _writer_children():
    return [p for p in multiprocessing.active_children() if p.name == "thirdbody-writer"]


@pytest.mark.parametrize("make", [potato_sim, layer_sim], ids=["particle", "layer"])
def test_saving_in_a_child_gives_the_file_of_saving_in_the_run(make, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        here = run_to_file(make(), tmp_path / "here.nc")
        child = run_to_file(make(), tmp_path / "child.nc", background=True)
    assert not _writer_children()                       # the child has exited
    on_disk = open_results(tmp_path / "child.nc")
    xr.testing.assert_identical(on_disk, child)
    xr.testing.assert_identical(on_disk.drop_vars(_timers(here)),
                                open_results(tmp_path / "here.nc").drop_vars(_timers(here)))


def test_an_interrupted_run_leaves_every_computed_step_and_resumes(tmp_path):
    """Ctrl-C (a KeyboardInterrupt in the run) during step 4: steps 0-2 were sent to the child,
    which saves them all before the run re-raises; the resumed run ends as an uninterrupted
    one."""
    path = tmp_path / "r.nc"
    with pytest.raises(KeyboardInterrupt):
        run_to_file(potato_sim(steps=8), path, progress=stop_after(4), background=True)
    assert not _writer_children()
    partial = open_results(path)
    assert partial.step.values.tolist() == [0, 1, 2]
    assert partial.attrs["status"] == "running"
    run_to_file(potato_sim(steps=8), path, resume=True, background=True)
    straight = potato_sim(steps=8).run()
    xr.testing.assert_identical(open_results(path).drop_vars(_timers(straight)),
                                straight.drop_vars(_timers(straight)))


@pytest.mark.parametrize("how", ["sigkill-run", "sigint-group"])
def test_a_run_killed_or_interrupted_leaves_the_steps_it_had_sent(how, tmp_path):
    """After step 4 was computed, SIGKILL of the run (not of its child), or SIGINT to the
    whole process group as Ctrl-C sends it: the child saves the steps it was sent (0-3), then
    exits (at the end of the pipe; it ignores SIGINT). The child is slowed down, so that those
    steps are still in the pipe when the signal comes. The run then resumes to the
    uninterrupted result."""
    path = tmp_path / "r.nc"
    script = textwrap.dedent(f"""
        import multiprocessing, os, signal, sys
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        import time
        from test_results_append import potato_sim
        from thirdbody.io import results, run_to_file

        save = results._StepWriter.save

        def slow_save(self, sim, blob):     # the child lags: steps wait in the pipe
            time.sleep(0.3)
            save(self, sim, blob)

        results._StepWriter.save = slow_save

        def progress(record):
            if record.step == 4:
                child, = [p for p in multiprocessing.active_children()
                          if p.name == "thirdbody-writer"]
                print(child.pid, flush=True)
                if {how!r} == "sigkill-run":
                    os.kill(os.getpid(), signal.SIGKILL)
                os.killpg(0, signal.SIGINT)

        try:
            run_to_file(potato_sim(steps=8), {str(path)!r}, progress=progress,
                        background=True)
        except KeyboardInterrupt:
            sys.exit(130)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300, start_new_session=True)
    assert proc.returncode == (-signal.SIGKILL if how == "sigkill-run" else 130), proc.stderr
    child = int(proc.stdout.split()[0])
    deadline = time.monotonic() + 60
    while _alive(child):                    # it exits by itself, at the end of the pipe
        assert time.monotonic() < deadline, "the writing child did not exit"
        time.sleep(0.05)
    on_disk = open_results(path)
    assert on_disk.step.values.tolist() == [0, 1, 2, 3]
    assert on_disk[results.STEP_HISTORY_VARIABLE].size == 4
    run_to_file(potato_sim(steps=8), path, resume=True)
    straight = potato_sim(steps=8).run()
    xr.testing.assert_identical(open_results(path).drop_vars(_timers(straight)),
                                straight.drop_vars(_timers(straight)))


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, not reaped in a container without init, counts as
    ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_an_error_in_the_child_stops_the_run_with_that_error(monkeypatch, tmp_path):
    """A full disk while appending step 2 (the fork inherits the patch): the run raises the
    child's OSError, the file holds steps 0 and 1."""
    original = results._StepWriter._append

    def full_disk(self, sim, *args):
        if len(sim.records) == 3:
            raise OSError(28, "No space left on device")
        return original(self, sim, *args)

    monkeypatch.setattr(results._StepWriter, "_append", full_disk)
    path = tmp_path / "r.nc"
    with pytest.raises(OSError, match="No space left"):
        run_to_file(potato_sim(steps=8), path, background=True)
    assert not _writer_children()
    assert open_results(path).step.values.tolist() == [0, 1]


def test_a_child_that_dies_stops_the_run(tmp_path):
    """The child killed after step 2: the run stops at a later step with a RuntimeError that
    says so (never finishes as if saved); the file holds whole steps."""
    def kill_the_child(record):
        if record.step == 2:
            while steps_on_disk(path) < 1:      # the child has written the first step
                time.sleep(0.01)
            (child,) = _writer_children()
            os.kill(child.pid, signal.SIGKILL)
            child.join()

    path = tmp_path / "r.nc"
    with pytest.raises(RuntimeError, match="saving the results died"):
        run_to_file(potato_sim(steps=8), path, progress=kill_the_child, background=True)
    on_disk = open_results(path)
    assert on_disk.step.values.tolist() == list(range(on_disk.sizes["step"]))
    assert 1 <= on_disk.sizes["step"] <= 3
