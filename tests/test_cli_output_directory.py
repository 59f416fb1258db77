"""The output directory of `thirdbody run`: an unusable one is refused before anything is
written, a run directory is never damaged (a resume with other inputs touches nothing), and its
lock lets one run at a time write into it."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

import thirdbody as tb
from _cli import SMALL, _cli, _refused, _snapshot
from thirdbody.cli.lock import LOCK_NAME
from thirdbody.io import open_results


def test_unusable_output_directories_are_refused(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out, needle in ((afile, "not a directory"), (afile / "below", "is a file")):
        code, text = _cli("run", str(config), "-o", str(out))
        _refused(code, text, str(afile), needle)
    assert afile.read_text() == "x"
    if os.geteuid() != 0:                              # root may write anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        code, text = _cli("run", str(config), "-o", str(locked / "out"))
        _refused(code, text, "permission")

def test_resume_into_a_missing_directory_creates_nothing(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    code, text = _cli("run", str(config), "-o", str(tmp_path / "nowhere"), "--resume")
    _refused(code, text, "nothing to resume")
    assert not (tmp_path / "nowhere").exists()

def _partial_run(tmp_path: Path, config: Path) -> Path:
    """A run stopped after two of its four steps, through the CLI's own writer."""
    from thirdbody.io import load_config, run_to_file

    out = tmp_path / "partial"
    out.mkdir()
    (out / "config.toml").write_text(config.read_text())
    body, plates, load, numerics = load_config(config).build()
    sim = tb.Simulation(body, plates, load, **numerics)

    def stop(record):
        if record.step == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_file(sim, out / "results.nc", progress=stop)
    return out

@pytest.mark.slow
def test_resume_with_other_inputs_touches_nothing(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    other = tmp_path / "other.toml"
    other.write_text(SMALL.replace("mu_up = 0.46", "mu_up = 0.3"))
    # a finished run
    code, text = _cli("run", str(config), "-o", str(tmp_path / "done"), "--no-plots")
    assert code == 0, text
    before = _snapshot(tmp_path / "done")
    code, text = _cli("run", str(other), "-o", str(tmp_path / "done"), "--resume")
    _refused(code, text, "finished run")
    assert _snapshot(tmp_path / "done") == before
    # an unfinished one
    partial = _partial_run(tmp_path, config)
    assert open_results(partial / "results.nc").sizes["step"] >= 1
    before = _snapshot(partial)
    code, text = _cli("run", str(other), "-o", str(partial), "--resume")
    _refused(code, text, "different inputs")
    assert _snapshot(partial) == before
    code, text = _cli("run", str(config), "-o", str(partial), "--resume", "--no-plots")
    assert code == 0, text                              # the right config still resumes

def test_a_second_run_into_a_locked_directory_names_the_holder(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    out = tmp_path / "out"
    out.mkdir()
    with (out / LOCK_NAME).open("a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        held.write(f"{os.getpid()}\n")             # a live holder
        held.flush()
        start = time.monotonic()
        code, text = _cli("run", str(config), "-o", str(out))
        _refused(code, text, "in use", f"pid {os.getpid()}")
        assert "waiting" not in text and time.monotonic() - start < 30   # refused at once
    assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]      # nothing else written
    code, text = _cli("run", str(config), "-o", str(out), "--no-plots")
    assert code == 0, text                                        # released: it runs
    assert not (out / LOCK_NAME).exists()                         # and removed at its end

def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid

def test_a_lock_held_for_a_killed_run_is_waited_for(tmp_path):
    """A killed run's child process that saves its last steps holds the lock (the file names
    the dead run): the next run waits for it instead of refusing."""
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, sys\n"
         f"h = open({str(out / LOCK_NAME)!r}, 'a+'); fcntl.flock(h, fcntl.LOCK_EX)\n"
         f"h.write('{_dead_pid()}\\n'); h.flush(); print('held', flush=True)\n"
         "sys.stdin.readline()"],                  # holds the lock until told to let go
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline() == "held\n"
    run = subprocess.Popen([sys.executable, "-m", "thirdbody", "run", str(config), "-o",
                            str(out), "--no-plots"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    first = run.stderr.readline()
    assert "waiting for the killed run" in first, first
    assert run.poll() is None                   # still waiting
    holder.communicate("go\n", timeout=30)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 0, stderr
    assert (out / "results.nc").exists()
    assert not (out / LOCK_NAME).exists()


def test_a_crashed_runs_stale_lock_is_taken_over_and_removed(tmp_path):
    """A killed run leaves its lock file, naming a dead pid, held by nobody: the next run
    takes it over, and removes it when it ends."""
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_NAME).write_text(f"{_dead_pid()}\n")
    code, text = _cli("run", str(config), "-o", str(out), "--no-plots")
    assert code == 0, text
    assert "waiting" not in text
    assert not (out / LOCK_NAME).exists()


def test_a_lock_file_removed_as_another_run_opens_it_is_not_shared(tmp_path, monkeypatch):
    """The run holding the lock ends (and removes the file) between a second run's open and
    its lock: the second run must lock the file now at the path, so that a third is still
    refused. Without the check it would hold a lock on the removed file, and the third run
    would create a new one and run too."""
    import typer

    from thirdbody.cli import lock as lock_module

    first = lock_module.lock(tmp_path)
    flock, ended = fcntl.flock, []

    def first_ends_now(handle, operation):
        if not ended:
            ended.append(True)
            lock_module.unlock(tmp_path, first)
        return flock(handle, operation)

    monkeypatch.setattr(fcntl, "flock", first_ends_now)
    second = lock_module.lock(tmp_path)
    monkeypatch.setattr(fcntl, "flock", flock)
    assert ended
    assert os.fstat(second.fileno()).st_ino == os.stat(tmp_path / LOCK_NAME).st_ino
    with pytest.raises(typer.Exit) as refused:
        lock_module.lock(tmp_path)
    assert refused.value.exit_code == 2
    lock_module.unlock(tmp_path, second)
    assert not (tmp_path / LOCK_NAME).exists()
