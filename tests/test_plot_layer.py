"""Figures of a layer of particles: the top view draws one outline per particle in the colour of
its state, the true mid-plane sections of spheres and of a turned ellipsoid, dots whose area is
proportional to the normal force; save_all writes the layer's figures for a layer's results.

Most tests use a hand-made dataset with the layout of a layer's results, so that the states,
forces, heights and orientations are known exactly."""

import json

import matplotlib
import numpy as np
import pytest
import xarray as xr
from matplotlib.colors import to_rgba
from matplotlib.patches import PathPatch
from scipy.spatial.transform import Rotation

import thirdbody as tb
from thirdbody import plot, shapes
from thirdbody.plot import layer_top_view, load_shares, particle_ratios, save_all

matplotlib.use("Agg")

MEANINGS = "stick roll_upper roll_lower rotate failed unloaded".split()
CODE = {m: k for k, m in enumerate(MEANINGS)}
COLOUR = {"stick": "#4c72b0", "roll_upper": "#dd8452", "roll_lower": "#c44e52",
          "rotate": "#55a868", "failed": "0.35", "unloaded": "0.75"}

GAP = 1.6e-3
X0 = np.array([0.0, 3e-3, 6e-3, 9e-3])
Y0 = np.array([0.0, 0.5e-3, -0.5e-3, 0.0])
#: particle 0, 1, 2: spheres; 3: an ellipsoid turned by 90° about z (its long axis along y)
RADII = (1.0e-3, 0.8e-3, 0.6e-3)
SEMI_AXES = (1.0e-3, 0.5e-3, 0.5e-3)
#: centroid heights above the lower plate; the mid-plane is 0.3, 0, 0.2 and 0 mm above the centroids
HEIGHT = np.array([0.5e-3, 0.8e-3, 0.6e-3, 0.8e-3])
TURN = Rotation.from_euler("z", 90, degrees=True)
STATES = [["stick", "unloaded", "unloaded", "unloaded"],
          ["roll_lower", "stick", "unloaded", "stick"],
          ["rotate", "roll_upper", "stick", "failed"]]
FORCES = np.array([[1.0, 0.0, 0.0, 0.0],
                   [2.0, 0.5, 0.0, 0.25],
                   [3.0, 1.5, 0.5, 1.0]])
#: the centroids' displacement in the last step (m)
SHIFT = np.array([[0.1e-3, -0.2e-3], [0.0, 0.05e-3], [-0.1e-3, 0.0], [0.0, 0.0]])


def synthetic() -> xr.Dataset:
    """A layer's results, three steps of four particles (see the constants above)."""
    n_steps, n = FORCES.shape
    state = np.array([[CODE[s] for s in row] for row in STATES], dtype=np.int8)
    loaded = (state != CODE["unloaded"]).sum(axis=1)
    total = FORCES.sum(axis=1)
    ratio = np.where(state == CODE["unloaded"], np.nan, 0.2 + 0.1 * np.arange(n) + 0.2
                     * np.arange(n_steps)[:, None])
    position = np.zeros((n_steps, n, 2))
    position[-1] = SHIFT
    quaternion = np.tile([0.0, 0.0, 0.0, 1.0], (n_steps, n, 1))
    quaternion[:, 3] = TURN.as_quat()
    fractions = {name: np.array([sum(s in group for s in row if s != "unloaded") / max(m, 1)
                                 for row, m in zip(STATES, loaded, strict=True)])
                 for name, group in (("fraction_stick", ("stick",)),
                                     ("fraction_roll", ("roll_upper", "roll_lower")),
                                     ("fraction_rotate", ("rotate",)))}
    data = {
        "load_value": ("step", total), "total_force": ("step", total),
        "plate_gap": ("step", np.full(n_steps, GAP)),
        "compression": ("step", np.array([0.02, 0.05, 0.08])),
        "loaded": ("step", loaded),
        **{name: ("step", v) for name, v in fractions.items()},
        "normal_force": (("step", "particle"), FORCES),
        "load_share": (("step", "particle"), FORCES / total[:, None]),
        "state": (("step", "particle"), state,
                  {"flag_values": np.arange(6, dtype=np.int8),
                   "flag_meanings": " ".join(MEANINGS)}),
        "ratio": (("step", "particle", "interface"), np.stack([ratio * 0.9, ratio], axis=-1)),
        "tangential_force": (("step", "particle", "component"), np.zeros((n_steps, n, 2))),
        "quaternion": (("step", "particle", "quaternion_component"), quaternion),
        "position": (("step", "particle", "component"), position),
        "centroid_height": (("step", "particle"), np.tile(HEIGHT, (n_steps, 1))),
        "x0": ("particle", X0), "y0": ("particle", Y0),
        "size": ("particle", np.array([*RADII, max(SEMI_AXES)])),
    }
    coords = {"step": np.arange(n_steps), "particle": np.arange(n),
              "interface": ["upper", "lower"], "component": ["x", "y"],
              "quaternion_component": ["x", "y", "z", "w"]}
    return xr.Dataset(data, coords=coords, attrs={"inputs": json.dumps({"mu_up": 0.3,
                                                                         "mu_low": 0.3}),
                                                  "status": "complete"})


