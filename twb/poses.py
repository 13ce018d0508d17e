"""Parsing of command-line values: poses such as ``0.3,0.3,90deg``, time scales such as ``20`` or ``max``."""

from __future__ import annotations

import math

from .errors import fail

__all__ = ["parse_cli_pose", "parse_time_scale"]


def parse_cli_pose(text: str, what: str) -> list[float]:
    """``X,Y[,A]`` in metres, A in radians, or in degrees with a ``deg`` suffix; returns 2 or 3 floats."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (2, 3):
        fail(f"--{what} must be X,Y or X,Y,A (metres, radians or e.g. 90deg), got {text!r}")
    out = []
    for i, p in enumerate(parts):
        deg = i == 2 and p.lower().endswith("deg")
        try:
            v = float(p[:-3] if deg else p)
        except ValueError:
            fail(f"--{what}: {p!r} is not a number (expected X,Y[,A])")
        if not math.isfinite(v):
            fail(f"--{what}: {p!r} must be finite")
        out.append(math.radians(v) if deg else v)
    return out


def parse_time_scale(text: str) -> float:
    """``--time-scale``: experiment seconds per wall second, > 0; ``max`` (or ``inf``) is as fast as possible."""
    if text.strip().lower() in ("max", "inf"):
        return math.inf
    try:
        v = float(text)
    except ValueError:
        fail(f"--time-scale must be a number > 0 or 'max', got {text!r}")
    if not (math.isfinite(v) and v > 0):
        fail(f"--time-scale must be a number > 0 or 'max', got {text!r}")
    return v
