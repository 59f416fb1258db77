"""Every figure, rendered and read back as matplotlib objects (not pixels): labels a reader
understands (no underscore outside mathtext, quantities with units), whole-number ticks on load
step axes, a legend entry per named particle, the stick band only below the friction limit, the
slip limit under the data, the state fractions as bars, and the sweep's colour bar over the range
of its data (or a note that every value is the same).

The particle figures use a short simulated run; the layer figures the hand-made layer of
test_plot_layer and a larger one made here; the sweep figure a hand-made summary."""

import json
import re

import matplotlib
import numpy as np
import pytest
import xarray as xr
from matplotlib.collections import PolyCollection
from matplotlib.patches import Rectangle

import thirdbody as tb
from test_plot_layer import synthetic, synthetic_layer
from thirdbody import plot, schema
from thirdbody.shapes import Potato

matplotlib.use("Agg")


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.fixture(scope="module")
def run():
    """The Fig. 4 potato with μ_up = 0.2, μ_low = 0.4: it rolls at first contact, then sticks
    (three steps, maps at every step)."""
    shape = Potato((1.0e-3, 0.8e-3, 0.7e-3), seed=27, amplitude=0.055,
                   wavenumber_range=(2.0, 4.0))
    particle = tb.Particle(shape, tb.Material(1e9, 0.3), orientation_deg=-41.0)
    ds = tb.Simulation(particle, tb.Plates(mu_up=0.2, mu_low=0.4),
                       tb.LinearRamp(stop=3.0, steps=3), resolution=20, maps_every=1).run()
    assert bool(ds.turned.values.any()) and ds.sizes["map_step"] == 3
    return ds


# --- reading a figure ------------------------------------------------------------------------
def texts(fig) -> list[str]:
    """Every piece of text a reader sees: titles, axis labels, tick labels, legend entries and
    titles, colour bar labels, annotations."""
    found = [fig._suptitle.get_text()] if fig._suptitle else []
    for ax in fig.axes + [child for parent in fig.axes for child in parent.child_axes]:
        found += [ax.title.get_text(), ax._left_title.get_text(), ax._right_title.get_text()]
        found += [ax.get_xlabel(), ax.get_ylabel()]
        found += [t.get_text() for t in ax.get_xticklabels() + ax.get_yticklabels()]
        found += [t.get_text() for t in ax.texts]
        if ax.get_legend():
            found += [t.get_text() for t in ax.get_legend().get_texts()]
    for legend in fig.legends:
        found += [t.get_text() for t in legend.get_texts()] + [legend.get_title().get_text()]
    return [t for t in found if t]


def outside_mathtext(text: str) -> str:
    return re.sub(r"\$[^$]*\$", "", text)


def assert_readable(fig) -> None:
    """No raw underscore outside mathtext, and every mathtext parses."""
    fig.canvas.draw()               # raises on a mathtext error
    for text in texts(fig):
        assert text.count("$") % 2 == 0, text
        assert "_" not in outside_mathtext(text), text


def legend_labels(fig) -> list[str]:
    labels = []
    for legend in fig.legends + [ax.get_legend() for ax in fig.axes if ax.get_legend()]:
        labels += [t.get_text() for t in legend.get_texts()]
    return labels


def assert_integer_ticks(axis) -> None:
    ticks = [t for t in axis.get_ticklocs() if axis.get_view_interval()[0] - 1e-9 <= t
             <= axis.get_view_interval()[1] + 1e-9]
    assert len(ticks) >= 2
    assert np.all(np.asarray(ticks) == np.round(ticks)), ticks


def by_gid(ax, gid):
    found = [a for a in ax.get_children() if getattr(a, "get_gid", lambda: None)() == gid]
    assert len(found) == 1, (gid, found)
    return found[0]


def band(ax, gid) -> tuple[float, float]:
    """The y range of a horizontal band (axhspan), in data coordinates."""
    patch = by_gid(ax, gid)
    if isinstance(patch, Rectangle):
        return patch.get_y(), patch.get_y() + patch.get_height()
    y = patch.get_path().vertices[:, 1]
    return float(y.min()), float(y.max())