def synthetic_layer() -> tb.Layer:
    mat = tb.Material(1e9, 0.3)
    bodies = [shapes.Sphere(r) for r in RADII] + [shapes.Ellipsoid(SEMI_AXES)]
    return tb.Layer([tb.PlacedParticle(tb.Particle(b, mat), (x, y))
                     for b, x, y in zip(bodies, X0, Y0, strict=True)])


def outlines(ax) -> dict[int, PathPatch]:
    found = {}
    for patch in ax.patches:
        gid = patch.get_gid() or ""
        if gid.startswith("outline "):
            found[int(gid.split()[1])] = patch
    return found


def markers(ax):
    (dots,) = [c for c in ax.collections if c.get_gid() == "normal force"]
    return dots


def cell(size: float) -> float:
    """The spacing (m) of the rays sampling a section of a particle of this size."""
    n = plot._OUTLINE_RAYS
    return float(np.diff(plot._grid(size, n))[0])


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


def test_save_all_writes_the_layer_figures_for_a_layer(tmp_path):
    written = save_all(synthetic(), tmp_path, formats=("png",))
    names = {"layer_top_view", "load_shares", "state_fractions", "particle_ratios"}
    assert sorted(p.name for p in written) == sorted(f"{n}.png" for n in names)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{n}.png" for n in names)


def test_top_view_draws_one_outline_per_particle_coloured_by_its_state():
    ds = synthetic()
    fig = layer_top_view(ds, steps=[0, 1, 2])
    axes = [ax for ax in fig.axes if outlines(ax)]
    assert len(axes) == 3
    for k, ax in enumerate(axes):
        found = outlines(ax)
        assert sorted(found) == [0, 1, 2, 3]
        for i, patch in found.items():
            assert patch.get_edgecolor() == pytest.approx(to_rgba(COLOUR[STATES[k][i]]))
        # the dots have the colour of the state too
        assert markers(ax).get_facecolors()[:, :3] == pytest.approx(
            np.array([to_rgba(COLOUR[s])[:3] for s in STATES[k]]))
        assert "circles" in ax.get_title()


def test_top_view_without_a_layer_draws_dashed_circles_of_the_size_at_the_centroid():
    ds = synthetic()
    fig = layer_top_view(ds, steps=[2])
    (ax,) = [ax for ax in fig.axes if outlines(ax)]
    for i, patch in outlines(ax).items():
        assert patch.get_linestyle() == "--"
        xy = patch.get_path().vertices[:-1] / 1e3
        centre = np.array([X0[i], Y0[i]]) + SHIFT[i]
        r = np.hypot(*(xy - centre).T)
        assert r == pytest.approx(float(ds["size"][i]), rel=1e-9)


