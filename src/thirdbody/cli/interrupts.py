"""Ctrl-C in the commands that write results (run, sweep)."""

from __future__ import annotations


def interruptible() -> None:
    """From here on Ctrl-C is a KeyboardInterrupt, which the command handles (it says what is
    on disk). Until then (the imports, typer's parsing, which turns a KeyboardInterrupt into a
    silent exit 130) it ends the process with one line (thirdbody._interrupt)."""
    from .._interrupt import restore

    restore()


def defer_interrupts() -> list[int]:
    """From now on Ctrl-C is recorded, not raised (for the rest of the process): returns the
    list the signal numbers go to."""
    import signal

    seen: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: seen.append(signum))
    return seen
