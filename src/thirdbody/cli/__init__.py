"""The ``thirdbody`` command line: run, sweep, plot, export-vtk, examples, validate.

One module per command, named after it (``run.py``, ``sweep.py``, ``plot.py`` with
``export-vtk``, ``examples.py``, ``validate.py``), plus what they share: ``app.py`` (the
commands put together, the entry point ``main``), ``errors.py`` (refusals, exit 2),
``interrupts.py`` (Ctrl-C) and ``lock.py`` (the output directory's lock).

Exit codes: 0 success; 1 a run that stopped on a failed step, or a validation check out of
tolerance; 2 bad input (configuration, file, option); 130 interrupted (resume with --resume).
"""

from .app import app, main

__all__ = ["app", "main"]
