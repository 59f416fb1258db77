"""Ctrl-C while the command line is still importing: exit 130 with one line, no traceback.

Importing this module (``thirdbody/__init__.py`` does it first) calls :func:`guard`, which acts
when the process is the ``thirdbody`` command (or ``python -m thirdbody``), so that an
interrupt during the ~0.5 s of imports ends the process quietly. It is called here, not after
the import, so that no instant passes between this module being imported and the guard being in
place; the ``run`` and ``sweep`` commands call :func:`restore` first thing (after the
imports and typer's parsing, which would turn a KeyboardInterrupt into a silent exit), and from
then on Ctrl-C is a ``KeyboardInterrupt`` that they handle (a run keeps its completed steps).
The other commands end quietly on Ctrl-C. Importing thirdbody as a library leaves the signal alone.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

__all__ = ["guard", "restore"]


def _quiet(signum, frame) -> None:  # pragma: no cover - runs in a subprocess test
    os.write(2, b"\ninterrupted\n")
    os._exit(130)


def _is_command() -> bool:
    first = sys.argv[0] if sys.argv else ""
    return Path(first).name == "thirdbody" or first == "-m" or \
        Path(first).parts[-2:] == ("thirdbody", "__main__.py")


def guard() -> None:
    """Make Ctrl-C exit 130 quietly, if this process is the thirdbody command."""
    if _is_command() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        try:
            signal.signal(signal.SIGINT, _quiet)
        except ValueError:          # not the main thread
            pass


def restore() -> None:
    """Ctrl-C raises KeyboardInterrupt again (Python's default)."""
    if signal.getsignal(signal.SIGINT) is _quiet:
        signal.signal(signal.SIGINT, signal.default_int_handler)


guard()
