"""Ctrl-C to `thirdbody run` says what is true: exit 130, no traceback, and the steps it says
are on disk are there (while the figures are drawn: they finish first)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import pytest

from _cli import FIG3
from thirdbody.io import open_results


@pytest.mark.slow
def test_ctrl_c_while_the_figures_are_drawn_lets_them_finish_and_exits_130(tmp_path):
    """The run is over and results.nc final: Ctrl-C while the figures are written (here once
    the first one is on disk) lets them all finish, then exits 130 saying the run is whole.
    Before, an interrupt inside matplotlib's or pandas' imports ended with a traceback."""
    config = tmp_path / "c.toml"
    config.write_text(FIG3.replace("resolution = 80.0", "resolution = 30.0"))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "thirdbody", "run", str(config), "-o",
                             str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 300
    while not list(out.glob("*.png")):
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted at the end" in err, err
    assert "holds 30 completed step(s), the whole run" in err
    names = sorted(f.name for f in out.iterdir() if f.suffix in (".png", ".pdf"))
    assert names == sorted(f"{n}.{x}" for n in ("state", "orientation", "contact_maps")
                           for x in ("png", "pdf"))
    assert open_results(out / "results.nc").sizes["step"] == 30

@pytest.mark.slow
def test_ctrl_c_at_any_moment_exits_130_and_says_what_is_on_disk(tmp_path):
    config = tmp_path / "c.toml"
    # resolution 40: the run lasts beyond the last delay (saving in a child made it faster)
    config.write_text(FIG3.replace("resolution = 80.0", "resolution = 40.0"))
    for k, delay in enumerate((0.0, 0.05, 0.3, 0.6, 1.0, 2.5)):
        out = tmp_path / f"o{k}"
        # the delays count from the moment thirdbody's first module is imported (-X importtime
        # reports it): an interrupt before that lands in the interpreter's own start-up, which
        # no code of ours can catch (seen under load at 0.05 s after Popen)
        proc = subprocess.Popen(
            [sys.executable, "-X", "importtime", "-m", "thirdbody", "run", str(config),
             "-o", str(out)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        while "thirdbody._interrupt" not in (line := proc.stderr.readline()):
            assert line, "thirdbody was never imported"
        rest: list[str] = []            # drain stderr, or the child blocks on a full pipe
        reader = threading.Thread(target=lambda out=rest, stream=proc.stderr:
                                  out.append(stream.read()))
        reader.start()
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
        reader.join(timeout=60)
        err = "\n".join(t for t in "".join(rest).splitlines()
                        if not t.startswith("import time:"))
        assert proc.returncode == 130, (delay, err)
        assert "Traceback" not in err and "KeyboardInterrupt" not in err, (delay, err)
        assert err.strip(), delay
        results = out / "results.nc"
        if "completed step" in err:
            n = int(err.split("holds ")[1].split(" ")[0])
            assert open_results(results).sizes["step"] == n
        else:
            assert not results.exists(), (delay, err)
        assert not (out / "results.nc.tmp").exists()
