"""Hertz contact of a sphere on a rigid plate, solved by thirdbody and checked against theory.

Writes ``hertz_pressure.png`` (pressure map and the profile through the centre against Hertz's
solution) and ``hertz_summary.txt`` into the output folder.

    python examples/hertz_demo.py --out out/ [--cells 256]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import thirdbody as tb
from thirdbody.reference import hertz


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder")
    parser.add_argument("--cells", type=int, default=256, help="cells across the window")
    parser.add_argument("--force", type=float, default=10.0, help="normal force, N")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    material = tb.Material(E=210e9, nu=0.3)        # steel particle, Pa
    radius = 5e-3                                   # sphere radius, m
    ref = hertz.sphere(args.force, radius, material.E_star)
    side = 8 * ref.contact_radius                   # window: contact radius = 1/8 of the side
    grid = tb.Grid(args.cells, side / args.cells)
    gap = grid.paraboloid(radius)

    t0 = time.perf_counter()
    res = tb.solve_normal(gap, grid, material, force=args.force)
    elapsed = time.perf_counter() - t0

    a_num = np.sqrt(res.area / np.pi)
    lines = [
        f"Hertz sphere R = {radius * 1e3:g} mm, F = {args.force:g} N, E = {material.E:.3g} Pa, "
        f"nu = {material.nu}, {args.cells}x{args.cells} cells of {grid.dx * 1e6:.3f} um",
        f"solved in {elapsed:.3f} s, {res.iterations} iterations, residual {res.residual:.1e}",
        f"{'quantity':<22}{'thirdbody':>14}{'Hertz':>14}{'error':>10}",
    ]
    for name, num, exact, unit in [
        ("approach", res.approach, ref.approach, "m"),
        ("peak pressure", res.pressure.max(), ref.peak_pressure, "Pa"),
        ("contact radius", a_num, ref.contact_radius, "m"),
    ]:
        lines.append(f"{name + ' (' + unit + ')':<22}{num:>14.6g}{exact:>14.6g}"
                     f"{num / exact - 1:>10.2%}")
    summary = "\n".join(lines)
    print(summary)
    (args.out / "hertz_summary.txt").write_text(summary + "\n")

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    um = 1e6
    extent = np.array([grid.x[0] - grid.dx / 2, grid.x[-1] + grid.dx / 2,
                       grid.y[0] - grid.dy / 2, grid.y[-1] + grid.dy / 2]) * um
    im = ax0.imshow(res.pressure / 1e6, origin="lower", extent=extent, cmap="viridis")
    ax0.set(xlabel="x (µm)", ylabel="y (µm)", title="contact pressure")
    fig.colorbar(im, ax=ax0, label="p (MPa)")
    j = grid.ny // 2
    x = grid.x
    ax1.plot(x * um, res.pressure[j] / 1e6, "o", ms=3, label="thirdbody (cells)")
    xf = np.linspace(x[0], x[-1], 1000)
    ax1.plot(xf * um, ref.pressure(np.hypot(xf, grid.y[j])) / 1e6, "k-", lw=1,
             label="Hertz")
    ax1.set(xlabel="x (µm)", ylabel="p (MPa)", title=f"profile at y = {grid.y[j] * um:.2f} µm")
    ax1.legend()
    fig.savefig(args.out / "hertz_pressure.png", dpi=120)
    print(f"wrote {args.out / 'hertz_pressure.png'} and {args.out / 'hertz_summary.txt'}")


if __name__ == "__main__":
    main()
