"""The README stays short, and every ```python block of it runs, in order, as a user would paste
it (in a scratch directory with what the blocks read: see ``_snippets.py``)."""

from __future__ import annotations

import sys

import pytest

from _snippets import ROOT, fake_jobqueue, python_blocks, run_blocks, scratch

README = ROOT / "README.md"


def test_the_readme_is_under_300_lines():
    lines = README.read_text().count("\n")
    assert lines < 300, f"README.md has {lines} lines: move details into docs/"


def test_the_readme_keeps_the_quick_start_commands():
    text = README.read_text()
    assert "make demo" in text and "make test" in text


@pytest.mark.slow
def test_every_python_block_of_the_readme_runs(tmp_path, monkeypatch):
    blocks = python_blocks(README)
    assert len(blocks) >= 4
    scratch(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, "dask_jobqueue", fake_jobqueue())
    run_blocks(blocks, "README.md")
