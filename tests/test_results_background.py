"""Saving each step in a child process while the run computes the next (``run_to_file(...,
background=True)``, what ``thirdbody run`` does; issue 15): the file is the same as when saving
in the run's own process, an interrupted run leaves every step it had computed, a run killed
outright leaves the steps it had sent to the child, and a failing or dying child stops the run
with its error instead of losing steps in silence. The child is a fresh interpreter: faulty
writers reach it by name from tests/_faulty_writers.py (``tests`` on its PYTHONPATH)."""

import fcntl
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
from test_results_append import layer_sim, potato_sim, steps_on_disk, stop_after, straight_run
from thirdbody.cli.lock import LOCK_NAME
from thirdbody.io import open_results, run_to_file


def _timers(ds):
    return [v for v in ds.data_vars if v.startswith("time_")]


TESTS = os.path.dirname(os.path.abspath(__file__))


@pytest.fixture
def children(monkeypatch):
    """The background writers started in this test (their ``proc`` is the child)."""
    made = []
    original = results._BackgroundWriter.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(results._BackgroundWriter, "__init__", init)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [TESTS, *filter(None, [os.environ.get("PYTHONPATH")])]))
    return made


# the particle's case is slow (CI's budget): the layer's runs the same child writer
@pytest.mark.parametrize("make", [pytest.param(potato_sim, marks=pytest.mark.slow), layer_sim],
                         ids=["particle", "layer"])
def test_saving_in_a_child_gives_the_file_of_saving_in_the_run(make, tmp_path, children):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        here = run_to_file(make(), tmp_path / "here.nc")
        child = run_to_file(make(), tmp_path / "child.nc", background=True)
    (child_writer,) = children
    assert child_writer.proc.returncode == 0            # the child has exited
    assert child_writer.stats["appended"] == here.sizes["step"] - 1
    on_disk = open_results(tmp_path / "child.nc")
    xr.testing.assert_identical(on_disk, child)
    xr.testing.assert_identical(on_disk.drop_vars(_timers(here)),
                                open_results(tmp_path / "here.nc").drop_vars(_timers(here)))


def test_an_interrupted_run_leaves_every_computed_step_and_resumes(tmp_path, children):
    """Ctrl-C (a KeyboardInterrupt in the run) during step 4: steps 0-2 were sent to the child,
    which saves them all before the run re-raises; the resumed run ends as an uninterrupted
    one."""
    path = tmp_path / "r.nc"
    with pytest.raises(KeyboardInterrupt):
        run_to_file(potato_sim(steps=8), path, progress=stop_after(4), background=True)
    assert children[0].proc.returncode == 0
    partial = open_results(path)
    assert partial.step.values.tolist() == [0, 1, 2]
    assert partial.attrs["status"] == "running"
    run_to_file(potato_sim(steps=8), path, resume=True, background=True)
    straight = straight_run(steps=8)
    xr.testing.assert_identical(open_results(path).drop_vars(_timers(straight)),
                                straight.drop_vars(_timers(straight)))


@pytest.mark.parametrize("how", ["sigkill-run",
                                 pytest.param("sigint-group", marks=pytest.mark.slow)])