# --- one particle ------------------------------------------------------------------------------
def test_state_curve_labels_and_the_stick_band_below_the_limit(run):
    fig = plot.state_curve(run)
    assert_readable(fig)
    ax = fig.axes[0]
    ylabel = ax.get_ylabel()
    assert r"$F_T/(\mu F_N)$" in ylabel and "negative" in ylabel and "first direction" in ylabel
    assert ax.get_xlabel() == "compression $(d_0 - h)/d_0$"
    labels = legend_labels(fig)
    assert r"upper plate: $F_T/(\mu_\mathrm{up} F_N)$" in labels
    assert r"lower plate: $F_T/(\mu_\mathrm{low} F_N)$" in labels
    assert "turned in the step" in labels
    assert any(label.startswith("stick") for label in labels)
    assert r"$\mu_\mathrm{up}$ = 0.2" in ax.get_title()
    # every value is positive: the band runs from 0 (not from the axis' bottom) up to the limit
    low, high = band(ax, "stick region")
    assert (low, high) == (0.0, 1.0)
    assert ax.get_ylim()[0] < 0.0 and ax.get_ylim()[1] >= 1.2
    assert by_gid(ax, "slip limit").get_zorder() < min(
        line.get_zorder() for line in ax.get_lines() if line.get_gid() is None)


def test_state_curve_band_reaches_down_to_a_negative_ratio(run):
    # F' reversed in the last step: its ratio is drawn negative and the band reaches it
    flipped = run.copy(deep=True)
    flipped["tangential_force"][-1] *= -1
    fig = plot.state_curve(flipped)
    ax = fig.axes[0]
    lowest = -float(flipped.ratio.isel(step=-1, particle=0).max())
    assert band(ax, "stick region") == pytest.approx((lowest, 1.0))
    assert ax.get_ylim()[0] < lowest


def test_orientation_history_and_contact_maps_are_readable(run):
    fig = plot.orientation_history(run)
    assert_readable(fig)
    assert fig.axes[0].get_ylabel() == r"orientation $\theta$ about $y$ (°)"
    fig = plot.contact_maps(run)
    assert_readable(fig)
    colour_bars = [ax.get_ylabel() for ax in fig.axes if ax.get_ylabel().startswith("pressure")]
    assert colour_bars and set(colour_bars) == {"pressure $p$ (MPa)"}
    assert {"open", "stick", "slip"} <= set(legend_labels(fig))


# --- a layer ------------------------------------------------------------------------------------
def many(n: int = 12, steps: int = 11) -> xr.Dataset:
    """A layer of n particles over ``steps`` load steps: particle i is loaded from step i // 2
    on, its ratio rising to 1 - 0.05 i; particles 0 and 1 sit on the slip limit together."""
    ratio = np.full((steps, n), np.nan)
    for i in range(n):
        first = i // 2
        ratio[first:, i] = np.linspace(0.5, 1.0 - 0.05 * i, steps - first)
    ratio[2:, :2] = 1.0
    loaded = np.isfinite(ratio)
    state = np.where(loaded, 0, 5).astype(np.int8)
    share = np.where(loaded, 1.0, 0.0)
    share /= share.sum(axis=1, keepdims=True)
    ds = xr.Dataset(
        {"ratio": (("step", "particle", "interface"), np.stack([ratio, ratio], axis=-1)),
         "state": (("step", "particle"), state,
                   {"flag_meanings": "stick roll_upper roll_lower rotate failed unloaded"}),
         "load_share": (("step", "particle"), share),
         "total_force": ("step", np.linspace(1.0, 10.0, steps))},
        coords={"step": np.arange(steps), "particle": np.arange(n),
                "interface": ["upper", "lower"]},
        attrs={"inputs": json.dumps({"mu_up": 0.15, "mu_low": 0.2})})
    return ds


def test_layer_figures_are_readable_with_whole_load_steps():
    ds = synthetic()
    for figure in (plot.load_shares, plot.particle_ratios, plot.state_fractions):
        fig = figure(ds)
        assert_readable(fig)
        ax = fig.axes[0]
        assert ax.get_xlabel() == "load step"
        assert_integer_ticks(ax.xaxis)
    fig = plot.layer_top_view(ds, layer=synthetic_layer())
    assert_readable(fig)
    for ax in fig.axes:
        assert "$F_N$" in ax.get_title() and ax.get_xlabel() == "x (mm)"


def test_load_steps_of_a_long_run_have_integer_ticks():
    ds = many(steps=20)             # default ticks: 0, 2.5, 5, ...
    for figure in (plot.load_shares, plot.particle_ratios):
        fig = figure(ds)
        fig.canvas.draw()
        assert_integer_ticks(fig.axes[0].xaxis)


