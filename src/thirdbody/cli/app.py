"""The ``thirdbody`` command: its sub-commands put together, and the entry point."""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from .._version import __version__
from . import _help, examples, plot, run, sweep, validate

app = typer.Typer(add_completion=False, no_args_is_help=True, cls=_help.Group,
                  help=f"thirdbody {__version__}: a deformable third-body particle between two "
                       "plates (FFT-BEM).")
app.command(cls=_help.Command)(run.run)
app.command(cls=_help.Command)(sweep.sweep)
app.command(cls=_help.Command)(plot.plot)
app.command("export-vtk", cls=_help.Command)(plot.export_vtk)
app.command(cls=_help.Command)(validate.validate)
app.add_typer(examples.app, name="examples")


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"thirdbody {__version__}")
        raise typer.Exit()


@app.callback()
def _options(version: Annotated[bool, typer.Option(
        "--version", callback=_print_version, is_eager=True,
        help="print the version and exit")] = False) -> None:
    pass


def main() -> None:  # pragma: no cover - console entry point
    try:
        app(prog_name="thirdbody")
    except KeyboardInterrupt:
        sys.stderr.write("\ninterrupted\n")
        sys.exit(130)
