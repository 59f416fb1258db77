"""Partial slip of a tilted elastic ellipsoid on a rigid plate (the paper's Fig. 2).

The ellipsoid, tilted by θ about y, is pressed on the plate by a constant normal force F_N. The
plate then shifts along +x in equal increments, each solved with Coulomb's law with history,
until the tangential force reaches about ``--load-ratio`` x μF_N. Writes into the output folder:

* ``fig2.png``: (a) sketch, (b) stick/slip map, (c) τ_x map, (d) F_x against plate shift;
* ``fig2_stick_slip.png``, ``fig2_tau_x.png``, ``fig2_force_shift.png``: the panels alone;
* ``summary.txt``: the inputs with units and, per step, shift, F_x, stick fraction, iterations
  and Coulomb residual.

    python examples/fig2_partial_slip.py --out out/fig2 [--n 128] [--steps 8] [--theta 30]

The tilt breaks the fore-aft symmetry of the gap (cubic terms about the first-contact point), so
the contact, the pressure centroid and the stick zone are not centred on that point. The contact
is deliberately a sizeable fraction of the particle for this to show; the half-space (BEM)
model then remains a small-strain approximation.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Arc, FancyArrowPatch, Patch, Polygon, Rectangle

import thirdbody as tb
from thirdbody.reference import hertz, mindlin
from thirdbody.shapes import Ellipsoid

UM = 1e6     # m -> µm
MPA = 1e-6   # Pa -> MPa
OPEN, SLIP, STICK = 0, 1, 2
STATE_COLOURS = ("white", "0.62", "black")
STATE_NAMES = ("open", "slip", "stick")
XLABEL = r"$x - x_0$ (µm), $x_0$: first contact"


@dataclass(frozen=True)
class Fig2Run:
    """Everything the figures and the summary need (SI units, θ in rad)."""

    shape: Ellipsoid
    theta: float
    material: tb.Material
    mu: float
    normal_force: float
    first_contact: np.ndarray       # world (x, y, z) of the lowest point, m
    radii: tuple[float, float]      # principal radii of curvature there, m
    hertz: hertz.HertzEllipse       # the Hertz estimate used to size the window
    normal: tb.NormalContact
    steps: tuple[tb.TangentialContact, ...]
    step_times: tuple[float, ...]   # s
    normal_time: float              # s
    target_time: float              # s, the force-controlled solve that fixed the final shift

    @property
    def grid(self) -> tb.Grid:
        return self.normal.grid

    def stick_fraction(self, step: tb.TangentialContact) -> float:
        """Stick cells over contact cells, dimensionless."""
        return float(step.stick.sum()) / float(self.normal.contact.sum())


def local_radii(shape, theta: float, point: np.ndarray) -> tuple[float, float]:
    """Principal radii of curvature (m) of the lower surface at its lowest point.

    Central differences of the gap, which is 0 at the point; the ellipsoid is symmetric in y, so
    x and y are the principal directions.
    """
    h = 1e-3 * float(np.min(shape.semi_axes))
    x0, y0 = point[0], point[1]
    gxx = (shape.gap_lower(theta, x0 + h, y0) + shape.gap_lower(theta, x0 - h, y0)) / h**2
    gyy = (shape.gap_lower(theta, x0, y0 + h) + shape.gap_lower(theta, x0, y0 - h)) / h**2
    return 1.0 / float(gxx), 1.0 / float(gyy)


def solve_normal_in_window(shape, theta, point, material, force, n, half_width):
    """Force-controlled normal contact on an n x n window centred on the first-contact point.

    The window's half-width starts at ``half_width`` (m) and grows by 25 % while the contact
    touches its edge.
    """
    for _ in range(6):
        grid = tb.Grid(n, 2 * half_width / n, center=(point[0], point[1]))
        X, Y = grid.mesh()
        gap = shape.gap_lower(theta, X, Y)
        try:
            return tb.solve_normal(gap, grid, material, force=force)
        except tb.ContactAtEdgeError:
            half_width *= 1.25
    raise RuntimeError("the contact does not fit in the window; check the inputs")


def run(*, n: int = 128, steps: int = 8, E: float = 1e9, nu: float = 0.3, mu: float = 0.3,
        force: float = 20.0, semi_axes=(1.0e-3, 0.55e-3, 0.4e-3), theta_deg: float = 30.0,
        load_ratio: float = 0.8, margin: float = 1.4, progress: bool = True) -> Fig2Run:
    """Solve the normal contact, then march the plate shift in ``steps`` equal increments.

    The final shift is the one that a force-controlled solve gives for F_x = load_ratio μF_N
    from a virgin state; marching up to it in shift control reaches nearly the same force.
    ``margin`` is the window half-width over the larger Hertz semi-axis.
    """
    shape = Ellipsoid(semi_axes)
    theta = np.radians(theta_deg)
    material = tb.Material(E, nu)
    point = shape.lowest_point(theta)
    Rx, Ry = local_radii(shape, theta, point)
    ref = hertz.elliptic_from_radii(force, Rx, Ry, material.E_star)
    half_width = margin * max(ref.semi_axis_x, ref.semi_axis_y)

    t0 = time.perf_counter()
    normal = solve_normal_in_window(shape, theta, point, material, force, n, half_width)
    normal_time = time.perf_counter() - t0
    if progress:
        cells = int(normal.contact.any(axis=0).sum())
        print(f"normal: F_N = {normal.force:.4g} N, area = {normal.area * 1e6:.4g} mm², "
              f"{cells} cells across in x, peak p = {normal.pressure.max() * MPA:.4g} MPa, "
              f"{normal.iterations} iterations, {normal_time:.2f} s")

    t0 = time.perf_counter()
    target = tb.solve_tangential(normal, mu, force=(load_ratio * mu * normal.force, 0.0))
    target_time = time.perf_counter() - t0
    final_shift = float(target.shift[0])
    if progress:
        print(f"target: F_x = {load_ratio:g} μF_N needs a shift of {final_shift * UM:.4g} µm "
              f"({target.iterations} iterations, {target_time:.2f} s)")

    results, times = [], []
    previous = None
    for k in range(1, steps + 1):
        t0 = time.perf_counter()
        step = tb.solve_tangential(normal, mu, shift=(final_shift * k / steps, 0.0),
                                   previous=previous)
        times.append(time.perf_counter() - t0)
        results.append(step)
        previous = step
        if progress:
            frac = float(step.stick.sum()) / float(normal.contact.sum())
            print(f"step {k}/{steps}: shift {step.shift[0] * UM:7.3f} µm  "
                  f"F_x {step.force[0]:7.4f} N  F_x/μF_N {step.force[0] / (mu * normal.force):.3f}"
                  f"  stick {frac:6.1%}  {step.iterations:3d} it  residual {step.residual:.1e}"
                  f"  {times[-1]:.2f} s")
    return Fig2Run(shape=shape, theta=theta, material=material, mu=mu,
                   normal_force=normal.force, first_contact=point, radii=(Rx, Ry), hertz=ref,
                   normal=normal, steps=tuple(results), step_times=tuple(times),
                   normal_time=normal_time, target_time=target_time)


# ---------------------------------------------------------------------------------------- output

def summary_text(r: Fig2Run) -> str:
    A, B, C = r.shape.semi_axes
    g = r.grid
    muFN = r.mu * r.normal_force
    cx, cy = r.normal.centroid
    x0 = r.first_contact[0]
    xs, ys = g.x[r.normal.contact.any(axis=0)], np.abs(g.y[r.normal.contact.any(axis=1)])
    lines = [
        "Fig. 2 example: partial slip of a tilted elastic ellipsoid on a rigid plate",
        "",
        "inputs",
        f"  semi-axes A, B, C       {A * 1e3:g}, {B * 1e3:g}, {C * 1e3:g} mm (body x, y, z)",
        f"  tilt theta              {np.degrees(r.theta):g} deg (about +y)",
        f"  Young's modulus E       {r.material.E:.4g} Pa",
        f"  Poisson ratio nu        {r.material.nu:g}",
        f"  friction mu             {r.mu:g}",
        f"  normal force F_N        {r.normal_force:.6g} N",
        f"  grid                    {g.nx} x {g.ny} cells of {g.dx * UM:.4g} um, centred on the "
        f"first-contact point x = {x0 * 1e3:.4f} mm",
        "",
        "normal contact",
        f"  radii of curvature      R_x = {r.radii[0] * 1e3:.4g} mm, "
        f"R_y = {r.radii[1] * 1e3:.4g} mm at the first-contact point",
        f"  Hertz estimate          a_x = {r.hertz.semi_axis_x * UM:.4g} um, "
        f"a_y = {r.hertz.semi_axis_y * UM:.4g} um, p0 = {r.hertz.peak_pressure * MPA:.4g} MPa",
        f"  contact area            {r.normal.area * 1e6:.5g} mm^2 "
        f"(Hertz {np.pi * r.hertz.semi_axis_x * r.hertz.semi_axis_y * 1e6:.5g} mm^2)",
        f"  peak pressure           {r.normal.pressure.max() * MPA:.5g} MPa",
        f"  contact extent          x - x0 from {(xs.min() - x0) * UM:.4g} to "
        f"{(xs.max() - x0) * UM:.4g} um, y within +-{ys.max() * UM:.4g} um (cell centres)",
        f"  pressure centroid       x - x0 = {(cx - x0) * UM:.4g} um, y = {cy * UM:.3g} um",
        f"  approach                {r.normal.approach * UM:.5g} um",
        f"  iterations, residual    {r.normal.iterations}, {r.normal.residual:.1e}",
        f"  time                    {r.normal_time:.2f} s",
        "",
        f"tangential steps (plate shift along +x; mu F_N = {muFN:.5g} N)",
        f"{'step':>4} {'shift_um':>10} {'F_x_N':>10} {'F_x/muF_N':>10} {'stick_frac':>10} "
        f"{'stick_xc_um':>11} {'iters':>6} {'residual':>9} {'time_s':>7}",
    ]
    X, _ = g.mesh()
    for k, (s, t) in enumerate(zip(r.steps, r.step_times, strict=True), start=1):
        xc = (X[s.stick].mean() - x0) * UM if s.stick.any() else float("nan")
        lines.append(
            f"{k:>4} {s.shift[0] * UM:>10.4f} {s.force[0]:>10.5f} {s.force[0] / muFN:>10.4f} "
            f"{r.stick_fraction(s):>10.4f} {xc:>11.2f} {s.iterations:>6d} {s.residual:>9.1e} "
            f"{t:>7.2f}")
    lines += [
        "",
        "stick_frac: stick cells / contact cells. stick_xc_um: x of the stick zone's centroid",
        "relative to the first-contact point. residual: Coulomb complementarity residual over",
        "mu max p. Goodman approximation (no normal-tangential coupling).",
    ]
    return "\n".join(lines) + "\n"


def _extent(r: Fig2Run) -> list[float]:
    g, (x0, y0) = r.grid, r.first_contact[:2]
    return [(g.x[0] - g.dx / 2 - x0) * UM, (g.x[-1] + g.dx / 2 - x0) * UM,
            (g.y[0] - g.dy / 2 - y0) * UM, (g.y[-1] + g.dy / 2 - y0) * UM]


def _zoom(ax, r: Fig2Run, pad: float = 0.15) -> None:
    """Limit the axes to the contact's bounding box plus ``pad`` of its size."""
    g, (x0, y0) = r.grid, r.first_contact[:2]
    cols = np.flatnonzero(r.normal.contact.any(axis=0))
    rows = np.flatnonzero(r.normal.contact.any(axis=1))
    xlo, xhi = g.x[cols[0]] - g.dx / 2, g.x[cols[-1]] + g.dx / 2
    ylo, yhi = g.y[rows[0]] - g.dy / 2, g.y[rows[-1]] + g.dy / 2
    px, py = pad * (xhi - xlo), pad * (yhi - ylo)
    ax.set_xlim((xlo - px - x0) * UM, (xhi + px - x0) * UM)
    ax.set_ylim((ylo - py - y0) * UM, (yhi + py - y0) * UM)


