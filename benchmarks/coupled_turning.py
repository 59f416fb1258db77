"""A coupled particle run against the uncoupled one, and how many of its turning search's
evaluations could stop their coupled passes early (issue 28).

Each configuration runs through ``Simulation`` twice in this process, uncoupled and with
``coupling=True`` (ν < 0.5), and prints the CPU time of each (``time.process_time``; best of
``--repeat``), their ratio, the coupled evaluations and their passes.

The turning search only needs each evaluation's decision: the demand |F'|/F_N against μ
(stable or not) and the sign of the couple along the leg (turn on or back). An evaluation
whose passes stopped at a relative change c has an error of about c in both, so its decision
is certain when both lie further than 10 c from their threshold. For c in ``--loose`` the
script counts the search evaluations whose decision is certain: the ones that could stop
their passes early (about 3 of 7 passes at c = 1e-3, the passes falling about tenfold each).

    .venv/bin/python benchmarks/coupled_turning.py src/thirdbody/examples/fig3.toml \\
        src/thirdbody/examples/fig4a.toml src/thirdbody/examples/grain.toml
"""

from __future__ import annotations

import argparse
import time
import warnings

from thirdbody.io import load_config
from thirdbody.particle import turning
from thirdbody.particle.statics import PairStatics
from thirdbody.simulation import Simulation


def measure(path: str, coupling: bool) -> tuple[float, list, list]:
    """(CPU seconds, the search evaluations' (demand − μ, couple along the leg), the coupled
    evaluations' passes) of one run of the configuration at ``path``."""
    decisions: list[tuple[float, float]] = []
    passes: list[int] = []
    at, coupled = turning._Search.at, PairStatics._coupled

    def recorded_at(self, origin, t):
        ev = at(self, origin, t)
        decisions.append((ev.demand - self.mu_min, ev.drive(origin)))
        return ev

    def recorded_coupled(self, ev, surfaces):
        out = coupled(self, ev, surfaces)
        passes.append(out.coupling_passes)
        return out

    body, plates, load, numerics = load_config(path).build()
    numerics["coupling"] = coupling
    turning._Search.at, PairStatics._coupled = recorded_at, recorded_coupled
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cpu = time.process_time()
            Simulation(body, plates, load, **numerics).run()
            cpu = time.process_time() - cpu
    finally:
        turning._Search.at, PairStatics._coupled = at, coupled
    return cpu, decisions, passes


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("configs", nargs="+", help="particle configurations (TOML)")
    parser.add_argument("--repeat", type=int, default=1, help="best of this many runs each")
    parser.add_argument("--loose", type=float, nargs="+", default=[1e-2, 3e-3, 1e-3])
    args = parser.parse_args(argv)
    for path in args.configs:
        plain = min(measure(path, False)[0] for _ in range(args.repeat))
        runs = [measure(path, True) for _ in range(args.repeat)]
        cpu, decisions, passes = min(runs, key=lambda r: r[0])
        print(f"{path}: coupled {cpu:.2f} s, uncoupled {plain:.2f} s, ratio {cpu / plain:.2f}; "
              f"{len(passes)} coupled evaluations, {sum(passes)} passes", flush=True)
        for c in args.loose:
            certain = sum(1 for d, drive in decisions if abs(d) > 10 * c and abs(drive) > 10 * c)
            print(f"    passes stopped at a change of {c:g}: the decision is certain for "
                  f"{certain} of {len(decisions)} search evaluations", flush=True)


if __name__ == "__main__":
    main()
