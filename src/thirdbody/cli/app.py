"""The ``thirdbody`` command: its sub-commands put together, and the entry point."""

from __future__ import annotations

import sys

import typer

from . import examples, plot, run, sweep, validate

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="A deformable third-body particle between two plates (FFT-BEM).")
app.command()(run.run)
app.command()(sweep.sweep)
app.command()(plot.plot)
app.command("export-vtk")(plot.export_vtk)
app.command()(validate.validate)
app.add_typer(examples.app, name="examples")


def main() -> None:  # pragma: no cover - console entry point
    try:
        app(prog_name="thirdbody")
    except KeyboardInterrupt:
        sys.stderr.write("\ninterrupted\n")
        sys.exit(130)
