"""The secant predictor of network runs, on and off, on one configuration: each load step of a
run whose particles may touch (a ``[network]`` table) starts its first Newton pass from the last
step's motion times the ratio of the load increments (``thirdbody.network.run._predicted``);
off, it starts from the start poses. The two runs alternate in one process (the machine is
shared: compare CPU seconds and passes, which do not depend on its load); each prints its passes
per step, CPU and wall seconds, and the last step's μ_eff and gap. Run:

    .venv/bin/python benchmarks/predictor.py src/thirdbody/examples/shear_layer.toml --steps 23

(``make shear``'s compression and its first 20 sliding steps; without ``--steps`` the whole
program.)
"""

from __future__ import annotations

import argparse
import time
import warnings

import thirdbody as tb
import thirdbody.network.run as network_run
from thirdbody.io import load_config


def run(path: str, steps: int | None, predict: bool) -> tuple[list[int], float, float, dict]:
    """One run of the configuration, the predictor on or off: the passes of each step, CPU and
    wall seconds, and the last record's values."""
    real = network_run._predicted
    network_run._predicted = real if predict else (lambda *args: None)
    try:
        body, plates, load, numerics = load_config(path).build()
        sim = tb.Simulation(body, plates, load, **numerics)
        if sim.network is None:
            raise SystemExit(f"{path}: not a network run (no [network] table)")
        cpu, wall, passes, values = time.process_time(), time.perf_counter(), [], {}
        for record, _, _ in sim.steps():
            passes.append(int(record.values["network_iterations"]))
            values = record.values
            if steps is not None and len(passes) >= steps:
                break
        return passes, time.process_time() - cpu, time.perf_counter() - wall, values
    finally:
        network_run._predicted = real


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", help="a configuration with a [network] table")
    parser.add_argument("--steps", type=int, default=None, help="stop after this many steps")
    parser.add_argument("--rounds", type=int, default=1, help="on/off pairs (best CPU kept)")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")         # the half-space warnings of make shear's contacts
    best = {True: None, False: None}
    for _ in range(args.rounds):
        for predict in (True, False):
            passes, cpu, wall, values = run(args.config, args.steps, predict)
            print(f"predictor {'on ' if predict else 'off'}: {len(passes)} steps, "
                  f"{sum(passes)} passes, CPU {cpu:.1f} s, wall {wall:.1f} s; last step: "
                  f"mu_eff {values.get('mu_eff_sliding', float('nan')):.5f}, gap "
                  f"{values.get('plate_gap', float('nan')):.9e} m; passes {passes}", flush=True)
            if best[predict] is None or cpu < best[predict][1]:
                best[predict] = (sum(passes), cpu)
    print(f"passes on/off {best[True][0]}/{best[False][0]} = {best[True][0] / best[False][0]:.2f};"
          f" CPU on/off {best[True][1]:.1f}/{best[False][1]:.1f} s = "
          f"{best[True][1] / best[False][1]:.2f}")


if __name__ == "__main__":
    main()
