"""A sweep's summary: each case's scalars and, where the cases agree on the steps, their per-step
values, along the sweep axes (``summary.nc``, ``summary.csv``)."""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from .. import schema
from ..io.results import write_results
from ..records import direction_sign
from ..schema import BEHAVIOURS, STATES
from .cases import UnreadableCase, _CaseData, _read_case
from .spec import _BEHAVIOUR_CODE, Case, Sweep

# --- the summary -----------------------------------------------------------------------------
#: what a case's scalar summary reads, besides the variables whose steps the summary keeps
_SUMMARY_INPUTS = ("turned", "state", "quaternion", "ratio", "compression", "total_force",
                   "time_total", "tangential_force", "loaded", "fraction_stick",
                   "fraction_roll", "fraction_rotate", "sliding_distance", "mu_eff_sliding")


def _summary_names() -> tuple[str, ...]:
    """The variables a case file is read for: the scalar summary's inputs and every variable
    whose per-step values the summary keeps (:attr:`thirdbody.schema.Variable.summary`)."""
    kept = (v.name for v in schema.VARIABLES.values() if v.summary)
    return tuple(dict.fromkeys((*_SUMMARY_INPUTS, *kept)))


def _total_rotation(case: _CaseData) -> tuple[float, float]:
    """The angle (degrees) from the initial to the final orientation of a case's one particle,
    signed by the side of +y its axis points to (for the paper's turns about y: the change of
    θ), and the azimuth of its axis (degrees from +x)."""
    from scipy.spatial.transform import Rotation

    try:
        start = Rotation.from_quat(json.loads(case.inputs)["quaternion"])
    except (ValueError, KeyError, TypeError):
        return math.nan, math.nan
    vector = np.degrees((Rotation.from_quat(case.arrays["quaternion"][-1, 0]) * start.inv())
                        .as_rotvec())
    angle = float(np.linalg.norm(vector))
    if angle == 0:
        return 0.0, math.nan
    sign = -1.0 if vector[1] < 0 or (vector[1] == 0 and vector[0] < 0) else 1.0
    return sign * angle, math.degrees(math.atan2(vector[1], vector[0]))


def _steady_friction(distance: np.ndarray, mu: np.ndarray) -> dict[str, float]:
    """The steady state of a sliding run's effective friction: over the steps that end in the
    last half of the sliding distance (``distance``, m: the path length at the end of each
    step), the mean, standard deviation, smallest and largest ``mu`` (``mu_eff_sliding``, 1),
    mean and deviation weighted by each step's increment of distance (equal steps: equal
    weights). A run that did not slide: NaN, and a final sliding distance of 0."""
    distance = np.nan_to_num(np.asarray(distance, dtype=float))
    mu = np.asarray(mu, dtype=float)
    total = float(distance[-1]) if distance.size else 0.0
    out = {"final_sliding_distance": total, "steady_mu_eff": math.nan,
           "steady_mu_eff_std": math.nan, "steady_mu_eff_min": math.nan,
           "steady_mu_eff_max": math.nan}
    weight = np.diff(distance, prepend=0.0)
    last = (distance > 0.5 * total) & (weight > 0) & np.isfinite(mu)
    if not total > 0 or not last.any():
        return out
    w, m = weight[last], mu[last]
    mean = float(np.sum(w * m) / np.sum(w))
    out.update(steady_mu_eff=mean,
               steady_mu_eff_std=math.sqrt(float(np.sum(w * (m - mean) ** 2) / np.sum(w))),
               steady_mu_eff_min=float(m.min()), steady_mu_eff_max=float(m.max()))
    return out


def _case_summary(case: _CaseData) -> dict:
    """Scalar summaries of one case's per-step results: the first step in which a particle
    turned, the final compression, loaded count and state fractions; the behaviour is the
    state in which the first particle to turn did (``stick`` if none did); for a case of one
    particle also its total rotation, final state and signed final ratios; for a sliding run
    the steady-state effective friction (:func:`_steady_friction`)."""
    a = case.arrays
    out: dict[str, Any] = {v.name: v.fill if isinstance(v.fill, int | float) else math.nan
                           for v in schema.by_kind("summary")}
    n = len(a.get("state", ()))
    out.update(steps_done=n, behaviour=_BEHAVIOUR_CODE["failed"], compute_time=0.0)
    if n == 0:
        return out
    turned = a["turned"].astype(bool)                      # (step, particle)
    steps = np.flatnonzero(turned.any(axis=1))
    out.update(turning_steps=int(steps.size), final_compression=float(a["compression"][-1]),
               compute_time=float(np.sum(a["time_total"])),
               final_loaded=float(a["loaded"][-1]),
               final_fraction_stick=float(a["fraction_stick"][-1]),
               final_fraction_roll=float(a["fraction_roll"][-1]),
               final_fraction_rotate=float(a["fraction_rotate"][-1]))
    first = "stick"
    if steps.size:
        k = steps[0]
        out.update(first_turn_force=float(a["total_force"][k]),
                   first_turn_compression=float(a["compression"][k]))
        first = STATES[int(a["state"][k][np.flatnonzero(turned[k])[0]])]
    if "sliding_distance" in a and "mu_eff_sliding" in a:
        out.update(_steady_friction(a["sliding_distance"], a["mu_eff_sliding"]))
    if turned.shape[1] == 1:
        # a case that never turned did not rotate: exactly 0, not the round-off of q q0⁻¹
        total, azimuth = _total_rotation(case) if steps.size else (0.0, math.nan)
        sign = float(direction_sign(a["tangential_force"][:, 0])[-1])
        out.update(total_rotation=total, turn_azimuth=azimuth,
                   final_state=int(a["state"][-1, 0]),
                   final_ratio_up=sign * float(a["ratio"][-1, 0, 0]),
                   final_ratio_low=sign * float(a["ratio"][-1, 0, 1]))
    if case.status == "complete" and not case.partial:
        out["behaviour"] = _BEHAVIOUR_CODE.get(first, _BEHAVIOUR_CODE["failed"])
    return out


