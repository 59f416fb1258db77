"""The output directory's lock: one run at a time writes into a directory.

A run holds an exclusive ``fcntl.flock`` on ``OUT/.thirdbody.lock`` (which names its pid) for
as long as it lasts, and the child process that saves its results holds it too until it has
saved every step it was sent (see ``thirdbody.io.results._BackgroundWriter``). A second run
into the same directory is refused (exit 2) and told the holder's pid; if the holder is dead
(a killed run whose child still saves), it waits for the child, at most :data:`LOCK_WAIT` s.
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
    names the holder's pid. Returns the open lock file: keep it open."""
    import fcntl
    import os

    handle = (out / LOCK_NAME).open("a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.seek(0)
        holder = handle.read().strip() or "unknown"
        if not (_gone(holder) and _wait_for_lock(handle, holder)):
            handle.close()
            fail(f"-o {out} is in use by another thirdbody run (pid {holder}); wait for it or "
                 "choose another --out")
    handle.seek(0)
    handle.truncate()
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    return handle
