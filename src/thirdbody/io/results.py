"""Results files: NetCDF (HDF5, via xarray and h5netcdf), written after every load step.

Each write goes to a temporary file that then replaces the results file atomically
(``os.replace``), so the file on disk is always a complete, valid dataset of the steps done so
far: a reader can open it while the run goes on, and a run killed at any moment (Ctrl-C,
SIGKILL, a crash) loses at most the step in progress. While a run is incomplete the file also
holds its resume state (variable ``_resume_state``, the pickled solver state); ``--resume``
continues from it, and the finished file is the same as an uninterrupted run's (the per-step
wall-time variables ``time_*`` aside). The resume state is removed when the run ends. Only
resume files you made yourself: the state is a Python pickle.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["RESUME_VARIABLE", "open_results", "run_to_file", "write_results"]

RESUME_VARIABLE = "_resume_state"


def write_results(ds, path: str | Path, resume_state: bytes | None = None) -> None:
    """Write ``ds`` to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    if resume_state is not None:
        ds = ds.assign({RESUME_VARIABLE: (("resume_bytes",),
                                          np.frombuffer(resume_state, dtype=np.uint8),
                                          {"long_name": "pickled state to resume the run"})})
    ds.to_netcdf(tmp, engine="h5netcdf")
    os.replace(tmp, path)


def open_results(path: str | Path):
    """Load a results file into memory (the file is not kept open)."""
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()


def run_to_file(sim, path: str | Path, *, resume: bool = False,
                progress: Callable | None = None, attrs: dict | None = None):
    """Run ``sim``, writing ``path`` after every step; with ``resume`` continue the run saved
    there. ``attrs`` are added to the file's global attributes. Returns the final dataset."""
    path = Path(path)
    blob = None
    if resume:
        if not path.exists():
            raise FileNotFoundError(f"nothing to resume: {path} does not exist")
        saved = open_results(path)
        if RESUME_VARIABLE not in saved:
            raise ValueError(f"{path} holds a finished run ({saved.attrs.get('status')}); "
                             "nothing to resume")
        blob = saved[RESUME_VARIABLE].values.tobytes()

    extra = dict(attrs or {})

    def checkpoint(simulation, state) -> None:
        write_results(simulation.dataset().assign_attrs(extra), path, simulation.snapshot(state))

    ds = sim.run(progress=progress, checkpoint=checkpoint, resume_from=blob).assign_attrs(extra)
    write_results(ds, path)
    return ds
