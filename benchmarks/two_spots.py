"""Non-convex particles inside a cluster: plate and pair contacts of several spots (issue 25).

The particle is a two-bump potato: an ellipsoid (1, 0.6, 0.6) mm whose radius is modulated by
1 − A cos(2π d_x), two bumps on its upper and lower sides at x ≈ ±0.3 mm (A = 0.12: 0.64 mm
high, a dip to 0.53 mm between them), E = 1 GPa, ν = 0.3, lying on the lower plate. Two
cases, each solved by ``solve_cluster`` under force control (μ = 0.3 everywhere, tol 1e-5):

* ``plates``: the potato alone between the plates, F_N = ``--force`` (default 0.002 N), at
  each of ``--cells`` per size. By symmetry both plates carry F_N over two equal spots. A
  failure below some resolution is the contacts' size against the cells (a Hertz radius of a
  few µm on the bumps at 0.002 N, cells of 22 µm at 40 per size): the lattice is relative to
  the centroid, so the bump tops lie between cell centres and a small approach reaches none.
* ``sphere``: a sphere of radius ``--radius`` (m, several allowed) resting on both bumps, the
  upper plate pressing it with ``--force``. The pair touches on two spots whose own normals
  lean ± asin(x_bump/(R + r_bump)) from the vertical. The cluster splits the pair into one
  contact per spot (:data:`thirdbody.network.contact.SPLIT_TILT`), each along its own normal;
  until stop 45 one frame, the deepest spot's, held both, so the pair normal leaned by that
  angle and friction carried tan(lean) of the load (or no equilibrium was found). Printed per
  pair contact: its normal force, its normal's lean in x, its |T|/N, its spots and the tilt
  of any spot left in its frame (``spot_tilt``); the pair forces' sum on the potato; passes;
  the sphere's sideways translation.

    .venv/bin/python benchmarks/two_spots.py plates --cells 40 80 160
    .venv/bin/python benchmarks/two_spots.py sphere --radius 1e-3 3e-3 --force 0.02 --cells 60
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

import thirdbody as tb
from thirdbody.network import Body
from thirdbody.network.cluster import ClusterConvergenceError, ClusterNumerics, solve_cluster
from thirdbody.shapes import Sphere
from thirdbody.shapes.potato import Potato, Wave

MAT = tb.Material(1e9, 0.3)
MU = 0.3


def two_bumps(amplitude: float = 0.12) -> Potato:
    """The two-bump potato (semi-axes 1, 0.6, 0.6 mm)."""
    return Potato((1e-3, 0.6e-3, 0.6e-3), [Wave(amplitude, 2 * np.pi, 0.0, -np.pi / 2)])


def on_plate(shape) -> Body:
    """``shape`` unturned, centroid on the z axis, touching the lower plate."""
    lowest = float(shape.lowest_point(Body(shape, MAT, centre=(0, 0, 0)).rotation)[2])
    return Body(shape, MAT, centre=(0.0, 0.0, -lowest))


def sphere_on(body: Body, radius: float) -> Body:
    """A sphere of ``radius`` (m) above ``body`` at x = y = 0, lowered until it touches (the
    body's upper surface sampled by vertical rays every 0.5 µm along x)."""
    xs = np.linspace(-0.99 * radius, 0.99 * radius, 4001)
    _, top = body.shape.surfaces(body.rotation, xs, np.zeros_like(xs))
    height = np.where(np.isnan(top), -np.inf, top + body.centre[2]) \
        + np.sqrt(radius**2 - xs**2)
    return Body(Sphere(radius), MAT, centre=(0.0, 0.0, float(height.max())))


def solve(bodies, force: float, cells: float):
    """(result or the error's message, CPU seconds)."""
    cpu = time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = solve_cluster(bodies, mu_up=MU, mu_low=MU, mu_pp=MU, force=force,
                                   numerics=ClusterNumerics(resolution=cells, tol=1e-5))
    except ClusterConvergenceError as exc:
        parts = str(exc).split("; ")
        return "; ".join(parts[:1] + [p for p in parts[1:] if "spot" in p]), \
            time.process_time() - cpu
    return result, time.process_time() - cpu


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("case", choices=["plates", "sphere"])
    parser.add_argument("--force", type=float, default=None,
                        help="F_N, N (default 0.002 for plates, 0.02 for sphere)")
    parser.add_argument("--cells", type=float, nargs="+", default=[40.0])
    parser.add_argument("--radius", type=float, nargs="+", default=[1e-3, 3e-3])
    args = parser.parse_args(argv)
    potato = on_plate(two_bumps())
    if args.case == "plates":
        force = args.force or 0.002
        for cells in args.cells:
            out, cpu = solve([potato], force, cells)
            if isinstance(out, str):
                print(f"{cells:g} cells: FAILED ({out}), {cpu:.1f} s", flush=True)
                continue
            spots = {c.j: (c.normal_force, c.spots) for c in out.contacts}
            print(f"{cells:g} cells: {out.iterations} passes, lower {spots['lower'][0]:.4g} N "
                  f"in {spots['lower'][1]} spots, upper {spots['upper'][0]:.4g} N in "
                  f"{spots['upper'][1]}, {cpu:.1f} s", flush=True)
        return
    force = args.force or 0.02
    for radius in args.radius:
        top = sphere_on(potato, radius)
        for cells in args.cells:
            out, cpu = solve([potato, top], force, cells)
            if isinstance(out, str):
                print(f"R = {radius * 1e3:g} mm, {cells:g} cells: FAILED ({out}), {cpu:.1f} s",
                      flush=True)
                continue
            pairs = [c for c in out.contacts if c.j == 1]
            total = sum(c.force for c in pairs)          # on the potato, from the sphere
            parts = "; ".join(
                f"N {c.normal_force:.5g} N, normal leaning "
                f"{math.degrees(math.atan2(c.normal[0], c.normal[2])):+.2f}° in x, |T|/N "
                f"{float(np.linalg.norm(c.tangential_force)) / c.normal_force:.4f}, spots "
                f"{c.spots}, spot tilt {math.degrees(c.spot_tilt):.2f}°" for c in pairs)
            print(f"R = {radius * 1e3:g} mm, {cells:g} cells: {out.iterations} passes, "
                  f"{len(pairs)} pair contacts ({parts}); their sum on the potato "
                  f"({total[0]:+.2e}, {total[1]:+.2e}, {total[2]:+.6f}) N; sphere moved "
                  f"{out.translation[1][0] * 1e9:+.2f} nm along x, {cpu:.1f} s", flush=True)


if __name__ == "__main__":
    main()
