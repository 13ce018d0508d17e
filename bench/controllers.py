"""Controller benchmark: simulation speed of one robot with each path-tracking controller.

For every built-in controller (:mod:`contract.controller_specs`) and both
emulated backends, one robot follows the long loop through the ``room``
environment of ``bench/sim.py`` (blocks, collisions checked, tracker poses
logged) in :meth:`SimCore.advance`, the compiled loop.  The controllers are
timed interleaved, ``--runs`` rounds (default 5) of ``--steps`` control steps
(default 20000); ``ratio`` is the median over rounds of the controller's time
over the motor schema's in the same round (the schema is what ``bench/sim.py``
measures), ``realtime_factor`` experiment seconds per wall second at 50 Hz.
A plug-in controller (Python, stepped one step at a time outside the compiled
loop) is timed the same way with ``--plugin-steps`` steps (default 2000).

    python bench/controllers.py [--runs 5] [--steps 20000] [--plugin-steps 2000]
"""

from __future__ import annotations

import argparse
import math
import os
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench._common import interleaved, report  # noqa: E402
from bench.sim import busy_core  # noqa: E402
from contract.controller_specs import BUILTINS, Param, register_controller, select  # noqa: E402
from robot_agent.engine.noise import path_key  # noqa: E402
from robot_agent.engine.sim import SimCore, State  # noqa: E402

TARGET = 10_000.0  #: realtime factor of one ideal robot, every built-in controller


class PythonPursuit:
    """A plug-in in plain Python: head for the waypoint after the robot's projection (P-control)."""

    params = (Param("speed_m_s", "m/s", 0.2, 0.01, 1.0),)

    def command(self, pose, path, progress, params, dt):  # noqa: ANN001, ANN201 - the plug-in interface
        j = min(progress[0] + 1, len(path) - 1)
        err = math.remainder(math.atan2(path[j, 1] - pose[1], path[j, 0] - pose[0]) - pose[2], math.tau)
        return params["speed_m_s"] * max(math.cos(err), 0.0), 4.0 * err


def core_for(controller: str, backend: str, steps: int) -> SimCore:
    """One robot in the room following the bench loop with ``controller``, busy for ``steps`` steps."""
    core = busy_core(1, backend, steps)
    path = core._paths[0].copy()  # noqa: SLF001 - the loop busy_core gave it
    core.set_path(0, path, path_key(0), select(controller))
    return core


def figures(runs: int, steps: int, plugin_steps: int) -> list[dict]:
    register_controller("python_pursuit", PythonPursuit)
    results = []
    for backend in ("ideal", "field"):
        for names, n in ((list(BUILTINS), steps), (["schema", "python_pursuit"], plugin_steps)):
            cores = {name: core_for(name, backend, n * (runs + 2) + 100) for name in names}
            tasks = {name: (lambda c=core: c.advance(n)) for name, core in cores.items()}
            timed = interleaved(tasks, "schema", runs)
            for name, core in cores.items():
                if name == "schema" and n == plugin_steps:
                    continue
                assert core.state[0] == State.MOVING, f"{name} stopped during the timing"
                step_s = timed[name]["median_s"] / n
                results.append({"controller": name, "backend": backend, "compiled": name in BUILTINS,
                                "steps_per_run": n, "step_s": step_s, "realtime_factor": core.dt / step_s,
                                "ratio_to_schema": timed[name]["ratio"]})
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--plugin-steps", type=int, default=2000)
    a = ap.parse_args()
    results = figures(a.runs, a.steps, a.plugin_steps)
    met = all(r["realtime_factor"] >= TARGET for r in results if r["compiled"] and r["backend"] == "ideal")
    report("controllers", results, target=f"1 ideal robot realtime_factor >= {TARGET:g} for every built-in",
           target_met=met)


if __name__ == "__main__":
    main()