def _mark_points(ax, r: Fig2Run, centroid: bool = True) -> None:
    """The first-contact point (the origin of the axes) and the pressure centroid."""
    ax.plot(0, 0, marker="+", ms=10, mew=1.5, color="tab:red", ls="none",
            label="first-contact point")
    if centroid:
        cx, cy = r.normal.centroid
        ax.plot((cx - r.first_contact[0]) * UM, (cy - r.first_contact[1]) * UM, marker="x",
                ms=7, mew=1.5, color="tab:orange", ls="none", label="pressure centroid")


def plot_stick_slip(ax, r: Fig2Run, step: tb.TangentialContact) -> None:
    state = np.full(r.grid.shape, OPEN)
    state[step.slip] = SLIP
    state[step.stick] = STICK
    ax.imshow(state, origin="lower", extent=_extent(r), cmap=ListedColormap(STATE_COLOURS),
              vmin=-0.5, vmax=2.5, interpolation="nearest")
    _mark_points(ax, r)
    handles = [Patch(facecolor=c, edgecolor="0.3", label=name)
               for c, name in zip(STATE_COLOURS[::-1], STATE_NAMES[::-1], strict=True)]
    handles += ax.get_legend_handles_labels()[0]
    ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.9)
    _zoom(ax, r)
    ax.set(xlabel=XLABEL, ylabel="$y$ (µm)", aspect="equal")
    ax.set_title(f"stick {r.stick_fraction(step):.0%} of the contact", fontsize=10)


