"""Figures from a results dataset (matplotlib, Agg): the state curve, the orientation and
position history, and contact maps; for a layer of particles, a top view of the layer, the load
shares, the fractions of the states and each particle's F_T/(μF_N). Every function takes the
:class:`xarray.Dataset` written by :meth:`thirdbody.Simulation.run` and returns the figure;
:func:`save_all` writes them as PNG (and PDF) files.
"""

from __future__ import annotations

import json
from itertools import product as itertools_product
from pathlib import Path

import numpy as np

__all__ = ["contact_maps", "energy_split", "friction_map", "layer_top_view", "load_shares",
           "orientation_history", "particle_ratios", "quantity_label", "save_all",
           "save_state_map", "shear_curve", "slides", "state_curve", "state_fractions",
           "state_map"]

_STATUS_COLOURS = ("white", "black", "0.6")          # open, stick, slip


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _one(ds):
    """One particle's view of a results dataset (:func:`thirdbody.records.particle_view`);
    a view (no ``particle`` dimension) as it is."""
    from .records import particle_view

    if "particle" not in ds.dims:
        return ds
    if ds.sizes["particle"] != 1:
        raise ValueError(f"this figure draws one particle; the results have "
                         f"{ds.sizes['particle']}: pass particle_view(ds, i)")
    return particle_view(ds)


def _inputs(ds) -> dict:
    return json.loads(ds.attrs.get("inputs", "{}"))


def _mu_text(inputs: dict) -> str:
    """The friction coefficients as mathtext: "μ = 0.3", or both plates' when they differ."""
    nan = float("nan")
    up, low = inputs.get("mu_up", nan), inputs.get("mu_low", nan)
    if up == low:
        return f"$\\mu$ = {up:g}"
    return f"$\\mu_\\mathrm{{up}}$ = {up:g}, $\\mu_\\mathrm{{low}}$ = {low:g}"


def _title(ds) -> str:
    i = {k: v for k, v in _inputs(ds).items() if v is not None}
    nan = float("nan")
    start = f"$\\theta_0$ = {i.get('orientation_deg', nan):g}°"
    if i.get("tilt_axis_deg", 90.0) != 90.0 or i.get("yaw_deg", 0.0) != 0.0:
        start += f" about azimuth {i.get('tilt_axis_deg', nan):g}°"
        if i.get("yaw_deg", 0.0):
            start += f", yaw {i['yaw_deg']:g}°"
    return (f"$E$ = {i.get('E', nan) / 1e9:g} GPa, $\\nu$ = {i.get('nu', nan):g}, "
            f"{_mu_text(i)}, {start}")


def _integer_steps(axis) -> None:
    """Ticks of a load-step axis at whole steps only."""
    from matplotlib.ticker import MaxNLocator

    axis.set_major_locator(MaxNLocator(integer=True))


#: the compression ratio's axis label (mathtext)
_COMPRESSION = "compression $(d_0 - h)/d_0$"


def _initial_tilt(ds) -> np.ndarray:
    """The tilt vector (degrees) of the run's initial orientation, from its inputs."""
    from scipy.spatial.transform import Rotation

    q = _inputs(ds).get("quaternion")
    if q is None:
        return np.zeros(2)
    b = Rotation.from_quat(q).apply([0.0, 0.0, 1.0])
    horizontal = float(np.hypot(b[0], b[1]))
    if horizontal == 0:
        return np.zeros(2)
    angle = np.degrees(np.arctan2(horizontal, b[2]))
    return angle * np.array([-b[1], b[0]]) / horizontal


def _planar(ds) -> bool:
    """Every orientation and turn of the run is about the y axis (the paper's case)."""
    return bool(np.all(np.abs(ds.orientation.sel(component="x").values) < 1e-9)
                and np.all(np.abs(ds.rotation.sel(component="x").values) < 1e-9))


def _signed(ds) -> np.ndarray:
    """+1/−1 per step: the side on which the lower plate pushes, relative to the first
    non-zero F' of the run (for the paper's case, the sign of F'_x at the start)."""
    from .records import direction_sign

    return direction_sign(ds.tangential_force.transpose("step", "component").values)


def state_curve(ds, labels: dict[int, str] | None = None):
    """F_T/(μF_N) against the compression ratio (d₀ − h)/d₀ (the paper's Figs. 3a, 4, 5a).

    The slip limit at 1 is drawn, and the stick region below it is shaded from the lowest
    plotted value up; with unequal μ there is one curve per interface, each over its own μ.
    The sign says whether the lower plate pushes the way it did at the start (+) or the
    opposite way (−). Steps in which the particle turned are marked. ``labels`` maps step
    indices to letters written next to the curve.
    """
    plt = _plt()
    ds = _one(ds)
    i = _inputs(ds)
    c = ds.compression.values
    sign = _signed(ds)
    signed = {side: ds.ratio.sel(interface=side).values * sign for side in ("upper", "lower")}
    equal = i.get("mu_up") == i.get("mu_low")
    curves = [("lower", r"$F_T/(\mu F_N)$", "tab:blue", "o")]
    if not equal:
        curves = [("upper", r"upper plate: $F_T/(\mu_\mathrm{up} F_N)$", "tab:blue", "*"),
                  ("lower", r"lower plate: $F_T/(\mu_\mathrm{low} F_N)$", "tab:red", "^")]
    plotted = np.concatenate([signed[side] for side, *_ in curves])
    plotted = plotted[np.isfinite(plotted)]
    top = max(1.2, float(np.abs(plotted).max(initial=0.0)) * 1.1)
    lowest = min(0.0, float(plotted.min(initial=0.0)))
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.axhspan(lowest, 1.0, color="0.9", zorder=0, gid="stick region",
               label=r"stick: $F_T < \mu F_N$ (partial slip)")
    ax.axhline(1.0, color="tab:red", lw=1.5, zorder=1, gid="slip limit",
               label=r"slip limit: $F_T = \mu F_N$")
    for side, label, colour, marker in curves:
        ax.plot(c, signed[side], marker=marker, ms=4, color=colour, lw=1.2, label=label,
                zorder=2)
    turned = ds.turned.values.astype(bool)
    if turned.any():
        ax.plot(c[turned], np.ones(turned.sum()), "x", color="k", ms=6, zorder=3,
                label="turned in the step")
    for step, text in (labels or {}).items():
        k = int(np.flatnonzero(ds.step.values == step)[0])
        ax.annotate(text, (c[k], signed["lower"][k]), textcoords="offset points",
                    xytext=(4, 6), fontsize=11, fontweight="bold")
    ax.set_xlabel(_COMPRESSION)
    ax.set_ylabel("friction ratio " + (r"$F_T/(\mu F_N)$" if equal else
                                       r"$F_T/(\mu F_N)$ at each plate")
                  + "\n" + r"(negative: $F_T$ opposite to its first direction)")
    ax.set_ylim(lowest - 0.05 * (top - lowest), top)
    ax.set_xlim(0, float(c.max()) * 1.02 if c.size else 1)
    # below the axes: a curve may run anywhere in them (down to negative ratios)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=8, loc="outside lower center",
               ncols=3)
    ax.set_title(_title(ds), fontsize=9)
    return fig


