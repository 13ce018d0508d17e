"""Checks of decoded JSON fields shared by the environment file's parts; errors name the field."""

from __future__ import annotations

import math
from typing import Any, Mapping

from .errors import InvalidEnvironment

__all__ = ["check_keys", "number"]


def number(value: Any, where: str) -> float:
    """``value`` as a finite float; :class:`InvalidEnvironment` naming ``where`` otherwise."""
    # bool is an int subclass; "true" as a coordinate is a mistake, not 1.0
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InvalidEnvironment(f"{where} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise InvalidEnvironment(f"{where} must be finite, got {value!r}")
    return out


def check_keys(obj: Mapping[str, Any], allowed: set[str], where: str) -> None:
    """Refuse a key of ``obj`` outside ``allowed``, naming it and the allowed ones."""
    unknown = sorted(set(obj) - allowed)
    if unknown:
        raise InvalidEnvironment(
            f"{where} has unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})"
        )