def plot_tau_x(fig, ax, r: Fig2Run, step: tb.TangentialContact) -> None:
    tau = np.ma.masked_where(~r.normal.contact, step.traction[0] * MPA)
    cmap = plt.get_cmap("viridis").with_extremes(bad="white")
    im = ax.imshow(tau, origin="lower", extent=_extent(r), cmap=cmap, interpolation="nearest")
    g, (x0, y0) = r.grid, r.first_contact[:2]
    ax.contour((g.x - x0) * UM, (g.y - y0) * UM, step.stick.astype(float), levels=[0.5],
               colors="white", linewidths=1.0, linestyles="--")
    _mark_points(ax, r, centroid=False)
    ax.plot([], [], color="white", ls="--", lw=1.0, label="stick-zone edge")
    ax.legend(loc="upper left", fontsize=8, facecolor="0.85", framealpha=0.9)
    _zoom(ax, r)
    ax.set(xlabel=XLABEL, ylabel="$y$ (µm)", aspect="equal")
    ax.set_title(rf"$\tau_x$, max {step.traction[0].max() * MPA:.3g} MPa", fontsize=10)
    fig.colorbar(im, ax=ax, label=r"$\tau_x$ (MPa)", shrink=0.85)


def plot_force_shift(ax, r: Fig2Run) -> None:
    muFN = r.mu * r.normal_force
    shift = np.array([0.0] + [s.shift[0] for s in r.steps]) * UM
    ratio = np.array([0.0] + [s.force[0] for s in r.steps]) / muFN
    # guide: Cattaneo-Mindlin for the sphere with the same Gaussian curvature
    radius = float(np.sqrt(r.radii[0] * r.radii[1]))
    q = np.linspace(0.0, ratio[-1], 60)
    cm = [mindlin.cattaneo_mindlin(qi * muFN, r.normal_force, r.mu, radius, r.material.E,
                                   r.material.nu).shift * UM for qi in q]
    ax.plot(cm, q, "-", color="0.45", lw=1.2,
            label=rf"Cattaneo–Mindlin, sphere $R = \sqrt{{R_x R_y}}$ = {radius * 1e3:.2f} mm")
    ax.plot(shift, ratio, "o", color="tab:blue", ms=5, label="thirdbody, shift steps")
    ax.axhline(1.0, color="tab:red", lw=1, ls="--", label=r"sliding, $F_x = \mu F_\mathrm{N}$")
    ax.set(xlabel=r"plate shift $s_x$ (µm)", ylabel=r"$F_x\,/\,(\mu F_\mathrm{N})$", ylim=(0, 1.08),
           xlim=(0, shift[-1] * 1.05))
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("tangential force against plate shift", fontsize=10)