def orientation_history(ds):
    """The orientation (degrees) and the centroid's horizontal position and the slips (µm)
    against the compression ratio. For a run turning about y only, the orientation is the
    paper's θ; otherwise both components of the tilt vector are drawn, and the turn axis of
    each turning step is shown in a top view."""
    plt = _plt()
    ds = _one(ds)
    c = ds.compression.values
    planar = _planar(ds)
    if planar:
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(6.4, 5.0), sharex=True,
                                     constrained_layout=True)
    else:
        fig = plt.figure(figsize=(10.5, 5.0), constrained_layout=True)
        grid = fig.add_gridspec(2, 2, width_ratios=(1.6, 1))
        a1 = fig.add_subplot(grid[0, 0])
        a2 = fig.add_subplot(grid[1, 0], sharex=a1)
        a3 = fig.add_subplot(grid[:, 1])
    tilt = ds.orientation.transpose("step", "component").values
    if planar:
        a1.plot(c, tilt[:, 1], "o-", ms=3)
        a1.set_ylabel(r"orientation $\theta$ about $y$ (°)")
    else:
        a1.plot(c, tilt[:, 0], "o-", ms=3, label="tilt vector x")
        a1.plot(c, tilt[:, 1], "s-", ms=3, label="tilt vector y")
        a1.set_ylabel("orientation (°)")
        a1.legend(fontsize=8)
    components = ("x",) if planar else ("x", "y")
    styles = {"x": ("-", "--", ":"), "y": ("-.", (0, (3, 1, 1, 1)), (0, (1, 3)))}
    for comp in components:
        suffix = f" {comp}" if not planar else ""
        centroid, upper, lower = styles[comp]
        a2.plot(c, ds.position.sel(component=comp).values * 1e6, marker="o", ms=3,
                linestyle=centroid, color="tab:green", label="centroid" + suffix)
        a2.plot(c, ds.slip.sel(interface="upper", component=comp).values * 1e6,
                linestyle=upper, color="tab:blue", label="slip, upper" + suffix)
        a2.plot(c, ds.slip.sel(interface="lower", component=comp).values * 1e6,
                linestyle=lower, color="tab:red", label="slip, lower" + suffix)
    a2.set_ylabel("displacement (µm)")
    a2.set_xlabel(_COMPRESSION)
    a2.legend(fontsize=7, ncols=2)
    a1.set_title(_title(ds), fontsize=9)
    if not planar:
        start = _initial_tilt(ds)
        path = np.vstack([start[None, :], tilt])
        a3.plot(path[:, 0], path[:, 1], "o-", ms=3, color="0.4", label="tilt vector")
        a3.plot(*start, "s", ms=6, color="0.2", label="start")
        turned = np.flatnonzero(ds.turned.values.astype(bool))
        rot = ds.rotation.transpose("step", "component").values
        for k in turned:
            a3.annotate("", xy=tuple(path[k + 1]), xytext=tuple(path[k]),
                        arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 1.5})
            azimuth = np.degrees(np.arctan2(rot[k, 1], rot[k, 0]))
            a3.annotate(f"{k}: {np.hypot(*rot[k]):.1f}° about {azimuth:.0f}°", tuple(path[k + 1]),
                        textcoords="offset points", xytext=(4, -10), fontsize=7,
                        color="tab:red")
        a3.plot([], [], color="tab:red", label="turn in step k: angle about the axis azimuth")
        a3.axhline(0, color="0.8", lw=0.8)
        a3.axvline(0, color="0.8", lw=0.8)
        a3.set_aspect("equal", adjustable="datalim")
        a3.set_xlabel("tilt vector x (°)")
        a3.set_ylabel("tilt vector y (°)")
        a3.set_title("top view: the tilt axis is the vector's direction", fontsize=8)
        a3.legend(fontsize=7)
    return fig


def _nice_length(span: float) -> float:
    """A round length (1, 2 or 5 × 10ᵏ) near a quarter of ``span``."""
    target = span / 4
    power = 10.0 ** np.floor(np.log10(target))
    return float(max(m * power for m in (1, 2, 5) if m * power <= target))


