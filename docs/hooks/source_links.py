"""MkDocs hook: links from the pages to the repository's files, and docstrings' Sphinx roles.

The pages link to tests, benchmarks and examples with paths relative to the page
(``../tests/test_normal.py`` from ``docs/validation.md``), as they work when the Markdown is read
in the repository. MkDocs only knows the files under ``docs/``, so before it checks the links this
hook checks that each such file exists (a missing one fails the build) and points the link at
``repo_url`` (``<repo_url>/blob/main/<path>``) when ``mkdocs.yml`` sets one, or shows the path as
code otherwise.

The docstrings cross-reference with Sphinx roles (``:class:`Shape```), which Markdown shows
literally; the role prefixes are dropped from the rendered HTML.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.exceptions import PluginError

_LINK = re.compile(r"(?<!!)\[(?P<text>[^\]]+)\]\((?P<target>[^)\s]+)\)")
_FENCE = re.compile(r"^(```|~~~)", re.M)
_ROLE = re.compile(r":(?:class|meth|func|mod|attr|data|exc|obj|py:\w+):(<code>)~?")


def _outside_docs(page_src: str, target: str, docs_dir: Path, root: Path) -> Path | None:
    if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith(("#", "/")):
        return None
    path = target.split("#", 1)[0]
    if not path:
        return None
    resolved = (docs_dir / posixpath.dirname(page_src) / path).resolve()
    if resolved.is_relative_to(docs_dir.resolve()):
        return None
    if not resolved.is_relative_to(root.resolve()):
        raise PluginError(f"{page_src}: the link {target!r} leaves the repository")
    return resolved


def on_page_markdown(markdown: str, page, config, files) -> str:
    docs_dir = Path(config["docs_dir"])
    root = Path(config["config_file_path"]).parent
    repo_url = (config.get("repo_url") or "").rstrip("/")
    pieces = _FENCE.split(markdown)
    # split() keeps the fence markers: text, marker, code, marker, text, ...; rewrite the text
    out, in_code = [], False
    for piece in pieces:
        if piece in ("```", "~~~"):
            in_code = not in_code
            out.append(piece)
            continue
        if in_code:
            out.append(piece)
            continue

        def rewrite(m: re.Match) -> str:
            target = m.group("target")
            resolved = _outside_docs(page.file.src_uri, target, docs_dir, root)
            if resolved is None:
                return m.group(0)
            if not resolved.exists():
                raise PluginError(f"{page.file.src_uri}: the link {target!r} points to "
                                  f"{resolved}, which does not exist")
            rel = resolved.relative_to(root.resolve()).as_posix()
            if repo_url:
                return f"[{m.group('text')}]({repo_url}/blob/main/{rel})"
            text = m.group("text")
            return text if text.startswith("`") else f"`{rel}`" if text == rel else text

        out.append(_LINK.sub(rewrite, piece))
    return "".join(out)


def on_page_content(html: str, page, config, files) -> str:
    return _ROLE.sub(r"\1", html)
