"""A sweep file: the base configuration, the axes and the cases they make (see
:mod:`thirdbody.sweep`)."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .. import schema
from ..io.config import Config, ConfigError, parse_config
from ..schema import BEHAVIOURS

#: Behaviour of a case over its whole run (``behaviour`` in the summary): ``stick`` if no
#: particle turned, else the state in which the first particle to turn did; ``failed`` if a step
#: failed, ``error`` if the case raised, ``missing`` if it has no result (the codes of
#: :data:`thirdbody.schema.BEHAVIOURS`).
_BEHAVIOUR_CODE = {name: i for i, name in enumerate(BEHAVIOURS)}


class SweepError(ValueError):
    """An invalid sweep file: the message names the key (and the case) at fault."""


@dataclass(frozen=True)
class Axis:
    """One sweep axis: a dotted configuration key and its values."""

    key: str
    values: tuple
    name: str                 # the summary dimension's name

    @property
    def units(self) -> str:
        return schema.parameter_units(self.key)


@dataclass(frozen=True)
class Case:
    """One point of the sweep: its axis indices and values, and its resolved configuration."""

    index: tuple[int, ...]
    values: dict[str, Any]
    data: dict                # the raw configuration (TOML tables) of this case
    config: Config
    case_id: str              # hash of the resolved configuration

    @property
    def filename(self) -> str:
        return f"{self.case_id}.nc"


@dataclass(frozen=True)
class Sweep:
    """A base configuration, keys set on every case, and the axes of the Cartesian product."""

    base: dict
    axes: tuple[Axis, ...]
    overrides: dict = field(default_factory=dict)
    base_dir: str = "."
    source: str = "<sweep>"

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.axes)

    def cases(self) -> list[Case]:
        """Every case, in axis order (the first axis varies slowest), each one validated.

        Raises :class:`SweepError` listing the cases whose configuration is invalid.
        """
        cases, problems = [], []
        base = _deep_copy(self.base)
        for key, value in self.overrides.items():
            _set_key(base, key, value)
        ranges = [range(len(a.values)) for a in self.axes]
        for index in itertools.product(*ranges):
            values = {a.key: a.values[i] for a, i in zip(self.axes, index, strict=True)}
            data = _deep_copy(base)
            for key, value in values.items():
                _set_key(data, key, value)
            label = ", ".join(f"{k} = {v!r}" for k, v in values.items()) or "the base"
            try:
                config = parse_config(data, source=f"{self.source} (case {label})",
                                      base_dir=self.base_dir)
            except ConfigError as exc:
                problems.append(str(exc))
                continue
            cases.append(Case(index, values, data, config, case_id(config)))
        if problems:
            shown = problems[:5] + ([f"... and {len(problems) - 5} more"]
                                    if len(problems) > 5 else [])
            raise SweepError("\n".join(shown))
        return cases

    def cost_estimate(self) -> str:
        """A rough cost of the whole sweep, from the base's steps and resolution alone (axes
        that change them are not looked at): about 1.2 s per load step at 60 cells per
        particle size on one core (the bundled Fig. 4 sweep), scaling with the cells."""
        data = _deep_copy(self.base)
        for key, value in self.overrides.items():
            _set_key(data, key, value)
        load, numerics = data.get("load", {}), data.get("numerics", {})
        steps = load.get("steps") or len(load.get("forces", [])) or \
            (load.get("hold_steps", 0) + load.get("ramp_steps", 0)) or 50
        resolution = numerics.get("resolution", 80.0)
        if not isinstance(steps, int | float) or not isinstance(resolution, int | float):
            return "cost unknown"
        hours = math.prod(self.shape) * steps * 1.2 * (resolution / 60.0) ** 2 / 3600.0
        return (f"roughly {hours:.2g} core-hours ({steps} steps at {resolution:g} cells per "
                "particle size per case, ~1.2 s a step at 60)")

    def to_toml(self) -> str:
        """The sweep as TOML (base inline), to store next to the results."""
        def value(v) -> str:
            return json.dumps(list(v) if isinstance(v, tuple) else v)

        lines = ["# thirdbody sweep (resolved)", ""]
        lines += ["[axes]"] + [f'"{a.key}" = {value(list(a.values))}' for a in self.axes]
        if self.overrides:
            lines += ["", "[set]"] + [f'"{k}" = {value(v)}' for k, v in self.overrides.items()]
        for table, entries in self.base.items():
            lines += ["", f"[base.{table}]"]
            lines += [f"{k} = {value(v)}" for k, v in entries.items()]
        return "\n".join(lines) + "\n"


#: particle keys added to the configuration after the case hash was defined (None when unset)
_LATER_KEYS = ("azimuth_deg",)


def case_id(config: Config) -> str:
    """16 hex digits of the SHA-256 of the resolved configuration (canonical JSON), with the
    content of its mesh files: an edited mesh is a new case."""
    data = config.model_dump(mode="json", exclude={"base_dir"})
    # keys added since case ids were defined are left out when unset: earlier sweeps keep
    # their ids (and their finished cases)
    for table in [data.get("particle"), *(data.get("particles") or [])]:
        for key in _LATER_KEYS:
            if table is not None and table.get(key) is None:
                table.pop(key, None)
    digests = config.mesh_digests()
    if digests:
        data["mesh_sha256"] = digests
    text = json.dumps(data, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# --- reading a sweep file --------------------------------------------------------------------
def load_sweep(path: str | Path) -> Sweep:
    """Read and check a sweep file (see the module docstring); :class:`SweepError` on problems."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise SweepError(f"cannot read sweep file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise SweepError(f"sweep file {path} is not UTF-8 text (a binary file?); a sweep "
                         "file is TOML") from None
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"sweep file {path} is not valid TOML: {exc}") from None
    return parse_sweep(data, base_dir=path.parent, source=str(path))


