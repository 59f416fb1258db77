"""MkDocs hook: the configuration keys' tables, generated from the pydantic models.

``docs/guide/configuration.md`` holds the marker ``<!-- config-table -->``; at build time it is
replaced by one table per TOML table, read from :mod:`thirdbody.io.config`: every key, its type
and allowed range, its default and its meaning. The type, range and default come from the models
themselves, so they cannot go stale. The meaning is the field's ``description`` where the model
gives one and the text in ``MEANINGS`` below otherwise; a key that has neither, or a meaning for
a key the models no longer have, fails the build.
"""

from __future__ import annotations

import types
import typing
from typing import Annotated, Literal, get_args, get_origin

import annotated_types as at
from mkdocs.exceptions import PluginError

MARKER = "<!-- config-table -->"

#: what each key means, where the model's own description says too little ("table.key"; for the
#: shape- and program-specific keys "table.variant.key")
MEANINGS: dict[str, str] = {
    "particle.shape": "the particle's shape; the keys below marked with a shape apply to it",
    "particle.sphere.radius": "radius",
    "particle.potato.semi_axes": "semi-axes of the ellipsoid the waves modulate",
    "particle.potato.seed": "seed of the random waves (the same seed, the same potato)",
    "particle.potato.n_waves": "number of random sine waves on the radius",
    "particle.potato.amplitude": "relative amplitude of each wave (drawn in [amplitude/2, "
                                 "amplitude])",
    "particle.potato.wavenumber_range": "range of the waves' angular wavenumbers",
    "particle.mesh.file": "a closed triangle mesh (STL, OBJ, PLY), relative to the "
                          "configuration file; refine it far below the cell size",
    "particle.mesh.scale": "metres per file unit",
    "particle.mesh.subdivisions": "rounds of Loop subdivision applied after loading",
    "particle.mesh.max_edge": "split edges longer than this (m, after scaling)",
    "particle.mesh.sha256": "the file's SHA-256; thirdbody writes it into the resolved "
                            "configuration and refuses an edited file",
    "particle.orientation_deg": "initial tilt angle about the tilt axis (the paper's θ when "
                                "the axis is +y)",
    "particle.tilt_axis_deg": "azimuth of the tilt axis from +x towards +y (90: +y, the "
                              "paper's plane of rotation)",
    "particle.yaw_deg": "rotation about the body's z axis, applied before the tilt",
    "particle.quaternion": "initial orientation (x, y, z, w), body to world, instead of "
                           "orientation_deg, tilt_axis_deg and yaw_deg",
    "layer.count": "how many particles (give count or area_fraction)",
    "layer.area_fraction": "fraction of the box covered by the particles' bounding discs "
                           "(give count or area_fraction)",
    "layer.shape": "the shape family; every particle gets its own random seed",
    "layer.size": "mean size (a sphere's radius, an ellipsoid's or potato's largest semi-axis)",
    "layer.size_std": "standard deviation of the size",
    "layer.distribution": "size distribution; \"list\" takes the sizes from `sizes`",
    "layer.sizes": "the sizes for distribution = \"list\": a list (m) or a CSV file",
    "layer.aspect": "semi-axis ratios; semi-axes = size × aspect / max(aspect)",
    "layer.amplitude": "potato waves: relative amplitude",
    "layer.n_waves": "potato waves: how many",
    "layer.wavenumber_range": "potato waves: range of angular wavenumbers",
    "layer.orientation": "\"random\": uniform 3-D; \"tilted\": random yaw, tilt up to "
                         "max_tilt_deg; \"upright\"",
    "layer.max_tilt_deg": "largest tilt for orientation = \"tilted\"",
    "layer.seed": "the generator's seed (the same seed, the same layer)",
    "layer.placement": "\"sequential\": one at a time, bounding discs apart (area fraction "
                       "<= 0.5); \"relaxed\": all at once, then the discs' overlaps relaxed "
                       "away (dense layers, <= 0.8); periodic with [network] periodic = true",
    "plates.mu_low": "friction coefficient of the lower plate (default: mu_up)",
    "network.mu_pp": "friction coefficient between particles; the table makes every contact, "
                     "particle-particle too, a BEM contact (particles may touch)",
    "network.periodic": "x and y periodic: contacts act across the sides of the box",
    "network.box": "the periodic box (L_x, L_y), centred on the origin (default: the [layer] "
                   "box)",
    "network.tol": "equilibrium tolerance of each step (force residuals over the mean contact "
                   "force)",
    "load.program": "the load history; the keys below marked with a program apply to it",
    "load.linear_ramp.steps": "load steps",
    "load.linear_ramp.start": "first step's force (default: stop / steps)",
    "load.hold_then_ramp.hold": "force held at first",
    "load.hold_then_ramp.hold_steps": "steps at the held force",
    "load.hold_then_ramp.stop": "final force of the ramp that follows",
    "load.hold_then_ramp.ramp_steps": "steps of the ramp",
    "load.force_table.forces": "the normal force of every step",
    "load.gap_ramp.steps": "load steps",
    "load.gap_ramp.start": "first step's compression (default: stop / steps)",
    "load.slide.compress_steps": "steps of the compression (equal increments up to force "
                                 "or compression) before the plate slides",
    "numerics.resolution": "cells per particle size (the largest centroid–surface distance)",
    "numerics.tol": "tolerance of the contact solvers (dimensionless residuals)",
    "numerics.angle_step_deg": "turning: march step along a turn",
    "numerics.angle_tol_deg": "turning: bisection tolerance of the stable orientation",
    "numerics.maps_every": "store contact maps every k steps (and the last); 0: none",
    "numerics.classification": "\"statics\": roll or rotate from equilibrium for unequal μ; "
                               "\"paper\": the paper's eq. 11 read literally",
    "numerics.workers": "processes that turn the particles of a layer in parallel (the "
                        "results do not depend on it)",
}

