"""Checkpoints of a simulation: what a run needs to continue after its last completed step.

A snapshot holds the inputs (to refuse resuming a different run), the particles' states, the
records and maps so far, and each interface's last normal solve (the next step's warm start),
so that a resumed run ends exactly as an uninterrupted one. It is a Python pickle: only load
snapshots you made yourself.

A results file stores the history (records and maps) one step at a time instead, next to a
snapshot without it (``history=False``, a size that does not grow with the run), and puts the
two together again with :func:`with_history` to resume.
"""

from __future__ import annotations

import pickle
from typing import TYPE_CHECKING

from .records import has_maps

if TYPE_CHECKING:
    from .simulation import LayerState, Simulation

__all__ = ["restore", "snapshot", "with_history"]


def snapshot(sim: Simulation, state: LayerState, *, history: bool = True) -> bytes:
    """Pickle everything needed to continue ``sim`` after its last completed step (without the
    records and maps if not ``history``: :func:`with_history` adds them)."""
    data = {
        "inputs": sim.inputs(), "state": state,
        "interfaces": [{k: i.last for k, i in m.interfaces.items()} for m in sim.members],
        "points": [(m.points, m._points_key) for m in sim.members],
    }
    if history:
        data.update(records=sim.records, maps=sim.maps)
    return pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)


def with_history(blob: bytes, records: list, maps: list) -> bytes:
    """A snapshot made with ``history=False``, completed with the run's records and maps."""
    data = pickle.loads(blob)
    data.update(records=list(records), maps=list(maps))
    return pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)


def restore(sim: Simulation, blob: bytes) -> tuple[LayerState, int]:
    """Load a :func:`snapshot` into ``sim``; returns (state, index of the next step).

    Raises ValueError if the snapshot was made with different inputs.
    """
    data = pickle.loads(blob)
    if data["inputs"] != sim.inputs():
        raise ValueError("cannot resume: the results were made with different inputs")
    if "records" not in data:
        raise ValueError("cannot resume: the snapshot holds no records (made with "
                         "history=False; complete it with with_history)")
    # (a layer's snapshot made before Simulation.run dropped empty maps entries may hold some)
    sim.records, sim.maps = list(data["records"]), [m for m in data["maps"] if has_maps(m)]
    for m, lasts, (points, points_key) in zip(sim.members, data["interfaces"], data["points"],
                                              strict=True):
        for k, last in lasts.items():
            m.interfaces[k].last = last
        m.points, m._points_key = points, points_key
    return data["state"], len(sim.records)
