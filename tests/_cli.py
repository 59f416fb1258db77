"""Helpers of the command-line tests: the command in a subprocess, a refusal's checks, a
directory tree's state, the Fig. 3 configuration."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIG3 = (ROOT / "src/thirdbody/examples/fig3.toml").read_text()
SMALL = FIG3.replace("resolution = 80.0", "resolution = 20.0").replace("steps = 30", "steps = 4")


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
