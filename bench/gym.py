"""Gymnasium benchmark: the vector environment's robot-steps per second against the engine's own stepping.

For each backend (ideal, field) and ``frame_skip`` (1: one control step per environment step; 5), the
:class:`~robot_agent.gym.envs.NavigationVectorEnv` of ``--robots`` robots (default 1000) steps with
uniformly random actions (drawn beforehand from a seeded generator, not timed), episodes ending and
resetting as they come (next-step autoreset).  ``robot_steps_per_s`` = environment steps x robots /
wall time; ``control_steps_per_s`` the same in the engine's control steps (x ``frame_skip``).

Measured in the same run, interleaved round by round with the environment (``bench._common.interleaved``,
so each round of both sees the same machine load), are the engine's own figures for the same robots:

- ``engine``: :meth:`SimCore.advance` over many steps per call with every robot following a long path
  in its own room (``bench/sim.py``'s set-up: what the engine reaches, ~3.8 M robot-steps/s for 1000 ideal
  robots on an idle machine);
- ``engine_velocity``: the engine as the environment drives it, velocity mode with the same random
  commands, ``frame_skip`` control steps per call, no observation.

A last row repeats ideal robots at ``frame_skip`` 1 with the observations computed on numba's threads
(``parallel=True``).  ``ratio_to_engine`` = environment robot-steps/s / the engine's; ``ratio_to_engine_velocity`` likewise.
On a shared machine wall time depends on the others' load (``load_average`` is reported): the ratios,
and the figures per CPU second (``robot_steps_per_cpu_s``, ``engine_control_steps_per_cpu_s``: one more
run of each timed by this process's CPU time), are what carry over.

    python bench/gym.py [--robots 1000] [--steps 200] [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np

from bench._common import interleaved, report
from bench.sim import busy_core
from robot_agent.gym.envs import NavigationVectorEnv

TARGET = 1_000_000  # robot-steps/s of the vector environment, 1000 robots, ideal robot, frame_skip 1


def figures(robots: int, backend: str, frame_skip: int, steps: int, runs: int, parallel: bool = False) -> dict:
    """One configuration's timings (see the module docstring)."""
    env = NavigationVectorEnv(robots, backend=backend, frame_skip=frame_skip, parallel=parallel)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    top = env.single_action_space.high.astype(float)
    actions = rng.uniform(-1.0, 1.0, (steps, robots, 2)) * top
    drive = NavigationVectorEnv(robots, backend=backend, frame_skip=frame_skip)
    drive.reset(seed=0)
    core = drive.fleet.core
    drive.fleet.step(actions[0])  # every robot in velocity mode from here on
    engine = busy_core(robots, backend, steps * frame_skip * (runs + 2) + 100)
    dones = [0]

    def run_env() -> None:
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            dones[0] += int(term.sum() + trunc.sum())

    def run_velocity() -> None:
        for a in actions:
            core.drive_all(a, 10.0)
            core.advance(frame_skip)

    def run_engine() -> None:
        engine.advance(steps * frame_skip)

    timed = interleaved({"engine": run_engine, "env": run_env, "engine_velocity": run_velocity}, "engine", runs)
    per_s = {name: steps * robots / t["median_s"] for name, t in timed.items()}
    cpu = {}
    for name, fn in (("engine", run_engine), ("env", run_env)):  # CPU time: what a loaded machine's wall time hides
        c0 = time.process_time()
        fn()
        cpu[name] = time.process_time() - c0
    engine_per_s = steps * frame_skip * robots / timed["engine"]["median_s"]  # control steps
    return {
        "robots": robots,
        "backend": backend,
        "frame_skip": frame_skip,
        "parallel_observations": parallel,
        "env_steps_per_run": steps,
        "robot_steps_per_s": per_s["env"],
        "control_steps_per_s": per_s["env"] * frame_skip,
        "episodes_ended_per_env_step": dones[0] / (steps * (runs + 1)),
        "engine_control_steps_per_s": engine_per_s,
        "engine_velocity_control_steps_per_s": per_s["engine_velocity"] * frame_skip,
        "ratio_to_engine": per_s["env"] * frame_skip / engine_per_s,
        "ratio_to_engine_velocity": timed["engine_velocity"]["median_s"] / timed["env"]["median_s"],
        "robot_steps_per_cpu_s": steps * robots / cpu["env"],
        "engine_control_steps_per_cpu_s": steps * frame_skip * robots / cpu["engine"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    results = [figures(args.robots, backend, fs, args.steps, args.runs)
               for backend in ("ideal", "field") for fs in (1, 5)]
    results.append(figures(args.robots, "ideal", 1, args.steps, args.runs, parallel=True))
    head = next(r for r in results if r["backend"] == "ideal" and r["frame_skip"] == 1)
    report("gym", results, cpus=os.cpu_count(), load_average=os.getloadavg(),
           targets_met={f"vector env >= {TARGET:,} robot-steps/s (ideal, frame_skip 1)":
                        head["robot_steps_per_s"] >= TARGET})


if __name__ == "__main__":
    main()
