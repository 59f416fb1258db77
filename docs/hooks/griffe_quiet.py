"""MkDocs hook: griffe's complaints about docstring layout are shown, not fatal.

A few numpy-style docstrings go on with a paragraph after their ``Parameters`` section, which
griffe cannot parse as parameters ("Could not parse line ..."). The text is still rendered, so
these messages are lowered to INFO (``mkdocs build --verbose`` shows them) and ``--strict`` keeps
failing on what matters: broken links, missing pages and references that do not resolve.
"""

from __future__ import annotations

import logging


class _LayoutNotFatal(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno == logging.WARNING and "Could not parse line" in record.getMessage():
            record.levelno, record.levelname = logging.INFO, "INFO"
        return True


logging.getLogger("mkdocs.plugins.griffe").addFilter(_LayoutNotFatal())
