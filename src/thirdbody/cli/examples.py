"""``thirdbody examples``: list the bundled examples, copy one to edit it."""

from __future__ import annotations

import shutil
from importlib import resources
from pathlib import Path
from typing import Annotated

import typer

from . import _help
from .errors import fail

app = typer.Typer(help="The bundled examples: the paper's figures, a mesh grain, a layer and a "
                       "sweep (listed without a command; `copy` one to edit it).",
                  invoke_without_command=True, cls=_help.Group)


def bundled() -> dict[str, Path]:
    """Bundled examples by name: the TOML configurations, and ``fig2`` (a Python script: the
    single-interface partial-slip example, run with ``python fig2.py --out DIR``)."""
    root = resources.files("thirdbody") / "examples"
    found = {p.name.removesuffix(".toml"): Path(str(p)) for p in root.iterdir()
             if p.name.endswith(".toml")}
    found["fig2"] = Path(str(root / "fig2_partial_slip.py"))
    return found


@app.callback()
def examples(ctx: typer.Context) -> None:
    """List the bundled examples."""
    if ctx.invoked_subcommand is None:
        for name, path in sorted(bundled().items()):
            if path.suffix == ".py":
                first = ("Fig. 2: partial slip of a tilted ellipsoid on a plate shifted in steps "
                         "(a script: python fig2.py --out DIR)")
            else:
                first = path.read_text().splitlines()[0].lstrip("# ")
            typer.echo(f"{name:12s} {first}")


@app.command("copy", cls=_help.Command)
def copy(name: Annotated[str, typer.Argument(help="example name")],
         directory: Annotated[Path, typer.Argument(help="where to copy it")]) -> None:
    """Copy an example configuration so you can edit it."""
    found = bundled()
    if name not in found:
        fail(f"no example {name!r}; choose one of: {', '.join(sorted(found))}")
    directory.mkdir(parents=True, exist_ok=True)
    target = directory / f"{name}{found[name].suffix}"
    shutil.copyfile(found[name], target)
    typer.echo(str(target))
    if found[name].suffix == ".toml":       # a mesh file next to the configuration goes along
        import tomllib

        mesh = tomllib.loads(found[name].read_text()).get("particle", {}).get("file")
        if mesh and not Path(mesh).is_absolute():
            shutil.copyfile(found[name].parent / mesh, directory / mesh)
            typer.echo(str(directory / mesh))
