"""A scripted navigation policy for Teleworkbench/Navigate-v0 that is also an uploadable controller program.

``GoToGoal()(obs)`` maps the environment's observation (``pose``, ``goal``, ``occupancy``; docs/gymnasium.md)
to body velocities: head for the goal, pushed away from occupied cells of the local window, slowing
down in front of obstacles and on the approach.  Use it in Gymnasium (examples/gym/rollout.py) or
upload this file as a controller program (docs/controllers.md, "Your own controller program"): run as a
program, it subscribes to the robot's localisation (``T,T,O,1``), builds the same observation from each
``PO`` line, the job's goal (``TWB_GOAL``) and the environment file's blocks (``TWB_ENV_FILE``), and
answers it with the policy's ``T,T,V``; within 3 cm of the goal it stops (``T,T,V,0,0``), which ends the
run.  A learned policy goes in the same place: replace ``policy`` (its weights inlined, or numpy where the
testbed's Python has it).  Standard library only.

    twb upload examples/gym/go_to_goal.py
    twb submit --env room --start 0.3,0.3 --goal 0.6,1.5 --modes sim,twb --controller-program 1 --wait
"""

from __future__ import annotations

import json
import math
import os
import socket
import sys

CELLS, CELL_M = 16, 0.05  # the environment's default occupancy window: 16 x 16 cells of 0.05 m
V_MAX, W_MAX = 0.2, 3.0  # the BeBot's top speeds, m/s and rad/s
REACH_M, SLOW_M, STOP_M = 0.25, 0.2, 0.03  # repulsion range, approach slow-down, stop within this of the goal


class GoToGoal:
    """The policy: body velocities (v m/s, w rad/s) for an observation ``{"pose", "goal", "occupancy"}``.

    Memory of one kind: once blocked, it turns towards the freer side and then drives straight on for
    ``FOLLOW_M`` before it heads for the goal again (a bug algorithm's wall following, short; by distance,
    so it acts alike at any rate of observations); call :meth:`reset` at an episode's start."""

    FOLLOW_M = 0.25

    def __init__(self, cell: float = CELL_M) -> None:
        self.cell = cell
        self.reset()

    def reset(self) -> None:
        """Forget the obstacle being followed."""
        self.follow: tuple[float, float] | None = None  # where following began
        self.side = 1.0

    def __call__(self, obs) -> tuple[float, float]:
        return self.act(obs)

    def act(self, obs) -> tuple[float, float]:
        """Body velocities for ``obs``."""
        cell = self.cell
        x, y, th = (float(v) for v in obs["pose"])
        gx, gy = float(obs["goal"][0]), float(obs["goal"][1])
        occ = obs["occupancy"]
        k = len(occ)
        dist = math.hypot(gx - x, gy - y)
        if dist < STOP_M:
            return 0.0, 0.0
        c, s = math.cos(th), math.sin(th)
        hx, hy = (c * (gx - x) + s * (gy - y)) / dist, (-s * (gx - x) + c * (gy - y)) / dist  # goal, robot frame
        ahead, left, right = math.inf, 0, 0
        for a in range(k):
            fx = (a + 0.5 - k / 2) * cell
            for b in range(k):
                if not occ[a][b]:
                    continue
                fy = (b + 0.5 - k / 2) * cell
                d = max(math.hypot(fx, fy), 1e-3)
                if d < REACH_M:  # pushed sideways by what is near, more the nearer
                    hy -= 0.6 * (REACH_M - d) / REACH_M * fy / d
                    if fx > 0.0:
                        left, right = left + (fy > 0), right + (fy < 0)
                if fx > 0.0 and abs(fy) < 0.07:
                    ahead = min(ahead, fx)
        if ahead < min(0.15, dist):  # blocked: turn on the spot towards the freer side (the goal's on a tie)
            if self.follow is None:
                self.side = 1.0 if left < right or (left == right and hy >= 0) else -1.0
            self.follow = (x, y)
            return 0.0, self.side * 0.5 * W_MAX
        if self.follow is not None:  # then straight on along the obstacle for a while
            if math.hypot(x - self.follow[0], y - self.follow[1]) < self.FOLLOW_M:
                return 0.6 * V_MAX, 0.0
            self.follow = None
        err = math.atan2(hy, hx)
        w = max(-W_MAX, min(W_MAX, 2.5 * err))
        v = V_MAX * min(1.0, dist / SLOW_M) * max(math.cos(err), 0.0) * max(0.2, min(1.0, (ahead - 0.08) / 0.15))
        return v, w