def summarize(sweep: Sweep, out: str | Path, cases: list[Case] | None = None,
              records: dict[str, dict] | None = None,
              loaded: dict[str, _CaseData] | None = None):
    """Combine the finished cases in ``out/cases`` along the sweep axes: writes
    ``out/summary.nc`` and ``out/summary.csv`` and returns the dataset. ``loaded``: case
    files already read (by case id), not read again."""
    import xarray as xr

    out = Path(out)
    cases = cases if cases is not None else sweep.cases()
    records = records or {}
    shape = sweep.shape
    dims = tuple(a.name for a in sweep.axes)
    summaries = {v.name: v for v in schema.by_kind("summary")}
    scalars = {name: np.full(shape, np.nan) for name in summaries}
    status = np.full(shape, "missing", dtype=object)
    ids = np.full(shape, "", dtype=object)
    datasets = {}
    rows = []
    for case in cases:
        rec = records.get(case.case_id, {})
        path = out / "cases" / case.filename
        ids[case.index] = case.case_id
        summ = {}
        data_ = (loaded or {}).get(case.case_id)
        if data_ is None:
            try:
                data_ = _read_case(path, _summary_names())
            except UnreadableCase:          # reported as missing; the file stays
                data_ = None
        if data_ is not None:
            summ = _case_summary(data_)
            if data_.partial:
                summ["behaviour"] = _BEHAVIOUR_CODE["missing"]
                status[case.index] = "incomplete"
            else:
                status[case.index] = data_.status
            datasets[case.index] = data_
        else:
            summ = {"behaviour": _BEHAVIOUR_CODE["missing"]}
        if str(rec.get("status", "")).startswith("error"):
            status[case.index] = rec["status"]
            summ["behaviour"] = _BEHAVIOUR_CODE["error"]
        for name, value in summ.items():
            scalars[name][case.index] = value
        rows.append({**{a.key: case.values[a.key] for a in sweep.axes}, "case": case.case_id,
                     "status": status[case.index],
                     **{k: summ.get(k, math.nan) for k in summaries}})
    data = {}
    for name, var in summaries.items():
        values = scalars[name]
        if var.dtype != "float64":
            fill = var.fill if not var.flags else var.flags.index(var.fill)
            values = np.nan_to_num(values, nan=fill).astype(var.dtype)
        data[name] = (dims, values, var.attrs)
    data["final_state"][2].update(flag_values=np.arange(len(STATES), dtype=np.int8),
                                  flag_meanings=" ".join(STATES))
    data["status"] = (dims, status.astype(str), {"long_name": "case status"})
    data["case"] = (dims, ids.astype(str), {"long_name": "case id: file cases/<case>.nc"})
    coords = {a.name: (a.name, _coord(a.values), {"config_key": a.key, "units": a.units})
              for a in sweep.axes}
    complete = [d for d in datasets.values() if d.status == "complete" and not d.partial]
    if len({len(d.arrays["state"]) for d in complete}) == 1:
        # per-step values share one step axis (per-particle ones: and one particle count)
        n_steps = len(complete[0].arrays["state"])
        same_particles = len({d.arrays["state"].shape[1] for d in complete}) == 1
        coords["step"] = ("step", np.arange(n_steps), {"long_name": "load step index"})
        for var in schema.VARIABLES.values():
            if not var.summary or (var.kind == "particle" and not same_particles):
                continue
            lead = (n_steps,) if var.kind == "step" else (
                n_steps, complete[0].arrays["state"].shape[1])
            arr = np.full((*shape, *lead, *var.shape), np.nan)
            for index, d in datasets.items():
                values = d.arrays[var.name][:n_steps]
                if values.shape[1:] == arr.shape[len(shape) + 1:]:
                    arr[index][:len(values)] = values
            if var.flags:
                arr = np.nan_to_num(arr, nan=-1).astype(np.int8)
            extra = ("step",) if var.kind == "step" else ("step", "particle")
            data[var.name] = ((*dims, *extra, *var.tail), arr, var.attrs)
            for d in var.tail:
                coords[d] = (d, list(schema.DIMENSIONS[d].labels))
            if var.kind == "particle":
                coords["particle"] = ("particle", np.arange(lead[1]),
                                      {"long_name": "particle index (layer order)"})
    from .._version import __version__

    summary = xr.Dataset(data, coords=coords, attrs={
        "title": "thirdbody sweep summary", "thirdbody_version": __version__,
        "sweep": sweep.to_toml(), "cases": len(cases),
        "failed": int(sum(1 for s in status.flat if s != "complete"))})
    write_results(summary, out / "summary.nc")
    _write_csv(out / "summary.csv", rows)
    return summary


def _coord(values: Iterable) -> np.ndarray:
    values = list(values)
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        return np.asarray(values)
    return np.asarray([json.dumps(v) if not isinstance(v, str) else v for v in values])


def _write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: BEHAVIOURS[int(v)] if k == "behaviour" and v == v else v
                             for k, v in row.items()})
    os.replace(tmp, path)