def test_particle_ratios_name_every_loaded_particle_up_to_eight():
    ds = synthetic()                # four loaded particles: all named
    labels = legend_labels(plot.particle_ratios(ds))
    assert [x for x in labels if x.startswith("particle")] == [
        "particle 3", "particle 2", "particle 1", "particle 0"]
    assert not any("others" in x for x in labels)
    assert r"slip limit: $F_T = \mu F_N$" in labels

    ds = many(12)
    fig = plot.particle_ratios(ds)
    labels = legend_labels(fig)
    named = [x for x in labels if x.startswith("particle")]
    assert len(named) == 8 and named[:2] == ["particle 0", "particle 1"]
    assert "+ 4 others" in labels
    assert r"friction ratio $F_T/(\mu_\mathrm{min} F_N)$" == fig.axes[0].get_ylabel()
    assert r"slip limit: $F_T = \mu_\mathrm{min} F_N$" in labels


def test_particles_on_the_slip_limit_are_drawn_over_it_and_both_visible():
    fig = plot.particle_ratios(many(12))
    ax = fig.axes[0]
    limit = by_gid(ax, "slip line")
    lines = {line.get_gid(): line for line in ax.get_lines() if line.get_gid() != "slip line"}
    assert len(lines) == 12
    assert all(line.get_zorder() > limit.get_zorder() for line in lines.values())
    # particles 0 and 1 coincide on the limit: the one drawn first is wider
    first, second = lines["particle 0"], lines["particle 1"]
    np.testing.assert_array_equal(first.get_ydata()[2:], second.get_ydata()[2:])
    assert first.get_linewidth() > second.get_linewidth()
    widths = {line.get_linewidth() for gid, line in lines.items() if gid not in
              ("particle 0", "particle 1") and line.get_color() != "0.6"}
    assert widths == {second.get_linewidth()}      # lines that do not coincide: one width


def test_state_fractions_are_stacked_bars_per_load_step():
    ds = synthetic()
    fig = plot.state_fractions(ds)
    assert_readable(fig)
    ax = fig.axes[0]
    assert not [line for line in ax.get_lines()]          # no lines joining the fractions
    bars = {c.patches[0].get_gid(): c for c in ax.containers}
    names = ("fraction_stick", "fraction_roll", "fraction_rotate", "fraction_failed")
    assert set(bars) == set(names)
    heights = {name: np.array([r.get_height() for r in bars[name]]) for name in names}
    for name in names[:3]:
        np.testing.assert_allclose(heights[name], ds[name].values)
    # the last step: one of four failed; the bars of each step add up to 1
    np.testing.assert_allclose(heights["fraction_failed"], [0, 0, 0.25])
    np.testing.assert_allclose(sum(heights.values()), 1.0)
    assert [r.get_x() + r.get_width() / 2 for r in bars["fraction_stick"]] == [0, 1, 2]
    # the number of loaded particles, as steps, on whole numbers; compression on top
    twin = fig.axes[1]
    np.testing.assert_array_equal(twin.get_lines()[0].get_ydata(), ds.loaded.values)
    assert_integer_ticks(twin.yaxis)
    (top,) = ax.child_axes
    fig.canvas.draw()
    assert [t.get_text() for t in top.get_xticklabels() if t.get_text()] == [
        f"{100 * c:.1f}" for c in ds.compression.values]
    assert top.get_xlabel() == "compression $(d_0 - h)/d_0$ (%)"


# --- a sweep -----------------------------------------------------------------------------------
def summary(force: np.ndarray) -> xr.Dataset:
    """A 4 × 3 sweep summary over μ and θ₀ whose cases turned first at ``force`` (N)."""
    mu, theta = [0.2, 0.3, 0.4, 0.5], [-30.0, 0.0, 30.0]
    behaviour = np.where(np.isfinite(force), 3, 0).astype(np.int8)
    return xr.Dataset(
        {"behaviour": (("mu", "orientation_deg"), behaviour,
                       {"flag_meanings": " ".join(schema.BEHAVIOURS)}),
         "total_rotation": (("mu", "orientation_deg"), np.where(behaviour == 3, 5.0, 0.0)),
         "first_turn_force": (("mu", "orientation_deg"), force)},
        coords={"mu": ("mu", mu, {"config_key": "plates.mu", "units": "1"}),
                "orientation_deg": ("orientation_deg", theta,
                                    {"config_key": "particle.orientation_deg",
                                     "units": "degree"})},
        attrs={"cases": 12, "failed": 0})


def force_image(fig):
    (ax,) = [ax for ax in fig.axes if ax.get_title().startswith("normal force")]
    return ax, ax.images[0]


def test_state_map_axes_are_quantities_with_units():
    force = np.full((4, 3), np.nan)
    force[0, 0], force[1, 2] = 1.0, 3.0
    fig = plot.state_map(summary(force))
    assert_readable(fig)
    for ax in fig.axes[:2]:
        assert ax.get_xlabel() == r"$\mu$"
        assert ax.get_ylabel() == r"$\theta_0$ (°)"
        assert [t.get_text() for t in ax.get_xticklabels()] == ["0.2", "0.3", "0.4", "0.5"]


