"""The command line: config validation (exit 2, nothing written), --print-config, run, plot,
examples, validate, and a run killed with SIGKILL then resumed equals an uninterrupted one."""

import subprocess
import sys
import tomllib

import pytest
from typer.testing import CliRunner

from thirdbody import particle_view
from thirdbody.cli import app
from thirdbody.io import RESUME_VARIABLE, open_results

runner = CliRunner()

SMALL = """
[particle]
shape = "potato"
semi_axes = [1.0e-3, 0.8e-3, 0.7e-3]
seed = 4
amplitude = 0.1
wavenumber_range = [4.0, 8.0]
E = 1.0e9
nu = 0.3
orientation_deg = 20.0

[plates]
mu_up = 0.46

[load]
program = "linear_ramp"
stop = 10.0
steps = {steps}

[numerics]
resolution = 40.0
maps_every = 3
"""


def write(tmp_path, text, name="run.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("change, key", [
    (("E = 1.0e9", "E = -1.0"), "particle.E"),
    (("nu = 0.3", "nu = 0.7"), "particle.nu"),
    (("mu_up = 0.46", "mu_up = -0.1"), "plates.mu_up"),
    (("steps = {steps}", "steps = 0"), "load.steps"),
    (("stop = 10.0", "stop = 'ten'"), "load.stop"),
    (("seed = 4", "seed = 4\ncolour = 'red'"), "colour"),
    (("[numerics]", "[numerics]\nresolution_typo = 3"), "resolution_typo"),
    (("resolution = 40.0", "resolution = 2.0"), "numerics.resolution"),
    (("amplitude = 0.1", "amplitude = 0.4\nn_waves = 3"), "amplitude"),
    (("stop = 10.0", "stop = 0.001"), "numerics.resolution"),        # contact of a few cells
])
def test_bad_configuration_exits_2_names_the_key_and_writes_nothing(tmp_path, change, key):
    text = SMALL.replace(*change).replace("{steps}", "3")
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(write(tmp_path, text)), "-o", str(out)])
    assert result.exit_code == 2, result.output
    assert key in result.output
    assert not out.exists()


def test_broken_toml_and_missing_file(tmp_path):
    result = runner.invoke(app, ["run", str(write(tmp_path, "[particle\nE = 1"))])
    assert result.exit_code == 2 and "not valid TOML" in result.output
    result = runner.invoke(app, ["run", str(tmp_path / "nope.toml")])
    assert result.exit_code == 2 and "cannot read" in result.output


def test_print_config_shows_the_resolved_defaults(tmp_path):
    result = runner.invoke(app, ["run", str(write(tmp_path, SMALL.replace("{steps}", "3"))),
                                 "--print-config"])
    assert result.exit_code == 0
    resolved = tomllib.loads(result.output)
    assert resolved["numerics"]["tol"] == 1e-8            # a default, filled in
    assert resolved["particle"]["E"] == 1e9


def test_run_plot_and_examples(tmp_path):
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(write(tmp_path, SMALL.replace("{steps}", "3"))),
                                 "-o", str(out)])
    assert result.exit_code == 0, result.output
    ds = open_results(out / "results.nc")
    assert ds.attrs["status"] == "complete" and ds.sizes["step"] == 3
    assert RESUME_VARIABLE not in ds
    assert (out / "config.toml").exists() and (out / "state.png").exists()
    again = runner.invoke(app, ["run", str(tmp_path / "run.toml"), "-o", str(out)])
    assert again.exit_code == 2 and "exists" in again.output
    (out / "state.png").unlink()
    assert runner.invoke(app, ["plot", str(out / "results.nc")]).exit_code == 0
    assert (out / "state.png").stat().st_size > 1000
    listing = runner.invoke(app, ["examples"])
    assert all(f"fig{k}" in listing.output for k in (2, 3, 5))
    assert runner.invoke(app, ["examples", "copy", "fig2", str(tmp_path / "ex")]).exit_code == 0
    assert (tmp_path / "ex" / "fig2.py").stat().st_size > 1000
    copied = runner.invoke(app, ["examples", "copy", "fig5", str(tmp_path / "ex")])
    assert copied.exit_code == 0 and (tmp_path / "ex" / "fig5.toml").exists()
    assert runner.invoke(app, ["examples", "copy", "nope", str(tmp_path)]).exit_code == 2


