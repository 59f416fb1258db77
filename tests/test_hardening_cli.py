"""Issue 15: every bad input is a clean refusal (exit 2, one line naming the key or the path, no
traceback, nothing written), a run directory is never damaged, and Ctrl-C says what is true."""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import thirdbody as tb
from thirdbody.cli.lock import LOCK_NAME
from thirdbody.io import open_results, parse_config

ROOT = Path(__file__).resolve().parents[1]
FIG3 = (ROOT / "src/thirdbody/examples/fig3.toml").read_text()
SMALL = FIG3.replace("resolution = 80.0", "resolution = 20.0").replace("steps = 30", "steps = 4")
runner = CliRunner()


def _cli(*args: str) -> tuple[int, str]:
    """The command in a subprocess (a real traceback, a real exit code)."""
    proc = subprocess.run([sys.executable, "-m", "thirdbody", *args], capture_output=True,
                          text=True, timeout=120)
    return proc.returncode, proc.stdout + proc.stderr


def _refused(code: int, text: str, *needles: str) -> None:
    assert code == 2, text
    assert "Traceback" not in text, text
    for needle in needles:
        assert needle in text, (needle, text)


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.stat().st_mtime_ns, p.read_bytes() if p.is_file()
                                       else None) for p in sorted(root.rglob("*"))}


# --- bad input ---------------------------------------------------------------------------------
def test_binary_config_and_sweep_files_are_refused(tmp_path):
    binary = tmp_path / "bad.toml"
    binary.write_bytes(b"\x00\x01\xff\xfe\x80binary")
    for command in ("run", "sweep"):
        code, text = _cli(command, str(binary), "-o", str(tmp_path / command))
        _refused(code, text, "bad.toml", "UTF-8")
        assert not (tmp_path / command).exists()


@pytest.mark.parametrize(("old", "new", "key"), [
    ("resolution = 80.0", "cell_size = inf", "numerics.cell_size"),
    ("resolution = 80.0", "cell_size = 1e-9", "numerics.cell_size"),
    ("steps = 30", "steps = 1000000000", "load.steps"),
    ("E = 1.0e9", 'E = "1e9"', "particle.E"),
    ("nu = 0.3", 'nu = "0.27"', "particle.nu"),
    ("steps = 30", "steps = true", "load.steps"),
    ("orientation_deg = 20.0", 'orientation_deg = "20"', "particle.orientation_deg"),
    ("E = 1.0e9", "E = inf", "particle.E"),
])
def test_bad_values_are_refused_at_once_naming_the_key(tmp_path, old, new, key):
    config = tmp_path / "c.toml"
    config.write_text(FIG3.replace(old, new))
    start = time.perf_counter()
    code, text = _cli("run", str(config), "-o", str(tmp_path / "out"))
    _refused(code, text, key)
    assert "Material." not in text
    assert time.perf_counter() - start < 30          # an estimate, not 68 s of silence
    assert not (tmp_path / "out").exists()


def test_an_integer_is_a_float_but_a_bool_is_not_a_count():
    import tomllib

    data = tomllib.loads(FIG3.replace("E = 1.0e9", "E = 1000000000"))
    assert parse_config(data).particle.E == 1e9
    data = tomllib.loads(FIG3.replace("maps_every = 5", "maps_every = false"))
    with pytest.raises(ValueError, match=r"numerics\.maps_every"):
        parse_config(data)


def test_a_coarse_cell_size_is_named_as_set():
    sim = tb.Simulation(tb.Particle(tb.shapes.Sphere(0.5e-3), tb.Material(1e9, 0.3)),
                        tb.Plates(0.3), tb.LinearRamp(stop=0.01, steps=1), cell_size=1e-4,
                        maps_every=0)
    with pytest.raises(ValueError, match=r"cell_size \(numerics.cell_size\).*too coarse"):
        sim.preflight()


@pytest.mark.parametrize("name, text", [("shape.py", "print(1)\n"),
                                        ("shape.step", "ISO-10303-21;\n")])
def test_a_mesh_trimesh_cannot_read_is_refused(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    grain = (ROOT / "src/thirdbody/examples/grain.toml").read_text()
    config = tmp_path / "g.toml"
    config.write_text(grain.replace('file = "grain.stl"', f'file = "{name}"'))
    code, out = _cli("run", str(config), "-o", str(tmp_path / "out"))
    _refused(code, out, name, "readable formats")
    assert not (tmp_path / "out").exists()


def test_plot_refuses_a_netcdf_file_thirdbody_did_not_write(tmp_path):
    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"a": ("x", np.arange(3.0))}).to_netcdf(foreign, engine="h5netcdf")
    code, text = _cli("plot", str(foreign), "-o", str(tmp_path / "plots"))
    _refused(code, text, "foreign.nc", "not a thirdbody results file")
    assert not (tmp_path / "plots").exists()


