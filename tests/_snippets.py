"""Helpers for the tests that run the documentation: the ```python blocks of a Markdown file, run
in order in one namespace as a reader would paste them, in a scratch directory that holds the
files they read; and the relative links of a Markdown file.

Used by ``test_readme.py`` (the README) and ``test_docs.py`` (every page under ``docs/``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: a page whose blocks take more than about 10 s says so with this line (not shown on the site)
SLOW_MARK = "<!-- snippets: slow -->"

_BLOCK = re.compile(r"^```python\n(.*?)^```", flags=re.S | re.M)
_FENCED = re.compile(r"^(```|~~~).*?^\1", flags=re.S | re.M)
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")

#: a four-case sweep of the Fig. 4 potato, coarse enough to run in seconds: the ``sweep.toml``
#: the pages' sweep blocks read
SWEEP = """base = "fig4a"

[axes]
"plates.mu" = [0.2, 0.3]
"particle.orientation_deg" = [-60.0, 20.0]

[set]
"load.steps" = 2
"numerics.resolution" = 24.0
"numerics.maps_every" = 0
"""


def python_blocks(path: Path) -> list[str]:
    """The ```python blocks of a Markdown file, in order."""
    return _BLOCK.findall(Path(path).read_text())


def relative_links(path: Path) -> list[str]:
    """The targets of the Markdown links and images of a file that are paths (no URL, no
    page-internal anchor), outside fenced code, with any ``#anchor`` removed."""
    text = _FENCED.sub("", Path(path).read_text())
    targets = []
    for target in _LINK.findall(text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue
        targets.append(target.split("#", 1)[0])
    return targets


def fake_jobqueue() -> types.ModuleType:
    """A stand-in ``dask_jobqueue`` whose SLURMCluster (and PBSCluster) is a one-worker local
    cluster that takes their arguments."""
    from distributed import LocalCluster

    class SLURMCluster(LocalCluster):
        """A local one-worker cluster that takes SLURMCluster's arguments."""

        def __init__(self, **kwargs):
            super().__init__(n_workers=1, threads_per_worker=1, processes=False,
                             dashboard_address=None)

        def adapt(self, minimum_jobs: int = 1, maximum_jobs: int = 1, **kwargs):
            return None

        def scale(self, *args, **kwargs):
            return None

    module = types.ModuleType("dask_jobqueue")
    module.SLURMCluster = SLURMCluster
    module.PBSCluster = SLURMCluster
    return module


def coarse_fig3(text: str) -> str:
    """The Fig. 3 configuration at a coarse resolution and in 10 load steps (seconds, not
    minutes)."""
    assert "resolution = 80.0" in text and "steps = 30" in text
    return text.replace("resolution = 80.0", "resolution = 30.0").replace("steps = 30",
                                                                          "steps = 10")


def fig3_results(directory: Path) -> Path:
    """Run the coarse Fig. 3 configuration through the command line into
    ``directory/out/fig3`` (no figures) and return the results file."""
    directory.mkdir(parents=True, exist_ok=True)
    config = directory / "fig3.toml"
    config.write_text(coarse_fig3((ROOT / "src/thirdbody/examples/fig3.toml").read_text()))
    subprocess.run([sys.executable, "-m", "thirdbody", "run", str(config), "-o",
                    str(directory / "out/fig3"), "--no-plots"], check=True, capture_output=True)
    return directory / "out/fig3/results.nc"


def scratch(directory: Path, fig3: Path | None = None) -> None:
    """Lay out what the snippets read: ``fig3.toml`` (coarse), ``sweep.toml`` (four cases)
    and, when given, a copy of the Fig. 3 results as ``out/fig3/results.nc``."""
    (directory / "fig3.toml").write_text(
        coarse_fig3((ROOT / "src/thirdbody/examples/fig3.toml").read_text()))
    (directory / "sweep.toml").write_text(SWEEP)
    if fig3 is not None:
        (directory / "out/fig3").mkdir(parents=True, exist_ok=True)
        shutil.copy(fig3, directory / "out/fig3/results.nc")


def run_blocks(blocks: list[str], source: str) -> dict:
    """Run the blocks in order in one namespace (as pasted into one session); a failing block
    fails the test with its text."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    namespace: dict = {"__name__": "__snippets__"}
    try:
        for i, block in enumerate(blocks, 1):
            try:
                exec(compile(block, f"{source} (python block {i})", "exec"), namespace)
            except Exception as exc:  # pragma: no cover - the failure message is the point
                pytest.fail(f"{source}, python block {i} failed: {type(exc).__name__}: {exc}"
                            f"\n---\n{block}")
    finally:
        plt.close("all")
    return namespace
