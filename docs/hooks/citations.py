"""MkDocs hook: the references page, generated from the ``@cites`` decorators.

``docs/methods/references.md`` holds the marker ``<!-- citations -->``; at build time it is
replaced by every reference registered in :data:`thirdbody._citations.REFERENCES` (what
``thirdbody.citations()`` prints), each with the functions and classes that carry its
``@cites`` mark. Nothing is written by hand, so the list follows the code.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

from mkdocs.exceptions import PluginError

MARKER = "<!-- citations -->"


def _public_modules():
    import thirdbody

    yield thirdbody
    for info in pkgutil.walk_packages(thirdbody.__path__, "thirdbody."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts) or "examples" in parts:
            continue
        yield importlib.import_module(info.name)


def _users() -> dict[str, set[str]]:
    """Method name -> the qualified names of the objects marked with it."""
    users: dict[str, set[str]] = {}
    for module in _public_modules():
        for name, obj in vars(module).items():
            if getattr(obj, "__module__", None) != module.__name__:
                continue
            mark = getattr(obj, "__cites__", None)
            if mark is not None and (inspect.isfunction(obj) or inspect.isclass(obj)):
                users.setdefault(mark, set()).add(f"{module.__name__}.{name}")
    return users


def citations_markdown() -> str:
    from thirdbody._citations import REFERENCES

    users = _users()
    if not REFERENCES:
        raise PluginError("citations hook: no @cites reference is registered")
    lines = []
    for key in sorted(REFERENCES):
        used_by = ", ".join(f"`{u}`" for u in sorted(users.get(key, ())))
        lines.append(f"- **[{key}]** {REFERENCES[key]}"
                     + (f"  \n  Implemented in {used_by}." if used_by else ""))
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, citations_markdown())