# --- the output directory ----------------------------------------------------------------------
def test_unusable_output_directories_are_refused(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out, needle in ((afile, "not a directory"), (afile / "below", "is a file")):
        code, text = _cli("run", str(config), "-o", str(out))
        _refused(code, text, str(afile), needle)
    assert afile.read_text() == "x"
    if os.geteuid() != 0:                              # root may write anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        code, text = _cli("run", str(config), "-o", str(locked / "out"))
        _refused(code, text, "permission")


def test_resume_into_a_missing_directory_creates_nothing(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    code, text = _cli("run", str(config), "-o", str(tmp_path / "nowhere"), "--resume")
    _refused(code, text, "nothing to resume")
    assert not (tmp_path / "nowhere").exists()


def _partial_run(tmp_path: Path, config: Path) -> Path:
    """A run stopped after two of its four steps, through the CLI's own writer."""
    from thirdbody.io import load_config, run_to_file

    out = tmp_path / "partial"
    out.mkdir()
    (out / "config.toml").write_text(config.read_text())
    body, plates, load, numerics = load_config(config).build()
    sim = tb.Simulation(body, plates, load, **numerics)

    def stop(record):
        if record.step == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_file(sim, out / "results.nc", progress=stop)
    return out


def test_resume_with_other_inputs_touches_nothing(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    other = tmp_path / "other.toml"
    other.write_text(SMALL.replace("mu_up = 0.46", "mu_up = 0.3"))
    # a finished run
    code, text = _cli("run", str(config), "-o", str(tmp_path / "done"), "--no-plots")
    assert code == 0, text
    before = _snapshot(tmp_path / "done")
    code, text = _cli("run", str(other), "-o", str(tmp_path / "done"), "--resume")
    _refused(code, text, "finished run")
    assert _snapshot(tmp_path / "done") == before
    # an unfinished one
    partial = _partial_run(tmp_path, config)
    assert open_results(partial / "results.nc").sizes["step"] >= 1
    before = _snapshot(partial)
    code, text = _cli("run", str(other), "-o", str(partial), "--resume")
    _refused(code, text, "different inputs")
    assert _snapshot(partial) == before
    code, text = _cli("run", str(config), "-o", str(partial), "--resume", "--no-plots")
    assert code == 0, text                              # the right config still resumes


def test_a_second_run_into_a_locked_directory_names_the_holder(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    out = tmp_path / "out"
    out.mkdir()
    with (out / LOCK_NAME).open("a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        held.write(f"{os.getpid()}\n")             # a live holder
        held.flush()
        start = time.monotonic()
        code, text = _cli("run", str(config), "-o", str(out))
        _refused(code, text, "in use", f"pid {os.getpid()}")
        assert "waiting" not in text and time.monotonic() - start < 30   # refused at once
    assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]      # nothing else written
    code, text = _cli("run", str(config), "-o", str(out), "--no-plots")
    assert code == 0, text                                        # released: it runs


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_lock_held_for_a_killed_run_is_waited_for(tmp_path):
    """A killed run's child process that saves its last steps holds the lock (the file names
    the dead run): the next run waits for it instead of refusing."""
    config = tmp_path / "c.toml"
    config.write_text(SMALL)
    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, sys\n"
         f"h = open({str(out / LOCK_NAME)!r}, 'a+'); fcntl.flock(h, fcntl.LOCK_EX)\n"
         f"h.write('{_dead_pid()}\\n'); h.flush(); print('held', flush=True)\n"
         "sys.stdin.readline()"],                  # holds the lock until told to let go
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline() == "held\n"
    run = subprocess.Popen([sys.executable, "-m", "thirdbody", "run", str(config), "-o",
                            str(out), "--no-plots"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    first = run.stderr.readline()
    assert "waiting for the killed run" in first, first
    assert run.poll() is None                   # still waiting
    holder.communicate("go\n", timeout=30)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 0, stderr
    assert (out / "results.nc").exists()


# --- Ctrl-C ------------------------------------------------------------------------------------
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
