"""An uploaded Teleworkbench controller: a P-controller on the PO stream along the planned path's waypoints.

Inputs as for every uploaded program (docs/uploads.md), plus TWB_PATH_FILE: {"path": [[x, y, theta], ...]}
(m, m, rad). It subscribes to localisation (T,T,O,1), answers every PO line with body velocities (T,T,V:
mm/s, deg/s), moves on to the next waypoint within 5 cm of one, and stops (T,T,V,0,0) within 2 cm of the
last. Standard library only.
"""
import json
import math
import os
import socket
import sys

path = json.load(open(os.environ["TWB_PATH_FILE"]))["path"]
V_MAX, W_MAX = 150.0, 2.5  # mm/s, rad/s
K_V, K_W = 1500.0, 4.0  # (mm/s)/m, 1/s
SWITCH_M, STOP_M = 0.05, 0.02

sock = socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"])))
robot = sock.makefile("rw", newline="\n")
print("robot:", robot.readline().strip())  # HELLO,<robot_id>,<platform>,1
robot.write("T,T,O,1\n")
robot.flush()
k = 1  # the waypoint we head for
for line in robot:
    line = line.strip()
    if line.startswith(("EV,FAIL", "ERR")):
        print("robot:", line)  # the run is over (stopped at the goal, or a T,T,V after its end: ERR,STATE)
        sys.exit(0 if line.startswith(("EV,FAIL,STOPPED", "ERR,STATE")) else 1)
    if not line.startswith("PO,"):
        continue
    _, xs, ys, a, _t = line.split(",")
    x, y, th = float(xs) / 1000, float(ys) / 1000, math.radians(float(a))
    while k < len(path) - 1 and math.dist((x, y), path[k][:2]) < SWITCH_M:
        k += 1
    gx, gy = path[k][:2]
    d = math.hypot(gx - x, gy - y)
    if k == len(path) - 1 and d < STOP_M:
        robot.write("T,T,V,0,0\n")  # at the goal: stand (the testbed then ends the run)
        robot.flush()
        continue
    err = math.remainder(math.atan2(gy - y, gx - x) - th, math.tau)
    v = min(V_MAX, K_V * d) * max(math.cos(err), 0.0)
    w = max(-W_MAX, min(W_MAX, K_W * err))
    robot.write(f"T,T,V,{v:.1f},{math.degrees(w):.1f}\n")
    robot.flush()
print("the robot port closed")
