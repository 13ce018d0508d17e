"""An example planner plug-in: the grid A* path, then greedy line-of-sight shortcuts (any-angle).

Install it next to the testbed (``twb plugins install -e examples/planner_plugin``) and
select it by name: ``twb plan --planner shortcut ...``, ``twb submit
--planner shortcut ...`` or ``Client.submit(..., planner="shortcut")``.
"""

from __future__ import annotations

import numpy as np

from planners import Param, Planner, get_planner

__all__ = ["ShortcutPlanner"]


class ShortcutPlanner(Planner):
    """A* on the grid, then keep only the points needed to see from one to the next."""

    name = "shortcut"
    description = "grid A* with greedy line-of-sight shortcuts (any-angle, like Theta*)"
    parameters = (Param("lookahead", "points", 400, 1, 100_000, "how many points ahead to try (bounds the work per "
                        "point)", type="integer"),)

    def solve(self, space, start, goal, params, seed):
        out = get_planner("astar").solve(space, start, goal, {}, seed)     # (N, 2), or (path, info)
        raw = np.asarray(out[0] if isinstance(out, tuple) else out, dtype=float)
        lookahead = int(params["lookahead"])
        out, i = [raw[0]], 0
        while i < len(raw) - 1:
            cand = np.arange(min(len(raw) - 1, i + lookahead), i, -1)   # farthest first
            free = space.segments_free(np.repeat(raw[i:i + 1], len(cand), axis=0), raw[cand])
            i = int(cand[np.argmax(free)]) if free.any() else i + 1      # the next point is always visible
            out.append(raw[i])
        return np.array(out), {"points_before": len(raw), "points_after": len(out)}
