"""The documentation under ``docs/`` runs as written and its links hold.

Every ```python block of every page runs, page by page, in order in one namespace, in a scratch
directory with the files the blocks read (see ``_snippets.py``); a page marked
``<!-- snippets: slow -->`` is a slow test. Every relative link of the README and of the pages
points to an existing file. The configuration keys' tables the site shows are generated from the
pydantic models and cover every key.
"""

from __future__ import annotations

import importlib.util
import sys

import pytest

from _snippets import (
    ROOT,
    SLOW_MARK,
    fake_jobqueue,
    fig3_results,
    python_blocks,
    relative_links,
    run_blocks,
    scratch,
)

DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md") if "hooks" not in p.relative_to(DOCS).parts)
WITH_SNIPPETS = [p for p in PAGES if python_blocks(p)]


def _param(page):
    marks = [pytest.mark.slow] if SLOW_MARK in page.read_text() else []
    return pytest.param(page, id=page.relative_to(DOCS).as_posix(), marks=marks)


@pytest.fixture(scope="module")
def fig3(tmp_path_factory):
    """A coarse Fig. 3 run's results file, made once for the pages that read it."""
    return fig3_results(tmp_path_factory.mktemp("fig3"))


@pytest.mark.parametrize("page", [_param(p) for p in WITH_SNIPPETS])
def test_every_python_block_of_the_page_runs(page, tmp_path, monkeypatch, request):
    text = page.read_text()
    results = request.getfixturevalue("fig3") if "out/fig3/results.nc" in text else None
    scratch(tmp_path, results)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, "dask_jobqueue", fake_jobqueue())
    run_blocks(python_blocks(page), page.relative_to(ROOT).as_posix())


def test_the_pages_have_snippets_to_run():
    # a change of fence syntax would silently test nothing
    assert len(WITH_SNIPPETS) >= 8, [p.name for p in WITH_SNIPPETS]


@pytest.mark.parametrize("source", [ROOT / "README.md", *PAGES],
                         ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_points_to_an_existing_file(source):
    missing = [t for t in relative_links(source) if not (source.parent / t).exists()]
    assert not missing, f"{source.relative_to(ROOT)} links to missing files: {missing}"


def test_the_variables_page_keeps_the_marker_its_table_replaces():
    assert "<!-- variables-table -->" in (DOCS / "reference/variables.md").read_text()


def _hook(name: str):
    spec = importlib.util.spec_from_file_location(f"_docs_hook_{name}",
                                                  DOCS / "hooks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_configuration_tables_list_every_key_of_the_models():
    from thirdbody.io import config as c

    text = _hook("config_table").config_tables()
    models = [c.Particle, c.PlacedParticle, c.LayerGenerator, c.Plates, c.Numerics,
              c.SphereShape, c.EllipsoidShape, c.PotatoShape, c.MeshShapeConfig,
              c.LinearRampLoad, c.HoldThenRampLoad, c.ForceTableLoad, c.GapRampLoad,
              c.SlideLoad]
    for model in models:
        for name in model.model_fields:
            if name != "geometry":
                assert f"| `{name}`" in text, f"{model.__name__}.{name} is not in the tables"
    assert "| `resolution` | number in [10, 4000] | `80` |" in text


def test_the_references_page_lists_every_registered_citation():
    import thirdbody  # noqa: F401  (registers the @cites marks)
    from thirdbody._citations import REFERENCES

    text = _hook("citations").citations_markdown()
    for key in REFERENCES:
        assert f"**[{key}]**" in text
    assert "`thirdbody.bem.coupled.solve_coupled`" in text    # where each method is implemented
