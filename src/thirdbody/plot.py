"""Figures from a results dataset (matplotlib, Agg): the state curve, the orientation and
position history, and contact maps. Every function takes the :class:`xarray.Dataset` written by
:meth:`thirdbody.Simulation.run` and returns the figure; :func:`save_all` writes them as PNG
(and PDF) files.
"""

from __future__ import annotations

import json
from itertools import product as itertools_product
from pathlib import Path

import numpy as np

__all__ = ["contact_maps", "orientation_history", "save_all", "save_state_map", "state_curve",
           "state_map"]

_STATUS_COLOURS = ("white", "black", "0.6")          # open, stick, slip


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _inputs(ds) -> dict:
    return json.loads(ds.attrs.get("inputs", "{}"))


def _title(ds) -> str:
    i = {k: v for k, v in _inputs(ds).items() if v is not None}
    nan = float("nan")
    up, low = i.get("mu_up", nan), i.get("mu_low", nan)
    mu = f"μ = {up:g}" if up == low else f"μ_up = {up:g}, μ_low = {low:g}"
    start = f"θ₀ = {i.get('orientation_deg', nan):g}°"
    if i.get("tilt_axis_deg", 90.0) != 90.0 or i.get("yaw_deg", 0.0) != 0.0:
        start += f" about azimuth {i.get('tilt_axis_deg', nan):g}°"
        if i.get("yaw_deg", 0.0):
            start += f", yaw {i['yaw_deg']:g}°"
    return f"E = {i.get('E', nan) / 1e9:g} GPa, ν = {i.get('nu', nan):g}, {mu}, {start}"


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
    f = ds.tangential_force.transpose("step", "component").values
    norms = np.hypot(f[:, 0], f[:, 1])
    first = np.flatnonzero(norms > 0)
    if not first.size:
        return np.ones(len(f))
    ref = f[first[0]] / norms[first[0]]
    sign = np.sign(f @ ref)
    return np.where(sign == 0, 1.0, sign)


def state_curve(ds, labels: dict[int, str] | None = None):
    """F_T/(μF_N) against the compression ratio (d₀ − h)/d₀ (the paper's Figs. 3a, 4, 5a).

    The stick region (ratio < 1) is shaded, the slip line at 1 drawn; with unequal μ there is
    one curve per interface. The sign says whether the lower plate pushes the way it did at
    the start (+) or the opposite way (−). Steps in which the particle turned are marked.
    ``labels`` maps step indices to letters written next to the curve.
    """
    plt = _plt()
    i = _inputs(ds)
    c = ds.compression.values
    ratio = {side: ds.ratio.sel(interface=side).values for side in ("upper", "lower")}
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    finite = np.abs(ratio["lower"])[np.isfinite(ratio["lower"])]
    top = max(1.2, float(finite.max(initial=0.0)) * 1.1)
    ax.axhspan(-top, 1.0, color="0.88", zorder=0, label="stick (partial slip)")
    ax.axhline(1.0, color="tab:red", lw=1.5, label="slip: F_T = μF_N")
    sign = _signed(ds)
    equal = i.get("mu_up") == i.get("mu_low")
    curves = [("lower", "F_T/(μF_N)" if equal else "lower: F_T/(μ_low F_N)", "tab:blue", "o")]
    if not equal:
        curves = [("upper", "upper: F_T/(μ_up F_N)", "tab:blue", "*"),
                  ("lower", "lower: F_T/(μ_low F_N)", "tab:red", "^")]
    for side, label, colour, marker in curves:
        ax.plot(c, ratio[side] * sign, marker=marker, ms=4, color=colour, lw=1.2, label=label)
    turned = ds.turned.values.astype(bool)
    if turned.any():
        ax.plot(c[turned], np.ones(turned.sum()), "x", color="k", ms=6, label="turned")
    for step, text in (labels or {}).items():
        k = int(np.flatnonzero(ds.step.values == step)[0])
        ax.annotate(text, (c[k], ratio["lower"][k] * sign[k]), textcoords="offset points",
                    xytext=(4, 6), fontsize=11, fontweight="bold")
    ax.set_xlabel("compression (d₀ − h)/d₀")
    ax.set_ylabel("F_T / (μ F_N)")
    ax.set_ylim(min(-0.2, float(np.nanmin(ax.get_ylim()))), top)
    ax.set_xlim(0, float(c.max()) * 1.02 if c.size else 1)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(_title(ds), fontsize=9)
    return fig


def orientation_history(ds):
    """The orientation (degrees) and the centroid's horizontal position and the slips (µm)
    against the compression ratio. For a run turning about y only, the orientation is the
    paper's θ; otherwise both components of the tilt vector are drawn, and the turn axis of
    each turning step is shown in a top view."""
    plt = _plt()
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
        a1.set_ylabel("orientation θ about y (°)")
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
    a2.set_xlabel("compression (d₀ − h)/d₀")
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
                fig.colorbar(im, ax=ax_p, label="p (MPa)", shrink=0.8)
    handles = [Patch(facecolor=col, edgecolor="k", label=name)
               for col, name in zip(_STATUS_COLOURS, ("open", "stick", "slip"), strict=True)]
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8)
    fig.suptitle(_title(ds), fontsize=10)
    return fig


