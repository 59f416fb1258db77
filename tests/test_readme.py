"""Every ```python block of the README runs, in order, as a user would paste it.

The blocks run in a scratch directory that holds what they read: ``out/fig3/results.nc`` (a
coarse Fig. 3 run through the CLI) and ``sweep.toml`` (a four-case sweep over the axes the
README's sweep block selects). The SLURM block gets a stand-in ``dask_jobqueue`` whose
``SLURMCluster`` is a one-worker local cluster; its sweep writes the ``sweep/summary.nc`` the
sweep-results block opens.
"""

from __future__ import annotations

import re
import subprocess
import sys
import types
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)

SWEEP = """base = "fig4a"

[axes]
"plates.mu" = [0.2, 0.3]
"particle.orientation_deg" = [-60.0, 20.0]

[set]
"load.steps" = 2
"numerics.resolution" = 24.0
"numerics.maps_every" = 0
"""


def _fake_jobqueue() -> types.ModuleType:
    from distributed import LocalCluster

    class SLURMCluster(LocalCluster):
        """A local one-worker cluster that takes SLURMCluster's arguments."""

        def __init__(self, **kwargs):
            super().__init__(n_workers=1, threads_per_worker=1, processes=False,
                             dashboard_address=None)

        def adapt(self, minimum_jobs: int = 1, maximum_jobs: int = 1, **kwargs):
            return None

    module = types.ModuleType("dask_jobqueue")
    module.SLURMCluster = SLURMCluster
    module.PBSCluster = SLURMCluster
    return module


@pytest.mark.slow
def test_every_python_block_of_the_readme_runs(tmp_path, monkeypatch):
    assert len(BLOCKS) >= 7
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, "dask_jobqueue", _fake_jobqueue())
    fig3 = (ROOT / "src/thirdbody/examples/fig3.toml").read_text()
    (tmp_path / "fig3.toml").write_text(fig3.replace("resolution = 80.0", "resolution = 30.0"))
    subprocess.run([sys.executable, "-m", "thirdbody", "run", "fig3.toml", "-o", "out/fig3",
                    "--no-plots"], check=True, capture_output=True)
    (tmp_path / "sweep.toml").write_text(SWEEP)
    # the SLURM block writes the sweep the sweep-results block reads: run it first
    slurm = [b for b in BLOCKS if "SLURMCluster" in b]
    order = slurm + [b for b in BLOCKS if b not in slurm]
    for block in order:
        namespace: dict = {"__name__": "__readme__"}
        try:
            exec(compile(block, "README.md", "exec"), namespace)
        except Exception as exc:  # pragma: no cover - the failure message is the point
            pytest.fail(f"README block failed: {type(exc).__name__}: {exc}\n---\n{block}")
    assert (tmp_path / "out/mine").is_dir()
