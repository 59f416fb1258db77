"""The per-step line the sliding benchmarks print (lattice_shear.py, gouge.py)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np


def slide_progress(extra: Callable[[dict], str] = lambda values: "") -> Callable:
    """A ``Simulation.run(progress=...)`` callback printing each step's wall time since it was
    made, the Newton passes, the sub-steps and μ_eff along the sliding, then ``extra(values)``."""
    start = time.perf_counter()

    def progress(record) -> None:
        values = record.values
        print(f"step {record.step:3d}: {time.perf_counter() - start:6.0f} s, "
              f"{values.get('network_iterations')} passes, "
              f"{values.get('network_substeps')} sub-steps, "
              f"mu_eff {values.get('mu_eff_sliding', np.nan):.6g}{extra(values)}", flush=True)

    progress.start = start
    return progress