def save_all(ds, out: str | Path, formats: tuple[str, ...] = ("png", "pdf"),
             labels: dict[int, str] | None = None, map_steps: list[int] | None = None,
             ) -> list[Path]:
    """Write every figure for ``ds`` into ``out`` (created); returns the files written."""
    plt = _plt()
    figures = {"state": state_curve(ds, labels), "orientation": orientation_history(ds)}
    if "map_step" in ds.dims and ds.sizes["map_step"]:
        figures["contact_maps"] = contact_maps(ds, map_steps)
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
                      "rotate": "#55a868", "failed": "0.35", "error": "black", "missing": "white"}


def _axis_label(ds, name: str) -> str:
    units = ds[name].attrs.get("units", "")
    key = ds[name].attrs.get("config_key", name)
    return f"{key} ({units})" if units and units != "1" else key


def _ticks(ds, name: str | None) -> tuple[range, list[str]]:
    """Positions and labels of a sweep coordinate's values (none for no dimension)."""
    if name is None:
        return range(0), []
    values = ds[name].values.tolist()
    return range(len(values)), [f"{v:g}" if isinstance(v, float) else str(v) for v in values]


def state_map(summary, x: str | None = None, y: str | None = None):
    """The sweep's behaviour map: per case, the behaviour (colour: stick, roll about the upper
    or lower interface, rotate, failed) with the total rotation (degrees) written in the cell,
    and the normal force (N) at the first turn. ``x``, ``y``: sweep dimensions (default the
    first two); further dimensions become rows of panels (at most six)."""
    plt = _plt()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    dims = [d for d in summary.behaviour.dims]
    if not dims:
        raise ValueError("the summary has no sweep dimension")
    x = x or dims[0]
    y = y or (next((d for d in dims if d != x), None))
    for name in (x, y):
        if name is not None and name not in dims:
            raise ValueError(f"{name!r} is not a sweep dimension; choose from {dims}")
    rest = [d for d in dims if d not in (x, y)]
    combos = list(itertools_product(*[range(summary.sizes[d]) for d in rest]))[:6]
    meanings = summary.behaviour.attrs["flag_meanings"].split()
    cmap = ListedColormap([_BEHAVIOUR_COLOURS[m] for m in meanings])
    fig, axes = plt.subplots(len(combos), 2, figsize=(11, 4.2 * len(combos) + 0.4),
                             squeeze=False, constrained_layout=True)
    force_max = float(np.nanmax(summary.first_turn_force.values, initial=0.0))
    for row, combo in enumerate(combos):
        sel = {d: i for d, i in zip(rest, combo, strict=True)}
        part = summary.isel(sel)
        where = ", ".join(f"{d} = {summary[d].values[i]}" for d, i in sel.items())
        order = (y, x) if y else (x,)
        behaviour = part.behaviour.transpose(*order).values.reshape(-1, part.sizes[x])
        rotation = part.total_rotation.transpose(*order).values.reshape(behaviour.shape)
        force = part.first_turn_force.transpose(*order).values.reshape(behaviour.shape)
        ax_b, ax_f = axes[row]
        ax_b.imshow(behaviour, origin="lower", cmap=cmap, vmin=-0.5, vmax=len(meanings) - 0.5,
                    aspect="auto", interpolation="nearest")
        for (i, j), rot in np.ndenumerate(rotation):
            if rot == rot:
                colour = "black" if meanings[behaviour[i, j]] == "missing" else "white"
                label = f"{rot:+.1f}°" if abs(rot) >= 0.05 else "0°"
                ax_b.text(j, i, label, ha="center", va="center", fontsize=7,
                          color=colour)
        masked = np.ma.masked_invalid(force)
        ax_f.set_facecolor("0.88")
        im = ax_f.imshow(masked, origin="lower", cmap="magma_r", aspect="auto",
                         interpolation="nearest", vmin=0, vmax=force_max or 1.0)
        fig.colorbar(im, ax=ax_f, label="normal force at the first turn (N)", shrink=0.85)
        for (i, j), f in np.ndenumerate(force):
            if f == f:
                dark = f > 0.5 * (force_max or 1.0)
                ax_f.text(j, i, f"{f:.3g} N", ha="center", va="center", fontsize=7,
                          color="white" if dark else "black")
        ax_b.set_title("behaviour, total rotation" + (f" ({where})" if where else ""),
                       fontsize=9)
        ax_f.set_title("first turn (grey: never turned)" + (f" ({where})" if where else ""),
                       fontsize=9)
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


def save_state_map(summary, out: str | Path, formats: tuple[str, ...] = ("png", "pdf"),
                   ) -> list[Path]:
    """Write ``state_map.png`` (and ``.pdf``) for a sweep summary into ``out``."""
    return _save_figures(_plt(), {"state_map": state_map(summary)}, out, formats)