def _scale_bar(ax, span_um: float) -> None:
    """A white-boxed scale bar in the lower right corner, labelled in µm or mm."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    length = _nice_length(span_um)
    label = f"{length / 1000:g} mm" if length >= 1000 else f"{length:g} µm"
    bar = AnchoredSizeBar(ax.transData, length, label, "lower right", pad=0.3, borderpad=0.4,
                          sep=3, frameon=True, size_vertical=span_um / 150,
                          fontproperties={"size": 7})
    bar.patch.set_alpha(0.8)
    ax.add_artist(bar)


def _extent(ds, side: str) -> tuple[slice, slice]:
    """Rows and columns of the maps where ``side`` has contact at some stored step, with a
    margin of a tenth of the extent (at least 3 cells)."""
    touched = (ds.pressure.sel(interface=side).values > 0).any(axis=0)
    rows, cols = np.flatnonzero(touched.any(axis=1)), np.flatnonzero(touched.any(axis=0))
    if not rows.size:
        return slice(None), slice(None)
    margin = max(3, int(0.1 * max(rows[-1] - rows[0], cols[-1] - cols[0])))
    ny, nx = touched.shape
    return (slice(max(rows[0] - margin, 0), min(rows[-1] + margin + 1, ny)),
            slice(max(cols[0] - margin, 0), min(cols[-1] + margin + 1, nx)))


def contact_maps(ds, steps: list[int] | None = None):
    """Pressure and stick/slip/open maps of both interfaces at the chosen steps (default: the
    first, the middle and the last stored map), side by side, axes in µm (particle frame)
    with a scale bar. Each interface's panels cover every spot it had at a stored step."""
    plt = _plt()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    ds = _one(ds)
    stored = list(ds.map_step.values)
    if steps is None:
        steps = sorted({stored[0], stored[len(stored) // 2], stored[-1]})
    steps = [s for s in steps if s in stored]
    x_all = ds.map_x.values * 1e6
    y_all = ds.map_y.values * 1e6
    spacing = float(x_all[1] - x_all[0]) if x_all.size > 1 else 1.0
    boxes = {side: _extent(ds, side) for side in ("upper", "lower")}
    aspect = {side: min(max((len(range(*c.indices(x_all.size))) + 1)
                            / (len(range(*r.indices(y_all.size))) + 1), 0.6), 4.0)
              for side, (r, c) in boxes.items()}
    widths = [aspect["upper"]] * 2 + [aspect["lower"]] * 2
    unit = min(3.2, 13.0 / sum(widths))          # inches per unit of panel aspect
    fig, axes = plt.subplots(len(steps), 4, figsize=(unit * sum(widths) + 1.2,
                                                     (unit + 0.9) * len(steps) + 0.8),
                             squeeze=False, constrained_layout=True,
                             gridspec_kw={"width_ratios": widths})
    status_map = ListedColormap(_STATUS_COLOURS)
    pmax = float(ds.pressure.max()) / 1e6
    for col, (side, where) in enumerate((("upper", "upper"), ("lower", "lower"))):
        rows, cols = boxes[side]
        x, y = x_all[cols], y_all[rows]
        extent = (x[0] - spacing / 2, x[-1] + spacing / 2, y[0] - spacing / 2,
                  y[-1] + spacing / 2)
        for row, step in enumerate(steps):
            k = stored.index(step)
            c = float(ds.compression.sel(step=step))
            spots = int(ds.spots.sel(step=step, interface=side))
            ax_p, ax_s = axes[row, 2 * col], axes[row, 2 * col + 1]
            p = ds.pressure.sel(interface=side).values[k][rows, cols] / 1e6
            status = ds.status.sel(interface=side).values[k][rows, cols]
            im = ax_p.imshow(p, origin="lower", extent=extent, cmap="viridis", vmin=0,
                             vmax=pmax)
            ax_s.imshow(status, origin="lower", extent=extent, cmap=status_map, vmin=-0.5,
                        vmax=2.5, interpolation="nearest")
            plural = "s" if spots != 1 else ""
            ax_p.set_title(f"step {step}, {where}: pressure (c = {c:.3f})", fontsize=9)
            ax_s.set_title(f"step {step}, {where}: stick / slip, {spots} spot{plural}",
                           fontsize=9)
            for ax in (ax_p, ax_s):
                ax.set_xlabel("x (µm)")
                ax.set_ylabel("y (µm)")
                _scale_bar(ax, float(extent[1] - extent[0]))
            if col == 1:
                fig.colorbar(im, ax=ax_p, label="pressure $p$ (MPa)", shrink=0.8)
    handles = [Patch(facecolor=col, edgecolor="k", label=name)
               for col, name in zip(_STATUS_COLOURS, ("open", "stick", "slip"), strict=True)]
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8)
    fig.suptitle(_title(ds), fontsize=10)
    return fig


def save_all(ds, out: str | Path, formats: tuple[str, ...] = ("png", "pdf"),
             labels: dict[int, str] | None = None, map_steps: list[int] | None = None,
             layer=None) -> list[Path]:
    """Write every figure for ``ds`` into ``out`` (created); returns the files written.

    For the results of a layer of several particles the figures are :func:`layer_top_view`
    (at ``map_steps`` if given, drawing the true outlines of ``layer``, a
    :class:`thirdbody.Layer`, or of the layer rebuilt from the run's ``config`` attribute),
    :func:`load_shares`, :func:`state_fractions` and :func:`particle_ratios`; ``labels`` is not
    used then."""
    plt = _plt()
    if ds.sizes.get("particle", 1) > 1:
        if layer is None:
            layer = _layer_from_config(ds)
        figures = {"layer_top_view": layer_top_view(ds, map_steps, layer),
                   "load_shares": load_shares(ds), "state_fractions": state_fractions(ds),
                   "particle_ratios": particle_ratios(ds)}
        if "contact" in ds.dims:
            figures["contact_network"] = contact_network(ds)
        if slides(ds):
            figures["shear"] = shear_curve(ds)
            figures["particle_rotations"] = particle_rotations(ds)
        return _save_figures(plt, figures, out, formats)
    whole = ds
    ds = _one(ds)
    figures = {"state": state_curve(ds, labels), "orientation": orientation_history(ds)}
    if "map_step" in ds.dims and ds.sizes["map_step"]:
        figures["contact_maps"] = contact_maps(ds, map_steps)
    if slides(whole):
        figures["shear"] = shear_curve(whole)
        figures["particle_rotations"] = particle_rotations(whole)
    return _save_figures(plt, figures, out, formats)


def _save_figures(plt, figures: dict, out: str | Path, formats: tuple[str, ...]) -> list[Path]:
    """Save each figure as ``out/<name>.<format>`` (``out`` created), then close it."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fig in figures.items():
        for fmt in formats:
            path = out / f"{name}.{fmt}"
            fig.savefig(path, dpi=130)
            written.append(path)
        plt.close(fig)
    return written


# --- sweeps ------------------------------------------------------------------------------------
_BEHAVIOUR_COLOURS = {"stick": "#4c72b0", "roll_upper": "#dd8452", "roll_lower": "#c44e52",
                      "rotate": "#55a868", "failed": "0.35", "error": "black", "missing": "white",
                      "roll": "#937860"}


#: the quantity a configuration key sets, as an axis label (mathtext); its units come from
#: :func:`thirdbody.schema.parameter_units`
QUANTITIES: dict[str, str] = {
    "plates.mu": r"$\mu$", "plates.mu_up": r"$\mu_\mathrm{up}$",
    "plates.mu_low": r"$\mu_\mathrm{low}$",
    "particle.orientation_deg": r"$\theta_0$", "particle.tilt_axis_deg": "tilt axis azimuth",
    "particle.yaw_deg": "yaw", "particle.azimuth_deg": "azimuth of the whole orientation",
    "particle.E": r"$E$", "particle.nu": r"$\nu$", "particle.radius": "radius",
    "particle.semi_axes": "semi-axes", "particle.amplitude": "wave amplitude",
    "particle.seed": "shape seed", "particle.n_waves": "number of waves",
    "particle.scale": "mesh scale", "load.stop": "final load", "load.hold": "held load",
    "load.steps": "load steps", "numerics.resolution": "resolution",
    "numerics.cell_size": "cell size", "layer.size": "mean particle size",
    "layer.size_std": "standard deviation of the size", "layer.count": "particle count",
    "layer.area_fraction": "area fraction", "layer.max_tilt_deg": "largest initial tilt",
    "layer.seed": "layer seed", "layer.E": r"$E$", "layer.nu": r"$\nu$",
    "network.mu_pp": r"$\mu_\mathrm{pp}$",
}

#: how a unit is written after a quantity (none for a pure number)
_UNIT_TEXT = {"1": "", "degree": "°"}


def quantity_label(key: str, units: str | None = None) -> str:
    """An axis label for the configuration key ``key``: the quantity it sets and its units,
    "θ₀ (°)" for ``particle.orientation_deg``, "E (Pa)" for ``particle.E``; an unlisted key
    is written as it is. ``units`` (default: :func:`thirdbody.schema.parameter_units`)."""
    from .schema import parameter_units

    units = parameter_units(key) if units is None else units
    units = _UNIT_TEXT.get(units, units)
    name = QUANTITIES.get(key, key)
    return f"{name} ({units})" if units else name


def _axis_label(ds, name: str) -> str:
    key = ds[name].attrs.get("config_key", name)
    units = ds[name].attrs.get("units") if key not in QUANTITIES else None
    return quantity_label(key, units)


def _value_text(ds, name: str, value) -> str:
    """"θ₀ = 30°", "μ = 0.2": one value of a sweep axis, for a panel's title."""
    from .schema import parameter_units

    key = ds[name].attrs.get("config_key", name)
    text = f"{value:g}" if isinstance(value, float) else str(value)
    if key not in QUANTITIES:
        return f"{key} = {text}"
    units = parameter_units(key)
    return f"{QUANTITIES[key]} = {text}{_UNIT_TEXT.get(units, ' ' + units)}"


def _ticks(ds, name: str | None) -> tuple[range, list[str]]:
    """Positions and labels of a sweep coordinate's values (none for no dimension)."""
    if name is None:
        return range(0), []
    values = ds[name].values.tolist()
    return range(len(values)), [f"{v:g}" if isinstance(v, float) else str(v) for v in values]


def _force_scale(force: np.ndarray):
    """The colour scale of the first-turn forces: over their range, with no text; or, when
    they are all equal (or there are none), a scale that puts them mid-way and a text that
    says so instead of a colour bar."""
    from matplotlib.colors import Normalize

    finite = force[np.isfinite(force)]
    if not finite.size:
        return Normalize(0.0, 1.0), "no case turned"
    lo, hi = float(finite.min()), float(finite.max())
    if hi - lo <= 1e-9 * max(abs(hi), 1e-300):
        return Normalize(lo - 1.0, hi + 1.0), (f"every case that turned did so at {hi:.3g} N"
                                             if finite.size > 1 else f"one case turned, at "
                                             f"{hi:.3g} N")
    return Normalize(lo, hi), None


def _sweep_axes(summary, dims: list, x: str | None, y: str | None):
    """A sweep map's axes: ``x`` and ``y`` (default the first two sweep dimensions, checked),
    the other dimensions and their first six index combinations (the rows of panels)."""
    if not dims:
        raise ValueError("the summary has no sweep dimension")
    x = x or dims[0]
    y = y or (next((d for d in dims if d != x), None))
    for name in (x, y):
        if name is not None and name not in dims:
            raise ValueError(f"{name!r} is not a sweep dimension; choose from {dims}")
    rest = [d for d in dims if d not in (x, y)]
    combos = list(itertools_product(*[range(summary.sizes[d]) for d in rest]))[:6]
    return x, y, rest, combos


def state_map(summary, x: str | None = None, y: str | None = None):
    """The sweep's behaviour map: per case, the behaviour (colour: stick, roll about the upper
    or lower interface, rotate, failed) with the total rotation (degrees) written in the cell
    (for a layer: the behaviour of the first particle to turn, with the final fractions of the
    loaded particles rolling and rotating), and the normal force (N) at the first turn. ``x``,
    ``y``: sweep dimensions (default the first two); further dimensions become rows of panels
    (at most six)."""
    plt = _plt()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    dims = [d for d in summary.behaviour.dims]
    x, y, rest, combos = _sweep_axes(summary, dims, x, y)
    meanings = summary.behaviour.attrs["flag_meanings"].split()
    cmap = ListedColormap([_BEHAVIOUR_COLOURS[m] for m in meanings])
    fig, axes = plt.subplots(len(combos), 2, figsize=(11, 4.2 * len(combos) + 0.4),
                             squeeze=False, constrained_layout=True)
    norm, force_text = _force_scale(summary.first_turn_force.values)
    for row, combo in enumerate(combos):
        sel = {d: i for d, i in zip(rest, combo, strict=True)}
        part = summary.isel(sel)
        where = ", ".join(_value_text(summary, d, summary[d].values[i].item())
                          for d, i in sel.items())
        order = (y, x) if y else (x,)
        behaviour = part.behaviour.transpose(*order).values.reshape(-1, part.sizes[x])
        rotation = part.total_rotation.transpose(*order).values.reshape(behaviour.shape)
        force = part.first_turn_force.transpose(*order).values.reshape(behaviour.shape)
        layer = "final_fraction_roll" in part and not np.isnan(
            part.final_fraction_roll.values).all()
        if layer:       # a layer: the final fractions rolling and rotating, not one rotation
            roll = part.final_fraction_roll.transpose(*order).values.reshape(behaviour.shape)
            turn = part.final_fraction_rotate.transpose(*order).values.reshape(behaviour.shape)
        ax_b, ax_f = axes[row]
        ax_b.imshow(behaviour, origin="lower", cmap=cmap, vmin=-0.5, vmax=len(meanings) - 0.5,
                    aspect="auto", interpolation="nearest")
        for (i, j), rot in np.ndenumerate(rotation):
            if layer and roll[i, j] == roll[i, j]:
                colour = "black" if meanings[behaviour[i, j]] == "missing" else "white"
                ax_b.text(j, i, f"{roll[i, j]:.0%} roll\n{turn[i, j]:.0%} rot.", ha="center",
                          va="center", fontsize=7, color=colour)
            elif rot == rot:
                colour = "black" if meanings[behaviour[i, j]] == "missing" else "white"
                label = f"{rot:+.1f}°" if abs(rot) >= 0.05 else "0°"
                ax_b.text(j, i, label, ha="center", va="center", fontsize=7,
                          color=colour)
        masked = np.ma.masked_invalid(force)
        ax_f.set_facecolor("0.88")
        im = ax_f.imshow(masked, origin="lower", cmap="magma_r", aspect="auto",
                         interpolation="nearest", norm=norm)
        if force_text is None:          # a range of forces: a colour bar over it
            fig.colorbar(im, ax=ax_f, label="normal force at the first turn (N)", shrink=0.85)
        for (i, j), f in np.ndenumerate(force):
            if f == f:
                ax_f.text(j, i, f"{f:.3g} N", ha="center", va="center", fontsize=7,
                          color="white" if norm(f) > 0.5 else "black")
        what = ("first turn; final fractions rolling, rotating" if layer
                else "behaviour, total rotation")
        ax_b.set_title(what + (f" ({where})" if where else ""), fontsize=9)
        ax_f.set_title("normal force at the first turn (grey: never turned)"
                       + (f"\n{force_text}" if force_text else "")
                       + (f" ({where})" if where else ""), fontsize=9)
        for ax in (ax_b, ax_f):
            ax.set_xticks(*_ticks(summary, x))
            ax.set_xlabel(_axis_label(summary, x))
            ax.set_yticks(*_ticks(summary, y))
            ax.set_ylabel(_axis_label(summary, y) if y else "")
    present = sorted(set(np.asarray(summary.behaviour.values).ravel().tolist()))
    handles = [Patch(facecolor=_BEHAVIOUR_COLOURS[meanings[k]], edgecolor="k",
                     label=meanings[k].replace("_", " ")) for k in present]
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8)
    fig.suptitle(f"thirdbody sweep: {summary.attrs.get('cases', '?')} cases, "
                 f"{summary.attrs.get('failed', 0)} not complete", fontsize=10)
    return fig


def _sweep_slides(summary) -> bool:
    """Some case of the sweep slid its plates (a finite steady-state μ_eff)."""
    return "steady_mu_eff" in summary and bool(np.isfinite(summary.steady_mu_eff.values).any())


def friction_map(summary, x: str | None = None, y: str | None = None):
    """The sweep's map of the steady-state effective friction of its sliding cases: per case
    ``steady_mu_eff`` in colour, written in the cell with its spread (± ``steady_mu_eff_std``),
    grey where the case did not slide (or is missing). ``x``, ``y``: sweep dimensions
    (default the first two); further dimensions become rows of panels (at most six)."""
    plt = _plt()

    mu = summary.steady_mu_eff
    dims = list(mu.dims)
    x, y, rest, combos = _sweep_axes(summary, dims, x, y)
    finite = mu.values[np.isfinite(mu.values)]
    low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if high <= low:
        low, high = low - 0.05, high + 0.05
    fig, axes = plt.subplots(len(combos), 1, figsize=(6.4, 4.4 * len(combos) + 0.4),
                             squeeze=False, constrained_layout=True)
    order = (y, x) if y else (x,)
    for row, combo in enumerate(combos):
        sel = {d: i for d, i in zip(rest, combo, strict=True)}
        part = summary.isel(sel)
        where = ", ".join(_value_text(summary, d, summary[d].values[i].item())
                          for d, i in sel.items())
        values = part.steady_mu_eff.transpose(*order).values.reshape(-1, part.sizes[x])
        spread = part.steady_mu_eff_std.transpose(*order).values.reshape(values.shape)
        ax = axes[row][0]
        ax.set_facecolor("0.88")
        im = ax.imshow(np.ma.masked_invalid(values), origin="lower", cmap="viridis",
                       vmin=low, vmax=high, aspect="auto", interpolation="nearest")
        for (i, j), value in np.ndenumerate(values):
            if value == value:
                shade = (value - low) / (high - low)
                ax.text(j, i, f"{value:.3f}\n±{spread[i, j]:.2g}", ha="center", va="center",
                        fontsize=7, color="black" if shade > 0.6 else "white")
        fig.colorbar(im, ax=ax, label=r"steady-state $\mu_\mathrm{eff}$", shrink=0.85)
        ax.set_title("steady-state effective friction, mean ± spread over the last half of "
                     "the sliding\n(grey: did not slide)" + (f" ({where})" if where else ""),
                     fontsize=9)
        ax.set_xticks(*_ticks(summary, x))
        ax.set_xlabel(_axis_label(summary, x))
        ax.set_yticks(*_ticks(summary, y))
        ax.set_ylabel(_axis_label(summary, y) if y else "")
    fig.suptitle(f"thirdbody sweep: {summary.attrs.get('cases', '?')} cases, "
                 f"{summary.attrs.get('failed', 0)} not complete", fontsize=10)
    return fig


def save_state_map(summary, out: str | Path, formats: tuple[str, ...] = ("png", "pdf"),
                   ) -> list[Path]:
    """Write ``state_map.png`` (and ``.pdf``) for a sweep summary into ``out``, and for a
    sweep of sliding cases ``friction_map.png`` (:func:`friction_map`)."""
    figures = {"state_map": state_map(summary)}
    if _sweep_slides(summary):
        figures["friction_map"] = friction_map(summary)
    return _save_figures(_plt(), figures, out, formats)


# --- layers ------------------------------------------------------------------------------------
#: a layer particle's colour by its state in a step (the sweeps' behaviour colours)
_STATE_COLOURS = {**{k: _BEHAVIOUR_COLOURS[k] for k in ("stick", "roll_upper", "roll_lower",
                                                         "rotate", "failed", "roll")},
                  "unloaded": "0.75", "slide": "#8172b3",
                  "slide_upper": "#b3a3d9", "slide_lower": "#5a4a8c"}
_DEFAULT_STATES = "stick roll_upper roll_lower rotate failed unloaded"
_MARKER_AREA = 250.0            # pt²: the centroid marker of the run's largest normal force
_OUTLINE_RAYS = 40              # rays per side of the grid sampling a mid-plane section
_CARRIERS = 5                   # particles named in the load-share and ratio figures


def _state_names(ds) -> list[str]:
    """The state names in code order (the ``state`` variable's ``flag_meanings``)."""
    return str(ds.state.attrs.get("flag_meanings", _DEFAULT_STATES)).split()


def _state_colour(name: str) -> str:
    return _STATE_COLOURS.get(name, _STATE_COLOURS["unloaded"])


def _layer_title(ds) -> str:
    status = ds.attrs.get("status", "complete")
    return (f"layer of {ds.sizes['particle']} particles, {_mu_text(_inputs(ds))}"
            + ("" if status == "complete" else f" ({status})"))


def _layer_from_config(ds):
    """The :class:`thirdbody.Layer` rebuilt from the run's ``config`` attribute (TOML), or None
    when there is none, it cannot be built, or it does not match the results."""
    if not ds.attrs.get("config"):
        return None
    try:
        import thirdbody
        from thirdbody.io.config import body_from_results

        body = body_from_results(ds)
        if isinstance(body, thirdbody.Layer) and len(body) == ds.sizes["particle"]:
            return body
    except Exception:       # a config this version cannot build: draw circles instead
        pass
    return None


def _grid(size: float, n: int = _OUTLINE_RAYS) -> np.ndarray:
    """n ray positions along one side (m): ±size and a margin of two spacings, so that a
    section (within ``size`` of the centroid) never touches the grid's edge."""
    return np.linspace(-1.0, 1.0, n) * size * (n - 1) / (n - 5)


def _loops(s: np.ndarray, inside: np.ndarray) -> list[np.ndarray]:
    """Closed loops (k, 2) of the 0.5 contour of a 0/1 mask sampled at ``s`` × ``s``."""
    import contourpy

    if not inside.any():
        return []
    generator = contourpy.contour_generator(s, s, inside.astype(float),
                                            line_type=contourpy.LineType.Separate)
    return [np.asarray(line) for line in generator.lines(0.5) if len(line) > 2]


def _section(shape, rotation, z: float, n: int = _OUTLINE_RAYS) -> list[np.ndarray]:
    """The outline (closed loops (k, 2), m, centroid frame) of the section of ``shape`` at
    ``rotation`` (body to world) by the horizontal plane at height ``z`` (m) above its
    centroid: the 0.5 contour of where the lowest and highest crossings of a vertical ray lie
    either side of ``z``, on n × n rays over ±size. Empty when the plane misses the body."""
    s = _grid(shape.size, n)
    X, Y = np.meshgrid(s, s)
    lo, up = shape.surfaces(rotation, X, Y)
    with np.errstate(invalid="ignore"):
        inside = (lo <= z) & (z <= up)
    return _loops(s, inside)


def _silhouette(shape, rotation, n: int = _OUTLINE_RAYS) -> list[np.ndarray]:
    """The outline (m, centroid frame) of ``shape`` seen from above: where vertical rays hit."""
    s = _grid(shape.size, n)
    X, Y = np.meshgrid(s, s)
    lo, _ = shape.surfaces(rotation, X, Y)
    return _loops(s, np.isfinite(lo))


def _circle(radius: float, points: int = 73) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, points)
    return radius * np.column_stack([np.cos(t), np.sin(t)])