def test_true_section_of_a_sphere_has_the_radius_of_its_cut_at_the_mid_plane():
    fig = layer_top_view(synthetic(), steps=[2], layer=synthetic_layer())
    (ax,) = [ax for ax in fig.axes if outlines(ax)]
    assert "mid-plane sections" in ax.get_title()
    found = outlines(ax)
    for i, radius in enumerate(RADII):
        dz = GAP / 2 - HEIGHT[i]
        expected = np.sqrt(radius**2 - dz**2)          # 0.954, 0.8, 0.566 mm
        patch = found[i]
        assert patch.get_linestyle() == "-"
        xy = patch.get_path().vertices / 1e3
        centre = np.array([X0[i], Y0[i]]) + SHIFT[i]
        r = np.hypot(*(xy - centre).T)
        assert np.abs(r - expected).max() < cell(radius), (i, r.min(), r.max(), expected)
        assert abs(r.mean() - expected) < 0.25 * cell(radius)


def test_true_section_follows_the_particle_orientation():
    # the ellipsoid's long axis (2 mm) lies along y after the turn about z; across it, 1 mm
    fig = layer_top_view(synthetic(), steps=[1], layer=synthetic_layer())
    (ax,) = [ax for ax in fig.axes if outlines(ax)]
    xy = outlines(ax)[3].get_path().vertices / 1e3 - np.array([X0[3], Y0[3]])
    h = cell(max(SEMI_AXES))
    for end in (xy.min(axis=0), xy.max(axis=0)):
        assert np.abs(np.abs(end) - [SEMI_AXES[1], SEMI_AXES[0]]).max() < h


def test_a_particle_the_mid_plane_misses_is_drawn_from_above_dotted():
    ds = synthetic()
    ds["centroid_height"][:, 2] = 0.15e-3          # 0.65 mm below the mid-plane, R = 0.6 mm
    fig = layer_top_view(ds, steps=[2], layer=synthetic_layer())
    (ax,) = [ax for ax in fig.axes if outlines(ax)]
    patch = outlines(ax)[2]
    assert patch.get_linestyle() == ":"
    r = np.hypot(*(patch.get_path().vertices / 1e3 - np.array([X0[2], Y0[2]]) - SHIFT[2]).T)
    assert np.abs(r - RADII[2]).max() < cell(RADII[2])
    assert outlines(ax)[0].get_linestyle() == "-"


def test_marker_areas_are_proportional_to_the_normal_force_in_every_panel():
    fig = layer_top_view(synthetic(), steps=[0, 1, 2])
    axes = [ax for ax in fig.axes if outlines(ax)]
    areas = np.array([markers(ax).get_sizes() for ax in axes])
    assert areas.shape == FORCES.shape
    loaded = FORCES > 0
    per_newton = areas[loaded] / FORCES[loaded]
    assert per_newton == pytest.approx(np.full(per_newton.shape, per_newton[0]), rel=1e-12)
    assert np.all(areas[~loaded] == 0)


def test_top_view_checks_its_steps_and_layer():
    ds = synthetic()
    with pytest.raises(ValueError, match="none of the steps"):
        layer_top_view(ds, steps=[7])
    with pytest.raises(ValueError, match="particles"):
        layer_top_view(ds, layer=tb.Layer(list(synthetic_layer())[:2]))
    many = xr.concat([ds.assign_coords(step=ds.step + 3 * j) for j in range(3)], dim="step",
                     data_vars="minimal", coords="minimal", compat="override")
    fig = layer_top_view(many, steps=list(range(9)))
    assert len([ax for ax in fig.axes if outlines(ax)]) == 4


def test_load_shares_stack_every_particle_and_name_the_largest_carriers():
    fig = load_shares(synthetic())
    ax = fig.axes[0]
    assert len(ax.collections) == 4                 # one band per particle
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert [t.split(" (")[0] for t in labels[:4]] == ["particle 0", "particle 1",
                                                      "particle 3", "particle 2"]


def test_particle_ratios_one_line_per_loaded_particle_from_the_lower_interface():
    ds = synthetic()
    fig = particle_ratios(ds)
    ax = fig.axes[0]
    drawn = {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}
    assert set(drawn) == {"slip line", "particle 0", "particle 1", "particle 2", "particle 3"}
    assert drawn["slip line"].get_ydata() == pytest.approx([1.0, 1.0])
    lower = ds.ratio.sel(interface="lower").values
    np.testing.assert_array_equal(drawn["particle 1"].get_ydata(), lower[:, 1])