def test_state_map_colour_bar_spans_the_forces():
    force = np.full((4, 3), np.nan)
    force[0, 0], force[1, 2], force[3, 1] = 1.0, 3.0, 2.0
    fig = plot.state_map(summary(force))
    _, image = force_image(fig)
    assert image.get_clim() == (1.0, 3.0)
    assert image.colorbar is not None
    assert image.colorbar.ax.get_ylabel() == "normal force at the first turn (N)"


def test_state_map_says_when_every_first_turn_is_at_the_same_force():
    force = np.full((4, 3), np.nan)
    force[0, 0] = force[0, 2] = force[1, 0] = 1.0
    fig = plot.state_map(summary(force))
    assert_readable(fig)
    ax, image = force_image(fig)
    assert image.colorbar is None
    assert "every case that turned did so at 1 N" in ax.get_title()
    assert not [a for a in fig.axes if a.get_ylabel().startswith("normal force")]
    # none turned
    fig = plot.state_map(summary(np.full((4, 3), np.nan)))
    ax, image = force_image(fig)
    assert image.colorbar is None and "no case turned" in ax.get_title()


def test_a_sweep_of_sliding_cases_maps_its_steady_mu_eff(monkeypatch):
    """The friction map draws each case's steady_mu_eff over μ and θ₀ (grey, masked, where a
    case did not slide), written with its spread; save_state_map adds it only to a sweep in
    which some case slid."""
    s = summary(np.full((4, 3), np.nan))
    mu = np.arange(12.0).reshape(4, 3) / 40 + 0.1
    mu[2, 1] = np.nan
    std = np.full((4, 3), 0.002)
    s = s.assign(steady_mu_eff=(("mu", "orientation_deg"), mu),
                 steady_mu_eff_std=(("mu", "orientation_deg"), std))
    fig = plot.friction_map(s, x="mu", y="orientation_deg")
    assert_readable(fig)
    (ax,) = [a for a in fig.axes if a.images]
    image = ax.images[0].get_array()
    assert image.shape == (3, 4)                      # θ₀ along y, μ along x
    assert np.ma.getmaskarray(image)[1, 2] and np.ma.getmaskarray(image).sum() == 1
    assert image.filled(np.nan)[~np.isnan(mu.T)] == pytest.approx(mu.T[~np.isnan(mu.T)])
    texts = {(t.get_position()): t.get_text() for t in ax.texts}
    assert texts[(0, 0)] == "0.100\n±0.002" and texts[(3, 2)] == f"{mu[3, 2]:.3f}\n±0.002"
    assert (2, 1) not in texts and len(texts) == 11
    assert ax.get_xlabel() == r"$\mu$" and ax.get_ylabel() == r"$\theta_0$ (°)"
    saved = []                                  # what save_state_map hands to be written
    monkeypatch.setattr(plot, "_save_figures", lambda plt, figures, out, formats: (
        saved.extend(figures), [plt.close(f) for f in figures.values()]))
    plot.save_state_map(s, "unused", formats=("png",))
    assert sorted(saved) == ["friction_map", "state_map"]
    assert not plot._sweep_slides(s.assign(steady_mu_eff=s.steady_mu_eff * np.nan))
    assert not plot._sweep_slides(s.drop_vars("steady_mu_eff"))     # an older summary


def test_every_configuration_key_has_a_quantity_label():
    for key, units in schema.PARAMETERS.items():
        label = plot.quantity_label(key)
        assert "_" not in outside_mathtext(label) and "." not in outside_mathtext(label), key
        assert label.endswith(f"({plot._UNIT_TEXT.get(units, units)})") or units == "1", key
    assert plot.quantity_label("plates.mu") == r"$\mu$"
    assert plot.quantity_label("particle.orientation_deg") == r"$\theta_0$ (°)"
    assert plot.quantity_label("particle.E") == "$E$ (Pa)"
    assert plot.quantity_label("layer.area_fraction") == "area fraction"
    assert plot.quantity_label("particle.unknown_key") == "particle.unknown_key"


def test_a_third_sweep_axis_names_its_value_as_a_quantity():
    s = summary(np.full((4, 3), 2.0)).expand_dims(E=[1e9, 2e9])
    s["E"].attrs.update(config_key="particle.E", units="Pa")
    fig = plot.state_map(s, x="mu", y="orientation_deg")
    assert_readable(fig)
    titles = [ax.get_title() for ax in fig.axes]
    assert any("($E$ = 1e+09 Pa)" in t for t in titles)
    assert not any(isinstance(c, PolyCollection) for ax in fig.axes for c in ax.collections)
