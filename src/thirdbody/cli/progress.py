"""What a run or a sweep shows while it goes on: a progress bar in a terminal; without one (a
SLURM log, ``nohup``, a pipe) plain lines, at most one per step and one per
:data:`LINE_SECONDS` seconds, so that a 10 000-step run does not flood its log; nothing with
``--quiet``."""

from __future__ import annotations

import sys
import time
from collections import Counter
from collections.abc import Callable

import typer

#: without a terminal, at most one progress line per this many seconds (and per step)
LINE_SECONDS = 10.0


def duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``2 h 07 min``."""
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


def step_text(record) -> str:
    """One step in a line: its index, the load, and the state (a layer: how many particles
    are in each state)."""
    particles = getattr(record, "particles", None)
    if particles is None or len(particles) == 1:
        return str(record)
    v = record.values
    counts = Counter(r.state for r in particles if r.state != "unloaded")
    states = ", ".join(f"{n} {state}" for state, n in sorted(counts.items()))
    network = ""
    if getattr(record, "contacts", None) is not None:       # particles that may touch
        network = (f"; {v['particle_contacts']} particle contacts, coordination "
                   f"{v['coordination']:.2f}")
    return (f"step {record.step}: F_N {v['total_force']:.4g} N, {v['loaded']} of "
            f"{len(particles)} loaded" + (f": {states}" if states else "") + network)


class Progress:
    """``total`` things (steps, cases) to do: :meth:`update` after each, :meth:`note` for a
    line of its own. A rich bar when stdout is a terminal, else plain lines with the elapsed
    time and an estimate of the time left."""

    def __init__(self, total: int, unit: str, quiet: bool = False,
                 every: float = LINE_SECONDS, terminal: bool | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.total, self.unit, self.quiet, self.every, self.clock = total, unit, quiet, every, clock
        self.terminal = sys.stdout.isatty() if terminal is None else terminal
        self.start = clock()
        self.first: int | None = None       # the first count updated (a resumed run's)
        self.last_line: float | None = None
        self.bar = None

    def __enter__(self) -> Progress:
        if self.terminal and not self.quiet:
            from rich.progress import BarColumn, TextColumn, TimeRemainingColumn
            from rich.progress import Progress as Bar

            self.bar = Bar(TextColumn("{task.description}"), BarColumn(),
                           TextColumn(f"{{task.completed}}/{{task.total}} {self.unit}"),
                           TimeRemainingColumn(), transient=False)
            self.bar.__enter__()
            self.task = self.bar.add_task("starting", total=self.total)
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
            self.bar = None

    def update(self, done: int, text: str, always: bool = False) -> None:
        """``done`` of the total are done, the last one described by ``text``; ``always``:
        print its line even if the last one was printed less than ``every`` s ago."""
        now = self.clock()
        if self.first is None:
            self.first = done - 1
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.update(self.task, completed=done, description=text)
            return
        due = self.last_line is None or now - self.last_line >= self.every
        if not (due or always or done >= self.total):
            return
        self.last_line = now
        elapsed = now - self.start
        line = f"[{done}/{self.total}] {text}; {duration(elapsed)} elapsed"
        ran = done - self.first
        if done < self.total and ran > 0:
            line += f", about {duration(elapsed / ran * (self.total - done))} left"
        typer.echo(line)

    def note(self, text: str) -> None:
        """A line of its own (what comes next, e.g. the figures being drawn)."""
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.console.print(text, highlight=False, markup=False)
        else:
            typer.echo(text)
