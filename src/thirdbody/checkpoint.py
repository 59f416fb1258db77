"""Checkpoints of a run: what it needs to continue after its last completed step.

A snapshot is the run's inputs (to refuse resuming a different run), its
:class:`~thirdbody.state.LayerState` (every particle's pose, tangential histories and warm
starts: a resumed run ends exactly as an uninterrupted one) and the records and maps so far. It
is a Python pickle: only load snapshots you made yourself.

A results file stores the history (records and maps) one step at a time instead, next to a
snapshot without it (a size that does not grow with the run), and puts the two together again
with :func:`with_history` to resume.
"""

from __future__ import annotations

import pickle

from .records import has_maps
from .state import LayerState

__all__ = ["restore", "snapshot", "with_history"]


def snapshot(inputs: dict, state: LayerState, history: tuple[list, list] | None = None) -> bytes:
    """Pickle ``inputs`` (the run's, as plain data), ``state`` and, if given, the ``history``
    (records, maps) so far."""
    data = {"inputs": inputs, "state": state}
    if history is not None:
        data.update(records=list(history[0]), maps=list(history[1]))
    return pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)


def with_history(blob: bytes, records: list, maps: list) -> bytes:
    """A snapshot made without its history, completed with the run's records and maps."""
    data = pickle.loads(blob)
    data.update(records=list(records), maps=list(maps))
    return pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)


def restore(blob: bytes, inputs: dict) -> tuple[LayerState, list, list]:
    """Load a :func:`snapshot`; returns (state, records, maps).

    Raises ValueError if the snapshot was made with inputs other than ``inputs``, or holds no
    history.
    """
    data = pickle.loads(blob)
    if data["inputs"] != inputs:
        raise ValueError("cannot resume: the results were made with different inputs")
    if "records" not in data:
        raise ValueError("cannot resume: the snapshot holds no records (made without its "
                         "history; complete it with with_history)")
    if "interfaces" in data:
        raise ValueError("cannot resume: the snapshot was made by an earlier thirdbody (its "
                         "warm starts lived outside the state); run it again")
    return data["state"], list(data["records"]), [m for m in data["maps"] if has_maps(m)]
