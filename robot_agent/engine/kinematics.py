"""Pure kinematics of a differential-drive robot (compiled scalar functions).

A pose is x, y (m) and heading (rad); body velocities are forward speed v
(m/s) and turn rate w (rad/s); track (wheel) speeds are left and right (m/s).
The functions take and return floats; the simulation's kernels call them for
each robot, and they can be called from Python as they are.
"""

from __future__ import annotations

import math

from .compiled import kernel

__all__ = ["body_to_tracks", "tracks_to_body", "unicycle_step", "wrap_angle"]


@kernel
def wrap_angle(a: float) -> float:
    """Angle (rad) wrapped to [-pi, pi)."""
    if -math.pi <= a < math.pi:  # the common case, and exact
        return a
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@kernel
def unicycle_step(x: float, y: float, theta: float, v: float, w: float, dt: float) -> tuple[float, float, float]:
    """The pose after moving with body velocities ``(v, w)`` for ``dt`` seconds (midpoint rule).

    Second-order accurate: the chord of the arc is taken at the mean heading.
    """
    mid = theta + 0.5 * dt * w
    return x + v * dt * math.cos(mid), y + v * dt * math.sin(mid), wrap_angle(theta + w * dt)


@kernel
def body_to_tracks(v: float, w: float, wheel_base: float) -> tuple[float, float]:
    """Left and right track speeds (m/s) for body velocities ``(v, w)``; ``wheel_base`` in m."""
    half = 0.5 * wheel_base * w
    return v - half, v + half


@kernel
def tracks_to_body(left: float, right: float, wheel_base: float) -> tuple[float, float]:
    """Body velocities (v m/s, w rad/s) of left/right track speeds (m/s)."""
    return (left + right) / 2.0, (right - left) / wheel_base
