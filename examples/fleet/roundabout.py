"""An uploaded Teleworkbench fleet planner: every robot's path, one T,T,P per robot port (docs/uploads.md).

A roundabout: a robot whose straight line to its goal passes near the field's centre drives to a circle
around the centre, goes round it counter-clockwise to the point nearest its goal and leaves there; the
others go straight.  Robots that enter together keep their spacing on the circle, so four robots swapping
the corners of the `swap` sub-field pass each other.  Standard library only; blocks are not looked at
(an empty field such as `swap`).
"""
import math
import os
import socket

RING_M = 0.35  # the roundabout's radius, m

W, H = (float(v) for v in os.environ["TWB_FIELD_SIZE"].split(","))
CX, CY = W / 2, H / 2
starts = [[float(v) for v in p.split(",")] for p in os.environ["TWB_STARTS"].split(";")]
goals = [[float(v) for v in p.split(",")] for p in os.environ["TWB_GOALS"].split(";")]  # [x, y] or [x, y, theta]
ports = [int(p) for p in os.environ["TWB_ROBOT_PORTS"].split(",")]
keep = float(os.environ["TWB_ROBOT_RADIUS"]) + float(os.environ["TWB_PLANNING_MARGIN"])


def near_centre(a, b):
    """The segment a-b passes closer to the centre than the ring plus the clearance."""
    (ax, ay), (bx, by) = a[:2], b[:2]
    dx, dy = bx - ax, by - ay
    t = max(0.0, min(1.0, ((CX - ax) * dx + (CY - ay) * dy) / (dx * dx + dy * dy or 1.0)))
    return math.hypot(ax + t * dx - CX, ay + t * dy - CY) < RING_M + 2 * keep


def on_ring(angle):
    return [CX + RING_M * math.cos(angle), CY + RING_M * math.sin(angle)]


def plan(start, goal):
    """Points from the start to the goal (m): straight, or round the ring counter-clockwise."""
    if not near_centre(start, goal):
        return [start[:2], goal[:2]]
    enter = math.atan2(start[1] - CY, start[0] - CX)
    turn = (math.atan2(goal[1] - CY, goal[0] - CX) - enter) % (2 * math.pi)
    steps = max(1, int(turn / math.radians(10)))
    return [start[:2]] + [on_ring(enter + turn * k / steps) for k in range(steps + 1)] + [goal[:2]]


def line(points, goal):
    """The T,T,P line (mm, mm, degrees): each point faces the next, the last takes the goal's heading."""
    heading = [math.atan2(q[1] - p[1], q[0] - p[0]) for p, q in zip(points, points[1:])]
    heading.append(goal[2] if len(goal) > 2 else heading[-1])
    return "T,T,P," + ";".join(f"{x * 1000:.0f},{y * 1000:.0f},{math.degrees(a):.1f}"
                               for (x, y), a in zip(points, heading))


for k, (start, goal, port) in enumerate(zip(starts, goals, ports)):
    points = plan(start, goal)
    with socket.create_connection((os.environ["TWB_ROBOT_HOST"], port)) as sock:
        robot = sock.makefile("rw", newline="\n")
        hello = robot.readline().strip()  # HELLO,<robot_id>/<k>,<platform>,1
        robot.write(line(points, goal) + "\n")
        robot.flush()
        print(f"robot {k}: {hello} -> {len(points)} points -> {robot.readline().strip()}")  # OK,P,<n>