def _round_down(value: float) -> float:
    """The largest 1, 2 or 5 × 10ᵏ not above ``value`` (> 0)."""
    power = 10.0 ** np.floor(np.log10(value))
    return float(max(m * power for m in (1, 2, 5) if m * power <= value * (1 + 1e-12)))


def _top_view_steps(ds, steps) -> list[int]:
    stored = [int(s) for s in ds.step.values]
    if not stored:
        raise ValueError("the results have no step to draw")
    if steps is None:
        steps = sorted({stored[0], stored[len(stored) // 2], stored[-1]})
    chosen = [s for s in dict.fromkeys(int(s) for s in steps) if s in stored]
    if not chosen:
        raise ValueError(f"none of the steps {list(steps)} is in the results (steps "
                         f"{stored[0]} to {stored[-1]})")
    if len(chosen) > 4:
        chosen = [chosen[round(i)] for i in np.linspace(0, len(chosen) - 1, 4)]
    return chosen


def layer_top_view(ds, steps: list[int] | None = None, layer=None):
    """A top view of the layer at the chosen steps (default: the first, the middle and the
    last; at most four panels), axes in mm. Each particle is drawn by its outline at the
    mid-plane z = h/2 with the colour of its state in the step, and a dot at its centroid
    whose area is proportional to its normal force (the same scale in every panel).

    The outlines are the true sections when ``layer`` (the :class:`thirdbody.Layer` that was
    run) is given, sampled on a grid of vertical rays in each particle's orientation of the
    step; a particle the mid-plane misses is drawn by its outline seen from above (dotted).
    Without ``layer`` they are circles of radius ``size`` (dashed), as the panel titles say.
    """
    plt = _plt()
    from matplotlib.colors import to_rgba
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, PathPatch
    from matplotlib.path import Path as MplPath
    from scipy.spatial.transform import Rotation

    n = ds.sizes["particle"]
    if layer is not None and len(layer) != n:
        raise ValueError(f"the layer has {len(layer)} particles, the results {n}")
    steps = _top_view_steps(ds, steps)
    stored = [int(s) for s in ds.step.values]
    names = _state_names(ds)
    force = np.nan_to_num(ds.normal_force.transpose("step", "particle").values)
    fmax = float(force.max(initial=0.0))
    scale = _MARKER_AREA / fmax if fmax > 0 else 0.0          # pt² per N
    x0, y0, size = ds.x0.values, ds.y0.values, ds["size"].values
    position = ds.position.transpose("step", "particle", "component").sel(
        component=["x", "y"]).values
    quaternion = ds.quaternion.transpose("step", "particle", "quaternion_component").sel(
        quaternion_component=["x", "y", "z", "w"]).values
    height = ds.centroid_height.transpose("step", "particle").values
    state = ds.state.transpose("step", "particle").values
    ks = [stored.index(s) for s in steps]
    cx, cy = x0 + position[ks, :, 0], y0 + position[ks, :, 1]        # (panel, particle), m
    pad = 0.05 * max(float(np.ptp(cx) + 2 * size.max()), float(np.ptp(cy) + 2 * size.max()))
    xlim = (float((cx - size).min() - pad) * 1e3, float((cx + size).max() + pad) * 1e3)
    ylim = (float((cy - size).min() - pad) * 1e3, float((cy + size).max() + pad) * 1e3)
    width = (xlim[1] - xlim[0]) / (ylim[1] - ylim[0])
    side = min(4.2, 14.0 / len(steps) / max(width, 1.0))
    fig, axes = plt.subplots(1, len(steps), figsize=(side * width * len(steps) + 0.6,
                                                     side + 1.6),
                             squeeze=False, constrained_layout=True)
    outline = "circles of radius `size` (shapes not given)" if layer is None \
        else "mid-plane sections"
    present, silhouettes, network = set(), False, None
    for panel, (ax, step, k) in enumerate(zip(axes[0], steps, ks, strict=True)):
        gap = float(ds.plate_gap.values[k])
        colours = [_state_colour(names[code]) for code in state[k]]
        present.update(int(code) for code in state[k])
        for i in range(n):
            style = "--"
            if layer is None:
                loops = [_circle(float(size[i]))]
            else:
                shape = layer[i].particle.shape
                rotation = Rotation.from_quat(quaternion[k, i])
                loops, style = _section(shape, rotation, gap / 2 - height[k, i]), "-"
                if not loops:
                    loops, style, silhouettes = _silhouette(shape, rotation), ":", True
            centre = np.array([cx[panel, i], cy[panel, i]])
            path = MplPath.make_compound_path(
                *[MplPath((loop + centre) * 1e3, closed=True) for loop in loops])
            ax.add_patch(PathPatch(path, facecolor=to_rgba(colours[i], 0.3),
                                   edgecolor=colours[i], linestyle=style, lw=1.3,
                                   gid=f"outline {i}"))
            dot = float(np.sqrt(scale * force[k, i])) / 2            # the dot's radius, pt
            ax.annotate(str(i), tuple(centre * 1e3), textcoords="offset points",
                        xytext=(dot + 2, dot + 2), fontsize=6, color="0.25")
        ax.scatter(cx[panel] * 1e3, cy[panel] * 1e3, s=scale * force[k], c=colours,
                   edgecolors="k", linewidths=0.5, zorder=3, gid="normal force")
        if "contact" in ds.dims:
            network = _force_network(ax, ds, step, cx[panel], cy[panel], network)
        box = _inputs(ds).get("box")
        if box:                                     # the periodic box, centred on the origin
            from matplotlib.patches import Rectangle

            ax.add_patch(Rectangle((-box[0] / 2 * 1e3, -box[1] / 2 * 1e3), box[0] * 1e3,
                                   box[1] * 1e3, fill=False, ls=":", lw=1.0, color="0.4",
                                   gid="periodic box"))
        c = float(ds.compression.values[k])
        ax.set_title(f"step {step}: c = {100 * c:.2f} %, $F_N$ = "
                     f"{float(ds.total_force.values[k]):.3g} N, "
                     f"{int(ds.loaded.values[k])} loaded\n{outline}", fontsize=8)
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
    states = [Patch(facecolor=to_rgba(_state_colour(names[code]), 0.3),
                    edgecolor=_state_colour(names[code]), label=names[code].replace("_", " "))
              for code in sorted(present)]
    if silhouettes:
        states.append(Line2D([], [], color="0.3", ls=":",
                             label="seen from above (the mid-plane misses it)"))
    fig.legend(handles=states, loc="outside lower left", ncols=min(len(states), 4),
               fontsize=8, title="state in the step", title_fontsize=8)
    if fmax > 0:
        keys = sorted({_round_down(fmax), _round_down(fmax / 3), _round_down(fmax / 10)})
        sizes = [Line2D([], [], ls="", marker="o", markersize=float(np.sqrt(scale * f)),
                        markerfacecolor="none", markeredgecolor="k", label=f"{f:g} N")
                 for f in keys]
        fig.legend(handles=sizes, loc="outside lower right", ncols=len(sizes), fontsize=8,
                   title="normal force (dot area)", title_fontsize=8, frameon=True)
    if network:
        fig.legend(handles=[Line2D([], [], color=_NETWORK_COLOUR, lw=_NETWORK_WIDTH,
                                   label=f"{network:.3g} N")],
                   loc="outside upper right", fontsize=8, title="particle contact (line width)",
                   title_fontsize=8)
    fig.suptitle(f"top view at the mid-plane z = h/2: {_layer_title(ds)}", fontsize=10)
    return fig


_NETWORK_COLOUR = "#8c2d04"
_NETWORK_WIDTH = 4.0            # pt: the line of the run's largest particle contact force


def _force_network(ax, ds, step: int, cx: np.ndarray, cy: np.ndarray,
                   largest: float | None) -> float:
    """Draw the particle-particle contacts of ``step`` as lines between the centroids (cx, cy
    in m, layer frame; across a periodic box's side to the touching image), width ∝ normal
    force (the run's largest: :data:`_NETWORK_WIDTH`). Returns that largest force (N)."""
    j = ds.contact_j.values
    pair = j >= 0
    if largest is None:
        forces = ds.contact_normal_force.values[pair]
        largest = float(forces.max(initial=0.0))
    rows = np.flatnonzero(pair & (ds.contact_step.values == step)
                          & (ds.contact_normal_force.values > 0))
    if not len(rows) or largest <= 0:
        return largest
    box = _inputs(ds).get("box")
    i = ds.contact_i.values[rows]
    jj = j[rows]
    image = ds.contact_image.transpose("contact", "component").values[rows].astype(float)
    shift = image * (np.asarray(box, dtype=float) if box else 0.0)
    start = np.column_stack([cx[i], cy[i]])
    end = np.column_stack([cx[jj], cy[jj]]) + shift
    if box:     # the centroids are not wrapped: the image of j nearest to i
        L = np.asarray(box, dtype=float)
        end = start + (end - start) - L * np.round((end - start) / L)
    widths = _NETWORK_WIDTH * ds.contact_normal_force.values[rows] / largest
    from matplotlib.collections import LineCollection

    ax.add_collection(LineCollection(np.stack([start, end], axis=1) * 1e3, linewidths=widths,
                                     colors=_NETWORK_COLOUR, zorder=4, capstyle="round",
                                     gid="force network"))
    return largest


def contact_network(ds):
    """A network run's contacts against the load: the coordination number (mean contacts of a
    loaded particle) and the number of particle-particle contacts (left); the upper plate's
    load F_N and the part of it carried by particles touching both plates (right)."""
    plt = _plt()
    x = ds.compression.values * 100
    fig, (left, right) = plt.subplots(1, 2, figsize=(10.0, 4.0), constrained_layout=True)
    left.plot(x, ds.coordination.values, "o-", color="C0", label="coordination number")
    left.set_xlabel("compression $(d_0 - h)/d_0$ (%)")
    left.set_ylabel("coordination number (contacts per loaded particle)")
    twin = left.twinx()
    twin.plot(x, ds.particle_contacts.values, "s--", color="C1",
              label="particle-particle contacts")
    twin.set_ylabel("particle-particle contacts")
    lines = left.get_lines() + twin.get_lines()
    left.legend(lines, [ln.get_label() for ln in lines], fontsize=8, loc="upper left")
    right.plot(x, ds.total_force.values, "o-", color="k", label="$F_N$ (all particles)")
    right.plot(x, ds.both_plates_force.values, "s-", color="C2",
               label="carried by particles touching both plates")
    right.set_xlabel("compression $(d_0 - h)/d_0$ (%)")
    right.set_ylabel("normal force of the upper plate (N)")
    right.legend(fontsize=8)
    fig.suptitle(f"contact network: {_layer_title(ds)}", fontsize=10)
    return fig


def slides(ds) -> bool:
    """The upper plate of the run slid (a :class:`~thirdbody.loading.Slide` program)."""
    return "sliding_distance" in ds and bool(np.nanmax(ds.sliding_distance.values,
                                                       initial=0.0) > 0)


def energy_split(ds, start: int = 0) -> dict[str, np.ndarray]:
    """Where the plates' work went, step by step, from the end of step ``start`` (all 0 there):
    the cumulative work of the upper plate ``plate_work`` (Σ plate_work), the change of the
    stored ``elastic_energy``, and the cumulative frictional dissipation at the plate contacts
    (``dissipation_plate``: the contact table's rows with ``contact_j`` < 0) and at the
    particle–particle contacts (``dissipation_particle``), each an array over the steps from
    ``start`` (J). Their balance: plate_work ≈ elastic_energy + both dissipations."""
    n = ds.sizes["step"]
    steps = ds.contact_step.values.astype(int)
    plate = ds.contact_j.values < 0
    lost = np.nan_to_num(ds.contact_dissipation.values.astype(float))
    by_step = {kind: np.bincount(steps[rows], weights=lost[rows], minlength=n)[:n]
               for kind, rows in (("plate", plate), ("particle", ~plate))}
    rows = slice(start + 1, None)

    def cumulative(values: np.ndarray) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(np.nan_to_num(values[rows]))])

    elastic = ds.elastic_energy.values.astype(float)
    return {"plate_work": cumulative(ds.plate_work.values.astype(float)),
            "elastic_energy": elastic[start:] - elastic[start],
            "dissipation_plate": cumulative(by_step["plate"]),
            "dissipation_particle": cumulative(by_step["particle"])}


def _has_energy(ds) -> bool:
    return all(name in ds for name in ("contact_dissipation", "contact_j", "contact_step",
                                       "plate_work", "elastic_energy")) and bool(
        np.isfinite(ds.plate_work.values).any())


def shear_curve(ds):
    """The shear test: the effective friction (top) and the dilatancy (middle) against the
    sliding distance (the path length of the upper plate, µm), from the end of the compression
    (s = 0, dilatancy 0). μ_eff is drawn along the sliding (``mu_eff_sliding``: > 0 where the
    layer resists the plate's motion) and as a magnitude |F_T|/F_N (dashed); dotted vertical
    lines mark where the plate changed direction (a reversal or a corner of its path). For a
    run with the energy balance, a bottom panel splits the energy (µJ) since the end of the
    compression (:func:`energy_split`): the plate's cumulative work, the change of the
    elastic energy, the cumulative dissipation at the plate contacts and at the
    particle–particle contacts, and the elastic energy plus both dissipations (dashed: on
    the work where the balance closes)."""
    plt = _plt()
    distance = ds.sliding_distance.values
    moving = np.flatnonzero(distance > 0)
    first = int(moving[0])
    start = max(first - 1, 0)                   # the end of the compression
    shift = ds.plate_shift.transpose("step", "component").values
    increments = np.diff(shift, axis=0, prepend=shift[:1] * 0.0)
    e0 = increments[first] / np.linalg.norm(increments[first])
    mu_vector = ds.mu_eff.transpose("step", "component").values
    along = ds.mu_eff_sliding.values.astype(float).copy()
    along[start] = -float(mu_vector[start] @ e0) if start < first else along[start]
    dilatancy = np.nan_to_num(ds.dilatancy.values.astype(float))
    rows = slice(start, None)
    s = distance[rows] * 1e6
    energy = _has_energy(ds)
    fig, axes = plt.subplots(3 if energy else 2, 1, figsize=(6.4, 8.2 if energy else 5.6),
                             sharex=True, constrained_layout=True)
    top, bottom = axes[:2]
    top.axhline(0.0, color="0.6", lw=0.8)
    top.plot(s, along[rows], "o-", color="C0", ms=3, label=r"$\mu_\mathrm{eff}$ along the "
                                                         "sliding (> 0: resisting)")
    top.plot(s, ds.mu_eff_magnitude.values[rows], "--", color="C1",
             label=r"$|F_T|/F_N$")
    for name, colour in (("mu_up", "C2"), ("mu_low", "C3")):
        mu = _inputs(ds).get(name)
        if mu is not None:
            top.axhline(mu, color=colour, lw=0.8, ls=":",
                        label=rf"$\mu_\mathrm{{{name[3:]}}}$ = {mu:g}")
    top.set_ylabel(r"effective friction $\mu_\mathrm{eff}$")
    top.legend(fontsize=8)
    bottom.axhline(0.0, color="0.6", lw=0.8)
    bottom.plot(s, dilatancy[rows] * 1e6, "o-", color="k", ms=3)
    bottom.set_ylabel(r"dilatancy $h - h_c$ (µm)")
    if energy:
        split = energy_split(ds, start)
        ax = axes[2]
        ax.axhline(0.0, color="0.6", lw=0.8)
        for name, label, style in (
                ("plate_work", "work of the plate", dict(color="k", marker="o", ms=3)),
                ("elastic_energy", "elastic energy (change)", dict(color="C4")),
                ("dissipation_plate", "dissipated at plate contacts", dict(color="C3")),
                ("dissipation_particle", "dissipated between particles", dict(color="C0"))):
            ax.plot(s, 1e6 * split[name], label=label, gid=name, **style)
        ax.plot(s, 1e6 * (split["elastic_energy"] + split["dissipation_plate"]
                          + split["dissipation_particle"]), "--", color="0.4",
                label="elastic + dissipated", gid="energy_total")
        ax.set_ylabel("energy since the compression (µJ)")
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("sliding distance (µm, path length of the upper plate)")
    # a change of direction: an increment not along the one before
    steps = increments[first:]
    norms = np.linalg.norm(steps, axis=1)
    for k in range(1, len(steps)):
        if norms[k] > 0 and norms[k - 1] > 0 and (
                steps[k] @ steps[k - 1] < (1 - 1e-9) * norms[k] * norms[k - 1]):
            for ax in axes:
                ax.axvline(distance[first + k - 1] * 1e6, color="0.5", lw=0.8, ls=":",
                           gid="reversal")
    title = _layer_title(ds) if ds.sizes.get("particle", 1) > 1 else _title(_one(ds))
    fig.suptitle(f"shear: {title}", fontsize=10)
    return fig


def rolling_turns(ds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each particle's turn since the end of the compression about the rolling axis
    e_r = ẑ × e (e the direction of the plate's first sliding increment), from the
    orientations (``quaternion``): the rotation R_k R_c⁻¹'s vector projected on e_r, rad,
    positive in the sense a particle rolling without slip under the sliding plate turns. Returns
    (the plate's displacement along e since the compression, m, over the steps from the end of
    the compression; the turns, (steps, particles), rad; the gap at the end of the compression,
    m). A particle rolling without slip turns by that displacement over the gap."""
    from scipy.spatial.transform import Rotation

    distance = ds.sliding_distance.values
    first = int(np.flatnonzero(distance > 0)[0])
    start = max(first - 1, 0)
    shift = ds.plate_shift.transpose("step", "component").values
    e = shift[first] - shift[start]
    e = e / np.linalg.norm(e)
    axis = np.array([-e[1], e[0], 0.0])                  # ẑ × e
    quats = ds.quaternion.transpose("step", "particle", "quaternion_component").values
    turns = np.empty((len(distance) - start, quats.shape[1]))
    for i in range(quats.shape[1]):
        rel = Rotation.from_quat(quats[start:, i]) * Rotation.from_quat(quats[start, i]).inv()
        turns[:, i] = rel.as_rotvec() @ axis
    along = (shift[start:] - shift[start]) @ e
    return along, turns, float(ds.plate_gap.values[start])


def particle_rotations(ds):
    """How the particles accommodate the sliding: each particle's turn about the rolling axis
    since the end of the compression (degrees, :func:`rolling_turns`) against the plate's
    displacement along its first sliding direction (µm), dots coloured by the particle's state
    in the step; the dashed line is rolling without slip between the plates, a turn of s/h_c
    (h_c the gap at the end of the compression). A particle on it rolls; one that stays near 0
    slides (or sticks to both plates, which then cannot slide); between, it rolls and slips.
    The particles that turned most are named (at most eight)."""
    plt = _plt()
    along, turns, gap = rolling_turns(ds)
    start = ds.sizes["step"] - len(along)
    state = ds.state.transpose("step", "particle").values[start:]
    names = _state_names(ds)
    degrees = np.degrees(turns)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    s = along * 1e6
    span = np.array([min(s.min(), 0.0), max(s.max(), 0.0)])
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.plot(span, np.degrees(span * 1e-6 / gap), "--", color="k", lw=1.0, zorder=1,
            label=rf"rolling without slip: $s/h_c$ ($h_c$ = {gap * 1e3:.3g} mm)",
            gid="rolling")
    order = np.argsort(-np.abs(degrees).max(axis=0), kind="stable")
    named = [int(i) for i in order[:_NAMED]]
    palette = plt.get_cmap("Dark2").colors
    for i in range(degrees.shape[1]):
        if i in named:
            colour = palette[named.index(i) % len(palette)]
            ax.plot(s, degrees[:, i], lw=1.2, color=colour, zorder=2, label=f"particle {i}",
                    gid=f"particle {i}")
        else:
            ax.plot(s, degrees[:, i], lw=0.8, color="0.6", zorder=2, gid=f"particle {i}")
    loaded = state != names.index("unloaded")
    for i in range(degrees.shape[1]):
        ax.scatter(s[loaded[:, i]], degrees[loaded[:, i], i], s=10, zorder=3, edgecolors="k",
                   linewidths=0.3,
                   c=[_state_colour(names[code]) for code in state[loaded[:, i], i]])
    from matplotlib.lines import Line2D

    handles = ax.get_legend_handles_labels()[0]
    if degrees.shape[1] > len(named):
        handles.append(Line2D([], [], lw=0.8, color="0.6",
                              label=f"+ {degrees.shape[1] - len(named)} others"))
    shown = sorted({int(code) for code in state[loaded]})
    handles += [Line2D([], [], ls="", marker="o", ms=4, color=_state_colour(names[code]),
                       markeredgecolor="k", markeredgewidth=0.4,
                       label=names[code].replace("_", " ")) for code in shown]
    fig.legend(handles=handles, fontsize=7, loc="outside right upper")
    ax.set_xlabel("plate displacement along the sliding since the compression (µm)")
    ax.set_ylabel("turn about the rolling axis (degree)")
    title = _layer_title(ds) if ds.sizes.get("particle", 1) > 1 else _title(_one(ds))
    fig.suptitle(f"particle rotations: {title}", fontsize=9)
    return fig


def load_shares(ds):
    """Each particle's share of the total normal force against the load step, stacked: the
    particles that carried the most (by their largest share) at the bottom, in colour and
    named; the others in alternating greys."""
    plt = _plt()
    steps = ds.step.values
    share = np.nan_to_num(ds.load_share.transpose("step", "particle").values)
    n = share.shape[1]
    largest = share.max(axis=0, initial=0.0)
    order = np.argsort(-largest, kind="stable")
    carriers = [int(i) for i in order[:_CARRIERS] if largest[i] > 0]
    others = [int(i) for i in order if int(i) not in carriers]
    palette = plt.get_cmap("tab10").colors
    colours = [palette[j % 10] for j in range(len(carriers))] \
        + [("0.72", "0.84")[j % 2] for j in range(len(others))]
    labels = [f"particle {i} (up to {100 * largest[i]:.0f} %)" for i in carriers] \
        + [f"+ {len(others)} others" if j == 0 else "_nolegend_" for j in range(len(others))]
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.stackplot(steps, share[:, carriers + others].T, colors=colours, labels=labels,
                 edgecolor="white", linewidth=0.3)
    ax.set_xlabel("load step")
    _integer_steps(ax.xaxis)
    ax.set_ylabel("share of the total normal force")
    ax.set_ylim(0, 1.0)
    ax.set_xlim(float(steps.min(initial=0)), float(steps.max(initial=1)))
    twin = ax.twinx()
    twin.plot(steps, ds.total_force.values, color="k", lw=1.2, ls="--")
    twin.set_ylabel("total normal force $F_N$ (N), dashed")
    twin.set_ylim(0, None)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=7, loc="outside lower center",
               ncols=3, title=f"{n} particles, bottom up", title_fontsize=7)
    ax.set_title(_layer_title(ds), fontsize=9)
    return fig


def state_fractions(ds):
    """What the loaded particles did in each load step: stacked bars of the fractions that stuck,
    rolled (about either plate), rotated, slid (a network run) and failed, with the number of
    loaded particles on the right-hand axis and the compression ratio (%) along the top."""
    plt = _plt()
    from matplotlib.ticker import FuncFormatter

    steps = ds.step.values
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    bottom = np.zeros(len(steps))
    state = ds.state.transpose("step", "particle").values
    names = _state_names(ds)
    failed = ((state == names.index("failed")).sum(axis=1) if "failed" in names
              else np.zeros(len(steps)))
    fractions = {name: np.nan_to_num(ds[name].values.astype(float))
                 for name in ("fraction_stick", "fraction_roll", "fraction_rotate")}
    if "fraction_slide" in ds:          # files written before network runs have none
        fractions["fraction_slide"] = np.nan_to_num(ds.fraction_slide.values.astype(float))
    fractions["fraction_failed"] = failed / np.maximum(ds.loaded.values, 1)
    for name, label, colour in (("fraction_stick", "stick", "stick"),
                                ("fraction_roll", "roll", "roll_upper"),
                                ("fraction_rotate", "rotate", "rotate"),
                                ("fraction_slide", "slide", "slide"),
                                ("fraction_failed", "failed", "failed")):
        if name in ("fraction_failed", "fraction_slide") and not fractions.get(
                name, np.zeros(1)).any():
            continue
        ax.bar(steps, fractions[name], width=0.8, bottom=bottom, color=_state_colour(colour),
               label=label, gid=name)
        bottom += fractions[name]
    ax.set_ylim(0, 1.0)
    ax.set_xlim(float(steps.min(initial=0)) - 0.6, float(steps.max(initial=0)) + 0.6)
    ax.set_xlabel("load step")
    _integer_steps(ax.xaxis)
    ax.set_ylabel("fraction of the loaded particles")
    twin = ax.twinx()
    twin.step(steps, ds.loaded.values, where="mid", color="k", lw=1.2, ls="--",
              label="loaded particles (right)")
    twin.set_ylim(0, ds.sizes["particle"] + 0.5)
    _integer_steps(twin.yaxis)
    twin.set_ylabel("loaded particles")
    # along the top, the compression of the steps the bottom axis names
    compression = dict(zip(steps.tolist(), 100 * ds.compression.values, strict=True))
    top = ax.secondary_xaxis("top")
    _integer_steps(top.xaxis)
    top.xaxis.set_major_formatter(FuncFormatter(
        lambda t, _: f"{compression[round(t)]:.1f}" if round(t) in compression else ""))
    top.set_xlabel(_COMPRESSION + " (%)", fontsize=8)
    top.tick_params(labelsize=8)
    handles = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncols=len(handles))
    ax.set_title(_layer_title(ds), fontsize=9)
    return fig


#: particles named in the friction-ratio figure; more are drawn grey and counted
_NAMED = 8


def _stacked_widths(lines: np.ndarray, tol: float, base: float = 1.2,
                    extra: float = 1.3) -> list[float]:
    """Line widths for the columns of ``lines`` (steps × lines), drawn in column order, so
    that a line that coincides with later ones over a segment (two consecutive steps within
    ``tol``) stays visible under them: ``base`` plus ``extra`` per later line it coincides
    with."""
    finite = np.isfinite(lines)
    widths = []
    for a in range(lines.shape[1]):
        later = 0
        for b in range(a + 1, lines.shape[1]):
            with np.errstate(invalid="ignore"):
                same = finite[:, a] & finite[:, b] & (np.abs(lines[:, a] - lines[:, b]) <= tol)
            later += bool(np.any(same[1:] & same[:-1]))
        widths.append(base + extra * later)
    return widths


def particle_ratios(ds):
    """F_T/(μF_N) at the interface with the smaller μ (1 is where the pair slips) of every
    particle loaded at some step against the load step, dots coloured by the particle's state.
    The slip limit at 1 is drawn under the data, the stick region below it shaded. The
    particles that came nearest to slipping are named (at most eight; the others are grey and
    counted in the legend), each with its colour and rings around its dots; lines that
    coincide are drawn thinner over thicker, so that every named particle stays visible."""
    plt = _plt()
    from matplotlib.lines import Line2D

    steps = ds.step.values
    # the interface with the smaller μ (the larger ratio): 1 is the limit of the pair
    both = ds.ratio.transpose("step", "particle", "interface").values
    lower = np.isfinite(both[..., 1]) & ~(both[..., 0] > both[..., 1])
    ratio = np.where(lower, both[..., 1], both[..., 0])
    mu = _inputs(ds)
    which = r"\mu_\mathrm{min}" if mu.get("mu_up") != mu.get("mu_low") else r"\mu"
    state = ds.state.transpose("step", "particle").values
    names = _state_names(ds)
    loaded = [i for i in range(ratio.shape[1]) if np.isfinite(ratio[:, i]).any()]
    peak = {i: float(np.nanmax(np.abs(ratio[:, i]))) for i in loaded}
    named = sorted(loaded, key=lambda i: -peak[i])[:_NAMED]
    others = [i for i in loaded if i not in named]
    top = max(1.2, 1.1 * max(peak.values(), default=0.0))
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.axhspan(0, 1.0, color="0.9", zorder=0, gid="stick region")
    ax.axhline(1.0, color="tab:red", lw=1.0, ls="--", zorder=1,
               label=rf"slip limit: $F_T = {which} F_N$", gid="slip line")
    palette = plt.get_cmap("Dark2").colors          # apart from the state colours
    for i in others:
        ax.plot(steps, ratio[:, i], lw=0.8, color="0.6", zorder=2, gid=f"particle {i}")
    widths = _stacked_widths(ratio[:, named], 1e-3 * top)
    for rank, i in enumerate(named):
        colour = palette[rank % len(palette)]
        ax.plot(steps, ratio[:, i], lw=widths[rank], color=colour, marker="o", ms=6.5,
                mfc="none", mec=colour, mew=1.0, zorder=2, label=f"particle {i}",
                gid=f"particle {i}")
    for i in loaded:
        finite = np.isfinite(ratio[:, i])
        ax.scatter(steps[finite], ratio[finite, i], s=16, zorder=3, edgecolors="k",
                   linewidths=0.4, c=[_state_colour(names[code]) for code in state[finite, i]])
    handles = ax.get_legend_handles_labels()[0]
    if others:
        handles.append(Line2D([], [], lw=0.8, color="0.6", label=f"+ {len(others)} others"))
    shown = sorted({int(code) for i in loaded for code in state[np.isfinite(ratio[:, i]), i]})
    handles += [
        Line2D([], [], ls="", marker="o", ms=4, color=_state_colour(names[code]),
               markeredgecolor="k", markeredgewidth=0.4, label=names[code].replace("_", " "))
        for code in shown]
    fig.legend(handles=handles, fontsize=7, loc="outside right upper")
    ax.set_ylim(0, top)
    ax.set_xlabel("load step")
    _integer_steps(ax.xaxis)
    ax.set_ylabel(rf"friction ratio $F_T/({which} F_N)$")
    ax.set_title(f"{_layer_title(ds)}: {len(loaded)} loaded at some step", fontsize=9)
    return fig
