"""A case's results file: reading it for the summary, and setting aside one that cannot be
read."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import schema
from ..io.results import RESUME_VARIABLE, open_results


class UnreadableCase(OSError):
    """A case file exists but cannot be read (damaged, or locked by HDF5 on a network file
    system). It is never deleted: a run moves it aside (:func:`_set_aside`) and recomputes."""


def _set_aside(path: Path) -> Path:
    """Rename an unreadable case file to ``<name>.unreadable-<n>`` (kept for inspection)."""
    n = 1
    while (target := path.with_name(f"{path.name}.unreadable-{n}")).exists():
        n += 1
    path.rename(target)
    return target


def _case_status(path: Path) -> str | None:
    """The status of a finished case file, None (absent or partial), or ``"unreadable"``.
    Reads only: changes nothing on disk (``--dry-run``)."""
    try:
        case = _read_case(path, ())
    except UnreadableCase:
        return "unreadable"
    if case is None or case.partial:
        return None
    return case.status


@dataclass
class _CaseData:
    status: str
    partial: bool                       # holds a resume state: the run is not finished
    inputs: str                         # the ``inputs`` attribute (JSON)
    version: str                        # the thirdbody version that wrote it
    arrays: dict[str, np.ndarray]
    attrs: dict[str, dict]


_KEPT_ATTRS = ("units", "long_name", "flag_values", "flag_meanings")


def _read_case(path: Path, names: Iterable[str]) -> _CaseData | None:
    """Read a case file's status and the per-step variables ``names`` straight through h5py
    (faster than xarray, and the summary reads every case). None if there is no file; an unreadable
    file raises :class:`UnreadableCase` and is left as it is."""
    import h5py

    if not path.exists():
        return None
    try:
        with h5py.File(path, "r") as f:
            old = int(np.ravel(f.attrs.get("thirdbody_format", 1))[0]) < schema.FORMAT_VERSION
            arrays, attrs = {}, {}
            for name in () if old else names:
                if name in f:
                    arrays[name] = f[name][()]
                    attrs[name] = {k: _text(v) for k, v in f[name].attrs.items()
                                   if k in _KEPT_ATTRS}
            case = _CaseData(_text(f.attrs.get("status", "complete")), RESUME_VARIABLE in f,
                             _text(f.attrs.get("inputs", "")),
                             _text(f.attrs.get("thirdbody_version", "")), arrays, attrs)
        if old and not case.partial:        # an earlier format: read in today's form
            ds = open_results(path)
            for name in names:
                if name in ds:
                    case.arrays[name] = ds[name].values
                    case.attrs[name] = {k: v for k, v in ds[name].attrs.items()
                                        if k in _KEPT_ATTRS}
        return case
    except OSError as exc:
        raise UnreadableCase(f"{path}: {exc}") from None


def _text(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray) and value.dtype.kind in "SO":
        return " ".join(_text(v) for v in value)
    return value
