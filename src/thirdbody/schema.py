"""What thirdbody writes, in one registry: every variable's name, dimensions, units, dtype, fill
value and long name, once.

The results dataset, the blank record of an unloaded particle, the maps, the sweep summary, the
VTK export and the documentation's table of variables all read :data:`VARIABLES`; a new output is
one entry here (and, unless it is :attr:`Variable.derive`\\ d from the others, the line of
:mod:`thirdbody.records` that computes it).

Dimensions (:data:`DIMENSIONS`): ``step`` (load steps), ``particle`` (layer order; size 1 for a
single particle), ``interface`` = (upper, lower), ``component`` = (x, y) for horizontal vectors,
``quaternion_component`` = (x, y, z, w); maps on ``map_step`` and the cell indices ``map_j``,
``map_i`` of each particle's lattice, with the cell centres in metres as the coordinates
``map_x`` (particle, map_i) and ``map_y`` (particle, map_j) in the particle frame (centroid at
the origin); the ``event`` table; ``case`` stands for a sweep's axes. Units follow UDUNITS
spelling (``m``, ``N``, ``Pa``, ``m2``, ``J``, ``degree``, ``s``; ``1`` for dimensionless).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["BEHAVIOURS", "COMPONENTS", "CONTACT_STATES", "DIMENSIONS", "EVENTS",
           "FORMAT_VERSION", "INTERFACES", "PARAMETERS", "SLIDING", "STATES", "VARIABLES", "XYZ",
           "Dimension", "Variable", "by_kind", "markdown_table", "parameter_units", "variable"]

#: the results file layout this version writes (``thirdbody_format`` attribute); version 1 (no
#: attribute) had no ``particle`` dimension for a single particle and maps on metres for one
#: particle but on cell indices for a layer. :func:`thirdbody.io.results.open_results` reads both.
FORMAT_VERSION = 2

#: what a particle did in a step (``state``), in code order; "roll…" and "rotate" turn,
#: "slide…" do not (network runs: :func:`thirdbody.network.run.particle_state`)
STATES = ("stick", "roll_upper", "roll_lower", "rotate", "failed", "unloaded", "roll", "slide",
          "slide_upper", "slide_lower")
#: the states of a particle that slid without turning (``fraction_slide``)
SLIDING = ("slide", "slide_upper", "slide_lower")
#: what the event table records (``event_kind``)
EVENTS = ("loaded", "unloaded", "roll_upper", "roll_lower", "rotate", "rolled_off")
#: a sweep case's behaviour over its run (``behaviour``), in code order (new codes go at the
#: end: "roll", a network run's particle that turned with contacts sticking and sliding while
#: touching other particles, was coded "failed" before it was added)
BEHAVIOURS = ("stick", "roll_upper", "roll_lower", "rotate", "failed", "error", "missing",
              "roll")
INTERFACES = ("upper", "lower")
COMPONENTS = ("x", "y")
XYZ = ("x", "y", "z")
#: what a contact of a network run did in a step (``contact_state``)
CONTACT_STATES = ("stick", "slide")
QUATERNION = ("x", "y", "z", "w")


@dataclass(frozen=True)
class Dimension:
    """A dimension of the results: its fixed labels (None: indices, or it grows), its units and
    long name (the attributes of its coordinate)."""

    name: str
    long_name: str
    labels: tuple[str, ...] | None = None
    units: str | None = None


DIMENSIONS: dict[str, Dimension] = {d.name: d for d in (
    Dimension("step", "load step index (from 0)", units="1"),
    Dimension("particle", "particle index (layer order)"),
    Dimension("interface", "the plate: upper or lower", INTERFACES),
    Dimension("component", "horizontal vector component", COMPONENTS),
    Dimension("quaternion_component", "quaternion component (x, y, z, w)", QUATERNION),
    Dimension("map_step", "load step index of the stored maps", units="1"),
    Dimension("map_j", "cell index along y from the particle's centroid"),
    Dimension("map_i", "cell index along x from the particle's centroid"),
    Dimension("event", "event index (step, then particle order)"),
    Dimension("contact", "contact index of a network run (step, then contact key order)"),
    Dimension("xyz", "3-D vector component", XYZ),
    Dimension("case", "a sweep's axes (one dimension per swept key)"),
)}


@dataclass(frozen=True)
class Variable:
    """One output variable.

    Attributes
    ----------
    name : str
        The variable's name in the dataset (and the record's key).
    dims : tuple of str
        Its dimensions, in order (from :data:`DIMENSIONS`).
    units : str
        UDUNITS units ("1": dimensionless).
    long_name : str
        What it is, in words, with its sign convention.
    dtype : str
        numpy dtype name: "float64", "int64", "int8" (flags and codes) or "str".
    fill : object
        The value where it is undefined: an unloaded particle's, a step without it.
    flags : tuple of str
        For codes: the meanings of 0, 1, … (CF ``flag_values``/``flag_meanings``); the record
        holds the meaning, the file the code.
    summary : bool
        A sweep's summary keeps its per-step values (along the sweep axes, ``step`` …) when the
        cases agree on the steps (and, for per-particle variables, on the particle count).
    derive : callable, optional
        For a per-particle or per-step variable computed from the others of the same record:
        ``derive(values) -> value`` (``values``: the record's variables by name).
    """

    name: str
    dims: tuple[str, ...]
    units: str
    long_name: str
    dtype: str = "float64"
    fill: Any = math.nan
    flags: tuple[str, ...] = ()
    summary: bool = False
    derive: Callable[[dict], Any] | None = None

    @property
    def kind(self) -> str:
        """"step" (one value per step: the layer's), "particle" (per step and particle),
        "static" (per particle), "map", "event", "contact" (a network run's contact table) or
        "summary" (per sweep case)."""
        d = self.dims
        if d[:1] == ("map_step",):
            return "map"
        if d[:2] == ("step", "particle"):
            return "particle"
        if d[:1] == ("step",):
            return "step"
        if d[:1] == ("particle",):
            return "static"
        if d[:1] == ("event",):
            return "event"
        if d[:1] == ("contact",):
            return "contact"
        if d[:1] == ("case",):
            return "summary"
        raise ValueError(f"variable {self.name}: no kind for dimensions {d}")

    @property
    def tail(self) -> tuple[str, ...]:
        """The dimensions of one record's value: those after ``step`` (and ``particle``)."""
        lead = {"particle": 2, "step": 1, "static": 1, "event": 1, "summary": 1, "map": 2,
                "contact": 1}
        return self.dims[lead[self.kind]:]

    @property
    def shape(self) -> tuple[int, ...]:
        """The shape of one record's value (:attr:`tail`'s label counts)."""
        return tuple(len(DIMENSIONS[d].labels) for d in self.tail)

    @property
    def attrs(self) -> dict:
        """The netCDF attributes: units, long_name, and CF flags for codes."""
        out: dict[str, Any] = {"units": self.units, "long_name": self.long_name}
        if self.flags:
            out.update(flag_values=np.arange(len(self.flags), dtype=np.int8),
                       flag_meanings=" ".join(self.flags))
        return out

    def blank(self) -> Any:
        """The record value where the variable is undefined: :attr:`fill` in :attr:`shape`
        (nested tuples, interface then component)."""
        value: Any = self.fill
        for n in reversed(self.shape):
            value = (value,) * n
        return value

    def array(self, values: list, lead: tuple[int, ...]) -> np.ndarray:
        """The records' ``values`` (one per leading index, flattened) as an array of shape
        ``lead`` + :attr:`shape` and dtype :attr:`dtype` (codes for :attr:`flags`)."""
        if self.flags:
            code = {name: i for i, name in enumerate(self.flags)}
            values = [code[v] for v in values]
        if self.dtype == "str":
            return np.array(values, dtype=str).reshape(lead)
        return np.array(values, dtype=self.dtype).reshape((*lead, *self.shape))


def _ratio(vector, scale: float) -> tuple[float, float]:
    """``vector`` / ``scale`` componentwise (NaN where ``scale`` is not > 0)."""
    if not scale > 0:
        return (math.nan, math.nan)
    return (float(vector[0]) / scale, float(vector[1]) / scale)


def _magnitude(vector) -> float:
    return math.hypot(float(vector[0]), float(vector[1]))


def _v(name: str, dims: str, units: str, long_name: str, **kw) -> Variable:
    return Variable(name, tuple(dims.split()), units, long_name, **kw)


_P = "step particle"            # per step and particle
_PI = "step particle interface"
_PC = "step particle component"
_PIC = "step particle interface component"

#: every variable, by name
VARIABLES: dict[str, Variable] = {v.name: v for v in (
    # --- the layer's (the plates'), per step -------------------------------------------------
    _v("load_value", "step", "N", "prescribed load: F_N (N) or the compression ratio (1), see "
                                  "load_kind"),
    _v("load_kind", "step", "1", "load control: force (load_value in N) or compression "
                                 "(load_value a ratio)", dtype="str", fill=""),
    _v("total_force", "step", "N", "total normal force F_N on each plate", summary=True),
    _v("plate_gap", "step", "m", "plate separation h (force-weighted mean over the loaded "
                                 "particles)"),
    _v("compression", "step", "1", "compression ratio (d0 - h) / d0, d0 the gap at first "
                                   "contact of the tallest particle", summary=True),
    _v("loaded", "step", "1", "number of particles the plates press", dtype="int64", fill=0,
       summary=True),
    _v("fraction_stick", "step", "1", "fraction of the loaded particles that stuck",
       summary=True),
    _v("fraction_roll", "step", "1", "fraction of the loaded particles that rolled (about "
                                     "either plate)", summary=True),
    _v("fraction_rotate", "step", "1", "fraction of the loaded particles that rotated about "
                                       "their centroid", summary=True),
    _v("plate_force", "step component", "N",
       "F_T: net tangential force of the particles on the upper plate (minus that on the "
       "lower); under sliding it points against the plate's motion when the layer resists it"),
    _v("plate_moment", "step component", "N m",
       "tilting moment of the particles' forces on the upper plate, about the origin on the "
       "lower plate"),
    _v("fraction_slide", "step", "1", "network runs: fraction of the loaded particles that "
                                      "slid without turning (slide, slide_upper, "
                                      "slide_lower)", summary=True),
    _v("particle_contacts", "step", "1", "network runs: number of touching particle pairs "
                                         "carrying load (a pair touching on contacts facing "
                                         "different ways counts once)", dtype="int64", fill=0,
       summary=True),
    _v("coordination", "step", "1",
       "network runs: mean number of contacts of a loaded particle (a particle-particle "
       "contact counts for both particles, a plate contact once, a neighbour touched on "
       "contacts facing different ways once)", summary=True),
    _v("both_plates_force", "step", "N",
       "network runs: the part of F_N carried by particles touching both plates (the upper "
       "plate's normal force on them)"),
    _v("network_residual", "step", "1",
       "network runs: the largest residual of the step's equilibrium (forces over the mean "
       "contact force, moments over it times the particle's size, the plate force over F_N)"),
    _v("network_iterations", "step", "1", "network runs: BEM passes over every contact in the "
                                          "step", dtype="int64", fill=0),
    _v("network_substeps", "step", "1",
       "network runs: the sub-steps the step was solved in (1; 2, 4, ... when it did not "
       "converge whole and was cut into halves: network.cutbacks)", dtype="int64", fill=0),
    # --- sliding plates (design notes §3d; loading.Slide) ---------------------------------
    _v("plate_shift", "step component", "m",
       "s: horizontal displacement of the upper plate relative to the lower one since the "
       "start of the run, at the end of the step", fill=0.0),
    _v("sliding_distance", "step", "m", "path length the upper plate has slid since the start "
                                        "of the run (the sum of |increment|)", fill=0.0),
    _v("mu_eff", "step component", "1",
       "effective friction vector F_T / F_N (plate_force / total_force): points against the "
       "sliding when the layer resists it",
       derive=lambda v: _ratio(v["plate_force"], v["total_force"])),
    _v("mu_eff_magnitude", "step", "1", "effective friction |F_T| / F_N (>= 0)",
       derive=lambda v: _magnitude(_ratio(v["plate_force"], v["total_force"]))),
    _v("mu_eff_sliding", "step", "1",
       "effective friction along the sliding: -F_T . e / F_N, e the direction of the last "
       "sliding increment; > 0 when the layer resists the sliding, < 0 when it pushes the "
       "plate along (NaN before the plate first slides)"),
    _v("dilatancy", "step", "m",
       "change of the plate gap since the end of the compression (the last step before the "
       "plate first slid): > 0 when the layer dilates (NaN before the plate slides)"),
    # --- the energy balance of a network run's step (design notes §3d) --------------------
    _v("plate_work", "step", "J",
       "network runs: work of the upper plate on the particles in the step, F . du with F its "
       "force on them (the mean of the step's start and end) and du = (ds_x, ds_y, dh): "
       "-plate_force . ds - F_N dh"),
    _v("elastic_energy", "step", "J",
       "network runs: elastic energy stored in every contact at the end of the step, "
       "1/2 sum (p u_n + tau . u_t) dA"),
    _v("dissipation", "step", "J",
       "network runs: frictional dissipation of every contact in the step, sum tau . "
       "slip increment dA (>= 0 but for rounding); contact_dissipation splits it by contact"),
    _v("energy_residual", "step", "1",
       "network runs: (plate_work - change of elastic_energy - dissipation) / (F_N (|ds| + "
       "|dh|)): the step's energy balance (NaN when the plate did not move)"),
    _v("share_error", "step", "1", "largest error of a particle's share of F_N accepted by the "
                                   "load sharing in the step (converged: <= 1e-7)"),
    _v("time_total", "step", "s", "wall time of the step"),
    # --- each particle's, per step ------------------------------------------------------------
    _v("normal_force", _P, "N", "normal force on the particle from each plate", fill=0.0,
       summary=True),
    _v("load_share", _P, "1", "the particle's share of F_N", fill=0.0),
    _v("plate_normal_force", _PI, "N", "normal force of each plate on the particle (network "
                                       "runs; otherwise both equal normal_force)", fill=0.0),
    _v("translation", f"{_P} xyz", "m", "network runs: displacement of the centroid in the "
                                        "step"),
    _v("quaternion", f"{_P} quaternion_component", "1",
       "orientation at the end of the step: unit quaternion (x, y, z, w), body to world"),
    _v("orientation", _PC, "degree",
       "tilt vector at the end of the step: tilt angle times its horizontal axis (the paper's "
       "theta about +y is the y component)", summary=True),
    _v("tilt", _P, "degree", "tilt angle of the body z axis from the vertical"),
    _v("tilt_azimuth", _P, "degree", "azimuth of the tilt axis, from +x towards +y"),
    _v("yaw", _P, "degree", "rotation about the body z axis before the tilt"),
    _v("rotation", _PC, "degree", "rotation vector of the turn in this step (horizontal "
                                  "components)"),
    _v("rotation_angle", _P, "degree", "angle turned in this step"),
    _v("state", _P, "1", "what the particle did in the step (roll... and rotate turned, "
                          "slide... did not)", dtype="int8", fill="unloaded",
       flags=STATES, summary=True),
    _v("turned", _P, "1", "the particle turned in this step", dtype="int8", fill=False),
    _v("balanced", _P, "1", "the turn ended at a balance of the couple, not inside the "
                            "friction limit", dtype="int8", fill=False),
    _v("tangential_force", _PC, "N",
       "F' = F_N (r_up - r_low) / h: force of the lower plate on the particle", fill=0.0),
    _v("demand_ratio", _PI, "1", "|F'| / (mu F_N) at the step's starting orientation"),
    _v("ratio", _PI, "1",
       "|F_T| / (mu F_N) at the final orientation: a magnitude, >= 0 (the state plot and the "
       "sweep summary sign it by the direction of F' against its first non-zero direction)",
       summary=True),
    _v("centroid", _PIC, "m", "pressure centroid (particle frame)"),
    _v("approach", _PI, "m", "approach of the plate from its first contact with the surface "
                             "cells"),
    _v("contact_area", _PI, "m2", "contact area", fill=0.0),
    _v("stick_area", _PI, "m2", "stick area", fill=0.0),
    _v("spots", _PI, "1", "number of separate contact spots", dtype="int64", fill=0),
    _v("position", _PC, "m", "horizontal displacement of the particle centroid",
       summary=True),
    _v("centroid_height", _P, "m", "height of the particle's centroid above the lower plate"),
    _v("slip", _PIC, "m", "accumulated slip of the particle over the plate while turning"),
    _v("shift", _PIC, "m", "rigid tangential shift of the plate in partial slip, since the "
                           "last turn", fill=0.0),
    _v("normal_iterations", _PI, "1", "normal solver iterations", dtype="int64", fill=0),
    _v("tangential_iterations", _PI, "1", "tangential solver CG iterations", dtype="int64",
       fill=0),
    _v("normal_residual", _PI, "1", "normal solver complementarity residual"),
    _v("tangential_residual", _PI, "1", "Coulomb residual"),
    _v("force_residual", _P, "1", "|F_up - F_low| / F_N from the pressure fields"),
    _v("tangential_force_residual", _P, "1", "|T_up + T_low| / F_N from the traction fields"),
    _v("moment_residual", _P, "1",
       "|F_N (r_up - r_low) + h T_up| / (F_N h) from the fields: tilting moment balance"),
    _v("twist_moment", _P, "N m", "moment about z of the tractions of both plates about the "
                                  "centroid", fill=0.0),
    _v("twist_ratio", _P, "1", "|twist_moment| / (max(mu) F_N a), a the contact radius",
       fill=0.0),
    _v("twist_angle", _P, "degree",
       "rotation of the particle about z relative to the plates since the last turn, from "
       "balancing twist_moment (0 when it was below twist_tol)", fill=0.0),
    _v("turn_evaluations", _P, "1", "orientations evaluated in the step", dtype="int64",
       fill=0),
    _v("time_normal", _P, "s", "wall time of the particle's normal solves", fill=0.0),
    _v("time_tangential", _P, "s", "wall time of the particle's tangential solves", fill=0.0),
    _v("time_geometry", _P, "s", "wall time computing the particle's surfaces (vertical rays)",
       fill=0.0),
    # --- each particle's, once ----------------------------------------------------------------
    _v("x0", "particle", "m", "initial centroid x"),
    _v("y0", "particle", "m", "initial centroid y"),
    _v("size", "particle", "m", "particle size: largest centroid-to-surface distance"),
    _v("cell_size", "particle", "m", "the particle's BEM cell size"),
    _v("shape", "particle", "1", "shape", dtype="str", fill=""),
    # --- events ------------------------------------------------------------------------------
    _v("event_step", "event", "1", "load step of the event", dtype="int64"),
    _v("event_particle", "event", "1", "particle of the event", dtype="int64"),
    _v("event_kind", "event", "1", "one of " + ", ".join(EVENTS), dtype="str"),
    _v("event_value", "event", "N or degree",
       "the normal force when loaded or unloaded (N); the angle turned (degree)"),
    # --- a network run's contacts (one row per contact and step) ----------------------------
    _v("contact_step", "contact", "1", "load step of the contact", dtype="int64"),
    _v("contact_i", "contact", "1", "the contact's first particle", dtype="int64"),
    _v("contact_j", "contact", "1",
       "the other particle, or -1 for the lower plate and -2 for the upper plate",
       dtype="int64"),
    _v("contact_image", "contact component", "1",
       "periodic image of particle j that touches i: j's centre + (m_x L_x, m_y L_y)",
       dtype="int64", fill=0),
    _v("contact_normal", "contact xyz", "1", "unit normal from particle i to j (or the plate)"),
    _v("contact_force", "contact xyz", "N", "force of the contact on particle i (on j: the "
                                            "opposite)"),
    _v("contact_normal_force", "contact", "N", "normal force of the contact (>= 0)"),
    _v("contact_point", "contact xyz", "m", "pressure centroid of the contact (world frame; "
                                            "particle i's side of the box)"),
    _v("contact_approach", "contact", "m", "approach of the two surfaces from first touch"),
    _v("contact_total_area", "contact", "m2", "contact area (all spots)"),
    _v("contact_stick_area", "contact", "m2", "stick area"),
    _v("contact_spots", "contact", "1", "number of separate contact spots", dtype="int64"),
    _v("contact_slip", "contact xyz", "m", "mean slip of j over i in the step over the "
                                           "slipping cells (0 if none)"),
    _v("contact_shift_increment", "contact xyz", "m",
       "rigid tangential displacement of j (or the plate) relative to i at the contact in the "
       "step: the step's increment of the contact's tangential loading (its sum over the "
       "steps of a contact that stays closed is the accumulated shift of Cattaneo-Mindlin)"),
    _v("contact_rolling_i", "contact", "m",
       "distance the contact point (pressure centroid) travelled over particle i's surface in "
       "the step, from i's rigid motion: the chord between its positions in i's body frame "
       "at the step's start and end (NaN for a contact new in the step)"),
    _v("contact_rolling_j", "contact", "m",
       "the same over particle j's surface, or over the plate's (the upper plate's frame "
       "moving with its shift); rolling without slip: equal to contact_rolling_i, sliding: "
       "they differ by the slip"),
    _v("contact_state", "contact", "1", "stick (some cells stick) or slide", dtype="int8",
       flags=CONTACT_STATES, fill="slide"),
    _v("contact_half_space_ratio", "contact", "1",
       "contact radius (its largest spot's) over the smallest radius of curvature of the two "
       "surfaces where that spot sits (the half-space approximation's measure)"),
    _v("contact_spot_tilt", "contact", "degree",
       "largest angle between a spot's own normal and the contact's normal (0 for one spot "
       "and for the plates): the spots of a pair contact share its frame, so a spot facing "
       "elsewhere (a non-convex particle touching on two bumps) is solved along the wrong "
       "normal; a warning is given past atan(half_space_limit)"),
    _v("contact_mu", "contact", "1", "friction coefficient of the contact"),
    _v("contact_elastic_energy", "contact", "J", "elastic energy stored in the contact at the "
                                                 "end of the step"),
    _v("contact_dissipation", "contact", "J", "frictional dissipation of the contact in the "
                                              "step (>= 0 but for rounding)"),
    # --- maps --------------------------------------------------------------------------------
    _v("pressure", "map_step particle interface map_j map_i", "Pa", "contact pressure",
       fill=0.0),
    _v("traction", "map_step particle interface component map_j map_i", "Pa",
       "traction of the plate on the particle", fill=0.0),
    _v("status", "map_step particle interface map_j map_i", "1", "0 open, 1 stick, 2 slip",
       dtype="int8", fill=0),
    # --- a sweep's summary (one value per case) ----------------------------------------------
    _v("behaviour", "case", "1", "behaviour over the run: " + ", ".join(BEHAVIOURS),
       dtype="int8", flags=BEHAVIOURS, fill="missing"),
    _v("total_rotation", "case", "degree",
       "one particle: angle from the initial to the final orientation, negative if its axis "
       "points to -y (turns about y: the change of theta)"),
    _v("turn_azimuth", "case", "degree", "one particle: azimuth of the axis of the total "
                                         "rotation, from +x"),
    _v("first_turn_force", "case", "N", "total normal force at the first step in which a "
                                        "particle turned (NaN: none turned)"),
    _v("first_turn_compression", "case", "1", "compression at that step"),
    _v("turning_steps", "case", "1", "number of steps in which a particle turned",
       dtype="int32", fill=0),
    _v("final_state", "case", "1", "one particle: state at the last step done (-1: none)",
       dtype="int8", fill=-1),
    _v("final_ratio_up", "case", "1", "one particle: F_T/(mu_up F_N) at the last step, signed "
                                      "as in the state plot: negative when F' points against "
                                      "its first direction"),
    _v("final_ratio_low", "case", "1", "one particle: F_T/(mu_low F_N) at the last step, "
                                       "signed as in the state plot"),
    _v("final_compression", "case", "1", "compression (d0 - h)/d0 at the last step"),
    _v("steps_done", "case", "1", "load steps completed", dtype="int32", fill=0),
    _v("compute_time", "case", "s", "wall time of the case's load steps (sum of time_total)"),
    _v("final_loaded", "case", "1", "particles loaded at the last step"),
    _v("final_fraction_stick", "case", "1", "fraction of the loaded particles sticking at the "
                                            "last step"),
    _v("final_fraction_roll", "case", "1", "fraction of the loaded particles rolling at the "
                                           "last step"),
    _v("final_fraction_rotate", "case", "1", "fraction of the loaded particles rotating at the "
                                             "last step"),
    _v("steady_mu_eff", "case", "1",
       "sliding runs: steady-state effective friction, the mean of mu_eff_sliding over the "
       "steps that end in the last half of the sliding distance, each weighted by its "
       "increment's length (NaN: the plates did not slide)"),
    _v("steady_mu_eff_std", "case", "1",
       "sliding runs: the spread of mu_eff_sliding over those steps, its standard deviation "
       "(weighted as the mean; NaN: no sliding)"),
    _v("steady_mu_eff_min", "case", "1", "sliding runs: the smallest mu_eff_sliding over "
                                         "those steps (NaN: no sliding)"),
    _v("steady_mu_eff_max", "case", "1", "sliding runs: the largest mu_eff_sliding over "
                                         "those steps (NaN: no sliding)"),
    _v("final_sliding_distance", "case", "m",
       "sliding runs: the path length the upper plate slid by the last step done (0: it did "
       "not slide)", fill=0.0),
)}

#: units of the configuration keys (a sweep's axes carry them; the docs list them)
PARAMETERS: dict[str, str] = {
    "plates.mu": "1", "plates.mu_up": "1", "plates.mu_low": "1",
    "particle.orientation_deg": "degree", "particle.tilt_axis_deg": "degree",
    "particle.yaw_deg": "degree", "particle.azimuth_deg": "degree", "particle.E": "Pa",
    "particle.nu": "1", "particle.radius": "m", "particle.semi_axes": "m",
    "particle.amplitude": "1", "particle.seed": "1", "particle.n_waves": "1",
    "particle.scale": "1", "load.stop": "N", "load.hold": "N", "load.steps": "1",
    "numerics.resolution": "cells per particle size", "numerics.cell_size": "m",
    "layer.size": "m", "layer.size_std": "m", "layer.count": "1", "layer.area_fraction": "1",
    "layer.max_tilt_deg": "degree", "layer.seed": "1", "layer.E": "Pa", "layer.nu": "1",
    "network.mu_pp": "1",
}


def parameter_units(key: str) -> str:
    """The units of a configuration key ("" if not listed)."""
    return PARAMETERS.get(key, "")


def variable(name: str) -> Variable:
    """The registered variable ``name`` (KeyError naming the known ones otherwise)."""
    try:
        return VARIABLES[name]
    except KeyError:
        raise KeyError(f"no output variable {name!r}; known: {', '.join(VARIABLES)}") from None


def by_kind(kind: str) -> Iterator[Variable]:
    """The registered variables of one :attr:`Variable.kind`, in registry order."""
    return (v for v in VARIABLES.values() if v.kind == kind)


def markdown_table() -> str:
    """The table of every variable (name, dimensions, units, meaning) for the documentation."""
    rows = ["| variable | dimensions | units | meaning |", "|---|---|---|---|"]
    for v in VARIABLES.values():
        meaning = v.long_name.replace("|", "\\|")
        if v.flags:
            meaning += " (codes: " + ", ".join(f"{i} {f}" for i, f in enumerate(v.flags)) + ")"
        rows.append(f"| `{v.name}` | {', '.join(v.dims)} | {v.units} | {meaning} |")
    return "\n".join(rows)