def test_a_run_killed_or_interrupted_leaves_the_steps_it_had_sent(how, tmp_path):
    """After step 3 was computed, SIGKILL of the run (not of its child), or SIGINT to the
    whole process group as Ctrl-C sends it: the child saves the steps it was sent (0-2), then
    exits (at the end of the pipe; it ignores SIGINT). The child saves nothing until a gate
    opens (after the signal), so that those steps are still in the pipe when the signal comes.
    The run then resumes to the uninterrupted result. The run holds the output directory's lock
    as the CLI does: the child holds it until it is done."""
    out = tmp_path / "out"
    out.mkdir()
    path = out / "results.nc"
    gate = tmp_path / "gate"
    script = textwrap.dedent(f"""
        import os, signal, sys
        from pathlib import Path
        sys.path.insert(0, {TESTS!r})
        os.environ["PYTHONPATH"] = {TESTS!r}
        os.environ["THIRDBODY_TEST_GATE"] = {str(gate)!r}
        from _faulty_writers import GatedWriter
        from test_results_append import potato_sim
        from thirdbody.cli.lock import lock
        from thirdbody.io import results, run_to_file

        held = lock(Path({str(out)!r}))

        results._StepWriter = GatedWriter   # the child waits: steps wait in the pipe
        made = []
        init = results._BackgroundWriter.__init__

        def record(self, *args, **kwargs):
            init(self, *args, **kwargs)
            made.append(self)

        results._BackgroundWriter.__init__ = record

        def progress(record):
            if record.step == 3:
                print(made[0].proc.pid, flush=True)
                if {how!r} == "sigkill-run":
                    os.kill(os.getpid(), signal.SIGKILL)
                os.killpg(0, signal.SIGINT)

        try:
            run_to_file(potato_sim(steps=8), {str(path)!r}, progress=progress,
                        background=True, keep_fds=(held.fileno(),))
        except KeyboardInterrupt:
            sys.exit(130)
    """)
    log = tmp_path / "log"
    with log.open("w") as err:          # not a pipe: the child keeps the run's stderr open
        proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                                stderr=err, text=True, start_new_session=True)
        child = int(proc.stdout.readline())
        if how == "sigkill-run":
            code = proc.wait(timeout=300)
            # the run is dead, its child still has steps to save: it holds the lock
            assert _alive(child)
            with (out / LOCK_NAME).open() as handle, pytest.raises(BlockingIOError):
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            gate.touch()
        else:
            gate.touch()                # the interrupted run waits for the child to finish
            code = proc.wait(timeout=300)
    assert code == (-signal.SIGKILL if how == "sigkill-run" else 130), log.read_text()
    deadline = time.monotonic() + 60
    while _alive(child):                    # it exits by itself, at the end of the pipe
        assert time.monotonic() < deadline, "the writing child did not exit"
        time.sleep(0.05)
    assert _lock_free(out / LOCK_NAME)          # released with the child
    on_disk = open_results(path)
    assert on_disk.step.values.tolist() == [0, 1, 2]
    assert on_disk[results.STEP_HISTORY_VARIABLE].size == 3
    run_to_file(potato_sim(steps=8), path, resume=True)
    straight = straight_run(steps=8)
    xr.testing.assert_identical(open_results(path).drop_vars(_timers(straight)),
                                straight.drop_vars(_timers(straight)))


def _lock_free(path, wait: float = 10.0) -> bool:
    """Whether the flock on ``path`` can be taken within ``wait`` s: the kernel may release the
    files of a process that has just exited a moment after it shows as ended."""
    deadline = time.monotonic() + wait
    with path.open() as handle:
        while True:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return True
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return False
                time.sleep(0.01)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, not reaped in a container without init, counts as
    ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_an_error_in_the_child_stops_the_run_with_that_error(monkeypatch, tmp_path, children):
    """A full disk while appending step 2: the run raises the child's OSError, the file holds
    steps 0 and 1."""
    from _faulty_writers import FullDiskWriter

    monkeypatch.setattr(results, "_StepWriter", FullDiskWriter)
    path = tmp_path / "r.nc"
    with pytest.raises(OSError, match="No space left"):
        run_to_file(potato_sim(steps=8), path, background=True)
    assert children[0].proc.returncode == 0
    assert open_results(path).step.values.tolist() == [0, 1]


def test_a_child_that_dies_stops_the_run(tmp_path, children):
    """The child killed after step 2: the run stops at a later step with a RuntimeError that
    says so (never finishes as if saved); the file holds whole steps."""
    def kill_the_child(record):
        if record.step == 2:
            while steps_on_disk(path) < 1:      # the child has written the first step
                time.sleep(0.01)
            os.kill(children[0].proc.pid, signal.SIGKILL)
            children[0].proc.wait()

    path = tmp_path / "r.nc"
    with pytest.raises(RuntimeError, match="saving the results died"):
        run_to_file(potato_sim(steps=8), path, progress=kill_the_child, background=True)
    on_disk = open_results(path)
    assert on_disk.step.values.tolist() == list(range(on_disk.sizes["step"]))
    assert 1 <= on_disk.sizes["step"] <= 3


