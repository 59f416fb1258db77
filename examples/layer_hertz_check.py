"""The layer against the exact Hertz sum: ten spheres of different radii between rigid plates.

A sphere of radius R_i between rigid plates a distance h apart carries
F_i = (√2/3) E* √R_i (2R_i − h)^{3/2} (Hertz at both poles, approach (2R_i − h)/2 each); the
gap follows from Σ F_i = F_N. The script runs the layer at 50, 100 and 200 cells per radius
and plots each sphere's force against the exact one, with the relative errors.

    python examples/layer_hertz_check.py --out out/layer_hertz
"""

from __future__ import annotations

import argparse
import math
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

import thirdbody as tb
from thirdbody.shapes import Sphere

MATERIAL = tb.Material(1e9, 0.3)
RADII = [1e-3 * (1 + 0.0005 * i) for i in range(10)]


def exact(total: float) -> tuple[float, np.ndarray]:
    """(h, F_i) of the exact Hertz sum at the total force ``total`` (N)."""
    radii = np.asarray(RADII)

    def forces(h):
        return (math.sqrt(2) / 3 * MATERIAL.E_star * np.sqrt(radii)
                * np.clip(2 * radii - h, 0, None) ** 1.5)

    h = brentq(lambda h: forces(h).sum() - total, radii.max(), 2 * radii.max(), xtol=1e-16,
               rtol=1e-15)
    return h, forces(h)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/layer_hertz"))
    args = parser.parse_args(argv)
    # the load at which the smallest sphere is pressed by 8 µm
    total = brentq(lambda F: exact(F)[0] - (2 * RADII[0] - 8e-6), 1e-2, 1e3)
    h, reference = exact(total)
    layer = tb.Layer([tb.PlacedParticle(tb.Particle(Sphere(r), MATERIAL), (3e-3 * i, 0.0))
                      for i, r in enumerate(RADII)])
    runs = {}
    for resolution in (50, 100, 200):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ds = tb.Simulation(layer, tb.Plates(0.3), tb.ForceTable([total]),
                               resolution=resolution, maps_every=0).run()
        runs[resolution] = ds
        F = ds.normal_force.values[0]
        gap_error = (2 * RADII[-1] - float(ds.plate_gap[0])) / (2 * RADII[-1] - h) - 1
        print(f"{resolution:4d} cells per radius: largest force error "
              f"{np.max(np.abs(F / reference - 1)):.2%}, approach error {gap_error:+.3%}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax_e) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    r_um = (np.asarray(RADII) - 1e-3) * 1e6
    ax.plot(r_um, reference, "k-", label="exact Hertz sum")
    for (resolution, ds), marker in zip(runs.items(), "os^", strict=True):
        F = ds.normal_force.values[0]
        ax.plot(r_um, F, marker, mfc="none", label=f"thirdbody, {resolution} cells / R")
        ax_e.plot(r_um, 100 * (F / reference - 1), marker + "-", mfc="none",
                  label=f"{resolution} cells / R")
    ax.set_xlabel("R − 1 mm (µm)")
    ax.set_ylabel("normal force F_i (N)")
    ax.set_title(f"10 spheres, F_N = {total:.3g} N, h = {h * 1e3:.4f} mm", fontsize=10)
    ax.legend(fontsize=8)
    ax_e.axhline(0, color="k", lw=0.8)
    ax_e.set_xlabel("R − 1 mm (µm)")
    ax_e.set_ylabel("error of F_i (%)")
    ax_e.set_title("relative error against the exact sum", fontsize=10)
    ax_e.legend(fontsize=8)
    args.out.mkdir(parents=True, exist_ok=True)
    for ext in ("png", "pdf"):
        fig.savefig(args.out / f"layer_hertz_sum.{ext}", dpi=120)
    print(args.out / "layer_hertz_sum.png")


if __name__ == "__main__":
    main()