def test_validate_prints_the_table_and_passes():
    result = runner.invoke(app, ["validate"])
    assert result.exit_code == 0, result.output
    assert result.output.count(" yes") == 7 and "NO" not in result.output


@pytest.mark.slow
def test_the_asymmetric_grain_example_turns_about_an_oblique_axis(tmp_path):
    """The bundled mesh example (copied with its mesh file), coarsened to run in seconds: it
    turns at first contact about an axis that is neither x nor y, and the orientation figure
    shows the turn in a top view."""
    copied = runner.invoke(app, ["examples", "copy", "grain", str(tmp_path)])
    assert copied.exit_code == 0, copied.output
    config = tmp_path / "grain.toml"
    assert (tmp_path / "grain.stl").stat().st_size > 100_000
    text = (config.read_text().replace("subdivisions = 3", "subdivisions = 2")
            .replace("resolution = 50.0", "resolution = 40.0").replace("steps = 10", "steps = 3"))
    config.write_text(text)
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(config), "-o", str(out)])
    assert result.exit_code == 0, result.output
    ds = particle_view(open_results(out / "results.nc"), 0)
    assert ds.turned.values[0] == 1
    rotation = ds.rotation.isel(step=0).values
    assert min(abs(rotation)) > 0.1 * max(abs(rotation))       # an oblique turn axis
    assert (ds.twist_ratio <= 1e-3).all()
    assert (out / "orientation.png").stat().st_size > 10_000


@pytest.mark.slow
def test_without_a_terminal_a_run_prints_plain_progress_lines(tmp_path):
    """Through a pipe (as in a SLURM log or under nohup): one line per step at most, the first
    and the last always, each with the step, its load and state, the time elapsed (and left);
    then the figures and the summary. --quiet prints nothing, and errors still reach stderr
    with exit code 2."""
    config = write(tmp_path, SMALL.replace("{steps}", "3"))
    cmd = [sys.executable, "-m", "thirdbody", "run", str(config)]
    proc = subprocess.run([*cmd, "-o", str(tmp_path / "out")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    steps = [t for t in lines if t.startswith("[")]
    assert 2 <= len(steps) <= 3, lines
    assert steps[0].startswith("[1/3] step 0: F_N ") and "left" in steps[0]
    assert steps[-1].startswith("[3/3] step 2: F_N ") and "elapsed" in steps[-1]
    assert all("\x1b" not in t for t in lines)                 # no terminal codes
    assert lines[-2:] == [f"drawing the figures in {tmp_path / 'out'}",
                          lines[-1]] and lines[-1].startswith("complete: 3 of 3 steps")
    quiet = subprocess.run([*cmd, "-o", str(tmp_path / "quiet"), "--quiet"],
                           capture_output=True, text=True)
    assert quiet.returncode == 0 and quiet.stdout == "", quiet.stdout
    again = subprocess.run([*cmd, "-o", str(tmp_path / "quiet"), "-q"], capture_output=True,
                           text=True)
    assert again.returncode == 2 and again.stdout == ""
    assert "exists" in again.stderr


def test_progress_lines_are_at_most_one_per_interval(capsys):
    """A 1000-step run at a step a second prints one line every 10 s, plus the last."""
    from thirdbody.cli.progress import Progress

    now = [0.0]
    with Progress(1000, "steps", every=10.0, terminal=False, clock=lambda: now[0]) as shown:
        for k in range(1000):
            now[0] += 1.0
            shown.update(k + 1, f"step {k}")
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 100 + 1
    assert lines[0] == "[1/1000] step 0; 1 s elapsed, about 16 min 39 s left"
    assert lines[-1] == "[1000/1000] step 999; 16 min 40 s elapsed"
    with Progress(3, "cases", quiet=True, terminal=False) as shown:
        shown.update(1, "case a", always=True)
        shown.note("x")
    assert capsys.readouterr().out == ""


def test_version_and_help():
    from thirdbody import __version__

    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output == f"thirdbody {__version__}\n"
    for command in ([], ["run"], ["sweep"], ["examples"]):
        shown = runner.invoke(app, [*command, "--help"])
        assert shown.exit_code == 0 and "<bool>" not in shown.output, shown.output
    assert f"thirdbody {__version__}" in runner.invoke(app, ["--help"]).output
    examples = runner.invoke(app, ["examples", "--help"]).output
    assert "Figs. 3-5" not in examples and "layer" in examples
