"""Run the scripted policy of examples/gym/go_to_goal.py in Teleworkbench/Navigate-v0 and report how it did.

    python examples/gym/rollout.py [--episodes 20] [--seed 0] [--backend field|ideal]
"""

from __future__ import annotations

import argparse
import os
import sys

import gymnasium
import numpy as np

import robot_agent.gym  # noqa: F401 - registers Teleworkbench/... (Gymnasium >= 1.0 loads no plug-ins itself)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from go_to_goal import GoToGoal


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--backend", default="field", choices=["field", "ideal"])
    args = ap.parse_args()
    env_id = "Teleworkbench/Navigate-v0" if args.backend == "field" else "Teleworkbench/NavigateIdeal-v0"
    env = gymnasium.make(env_id)
    ends = {"reached": 0, "collided": 0, "truncated": 0}
    returns = []
    policy = GoToGoal()
    obs, info = env.reset(seed=args.seed)
    for _ in range(args.episodes):
        total, done = 0.0, False
        policy.reset()
        while not done:
            obs, reward, terminated, truncated, info = env.step(np.array(policy(obs), dtype=np.float32))
            total += reward
            done = terminated or truncated
        ends["reached" if info["reached"] else "collided" if info["collided"] else "truncated"] += 1
        returns.append(total)
        obs, info = env.reset()
    print(f"{args.episodes} episodes on {env_id}: {ends}, mean return {np.mean(returns):.2f}")


if __name__ == "__main__":
    main()