def plot_sketch(ax, r: Fig2Run) -> None:
    """Side view (x-z section through y = 0) of the tilted ellipsoid on the plate."""
    A, _, C = r.shape.semi_axes * 1e3
    t = np.linspace(0, 2 * np.pi, 400)
    bx, bz = A * np.cos(t), C * np.sin(t)
    c, s = np.cos(r.theta), np.sin(r.theta)
    wx, wz = c * bx + s * bz, -s * bx + c * bz
    x0, z0 = r.first_contact[0] * 1e3, r.first_contact[2] * 1e3
    size = max(A, C)
    ax.add_patch(Polygon(np.c_[wx, wz], closed=True, facecolor="#d9e6f2", edgecolor="k", lw=1.2))
    # the body x axis against the horizontal, to show the tilt θ
    ax.plot([-c * A, c * A], [s * A, -s * A], color="0.4", lw=0.8, ls="-.")
    ax.plot([0, 0.75 * A], [0, 0], color="0.4", lw=0.8, ls=":")
    ax.add_patch(Arc((0, 0), 1.1 * A, 1.1 * A, theta1=-np.degrees(r.theta), theta2=0,
                     color="0.2", lw=1.0))
    ax.text(0.6 * A, -0.1 * A, "θ", fontsize=10, va="center")
    ax.add_patch(Rectangle((-1.3 * size, z0 - 0.18 * size), 2.6 * size, 0.18 * size,
                           facecolor="0.8", edgecolor="k", hatch="///", lw=1.0))
    # contact along y = 0 (its real extent, from the solution)
    g = r.grid
    row = r.normal.contact[np.argmin(np.abs(g.y - r.first_contact[1]))]
    xs = g.x[row] * 1e3
    ax.plot([xs.min(), xs.max()], [z0, z0], color="tab:red", lw=3.5, solid_capstyle="butt")
    # the load, drawn at the highest point (where an upper plate would press)
    ax.add_patch(FancyArrowPatch((-x0, -z0 + 0.4 * size), (-x0, -z0 + 0.01 * size),
                                 arrowstyle="-|>", mutation_scale=14, lw=1.5, color="k"))
    ax.text(-x0 + 0.06 * size, -z0 + 0.25 * size, rf"$F_\mathrm{{N}}$ = {r.normal_force:g} N",
            fontsize=9)
    ax.add_patch(FancyArrowPatch((x0 - 0.5 * size, z0 - 0.3 * size),
                                 (x0 + 0.3 * size, z0 - 0.3 * size),
                                 arrowstyle="-|>", mutation_scale=14, lw=1.5, color="tab:blue"))
    ax.text(x0 - 0.5 * size, z0 - 0.38 * size, r"plate shift $s_x$", color="tab:blue", fontsize=9,
            va="top")
    ax.set(xlim=(-1.3 * size, 1.3 * size), ylim=(z0 - 0.55 * size, -z0 + 0.45 * size),
           aspect="equal", xlabel="$x$ (mm)", ylabel="$z$ (mm)")
    ax.set_title("set-up, section $y$ = 0 (contact in red)", fontsize=10)


