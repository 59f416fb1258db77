"""The paper's Figs. 3-5: a "potato" particle compressed between two plates.

* ``--figure 3``: equal friction μ = 0.46 on both plates, normal force ramped linearly. The
  particle sticks at first contact (|ξ| < μ) and, as the contacts grow unevenly over the wavy
  surface, turns several times during compression.
* ``--figure 4``: the same with μ = 0.3 and μ = 0.2 (below |ξ| at the initial orientation): the
  particle turns at first contact, further for the smaller μ, then sticks. A third run,
  ``mu0.2_sign_change``, is the paper's Fig. 4(b) observation: another potato (seed 62) turns
  9° at first contact with μ = 0.2, sticks for the whole compression, and its tangential
  force changes sign at 2.3 N (5.4 % compression), as a second bump of the lower surface
  takes load.
* ``--figure 5``: μ_up = 0.2, μ_low = 0.4, the load held constant and then ramped: the
  particle rolls about the lower contact (the upper one slides) until it is stable, then is
  compressed without turning.

The potatoes (:class:`thirdbody.shapes.Potato`, table ``PARTICLES``) are ellipsoids with
semi-axes 1.0 x 0.8 x 0.7 mm modulated by three random sine waves, symmetric about the xz plane;
E = 1 GPa, ν = 0.3 (a stiff polymer). The paper's own potato is unpublished. Fig. 3 uses
seed 4 (10 % waves, angular wavenumbers 4-8, θ₀ = 20°): its contacts grow unevenly, and at
about 5 % compression a second bump lands on the plate. Fig. 4 uses seed 27 (5.5 % waves,
wavenumbers 2-4, θ₀ = −41°, |ξ(θ₀)| = 0.39), and so does Fig. 5. It turns 6.3° for
μ = 0.3 and 8.8° for μ = 0.2 (the paper: about 6° and 9°), and then sticks.

Usage::

    python examples/paper_figures.py --figure 3 --out out/fig3 [--resolution 80] [--steps 30]

Writes ``results.nc`` (the dataset), ``state.png``/``.pdf`` (F_T/(μF_N) against compression),
``orientation.png``, ``contact_maps.png`` and ``summary.txt`` (one line per step) into
``--out``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import thirdbody as tb
from thirdbody.io import write_results
from thirdbody.plot import save_all
from thirdbody.records import orientation_label
from thirdbody.shapes import Potato

SEMI_AXES = (1.0e-3, 0.8e-3, 0.7e-3)      # m
MATERIAL = tb.Material(1e9, 0.3)          # Pa, -
F_MAX = 10.0                              # N

#: (seed, amplitude, wavenumber range, initial orientation in degrees) of the potato per figure
PARTICLES = {
    3: (4, 0.10, (4.0, 8.0), 20.0),       # sticks, turns as the contacts grow, a bump lands
    4: (27, 0.055, (2.0, 4.0), -41.0),    # |ξ(θ₀)| = 0.39: turns at first contact, then sticks
    5: (27, 0.055, (2.0, 4.0), -41.0),    # the Fig. 4 particle
    "4c": (62, 0.10, (4.0, 8.0), 8.0),    # μ = 0.2: turns 9.3°, sticks, F_T changes sign
}
SEED, AMPLITUDE, WAVENUMBERS, THETA0 = PARTICLES[3]


def potato(figure: int | str = 3) -> Potato:
    seed, amplitude, wavenumbers, _ = PARTICLES[figure]
    return Potato(SEMI_AXES, seed=seed, amplitude=amplitude, wavenumber_range=wavenumbers)


def cases(figure: int, steps: int) -> list[tuple[str, tb.Plates, object]]:
    """(name, plates, load program) of the runs behind a figure."""
    ramp = tb.LinearRamp(stop=F_MAX, steps=steps)
    if figure == 3:
        return [("mu0.46", tb.Plates(0.46), ramp)]
    if figure == 4:
        return [("mu0.3", tb.Plates(0.3), ramp), ("mu0.2", tb.Plates(0.2), ramp),
                ("mu0.2_sign_change", tb.Plates(0.2), ramp)]
    if figure == 5:
        hold = tb.HoldThenRamp(hold=F_MAX / steps, hold_steps=max(steps // 8, 2), stop=F_MAX,
                               ramp_steps=steps)
        return [("mu_up0.2_mu_low0.4", tb.Plates(0.2, 0.4), hold)]
    raise ValueError(f"--figure must be 3, 4 or 5, got {figure}")


def run_case(name: str, plates: tb.Plates, load, resolution: float, out: Path,
             maps_every: int, figure: int | str = 3) -> object:
    particle = tb.Particle(potato(figure), MATERIAL, PARTICLES[figure][3])
    sim = tb.Simulation(particle, plates, load, resolution=resolution, maps_every=maps_every)
    start = time.perf_counter()

    def progress(r: tb.simulation.StepRecord) -> None:
        print(f"  [{name}] step {r.step:3d}  F_N = {r.normal_force:7.3f} N  "
              f"c = {r.compression:.4f}  {orientation_label(r):>10s}  {r.state:10s}  "
              f"F_T/μF_N = {r.ratio[1]:6.3f}  spots {r.spots[0]}+{r.spots[1]}  "
              f"({r.time_total:.2f} s)", flush=True)

    ds = sim.run(progress=progress)
    elapsed = time.perf_counter() - start
    out.mkdir(parents=True, exist_ok=True)
    write_results(ds, out / "results.nc")
    save_all(ds, out)
    with open(out / "summary.txt", "w") as f:
        f.write(f"# {name}: {sim.status}; {elapsed:.1f} s; cell size {sim.cell_size:.3g} m\n")
        f.write("# step F_N(N) compression theta(deg) state ratio_up ratio_low "
                "spots_up spots_low contact_low(m2) stick_low(m2) position_x(m)\n")
        for r in sim.records:
            f.write(f"{r.step} {r.normal_force:.6g} {r.compression:.6g} {r.orientation[1]:.6g} "
                    f"{r.state} {r.ratio[0]:.6g} {r.ratio[1]:.6g} {r.spots[0]} {r.spots[1]} "
                    f"{r.contact_area[1]:.6g} {r.stick_area[1]:.6g} {r.position[0]:.6g}\n")
    turned = [r for r in sim.records if r.turned]
    print(f"[{name}] {sim.status}: {len(sim.records)} steps in {elapsed:.1f} s, "
          f"{len(turned)} turning steps, final {orientation_label(sim.records[-1])}"
          if sim.records else f"[{name}] {sim.status}")
    return ds


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--figure", type=int, default=3, choices=(3, 4, 5))
    parser.add_argument("--out", type=Path, default=Path("out/fig3"))
    parser.add_argument("--resolution", type=float, default=80.0,
                        help="cells per particle size (largest centroid-surface distance)")
    parser.add_argument("--steps", type=int, default=30, help="load steps of the ramp")
    parser.add_argument("--maps-every", type=int, default=5, help="store maps every k steps")
    args = parser.parse_args(argv)
    results = {}
    for name, plates, load in cases(args.figure, args.steps):
        out = args.out if len(cases(args.figure, args.steps)) == 1 else args.out / name
        particle = "4c" if name.endswith("sign_change") else args.figure
        results[name] = run_case(name, plates, load, args.resolution, out, args.maps_every,
                                 particle)
    return results


if __name__ == "__main__":
    main(sys.argv[1:])
