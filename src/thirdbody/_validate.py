"""Input checks shared by the public functions: clear errors naming the argument and its range."""

from __future__ import annotations

import math
from collections.abc import Callable


def real(name: str, value: float, allowed: str, ok: Callable[[float], bool]) -> float:
    """``value`` as a float, or ValueError naming ``name`` and the ``allowed`` range."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number in {allowed}, got {value!r}") from None
    if not (math.isfinite(x) and ok(x)):
        raise ValueError(f"{name} must be a finite number in {allowed}, got {value!r}")
    return x


def positive(name: str, value: float) -> float:
    """``value`` as a finite float > 0, or ValueError naming ``name``."""
    return real(name, value, "(0, inf)", lambda x: x > 0)
