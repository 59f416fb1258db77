"""MkDocs hook: the table of results variables, generated from :mod:`thirdbody.schema`.

``docs/reference/variables.md`` holds the marker ``<!-- variables-table -->``; at build time it
is replaced by :func:`thirdbody.schema.markdown_table` (every registered variable: name,
dimensions, units, meaning) and the table of dimensions, so the page follows the registry.
"""

from __future__ import annotations

from mkdocs.exceptions import PluginError

MARKER = "<!-- variables-table -->"


def dimensions_table() -> str:
    """The dimensions of the results (:data:`thirdbody.schema.DIMENSIONS`) as a table."""
    from thirdbody import schema

    rows = ["| dimension | meaning | labels |", "|---|---|---|"]
    for d in schema.DIMENSIONS.values():
        labels = ", ".join(d.labels) if d.labels else ""
        rows.append(f"| `{d.name}` | {d.long_name} | {labels} |")
    return "\n".join(rows)


def on_page_markdown(markdown: str, page, **kwargs) -> str:
    if not page.file.src_uri.endswith("reference/variables.md"):
        return markdown
    if MARKER not in markdown:
        raise PluginError(f"{page.file.src_uri} lost its marker {MARKER}")
    from thirdbody import schema

    text = ("## Dimensions\n\n" + dimensions_table() + "\n\n## Variables\n\n"
            + schema.markdown_table())
    return markdown.replace(MARKER, text)