def test_save_all_rebuilds_the_layer_from_the_config(tmp_path, monkeypatch):
    import thirdbody.io.config as config

    layer = synthetic_layer()

    class Built:
        def build(self):
            return layer, None, None, {}

    seen = []
    monkeypatch.setattr(config, "parse_config", lambda data, *a, **k: seen.append(data)
                        or Built())
    monkeypatch.setattr(plot, "layer_top_view",
                        lambda ds, steps, layer: seen.append(layer) or plot.load_shares(ds))
    ds = synthetic()
    ds.attrs["config"] = 'title = "a layer"\n'
    save_all(ds, tmp_path, formats=("png",))
    assert seen == [{"title": "a layer"}, layer]
    # a config that cannot be built, or builds no matching layer: circles
    seen.clear()
    ds.attrs["config"] = "not = [toml"
    save_all(ds, tmp_path, formats=("png",))
    assert seen == [None]

    def unsupported(data, *args, **kwargs):
        seen.append(data)
        raise ValueError("no [layer] support yet")

    monkeypatch.setattr(config, "parse_config", unsupported)
    seen.clear()
    ds.attrs["config"] = 'title = "a layer"\n'
    save_all(ds, tmp_path, formats=("png",))
    assert seen == [{"title": "a layer"}, None]


def test_figures_of_a_simulated_layer(tmp_path):
    mat = tb.Material(1e9, 0.3)
    radii = [1.0e-3, 0.99e-3, 0.985e-3]
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(shapes.Sphere(r), mat), (3e-3 * i, 0.0))
                      for i, r in enumerate(radii)])
    ds = tb.Simulation(layer, tb.Plates(0.3), tb.ForceTable([1.0, 3.0]), resolution=40,
                       maps_every=1).run()
    written = save_all(ds, tmp_path, formats=("png",), layer=layer)
    assert {p.stem for p in written} == {"layer_top_view", "load_shares", "state_fractions",
                                        "particle_ratios"}
    fig = layer_top_view(ds, layer=layer)
    for ax in [ax for ax in fig.axes if outlines(ax)]:
        k = [int(s) for s in ds.step.values].index(int(ax.get_title().split(":")[0].split()[1]))
        gap = float(ds.plate_gap[k])
        for i, patch in outlines(ax).items():
            dz = gap / 2 - float(ds.centroid_height[k, i])
            centre = np.array([float(ds.x0[i]), float(ds.y0[i])]) + ds.position.values[k, i]
            r = np.hypot(*(patch.get_path().vertices / 1e3 - centre).T)
            assert np.abs(r - np.sqrt(radii[i] ** 2 - dz**2)).max() < cell(radii[i])
            state = MEANINGS[int(ds.state[k, i])]
            assert patch.get_edgecolor() == pytest.approx(to_rgba(COLOUR[state]))


def test_save_all_of_one_particle_is_unchanged(tmp_path):
    particle = tb.Particle(shapes.Sphere(1e-3), tb.Material(1e9, 0.3))
    ds = tb.Simulation(particle, tb.Plates(0.3), tb.ForceTable([1.0, 2.0]), resolution=40,
                       maps_every=1).run()
    written = save_all(ds, tmp_path, formats=("png",))
    assert sorted(p.name for p in written) == ["contact_maps.png", "orientation.png",
                                               "state.png"]


@pytest.mark.parametrize("n", [40, 41])
def test_a_section_as_wide_as_the_size_is_one_closed_loop(n):
    # the rays reach beyond ±size, so that the outline never runs into the grid's edge
    (loop,) = plot._section(shapes.Sphere(1e-3), Rotation.identity(), 0.0, n=n)
    assert loop[0] == pytest.approx(loop[-1])
    assert np.abs(np.hypot(*loop.T) - 1e-3).max() < cell(1e-3)
