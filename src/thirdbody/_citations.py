"""Provenance: which published method produced a result.

Every algorithm in thirdbody is decorated with the paper it implements; result objects record the
names of the methods that produced them (their ``methods`` field), and :func:`citations` lists the
references behind those names so a user can cite what a run used.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

F = TypeVar("F", bound=Callable)

#: method name -> full reference
REFERENCES: dict[str, str] = {}


def cites(name: str, reference: str) -> Callable[[F], F]:
    """Register ``reference`` under ``name`` and mark the decorated callable with it."""

    def mark(obj: F) -> F:
        REFERENCES[name] = reference
        obj.__cites__ = name  # type: ignore[attr-defined]
        return obj

    return mark


def citations(*names: str) -> str:
    """The references behind the given method names (all registered ones if none given)."""
    keys = names or tuple(REFERENCES)
    return "\n".join(f"[{k}] {REFERENCES[k]}" for k in keys if k in REFERENCES)
