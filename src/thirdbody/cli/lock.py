"""The output directory's lock: one run at a time writes into a directory.

A run holds an exclusive ``fcntl.flock`` on ``OUT/.thirdbody.lock`` (which names its pid) for
as long as it lasts, and the child process that saves its results holds it too until it has
saved every step it was sent (see ``thirdbody.io.results._BackgroundWriter``). A second run
into the same directory is refused (exit 2) and told the holder's pid; if the holder is dead
(a killed run whose child still saves), it waits for the child, at most :data:`LOCK_WAIT` s.

A run that ends removes the file (:func:`unlock`), unless its child still holds the lock. A
run that was killed leaves it behind, naming a dead pid: the next run takes it over. Whoever
locks the file checks that it is still the file at that path, since the run that held it may
have removed it between the open and the lock; if it was, it locks the new one.
"""

from __future__ import annotations

import time
from pathlib import Path

import typer

from .errors import fail

LOCK_NAME = ".thirdbody.lock"

#: seconds a run waits for the lock of a run that was killed while its child process finishes
#: saving the steps it was sent (see thirdbody.io.results._BackgroundWriter)
LOCK_WAIT = 60.0


def _gone(pid: str) -> bool:
    """Whether no process has the id ``pid`` (the lock file's text)."""
    import os

    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except (ValueError, OSError):
        return False
    return False


def _wait_for_lock(handle, holder: str) -> bool:
    """The run that holds the lock (pid ``holder``) is dead: its child process that saves the
    results still holds it for the steps it was sent. Wait for it (at most LOCK_WAIT s)."""
    import fcntl

    typer.echo(f"waiting for the killed run's (pid {holder}) saving of its last steps to "
               "finish", err=True)
    deadline = time.monotonic() + LOCK_WAIT
    while time.monotonic() < deadline:
        time.sleep(0.05)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except OSError:
            continue
    return False


def lock(out: Path):
    """An exclusive lock on the output directory for as long as the run lasts (fcntl; released
    when the process ends, however it ends). A second run into the same directory exits 2 and
    names the holder's pid. Returns the open lock file: keep it open, and give it to
    :func:`unlock` at the end."""
    import fcntl
    import os

    path = out / LOCK_NAME
    while True:
        handle = path.open("a+")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            if not (_gone(holder) and _wait_for_lock(handle, holder)):
                handle.close()
                fail(f"-o {out} is in use by another thirdbody run (pid {holder}); wait for it "
                     "or choose another --out")
        if _is_at(handle, path):
            break
        handle.close()          # removed by the run that held it: lock the one there now
    handle.seek(0)
    handle.truncate()
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    return handle


def _is_at(handle, path: Path) -> bool:
    """Whether the open file ``handle`` is the file at ``path`` (not one removed since)."""
    import os

    try:
        there = os.stat(path)
    except FileNotFoundError:
        return False
    mine = os.fstat(handle.fileno())
    return (mine.st_dev, mine.st_ino) == (there.st_dev, there.st_ino)


def unlock(out: Path, handle) -> None:
    """Release the lock taken by :func:`lock` and remove the lock file, unless someone still
    holds the lock: the child saving a run's results shares the run's lock (an interrupt may
    have cut the run's wait for it short), or another run has taken it meanwhile."""
    import fcntl

    path = out / LOCK_NAME
    handle.close()
    try:
        again = path.open("r")
    except FileNotFoundError:
        return
    with again:
        try:
            fcntl.flock(again, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return
        if _is_at(again, path):
            path.unlink()
