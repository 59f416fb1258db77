"""``thirdbody plot`` and ``thirdbody export-vtk``: figures and ParaView files from a results
file that is already written."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .errors import fail
from .run import open_or_fail


def plot(results: Annotated[Path, typer.Argument(
        help="a results.nc file, or a sweep's summary.nc")],
         out: Annotated[Path | None, typer.Option("-o", "--out",
                                                  help="directory (default: next to it)")] = None,
         quiet: Annotated[bool, typer.Option(
             "--quiet", "-q", help="do not list the files written")] = False,
         ) -> None:
    """Redraw every figure from a results file (or the state map from a sweep summary)."""
    from ..plot import save_all

    ds = open_or_fail(results)
    title = str(ds.attrs.get("title", ""))
    if not title.startswith("thirdbody") and "behaviour" not in ds:
        fail(f"{results} is not a thirdbody results file (no 'thirdbody' title attribute); "
             "plot reads the results.nc of `thirdbody run` or a sweep's summary.nc")
    if "behaviour" in ds:                       # a sweep's summary.nc
        from ..plot import save_state_map

        written = save_state_map(ds, out or results.parent)
    else:
        written = save_all(ds, out or results.parent)
    for path in [] if quiet else written:
        typer.echo(str(path))


def export_vtk(results: Annotated[Path, typer.Argument(help="a results.nc file")],
               out: Annotated[Path, typer.Argument(help="directory for the .vtu/.pvd files")],
               ) -> None:
    """Write each particle's surface at its pose with pressure, traction and stick/slip status
    on it, one .vtu file per load step plus a .pvd time series (ParaView)."""
    from ..io.vtk import export_vtk_cli

    code = export_vtk_cli(results, out)
    if code:
        raise typer.Exit(code)
