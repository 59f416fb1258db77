"""The simulation's error and warning classes: a contact that outgrows its window is a runtime
error (the inputs were valid), and a stopped run warns with its own class."""

from __future__ import annotations

import pytest

import thirdbody as tb
from thirdbody.shapes import Sphere


def _sphere_run(load, maps_every: int = 1):
    sim = tb.Simulation(tb.Particle(Sphere(0.5e-3), tb.Material(1e9, 0.3)), tb.Plates(0.3),
                        load, resolution=20, maps_every=maps_every)
    return sim.run()

def test_contact_at_edge_is_a_runtime_error():
    # the inputs were valid: the solution outgrew its window, like a ConvergenceError
    assert issubclass(tb.ContactAtEdgeError, RuntimeError)
    assert not issubclass(tb.ContactAtEdgeError, ValueError)

def test_a_stopped_run_warns_with_its_own_class():
    assert issubclass(tb.SimulationStoppedWarning, RuntimeWarning)
    # a load far beyond the half-space model: the run stops, with this warning only
    with pytest.warns(tb.SimulationStoppedWarning, match="simulation stopped"):
        ds = _sphere_run(tb.LinearRamp(stop=1e7, steps=1), maps_every=0)
    assert ds.attrs["status"].startswith("failed")