def parse_sweep(data: dict, base_dir: str | Path = ".", source: str = "<sweep>") -> Sweep:
    """Build a :class:`Sweep` from the tables of a sweep file."""
    unknown = sorted(set(data) - {"base", "axes", "set"})
    if unknown:
        raise SweepError(f"{source}: unknown key(s) {', '.join(unknown)} (allowed: base, axes, "
                         "set)")
    if "base" not in data:
        raise SweepError(f"{source}: base: required (a configuration file, a bundled example "
                         "name, or a [base] table)")
    base, base_dir = _load_base(data["base"], Path(base_dir), source)
    raw_axes = data.get("axes")
    if not isinstance(raw_axes, dict) or not raw_axes:
        raise SweepError(f"{source}: axes: required, a table of 'key = [values]' or "
                         "'key = {start, stop, num | step}'")
    flat = _flatten(raw_axes, is_leaf=lambda v: isinstance(v, list) or _is_range(v))
    overrides = _flatten(data.get("set", {}), is_leaf=lambda v: not isinstance(v, dict))
    axes = []
    for key, spec in flat.items():
        values = _axis_values(key, spec, source)
        if len(set(map(repr, values))) != len(values):
            raise SweepError(f"{source}: axes.{key}: repeated values {values!r}")
        axes.append(values)
    names = [k.rsplit(".", 1)[-1] for k in flat]
    names = [n if names.count(n) == 1 else k.replace(".", "_")
             for n, k in zip(names, flat, strict=True)]
    sweep = Sweep(base=base, overrides=overrides, base_dir=str(base_dir), source=source,
                  axes=tuple(Axis(k, tuple(v), n)
                             for (k, v, n) in zip(flat, axes, names, strict=True)))
    both = [k for k in flat if k in overrides]
    if both:
        raise SweepError(f"{source}: {', '.join(both)}: both an axis and in [set]")
    return sweep


def _load_base(spec, sweep_dir: Path, source: str) -> tuple[dict, Path]:
    if isinstance(spec, dict):
        return spec, sweep_dir
    if not isinstance(spec, str):
        raise SweepError(f"{source}: base: a file name, an example name or a table; got "
                         f"{spec!r}")
    candidates = [sweep_dir / spec, sweep_dir / f"{spec}.toml"]
    bundled = resources.files("thirdbody") / "examples"
    candidates += [Path(str(bundled / spec)), Path(str(bundled / f"{spec}.toml"))]
    for path in candidates:
        if path.is_file():
            try:
                return tomllib.loads(path.read_text()), path.parent
            except tomllib.TOMLDecodeError as exc:
                raise SweepError(f"{source}: base {path} is not valid TOML: {exc}") from None
    raise SweepError(f"{source}: base: no file {spec!r} next to the sweep file and no bundled "
                     "example of that name (see `thirdbody examples`)")


def _is_range(v) -> bool:
    return isinstance(v, dict) and {"start", "stop"} <= set(v) and set(v) <= {
        "start", "stop", "num", "step"}


def _flatten(table: dict, is_leaf: Callable, prefix: str = "") -> dict:
    out = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if is_leaf(v) or not isinstance(v, dict):
            out[key] = v
        else:
            out.update(_flatten(v, is_leaf, key + "."))
    return out


def _axis_values(key: str, spec, source: str) -> list:
    where = f"{source}: axes.{key}"
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where}: an empty list")
        return spec
    if not _is_range(spec):
        raise SweepError(f"{where}: a list of values or {{start, stop, num}} / "
                         f"{{start, stop, step}}; got {spec!r}")
    start, stop = spec["start"], spec["stop"]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (start, stop)):
        raise SweepError(f"{where}: start and stop must be numbers; got {spec!r}")
    if ("num" in spec) == ("step" in spec):
        raise SweepError(f"{where}: give exactly one of num and step; got {spec!r}")
    if "num" in spec:
        num = spec["num"]
        if not isinstance(num, int) or num < 1:
            raise SweepError(f"{where}.num: an integer >= 1; got {num!r}")
        values = np.linspace(start, stop, num) if num > 1 else np.array([start])
    else:
        step = spec["step"]
        if not isinstance(step, int | float) or step == 0 or (stop - start) * step < 0:
            raise SweepError(f"{where}.step: a non-zero number going from start towards stop; "
                             f"got {step!r}")
        count = math.floor((stop - start) / step * (1 + 1e-12) + 1e-9) + 1
        values = start + step * np.arange(count)
    if all(isinstance(v, int) for v in (start, stop, spec.get("step", 1))) and "num" not in spec:
        return [int(v) for v in values]
    return [float(f"{v:.12g}") for v in values]


def _set_key(data: dict, key: str, value) -> None:
    """Set a dotted key in the raw configuration tables; ``plates.mu`` sets both plates."""
    *tables, leaf = key.split(".")
    node = data
    for t in tables:
        node = node.setdefault(t, {})
        if not isinstance(node, dict):
            raise SweepError(f"{key}: {t} is not a table")
    if key == "plates.mu":
        node.pop("mu_low", None)
        node["mu_up"] = value
        return
    node[leaf] = list(value) if isinstance(value, tuple) else value


def _deep_copy(data: dict) -> dict:
    return json.loads(json.dumps(data))
