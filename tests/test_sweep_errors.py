"""A sweep's refusals, damaged files, reruns and Ctrl-C: an unreadable case file is never
destroyed, --dry-run changes nothing, the size is shown at once and capped, string axes are
refused, Ctrl-C stops cleanly, an edited mesh is a new case, and a rerun of a finished sweep
touches nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from conftest import local_client
from thirdbody.cli import app
from thirdbody.io import load_config, open_results
from thirdbody.sweep import case_id, load_sweep, run_sweep

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()

TINY = """base = "fig4a"

[axes]
"plates.mu" = [0.2, 0.3]

[set]
"load.steps" = 2
"numerics.resolution" = 20.0
"numerics.maps_every" = 0
"""


def _tree(root: Path) -> dict:
    """Every path under root with its mtime and bytes (directories: mtime only)."""
    if not root.exists():
        return {}
    return {str(p.relative_to(root)): (p.stat().st_mtime_ns,
                                       p.read_bytes() if p.is_file() else None)
            for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="module")
def client():
    yield from local_client(1)


def _sweep(tmp_path: Path, text: str = TINY) -> Path:
    path = tmp_path / "sweep.toml"
    path.write_text(text)
    return path


def test_an_unreadable_case_file_is_kept_and_dry_run_changes_nothing(tmp_path, client):
    path = _sweep(tmp_path)
    spec = load_sweep(path)
    first = spec.cases()[0]
    out = tmp_path / "out"
    (out / "cases").mkdir(parents=True)
    bad = out / "cases" / first.filename
    bad.write_bytes(b"not an HDF5 file: a case file another host still holds")
    before = _tree(out)
    result = runner.invoke(app, ["sweep", str(path), "-o", str(out), "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "unreadable" in result.output
    assert _tree(out) == before                                  # nothing moved or written
    result = runner.invoke(app, ["sweep", str(path), "-o", str(tmp_path / "new"), "--dry-run"])
    assert result.exit_code == 0 and not (tmp_path / "new").exists()
    # a real run keeps the bytes under another name and recomputes the case
    report = run_sweep(spec, out, client=client, plots=False)
    kept = out / "cases" / f"{first.filename}.unreadable-1"
    assert kept.read_bytes() == before[f"cases/{first.filename}"][1]
    assert report.set_aside == [(bad, kept)]
    assert report.records[first.case_id]["status"] == "complete"
    assert open_results(bad).attrs["status"] == "complete"


def test_the_size_is_shown_at_once_and_capped(tmp_path):
    big = _sweep(tmp_path, TINY.replace('"plates.mu" = [0.2, 0.3]',
                                        '"plates.mu" = {start = 0.1, stop = 0.5, num = 1000}\n'
                                        '"particle.orientation_deg" = '
                                        '{start = -60.0, stop = 60.0, num = 1000}'))
    start = time.perf_counter()
    result = runner.invoke(app, ["sweep", str(big), "-o", str(tmp_path / "o"), "--dry-run"])
    assert time.perf_counter() - start < 10
    assert result.exit_code == 2
    assert "1000000 cases (1000 x 1000)" in result.output and "core-hours" in result.output
    assert "--max-cases" in result.output
    assert not (tmp_path / "o").exists()
    small = _sweep(tmp_path, TINY)
    result = runner.invoke(app, ["sweep", str(small), "-o", str(tmp_path / "o"), "--dry-run",
                                 "--max-cases", "1"])
    assert result.exit_code == 2 and "2 cases exceed --max-cases 1" in result.output
    result = runner.invoke(app, ["sweep", str(small), "-o", str(tmp_path / "o"), "--dry-run",
                                 "--max-cases", "2"])
    assert result.exit_code == 0, result.output


def test_string_axis_values_are_refused(tmp_path):
    path = _sweep(tmp_path, TINY.replace("[0.2, 0.3]", '["0.2", "0.3"]'))
    result = runner.invoke(app, ["sweep", str(path), "-o", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert "plates.mu" in result.output and "valid number" in result.output
    assert not (tmp_path / "o").exists()


def test_an_edited_mesh_is_a_new_case_and_the_written_config_reruns_anywhere(tmp_path):
    grain = (ROOT / "src/thirdbody/examples/grain.toml").read_text()
    stl = (ROOT / "src/thirdbody/examples/grain.stl").read_bytes()
    (tmp_path / "grain.stl").write_bytes(stl)
    cfg_path = tmp_path / "grain.toml"
    cfg_path.write_text(grain.replace("steps = 10", "steps = 1")
                        .replace("resolution = 50.0", "resolution = 20.0")
                        .replace("subdivisions = 3", "subdivisions = 1"))
    before = case_id(load_config(cfg_path))
    # the same path, other content (the binary STL's 80-byte header: the same triangles)
    edited = b"edited".ljust(80, b"\0") + stl[80:]
    (tmp_path / "grain.stl").write_bytes(edited)
    assert case_id(load_config(cfg_path)) != before
    # the written config names the mesh by absolute path and hash: it reruns from elsewhere
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(cfg_path), "-o", str(out), "--no-plots"])
    assert result.exit_code == 0, result.output
    written = (out / "config.toml").read_text()
    assert f'file = "{(tmp_path / "grain.stl").resolve()}"' in written
    assert "sha256 = " in written
    other = tmp_path / "elsewhere"
    other.mkdir()
    proc = subprocess.run([sys.executable, "-m", "thirdbody", "run", str(out / "config.toml"),
                           "-o", "again", "--no-plots"], cwd=other, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    # and it refuses the file once edited
    (tmp_path / "grain.stl").write_bytes(stl)
    proc = subprocess.run([sys.executable, "-m", "thirdbody", "run", str(out / "config.toml"),
                           "-o", "third", "--no-plots"], cwd=other, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and "has changed" in proc.stderr, proc.stderr


@pytest.mark.slow
def test_a_rerun_of_a_finished_sweep_touches_nothing(tmp_path):
    path = _sweep(tmp_path)
    out = tmp_path / "out"
    cmd = ["sweep", str(path), "-o", str(out), "--workers", "1"]
    result = runner.invoke(app, cmd)
    assert result.exit_code == 0, result.output
    before = _tree(out)
    assert "summary.nc" in before and "state_map.png" in before and "sweep.toml" in before
    result = runner.invoke(app, cmd)
    assert result.exit_code == 0, result.output
    assert "0 run, 2 already done" in result.output
    assert _tree(out) == before


@pytest.mark.slow
def test_ctrl_c_stops_a_sweep_with_one_line_and_no_error_files(tmp_path):
    # two short cases and two of 1000 steps: the signal comes when the first step of a case is
    # saved, while the long ones surely still run (a sleep after it instead let the whole sweep
    # finish first on a loaded machine: exit 0)
    path = _sweep(tmp_path, TINY.replace('"load.steps" = 2\n', '')
                  .replace('[set]', '"load.steps" = [2, 1000]\n\n[set]'))
    out = tmp_path / "out"
    # the whole process group gets the signal, as from a terminal
    proc = subprocess.Popen([sys.executable, "-m", "thirdbody", "sweep", str(path), "-o",
                             str(out), "--workers", "2"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and not list((out / "cases").glob("*.nc")):
        time.sleep(0.05)
    os.killpg(os.getpgid(proc.pid), signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "CommClosedError" not in err, err
    assert err.strip().splitlines()[-1].startswith("interrupted"), err
    assert not list((out / "cases").glob("*.error.txt"))
    # stopped mid-sweep: a long case's file holds the steps it had, marked as running
    statuses = [open_results(f).attrs["status"] for f in (out / "cases").glob("*.nc")]
    assert "running" in statuses, statuses


@pytest.mark.slow
def test_an_interrupt_quiets_the_workers_logs_before_the_cluster_closes(monkeypatch):
    # the CI's one red run: a worker whose heartbeat met the closing scheduler logged an ERROR
    # with a traceback to the terminal. Its logs must be quiet before anything is closed.
    import logging

    from dask.distributed import Client

    from thirdbody.sweep import _dask_client

    seen = []
    close = Client.close

    def spying_close(self, *args, **kwargs):
        seen.append(self.run(lambda: logging.getLogger("distributed").level))
        return close(self, *args, **kwargs)

    monkeypatch.setattr(Client, "close", spying_close)
    with pytest.raises(KeyboardInterrupt), _dask_client(None, None, 2, True) as client:
        assert set(client.run(lambda: logging.getLogger("distributed").level).values()) \
            != {logging.CRITICAL}
        raise KeyboardInterrupt
    assert len(seen) == 1 and len(seen[0]) == 2
    assert set(seen[0].values()) == {logging.CRITICAL}
