"""The sweep summary of one case: a case that never turned rotated by exactly zero, and the
final ratios are signed like the state plot's."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation


def _case(quaternions, turned, forces, ratio_low):
    from thirdbody.sweep import _CaseData

    n = len(turned)
    # one particle: the per-particle variables along (step, particle = 1)
    arrays = {"turned": np.asarray(turned, dtype=np.int8)[:, None],
              "state": np.zeros((n, 1), dtype=np.int8),
              "quaternion": np.asarray(quaternions, dtype=float)[:, None],
              "ratio": np.stack([np.full(n, 0.5), ratio_low], axis=1)[:, None],
              "compression": np.linspace(0.01, 0.03, n), "total_force": np.arange(1.0, n + 1),
              "loaded": np.ones(n, dtype=np.int64), "fraction_stick": np.ones(n),
              "fraction_roll": np.zeros(n), "fraction_rotate": np.zeros(n),
              "time_total": np.ones(n),
              "tangential_force": np.asarray(forces, dtype=float)[:, None]}
    start = Rotation.from_euler("y", 20, degrees=True).as_quat()
    return _CaseData("complete", False, json.dumps({"quaternion": list(start)}), "0", arrays, {})

def test_a_case_that_never_turned_rotated_by_exactly_zero():
    from thirdbody.sweep import _case_summary

    # the stored orientation is the input's up to round-off (another route to the same turn)
    same = Rotation.from_euler("y", 20, degrees=True).as_quat()
    for _ in range(8):
        same[1] = np.nextafter(same[1], 1.0)
    off = (Rotation.from_quat(same) * Rotation.from_euler("y", 20, degrees=True).inv())
    assert off.magnitude() > 0                       # the round-off the summary must not report
    out = _case_summary(_case([same] * 3, [0, 0, 0], [[1.0, 0.0]] * 3, [0.2, 0.3, 0.4]))
    assert out["total_rotation"] == 0.0 and math.copysign(1.0, out["total_rotation"]) == 1.0
    assert math.isnan(out["turn_azimuth"])

def test_final_ratios_are_signed_like_the_state_plot():
    """F' reverses (its x component changes sign) in the last step: the summary reports the
    ratio negative, as the plot draws it; a run that keeps its direction stays positive."""
    from thirdbody.plot import _signed
    from thirdbody.sweep import _case_summary

    q = [Rotation.from_euler("y", 20, degrees=True).as_quat()] * 3
    forces = [[0.0, 0.0], [2.0, 0.5], [-1.0, 0.1]]
    out = _case_summary(_case(q, [0, 0, 0], forces, [0.2, 0.3, 0.072]))
    assert out["final_ratio_low"] == -0.072
    assert out["final_ratio_up"] == -0.5
    # the same sign as the plot's: computed here by hand, F'·F'_first < 0
    assert float(np.dot(forces[2], forces[1])) < 0
    import xarray as xr
    ds = xr.Dataset({"tangential_force": (("step", "component"), np.array(forces))})
    assert _signed(ds)[-1] == -1.0
    kept = _case_summary(_case(q, [0, 0, 0], [[1.0, 0.0]] * 3, [0.2, 0.3, 0.4]))
    assert kept["final_ratio_low"] == 0.4


def test_the_steady_mu_eff_of_a_sliding_case_is_over_the_last_half_of_its_distance():
    """Compression (2 steps, no sliding), then increments of 1, 1, 2, 1, 3 µm: 8 µm in all.
    The last half, (4, 8] µm, holds the steps that end at 5 and 8 µm (the one ending at 4 µm
    slid in the first half); their μ_eff 0.3 and 0.4, weighted by their increments 1 and
    3 µm: mean (0.3 + 3 · 0.4) / 4 = 0.375, deviation √((0.075² + 3 · 0.025²) / 4)
    = 0.04330, smallest 0.3, largest 0.4."""
    from thirdbody.sweep import _case_summary

    distance = 1e-6 * np.array([0.0, 0.0, 1.0, 2.0, 4.0, 5.0, 8.0])
    mu = np.array([np.nan, np.nan, 0.1, 0.2, 0.25, 0.3, 0.4])
    n = len(mu)
    q = [Rotation.from_euler("y", 20, degrees=True).as_quat()] * n
    case = _case(q, [0] * n, [[1.0, 0.0]] * n, np.full(n, 0.3))
    case.arrays.update(sliding_distance=distance, mu_eff_sliding=mu)
    out = _case_summary(case)
    assert out["steady_mu_eff"] == pytest.approx(0.375, rel=1e-12)
    assert out["steady_mu_eff_std"] == pytest.approx(math.sqrt((0.075**2 + 3 * 0.025**2) / 4),
                                                     rel=1e-12)
    assert out["steady_mu_eff_std"] == pytest.approx(0.0433013, rel=1e-6)
    assert (out["steady_mu_eff_min"], out["steady_mu_eff_max"]) == (0.3, 0.4)
    assert out["final_sliding_distance"] == 8e-6
    # the plates never slid (or a file from before sliding plates): NaN, distance 0
    case.arrays.update(sliding_distance=np.zeros(n), mu_eff_sliding=np.full(n, np.nan))
    still = _case_summary(case)
    for name in ("steady_mu_eff", "steady_mu_eff_std", "steady_mu_eff_min",
                 "steady_mu_eff_max"):
        assert math.isnan(still[name]), name
    assert still["final_sliding_distance"] == 0.0
    for name in ("sliding_distance", "mu_eff_sliding"):
        del case.arrays[name]
    assert math.isnan(_case_summary(case)["steady_mu_eff"])


def test_the_summary_names_its_steady_mu_eff_with_units():
    from thirdbody import schema

    for name in ("steady_mu_eff", "steady_mu_eff_std", "steady_mu_eff_min",
                 "steady_mu_eff_max"):
        assert schema.VARIABLES[name].kind == "summary" and schema.VARIABLES[name].units == "1"
    assert schema.VARIABLES["final_sliding_distance"].units == "m"
    assert schema.parameter_units("network.mu_pp") == "1"


@pytest.mark.parametrize("state", ["stick", "roll_upper", "roll_lower", "rotate", "roll"])
def test_the_behaviour_is_the_state_of_the_first_turn_whatever_it_was(state):
    """Every state a particle can be in when it turns (:func:`thirdbody.network.run.particle_state`
    with ``turned``; the layer's states are the first four) is a behaviour of its own: a network
    run's particle that turned while touching particles ("roll") was summarised as "failed"
    although its case completed."""
    from thirdbody.schema import BEHAVIOURS, STATES
    from thirdbody.sweep import _case_summary

    q = [Rotation.from_euler("y", 20, degrees=True).as_quat()] * 3
    case = _case(q, [0, 1, 1], [[1.0, 0.0]] * 3, [0.2, 0.3, 0.4])
    case.arrays["state"][1:, 0] = STATES.index(state)
    assert BEHAVIOURS[_case_summary(case)["behaviour"]] == state