def policy(obs, cell: float = CELL_M) -> tuple[float, float]:
    """Body velocities of a fresh :class:`GoToGoal` (no memory) for ``obs``."""
    return GoToGoal(cell).act(obs)


def occupancy(x: float, y: float, th: float, blocks: list, size: tuple[float, float], k: int = CELLS,
              cell: float = CELL_M) -> list[list[int]]:
    """The local window as the environment computes it, from exact geometry: cell ``[a][b]`` (``a`` along
    the heading, ``b`` to the left, from the back right corner) is 1 when its centre is off the field or a
    block or wall lies within ``cell / sqrt(2)`` of it.  ``blocks``: dicts ``x, y, w, h, angle`` (m, rad)."""
    near = cell * math.sqrt(0.5)
    c, s = math.cos(th), math.sin(th)
    rects = [(b["x"], b["y"], b["w"] / 2, b["h"] / 2, math.cos(b.get("angle", 0.0)), math.sin(b.get("angle", 0.0)))
             for b in blocks]
    out = []
    for a in range(k):
        fx = (a + 0.5 - k / 2) * cell
        row = []
        for b in range(k):
            fy = (b + 0.5 - k / 2) * cell
            px, py = x + c * fx - s * fy, y + s * fx + c * fy
            d = min(px, py, size[0] - px, size[1] - py)
            for cx, cy, hw, hh, bc, bs in rects:
                lx, ly = bc * (px - cx) + bs * (py - cy), -bs * (px - cx) + bc * (py - cy)
                d = min(d, math.hypot(max(abs(lx) - hw, 0.0), max(abs(ly) - hh, 0.0)))
            row.append(1 if d < near else 0)
        out.append(row)
    return out


def main() -> int:
    """The controller program: PO lines in, T,T,V lines out (docs/controllers.md)."""
    with open(os.environ["TWB_ENV_FILE"]) as f:
        env = json.load(f)
    size = (float(env["size"][0]), float(env["size"][1]))
    goal = [float(v) for v in os.environ["TWB_GOAL"].split(",")] + [0.0]
    sock = socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"])))
    robot = sock.makefile("rw", newline="\n")
    print("robot:", robot.readline().strip())  # HELLO,<robot_id>,<platform>,1
    robot.write("T,T,O,1\n")  # PO lines: the tracker's poses while the robot is in velocity mode
    robot.write("T,T,V,0,0\n")  # velocity mode (the testbed has begun it for a run; a standalone agent has not)
    robot.flush()
    drive = GoToGoal()
    for line in robot:
        line = line.strip()
        if line.startswith(("EV,FAIL", "ERR")):
            print("robot:", line)  # the run is over (stopped at the goal, or a T,T,V after its end: ERR,STATE)
            return 0 if line.startswith(("EV,FAIL,STOPPED", "ERR,STATE")) else 1
        if not line.startswith("PO,"):
            continue
        _, xs, ys, a, _t = line.split(",")
        x, y, th = float(xs) / 1000, float(ys) / 1000, math.radians(float(a))
        obs = {"pose": (x, y, th), "goal": goal[:3], "occupancy": occupancy(x, y, th, env.get("blocks", []), size)}
        v, w = drive(obs)
        robot.write(f"T,T,V,{v * 1000:.1f},{math.degrees(w):.1f}\n")  # mm/s, deg/s
        robot.flush()
    print("the robot port closed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
