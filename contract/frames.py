"""The Teleworkbench field's frames: its size, the sub-fields and where a host's robots live.

The one source of these numbers for the agent, the server and the ``twb``
commands (metres; sub-fields are numbered 1..4).  Pure numpy: importing it
does not load the simulation's compiled kernels.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FIELD_SIZE", "MAX_ROBOTS", "MAX_ROBOTS_SUBFIELD", "SUBFIELD_ORIGINS", "SUBFIELD_SIZE", "field_layout"]

FIELD_SIZE = (3.6, 3.6)
SUBFIELD_SIZE = (1.8, 1.8)
#: robots one multi-robot run may put on the whole field (what the overhead tracker follows), and on one sub-field
MAX_ROBOTS = 64
MAX_ROBOTS_SUBFIELD = 16
#: origins of sub-fields 1..4: lower-left, lower-right, upper-left, upper-right
SUBFIELD_ORIGINS = ((0.0, 0.0), (1.8, 0.0), (0.0, 1.8), (1.8, 1.8))


def field_layout(
    n: int,
    mode: str = "auto",
    area: tuple[float, float] | list[tuple[float, float]] | None = None,
    origins: list[tuple[float, float]] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where ``n`` robots live: ``(sizes (W, 2), world_of (N,), origin (N, 2), area (N, 2))``, metres.

    ``area`` is one (w, h) for every robot or one per robot (default: a
    1.8 m sub-field).  ``mode`` ``shared``: one 3.6 m field; robot i defaults
    to sub-field i (origins (0,0), (1.8,0), (0,1.8), (1.8,1.8)), or to origin
    (0, 0) when its area is larger than a sub-field (e.g. the whole field).
    ``separate``: every robot has a world of its own, of its area's size,
    origin (0, 0).  ``auto``: shared for up to 4 robots on their sub-fields,
    separate beyond, or when several robots each cover more than a sub-field.
    """
    if n < 1:
        raise ValueError("`robots` must be >= 1")
    if mode not in ("auto", "shared", "separate"):
        raise ValueError(f"`world` must be auto, shared or separate, got {mode!r}")
    a = np.array(area if area is not None else SUBFIELD_SIZE, dtype=float)
    if a.shape == (2,):
        a = np.tile(a, (n, 1))
    if a.shape != (n, 2) or not np.isfinite(a).all() or (a <= 0).any():
        raise ValueError(f"`area` must be W,H > 0 (metres), once or once per robot ({n}), got {area!r}")
    if mode == "auto":
        # several robots each larger than a sub-field (a simulation pool) would drive through each other
        overlapping = n > 1 and origins is None and (a > np.array(SUBFIELD_SIZE) + 1e-9).any()
        mode = "shared" if n <= 4 and not overlapping else "separate"
    if mode == "separate":
        if origins is not None:
            raise ValueError("`origins` only apply to a shared world")
        return a.copy(), np.arange(n), np.zeros((n, 2)), a
    big = (a > np.array(SUBFIELD_SIZE) + 1e-9).any(axis=1)
    if origins is not None:
        o = np.array(origins, dtype=float).reshape(-1, 2)
        if len(o) != n:
            raise ValueError(f"`origins` must give one X,Y per robot ({n}), got {len(o)}")
    elif n <= 4 or big.all():
        o = np.array([(0.0, 0.0) if big[i] else SUBFIELD_ORIGINS[i % 4] for i in range(n)], dtype=float)
    else:
        raise ValueError(f"a shared field has 4 sub-fields, not {n}: use world='separate' or give origins")
    size = np.array(FIELD_SIZE)
    if (o < 0).any() or ((o + a) > size + 1e-9).any():
        raise ValueError(f"robot areas must lie inside the {size[0]} m x {size[1]} m field")
    return size[None, :], np.zeros(n, dtype=np.int64), o, a