def test_steps_bigger_than_the_pipe_all_reach_the_file(monkeypatch, tmp_path, children):
    """A one-page pipe (each step's frame is larger) and a slow child: the run waits at each
    step until the pipe has taken all of it, so that nothing waits in the run's memory (a
    SIGKILL loses only the step in progress); every step reaches the file."""
    from _faulty_writers import SlowWriter

    monkeypatch.setattr(results, "_StepWriter", SlowWriter)
    monkeypatch.setattr(results, "_PIPE_BYTES", 4096)
    waiting = []                        # bytes left in the run after each step's hand-over
    original = results._BackgroundWriter.__call__

    def call(self, sim, state):
        original(self, sim, state)
        waiting.append(len(self.backlog))

    monkeypatch.setattr(results._BackgroundWriter, "__call__", call)
    ds = run_to_file(potato_sim(steps=6), tmp_path / "r.nc", background=True)
    assert children[0].stats["appended"] == 5
    assert waiting == [0] * 6
    assert max(children[0].frame_bytes) > 4096
    straight = straight_run(steps=6)
    xr.testing.assert_identical(open_results(tmp_path / "r.nc").drop_vars(_timers(ds)),
                                straight.drop_vars(_timers(ds)))


def test_the_run_waits_for_a_child_more_than_a_few_steps_behind(monkeypatch, tmp_path,
                                                                 children):
    """The child, once ready, saves nothing until a gate opens (a second after the start): the
    run hands over steps 0 to _MAX_BEHIND - 1, then waits at step _MAX_BEHIND until the child
    has saved a step, so that no step after it is computed before the gate opened. After every
    step the run is at most _MAX_BEHIND steps ahead of the file, and holds nothing in memory.
    (The run is held at its first step until the child says it is ready: the bound holds from
    then on; the next test is about the time before.)"""
    import select
    import threading

    from _faulty_writers import GatedWriter

    gate = tmp_path / "gate"
    monkeypatch.setenv("THIRDBODY_TEST_GATE", str(gate))
    monkeypatch.setattr(results, "_StepWriter", GatedWriter)
    behind, waiting, computed = [], [], []
    original = results._BackgroundWriter.__call__

    def call(self, sim, state):
        while not self.ready:
            select.select([self.replies], [], [], 0.1)
            self._check()
        original(self, sim, state)
        behind.append(len(sim.records) - self.saved)
        waiting.append(len(self.backlog))

    monkeypatch.setattr(results._BackgroundWriter, "__call__", call)
    opener = threading.Timer(1.0, gate.touch)
    opener.start()
    try:
        ds = run_to_file(potato_sim(steps=8), tmp_path / "r.nc", background=True,
                         progress=lambda r: computed.append((r.step, gate.exists())))
    finally:
        opener.cancel()
    bound = results._MAX_BEHIND
    assert max(behind) <= bound and waiting == [0] * 8
    assert all(opened for step, opened in computed if step > bound), computed
    assert children[0].stats["appended"] == 7
    straight = straight_run(steps=8)
    xr.testing.assert_identical(open_results(tmp_path / "r.nc").drop_vars(_timers(ds)),
                                straight.drop_vars(_timers(ds)))


def test_the_run_does_not_wait_for_a_child_that_is_not_ready_yet(monkeypatch, tmp_path,
                                                                 children):
    """A child that starts slowly (it receives the writer only once a gate opens): the run
    computes and hands over all 8 steps meanwhile (the gate is opened by the run's last step; a
    run that waited for the child would only go on when a 60 s fallback opened it), then the
    child saves them all, and the file is the uninterrupted run."""
    import threading

    from _faulty_writers import LateWriter

    gate = tmp_path / "gate"
    monkeypatch.setenv("THIRDBODY_TEST_GATE", str(gate))
    monkeypatch.setattr(results, "_StepWriter", LateWriter)
    opened_by = []

    def progress(record):
        if record.step == 7 and not gate.exists():
            opened_by.append("the run")
            gate.touch()

    fallback = threading.Timer(60.0, lambda: (opened_by.append("fallback"), gate.touch()))
    fallback.start()
    try:
        ds = run_to_file(potato_sim(steps=8), tmp_path / "r.nc", background=True,
                         progress=progress)
    finally:
        fallback.cancel()
    assert opened_by == ["the run"]
    assert children[0].stats["appended"] == 7
    straight = straight_run(steps=8)
    xr.testing.assert_identical(open_results(tmp_path / "r.nc").drop_vars(_timers(ds)),
                                straight.drop_vars(_timers(ds)))
