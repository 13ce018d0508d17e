"""OMPL's geometric planners as built-in planners, through the ``ompl`` package (the ``ompl`` extra).

Each planner plans in OMPL's 2-D real vector space over the field, with the project's own checks: a state is
valid when :meth:`~planners.grid.ConfigSpace.is_free` says so and a motion when the exact segment test of
:meth:`~planners.grid.ConfigSpace.segments_free` does (:mod:`planners._segment`, one compiled call per check),
so OMPL's paths are held to exactly the standard of ours.  The objective is path length.

- **Seeds.** OMPL seeds every random generator it creates from one process-wide seed generator; the planner
  resets it (``ompl.util.RNG.setSeed``) from the run's seed before it creates anything, so a run's seed
  decides its samples.  A planner that stops at its first solution (RRTConnect, KPIECE1, FMT*) then gives
  the same path for the same seed; an anytime planner (RRT*, Informed RRT*, BIT*, PRM*) improves its path
  until ``time_budget_s`` runs out, so how far it gets depends on the machine as well.
- **Time budget.** ``time_budget_s`` (s) bounds every planner; the anytime ones use all of it.
- **Simplification.** ``simplify`` runs OMPL's path simplifier (shortcutting and smoothing, checked by the same
  motion test) after planning; ``info["simplified"]`` says whether it ran.
- **Progress.** ``info["progress"]``: the best path length so far against the planning time, ``[[t_s,
  length_m], ...]``, one entry per improvement (the anytime planners; RRT*, Informed RRT* and BIT* report it
  as they go, the others once, at the end) — the curve of OMPL's Planner Arena progress page;
  ``info["time_to_first_solution_s"]`` (None for PRM*, whose solution thread reports only at the end).

Without the package, choosing one of these planners fails with one line naming the install command
(:data:`INSTALL_HINT`); listing them does not need it.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np

from .base import Param, Planner
from .errors import NoPathFound, PlanningError
from .grid import ConfigSpace

__all__ = ["INSTALL_HINT", "OMPL_PLANNERS", "OMPLPlanner", "ompl_builtins", "ompl_modules"]

INSTALL_HINT = "pip install 'teleworkbench[ompl]'"

#: our name: (OMPL's class in ``ompl.geometric``, what it is, whether it improves its path until the budget)
OMPL_PLANNERS: dict[str, tuple[str, str, bool]] = {
    "ompl_rrtconnect": ("RRTConnect", "OMPL RRT-Connect: two trees grown towards each other; first solution", False),
    "ompl_rrtstar": ("RRTstar", "OMPL RRT*: asymptotically optimal RRT, improves until the time budget", True),
    "ompl_informed_rrtstar": ("InformedRRTstar", "OMPL Informed RRT*: RRT* sampling only where the path can improve",
                              True),
    "ompl_bitstar": ("BITstar", "OMPL BIT*: batch informed trees, improves until the time budget", True),
    "ompl_prmstar": ("PRMstar", "OMPL PRM*: roadmap, asymptotically optimal connection; improves until the budget",
                     True),
    "ompl_kpiece1": ("KPIECE1", "OMPL KPIECE1: projection-based exploration; first solution", False),
    "ompl_fmt": ("FMT", "OMPL FMT*: fast marching tree over a fixed batch of samples", False),
}

#: OMPL planners that check their solution in a thread of their own: their termination stays in C++ (a Python
#: condition would be called from that thread while the planning thread holds the interpreter)
_THREADED = {"PRMstar"}

#: OMPL's seed is the process's: one OMPL plan at a time per process, so that each keeps its own seed
_LOCK = threading.Lock()


def ompl_modules() -> tuple[Any, Any, Any]:
    """``(ompl.base, ompl.geometric, ompl.util)``; :class:`PlanningError` with the install command without them."""
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except ImportError as exc:
        raise PlanningError(f"OMPL's planners need the ompl package, which is not installed: {INSTALL_HINT}") from exc
    return ob, og, ou


class OMPLPlanner(Planner):
    """One of OMPL's geometric planners (:data:`OMPL_PLANNERS`) on the configuration space's exact checks."""

    parameters = (
        Param("time_budget_s", "s", 1.0, 0.0, 60.0, "planning time: the anytime planners use all of it",
              low_exclusive=True),
        Param("simplify", "", False, None, None, "run OMPL's path simplifier on the solution", type="boolean"),
    )
    stochastic = True  # the samples come from the run's seed
    ompl_class = ""
    anytime = False

    def check_params(self, params: dict[str, Any]) -> None:
        """Refuse the planner (``ValueError``, one line with the install command) when OMPL is missing."""
        try:
            ompl_modules()
        except PlanningError as exc:
            raise ValueError(f"planner {self.name!r}: {exc}") from None

    def solve(
        self, space: ConfigSpace, start: np.ndarray, goal: np.ndarray, params: dict[str, Any], seed: int
    ) -> tuple[np.ndarray, dict[str, Any]]:
        ob, og, ou = ompl_modules()
        from ._segment import SegmentTest

        params = {**(self.defaults or {}), **params}
        test = SegmentTest(space)
        test.segment(*start, *goal)  # loads the compiled tests before the clock starts
        test.point(*start)
        with _LOCK:
            level = ou.getLogLevel()
            ou.setLogLevel(ou.LOG_NONE)  # OMPL logs to stderr; its outcome is in the result instead
            try:
                return self._solve(ob, og, ou, test, space, start, goal, params, seed)
            finally:
                ou.setLogLevel(level)

    def _solve(self, ob: Any, og: Any, ou: Any, test: Any, space: ConfigSpace, start: np.ndarray,
               goal: np.ndarray, params: dict[str, Any], seed: int) -> tuple[np.ndarray, dict[str, Any]]:
        ou.RNG.setSeed(seed % (2**32 - 1) + 1)  # before any generator exists; OMPL refuses 0
        state_space = ob.RealVectorStateSpace(2)
        bounds = ob.RealVectorBounds(2)
        bounds.setLow(0.0)
        bounds.setHigh(0, float(space.env.width))
        bounds.setHigh(1, float(space.env.height))
        state_space.setBounds(bounds)
        ss = og.SimpleSetup(state_space)
        si = ss.getSpaceInformation()
        point, segment = test.point, test.segment
        checks = [0]

        class Valid(ob.StateValidityChecker):  # type: ignore[misc, name-defined]
            def isValid(self, s: Any) -> bool:
                return point(s[0], s[1])

        class Motion(ob.MotionValidator):  # type: ignore[misc, name-defined]
            def checkMotion(self, a: Any, b: Any) -> bool:
                checks[0] += 1
                return segment(a[0], a[1], b[0], b[1])

        valid, motion = Valid(si), Motion(si)  # kept alive while OMPL holds them
        ss.setStateValidityChecker(valid)
        si.setMotionValidator(motion)
        s, g = state_space.allocState(), state_space.allocState()
        s[0], s[1] = float(start[0]), float(start[1])
        g[0], g[1] = float(goal[0]), float(goal[1])
        ss.setStartAndGoalStates(s, g)
        ss.setOptimizationObjective(ob.PathLengthOptimizationObjective(si))
        planner = getattr(og, self.ompl_class)(si)
        ss.setPlanner(planner)
        ss.setup()
        budget = float(params["time_budget_s"])
        progress: list[list[float]] = []
        t0 = time.perf_counter()
        if self.ompl_class in _THREADED:
            status = ss.solve(budget)
        else:
            best = getattr(planner, "bestCost", None)
            last = [math.inf]

            def stop() -> bool:
                t = time.perf_counter() - t0
                if best is not None:
                    c = best().value()
                    if c < last[0]:
                        last[0] = c
                        progress.append([round(t, 6), round(c, 6)])
                return t >= budget

            status = ss.solve(ob.PlannerTerminationCondition(stop))
        elapsed = time.perf_counter() - t0
        if not ss.haveExactSolutionPath():
            raise NoPathFound(f"{self.name} found no path within its time budget of {budget:g} s ({status})")
        if params["simplify"]:
            ss.simplifySolution(max(budget - elapsed, 0.0) or 0.1)
        path = ss.getSolutionPath()
        pts = np.array([[path.getState(i)[0], path.getState(i)[1]] for i in range(path.getStateCount())])
        length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
        if not progress or progress[-1][1] > round(length, 6):
            progress.append([round(elapsed, 6), round(length, 6)])
        pts[0], pts[-1] = start, goal  # OMPL copies the states: exactly the query's ends
        info = {"ompl_planner": self.ompl_class, "ompl_status": str(status), "motion_checks": checks[0],
                "simplified": bool(params["simplify"]), "progress": progress,
                # PRM* reports its path only at the end: its first solution's time is not known
                "time_to_first_solution_s": None if self.ompl_class in _THREADED else progress[0][0]}
        return pts, info


def ompl_builtins() -> dict[str, type[OMPLPlanner]]:
    """One :class:`OMPLPlanner` subclass per entry of :data:`OMPL_PLANNERS`, by our name."""
    return {name: type(f"OMPL_{cls}", (OMPLPlanner,), {"name": name, "ompl_class": cls, "anytime": anytime,
                                                         "description": f"{doc} (needs the ompl extra)"})
            for name, (cls, doc, anytime) in OMPL_PLANNERS.items()}