def _title(r: Fig2Run, step: tb.TangentialContact) -> str:
    A, B, C = r.shape.semi_axes
    return (f"Tilted ellipsoid {A * 1e3:g}×{B * 1e3:g}×{C * 1e3:g} mm on a rigid plate: "
            rf"θ = {np.degrees(r.theta):g}°, μ = {r.mu:g}, "
            rf"$F_\mathrm{{N}}$ = {r.normal_force:g} N, "
            f"E = {r.material.E / 1e9:g} GPa, ν = {r.material.nu:g}; "
            rf"$F_x$ = {step.force[0] / (r.mu * r.normal_force):.2f} $\mu F_\mathrm{{N}}$")


def write_figures(r: Fig2Run, out: Path, dpi: int = 130) -> list[Path]:
    final = r.steps[-1]
    paths = []

    fig, axes = plt.subplots(2, 2, figsize=(11, 8.6), constrained_layout=True)
    plot_sketch(axes[0, 0], r)
    plot_stick_slip(axes[0, 1], r, final)
    plot_tau_x(fig, axes[1, 0], r, final)
    plot_force_shift(axes[1, 1], r)
    for ax, label in zip(axes.flat, "abcd", strict=True):
        ax.text(-0.02, 1.02, f"({label})", transform=ax.transAxes, ha="right", va="bottom",
                fontsize=11, fontweight="bold")
    fig.suptitle(_title(r, final), fontsize=10.5)
    paths.append(out / "fig2.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.6, 4.8), constrained_layout=True)
    plot_stick_slip(ax, r, final)
    ax.set_title(_wrap(_title(r, final)) + f"\nstick {r.stick_fraction(final):.0%} of the contact",
                 fontsize=9)
    paths.append(out / "fig2_stick_slip.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.2, 4.8), constrained_layout=True)
    plot_tau_x(fig, ax, r, final)
    ax.set_title(_wrap(_title(r, final)) + "\nshear traction " + r"$\tau_x$", fontsize=9)
    paths.append(out / "fig2_tau_x.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.0, 3.6), constrained_layout=True)
    plot_force_shift(ax, r)
    paths.append(out / "fig2_force_shift.png")
    fig.savefig(paths[-1], dpi=dpi)
    plt.close(fig)
    return paths


def _wrap(title: str) -> str:
    head, _, tail = title.partition(": ")
    return f"{head}\n{tail}"


def main(argv: list[str] | None = None) -> Fig2Run:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/fig2"), help="output folder")
    parser.add_argument("--n", type=int, default=128, help="cells across the window")
    parser.add_argument("--steps", type=int, default=8, help="shift increments")
    parser.add_argument("--theta", type=float, default=30.0, help="tilt about y, degrees")
    parser.add_argument("--mu", type=float, default=0.3, help="friction coefficient")
    parser.add_argument("--force", type=float, default=20.0, help="normal force F_N, N")
    parser.add_argument("--E", type=float, default=1e9, help="Young's modulus, Pa")
    parser.add_argument("--nu", type=float, default=0.3, help="Poisson ratio")
    parser.add_argument("--semi-axes", type=float, nargs=3, default=(1.0, 0.55, 0.4),
                        metavar=("A", "B", "C"), help="ellipsoid semi-axes, mm")
    parser.add_argument("--load-ratio", type=float, default=0.8,
                        help="final F_x / (μ F_N), in (0, 1)")
    parser.add_argument("--dpi", type=int, default=130, help="resolution of the PNG files")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.n < 16 or not 0 < args.load_ratio < 1:
        parser.error("need --steps >= 1, --n >= 16 and 0 < --load-ratio < 1")
    args.out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    r = run(n=args.n, steps=args.steps, E=args.E, nu=args.nu, mu=args.mu, force=args.force,
            semi_axes=tuple(a * 1e-3 for a in args.semi_axes), theta_deg=args.theta,
            load_ratio=args.load_ratio)
    solve_time = time.perf_counter() - t0
    text = summary_text(r) + f"\ntotal solve time {solve_time:.2f} s\n"
    (args.out / "summary.txt").write_text(text)
    paths = [*write_figures(r, args.out, args.dpi), args.out / "summary.txt"]
    print(f"solved in {solve_time:.1f} s, total {time.perf_counter() - t0:.1f} s; wrote")
    for p in paths:
        print(f"  {p}")
    return r


if __name__ == "__main__":
    main()