_UNITS_ONLY = {"m", "N", "Pa"}


def _constraint_text(meta) -> tuple[str, str]:
    """(lower, upper) bound texts of a list of annotated_types constraints."""
    low = high = ""
    for m in meta:
        if isinstance(m, at.Gt):
            low = f"({m.gt:g}"
        elif isinstance(m, at.Ge):
            low = f"[{m.ge:g}"
        elif isinstance(m, at.Lt):
            high = f"{m.lt:g})"
        elif isinstance(m, at.Le):
            high = f"{m.le:g}]"
    return low, high


def _range(meta) -> str:
    low, high = _constraint_text(meta)
    if low and high:
        return f" in {low}, {high}"
    if low:
        return (" > " if low[0] == "(" else " ≥ ") + low[1:]
    if high:
        return (" < " if high[-1] == ")" else " ≤ ") + high[:-1]
    return ""


def _kind(tp, meta=()) -> str:
    """A reader's description of a type annotation: 'number > 0', '[number, number]', ..."""
    if get_origin(tp) is Annotated:
        base, *extra = get_args(tp)
        inner = []
        for e in extra:
            inner.extend(getattr(e, "metadata", []))
        return _kind(base, [*meta, *inner])
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        parts = [a for a in get_args(tp) if a is not type(None)]
        return " or ".join(_kind(a, meta) for a in parts)
    if origin is Literal:
        return "one of " + ", ".join(f'`"{v}"`' for v in get_args(tp))
    if origin is tuple:
        return "[" + ", ".join(_kind(a) for a in get_args(tp)) + "]"
    if origin is list:
        (item,) = get_args(tp)
        return f"list of ({_kind(item)})"
    names = {bool: "true or false", int: "integer", float: "number", str: "string"}
    if tp in names:
        return names[tp] + ("" if tp is bool else _range(meta))
    raise PluginError(f"config_table hook: no description for the type {tp!r}")


def _default(field) -> str:
    if field.is_required():
        return "required"
    value = field.get_default(call_default_factory=True)
    if value is None:
        return "–"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, tuple | list):
        return "`[" + ", ".join(f"{v:g}" for v in value) + "]`"
    if isinstance(value, float):
        return f"`{value:g}`"
    return f"`{value}`"


