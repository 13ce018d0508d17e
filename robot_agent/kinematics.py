"""Pure kinematics of differential-drive robots, vectorised over robots.

Poses are ``(N, 3)`` arrays of x, y (m) and heading (rad); body velocities
``(N, 2)`` of forward speed v (m/s) and turn rate w (rad/s); track (wheel)
speeds ``(N, 2)`` of left and right (m/s).
"""

from __future__ import annotations

import numpy as np

__all__ = ["body_to_tracks", "tracks_to_body", "unicycle_step", "wrap_angle"]


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped to [-pi, pi)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def unicycle_step(pose: np.ndarray, vw: np.ndarray, dt: float, out: np.ndarray | None = None) -> np.ndarray:
    """Advance ``pose`` by body velocities ``vw`` for ``dt`` seconds (midpoint rule).

    Second-order accurate: the chord of each arc is taken at the mean heading.
    Writes into ``out`` when given (may be ``pose`` itself) and returns it.
    """
    v, w = vw[:, 0], vw[:, 1]
    mid = pose[:, 2] + 0.5 * dt * w
    if out is None:
        out = np.empty_like(pose)
    out[:, 0] = pose[:, 0] + v * dt * np.cos(mid)
    out[:, 1] = pose[:, 1] + v * dt * np.sin(mid)
    out[:, 2] = wrap_angle(pose[:, 2] + w * dt)
    return out


def body_to_tracks(vw: np.ndarray, wheel_base: float) -> np.ndarray:
    """Left and right track speeds (m/s) for body velocities ``vw``; ``wheel_base`` in m."""
    half = 0.5 * wheel_base * vw[:, 1]
    return np.stack([vw[:, 0] - half, vw[:, 0] + half], axis=1)


def tracks_to_body(tracks: np.ndarray, wheel_base: float) -> np.ndarray:
    """Body velocities (v m/s, w rad/s) of left/right track speeds (m/s)."""
    return np.stack([tracks.mean(axis=1), (tracks[:, 1] - tracks[:, 0]) / wheel_base], axis=1)
