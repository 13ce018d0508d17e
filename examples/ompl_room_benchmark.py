"""OMPL's own benchmark of twb's room problem (plan A), to plot next to a twb study in Planner Arena.

Needs OMPL's Python package (``pip install -e '.[ompl]'``).  Runs OMPL's ``Benchmark`` class with RRTConnect
and RRT* (an anytime planner: it reports progress) on the room as a 2-D point problem in which a state is valid
where the robot's centre is farther than its radius (0.045 m) from every obstacle, and writes OMPL's benchmark log
``room-A.log`` (its experiment name ``room-A``, twb's name for the problem).  A state's clearance is its distance
to the obstacles, as in twb's export, so ``solution_clearance`` means the same for both.  Then, as in docs/study.md
("OMPL / Planner Arena")::

    ompl_benchmark_statistics -d room.db room-A.log       # OMPL's log -> OMPL's database
    twb export-ompl mystudy --out room.db --append         # the study's runs beside OMPL's

Options: ``--runs N`` (per planner, default 10), ``--time S`` (each run's time limit, default 1 s).
"""

from __future__ import annotations

import argparse

import numpy as np

from planners import load_environment
from planners.geometry import distance_to_obstacles

ROBOT_RADIUS = 0.045  # m, twb's default robot


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10, help="runs per planner")
    ap.add_argument("--time", type=float, default=1.0, help="each run's time limit (s)")
    args = ap.parse_args()
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import tools as ot
    except ImportError:
        raise SystemExit("OMPL's Python package is not installed: pip install -e '.[ompl]'") from None

    env = load_environment("room")
    start, goal = env.plan("A").start, env.plan("A").goal
    space = ob.RealVectorStateSpace(2)
    bounds = ob.RealVectorBounds(2)
    bounds.setLow(0, 0.0)
    bounds.setHigh(0, env.width)
    bounds.setLow(1, 0.0)
    bounds.setHigh(1, env.height)
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)

    class Room(ob.StateValidityChecker):
        """Valid: the centre farther than the robot's radius from the obstacles; clearance: the centre's distance
        to them (m), the state clearance twb's export uses, so both solution_clearance columns mean the same."""

        def clearance(self, state):  # type: ignore[no-untyped-def]
            return float(distance_to_obstacles(env, np.array([[state[0], state[1]]]))[0])

        def isValid(self, state):  # type: ignore[no-untyped-def]
            return self.clearance(state) > ROBOT_RADIUS

    checker = Room(setup.getSpaceInformation())
    setup.setStateValidityChecker(checker)
    a, b = space.allocState(), space.allocState()
    a[0], a[1], b[0], b[1] = start[0], start[1], goal[0], goal[1]
    setup.setStartAndGoalStates(a, b)
    bench = ot.Benchmark(setup, "room-A")
    si = setup.getSpaceInformation()
    bench.addPlanner(og.RRTConnect(si))
    bench.addPlanner(og.RRTstar(si))
    # time limit, memory limit (MB), runs, time between progress updates (s), no progress bar, no console files
    bench.benchmark(ot.Request(args.time, 1024.0, args.runs, 0.01, False, False, True))
    bench.saveResultsToFile("room-A.log")
    print("wrote room-A.log")


if __name__ == "__main__":
    main()