def _meaning(key: str, field, used: set[str]) -> str:
    if key in MEANINGS:
        used.add(key)
        text = MEANINGS[key]
        if field.description and field.description in _UNITS_ONLY:
            text = f"{text}, {field.description}"
        return text
    if field.description:
        return field.description
    raise PluginError(f"config_table hook: the configuration key {key!r} has no meaning: add "
                      "a description to its pydantic Field or an entry to MEANINGS in "
                      "docs/hooks/config_table.py")


def _rows(model, prefix: str, used: set[str], skip=(), variant: str = "") -> list[str]:
    rows = []
    for name, field in model.model_fields.items():
        if name in skip or field.exclude:
            continue
        key = f"{prefix}.{variant + '.' if variant else ''}{name}"
        label = f"`{name}`" + (f" ({variant})" if variant else "")
        kind = _kind(field.annotation, field.metadata)
        rows.append(f"| {label} | {kind} | {_default(field)} | {_meaning(key, field, used)} |")
    return rows


def _union_rows(annotation, prefix: str, tag: str, used: set[str]) -> list[str]:
    """Rows of a discriminated union (shapes, load programs): the tag, then each variant's."""
    if get_origin(annotation) is Annotated:
        annotation = get_args(annotation)[0]
    variants = get_args(annotation)
    values = [get_args(v.model_fields[tag].annotation)[0] for v in variants]
    key = f"{prefix}.{tag}"
    used.add(key)
    rows = [f"| `{tag}` | one of " + ", ".join(f'`"{v}"`' for v in values)
            + f" | required | {MEANINGS[key]} |"]
    for variant, value in zip(variants, values, strict=True):
        rows += _rows(variant, prefix, used, skip=(tag,), variant=value)
    return rows


HEAD = ["| key | type and range | default | meaning |", "|---|---|---|---|"]


def config_tables() -> str:
    from thirdbody.io import config as c

    used: set[str] = set()
    particle = c.Particle.model_fields["geometry"]
    out = ["### `[particle]`: one particle", "", *HEAD,
           *_union_rows(particle.annotation, "particle", "shape", used),
           *_rows(c.Particle, "particle", used, skip=("geometry",)), ""]
    placed_only = [n for n in c.PlacedParticle.model_fields if n not in c.Particle.model_fields]
    out += ["### `[[particles]]`: a layer placed by hand", "",
            "One `[[particles]]` table per particle: every `[particle]` key, plus:", "", *HEAD,
            *_rows(c.PlacedParticle, "particles", used,
                   skip=tuple(c.Particle.model_fields)), ""]
    assert placed_only, "PlacedParticle adds the centroid"
    out += ["### `[layer]`: a generated layer", "", *HEAD, *_rows(c.LayerGenerator, "layer", used),
            ""]
    out += ["### `[network]` (optional): particles that touch", "", *HEAD,
            *_rows(c.Network, "network", used), ""]
    out += ["### `[plates]`", "", *HEAD, *_rows(c.Plates, "plates", used), ""]
    load = c.Config.model_fields["load"]
    out += ["### `[load]`", "", *HEAD, *_union_rows(load.annotation, "load", "program", used), ""]
    out += ["### `[numerics]` (optional)", "", *HEAD, *_rows(c.Numerics, "numerics", used), ""]
    stale = sorted(set(MEANINGS) - used)
    if stale:
        raise PluginError("config_table hook: MEANINGS describes keys the configuration models "
                          f"do not have: {', '.join(stale)}")
    top = [n for n, f in c.Config.model_fields.items() if not f.exclude]
    expected = {"particle", "particles", "layer", "network", "plates", "load", "numerics"}
    if set(top) != expected:
        raise PluginError(f"config_table hook: the configuration's tables are {sorted(top)}, "
                          f"the hook documents {sorted(expected)}: update it")
    return "\n".join(out)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, config_tables())
