"""Backends: the physical side of a fleet of robots, behind one interface.

The simulation core (:mod:`robot_agent.sim`) runs the path follower for all
robots of a host and talks to the robots only through a :class:`Backend`:

- :meth:`Backend.begin_path` — a path starts for some robots (per-run draws);
- :meth:`Backend.sense` — where each robot *believes* it is (what its
  controller acts on) and the poses the overhead tracker logs this step;
- :meth:`Backend.actuate` — apply body velocity commands for one step;
- :meth:`Backend.halt` — stop robots at once (after a collision);
- :attr:`Backend.pose` — the robots' actual poses (the world checks
  collisions with them);
- :meth:`Backend.place` — the gripper put a robot somewhere;
- :meth:`Backend.in_motion` — robots that still move with zero commands;
- :attr:`Backend.belief` — each robot's latest believed pose.

All arrays are over the host's robots, in each robot's own frame (metres,
radians).  Two emulated backends ship: :class:`IdealBackend` (Player/Stage
like: perfect actuation, exact pose at the control rate) and
:class:`FieldBackend` (the emulated physical robot on the Teleworkbench field).

**A real robot plugs in here**: subclass :class:`Backend`, send the commands
of :meth:`actuate` to the robots (radio/Bluetooth), fill the beliefs and
logged poses of :meth:`sense` from the real overhead tracker, report
:attr:`pose` from the tracker too, and refuse :meth:`place` (no emulated
gripper) by raising ``NotImplementedError``.  No such driver ships.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from .kinematics import body_to_tracks, tracks_to_body, unicycle_step, wrap_angle
from .noise import box_muller, uniforms
from .params import RobotParams

__all__ = ["BACKENDS", "Backend", "FieldBackend", "IdealBackend", "make_backend"]

# Counters reserved for per-run draws (a path never runs 2**40 steps).
_RUN_COUNTER = 1 << 40


class Backend(ABC):
    """The physical side of ``n`` robots (see the module docstring)."""

    name: str = ""

    def __init__(self, n: int, params: RobotParams) -> None:
        self.n = n
        self.params = params
        self.dt = params.dt
        self.pose = np.zeros((n, 3))  #: actual poses (N, 3), each robot's frame
        self.belief = self.pose  #: believed poses (N, 3); backends with their own localisation replace it

    @abstractmethod
    def begin_path(self, mask: np.ndarray, keys: np.ndarray, from_rest: np.ndarray) -> None:
        """Paths start for robots in ``mask`` with noise ``keys`` (uint64); ``from_rest`` marks
        robots that were not following a path (their localisation restarts)."""

    @abstractmethod
    def sense(self, step: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Localise at the start of a control step.

        ``step`` ``(N,)`` counts control steps since each robot's path began;
        ``moving`` marks robots following a path.  Returns the beliefs
        ``(N, 3)``, the mask of robots whose pose the tracker logs now and
        those logged poses ``(N, 3)``.
        """

    @abstractmethod
    def actuate(self, cmd: np.ndarray) -> None:
        """Apply body velocity commands ``(N, 2)`` (v m/s, w rad/s) for one control step."""

    @abstractmethod
    def halt(self, mask: np.ndarray) -> None:
        """Stop robots in ``mask`` at once (collision): their tracks stop."""

    @abstractmethod
    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        """The gripper put robot ``i`` at ``pose`` (m, m, rad), at rest."""

    @abstractmethod
    def in_motion(self) -> np.ndarray:
        """Mask ``(N,)`` of robots that still move although commanded to stand still."""

    def busy(self) -> bool:
        """True while some robot still moves although commanded to stand still."""
        return bool(self.in_motion().any())


class IdealBackend(Backend):
    """Player/Stage-like: commands are executed exactly; the belief is the true pose."""

    name = "ideal"

    def begin_path(self, mask: np.ndarray, keys: np.ndarray, from_rest: np.ndarray) -> None:
        pass

    def sense(self, step: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.pose, moving, self.pose

    def actuate(self, cmd: np.ndarray) -> None:
        unicycle_step(self.pose, cmd, self.dt, out=self.pose)

    def halt(self, mask: np.ndarray) -> None:
        pass

    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        self.pose[i] = pose

    def in_motion(self) -> np.ndarray:
        return np.zeros(self.n, dtype=bool)

    def busy(self) -> bool:
        return False


class FieldBackend(Backend):
    """The emulated physical robot on the field.

    Localisation: the overhead tracker measures each robot at
    ``camera_rate_hz`` (frames timed from the path start, on the control
    grid), with Gaussian noise, dropped frames and ``tracker_latency_s``
    delay (rounded to control steps); between frames the belief is held.
    Actuation: body commands become track speeds, scaled by a per-run gain
    per track (bias), perturbed by speed noise, zeroed below the dead band,
    then the tracks follow with a first-order lag (``motor_time_constant_s``)
    and at most ``max_accel_m_s2``.  All noise comes from
    :mod:`robot_agent.noise` keyed per run, so runs replay exactly.
    """

    name = "field"

    def __init__(self, n: int, params: RobotParams) -> None:
        super().__init__(n, params)
        f = params.field
        self.delay = int(round(f.tracker_latency_s / self.dt))  # control steps
        self.belief = np.zeros((n, 3))
        self.tracks = np.zeros((n, 2))  # actual left/right track speeds, m/s
        self.gain = np.ones((n, 2))  # per-run track gains
        self.keys = np.zeros(n, dtype=np.uint64)
        self.ring = np.zeros((n, self.delay + 1, 3))  # measurements in flight
        self.ring_ok = np.zeros((n, self.delay + 1), dtype=bool)
        self.ring_pos = np.zeros(n, dtype=np.int64)
        self._rows = np.arange(n)
        self._noise = np.zeros((n, 6))
        self._sigma = np.array([f.tracker_noise_xy_m, f.tracker_noise_xy_m, f.tracker_noise_theta_rad])
        self._alpha = 1.0 - np.exp(-self.dt / f.motor_time_constant_s) if f.motor_time_constant_s > 0 else 1.0

    def _measure(self, normal3: np.ndarray) -> np.ndarray:
        m = self.pose + normal3 * self._sigma
        m[:, 2] = wrap_angle(m[:, 2])
        return m

    def begin_path(self, mask: np.ndarray, keys: np.ndarray, from_rest: np.ndarray) -> None:
        idx = np.flatnonzero(mask)
        self.keys[idx] = keys[idx]
        z = box_muller(uniforms(self.keys[idx], np.full(len(idx), _RUN_COUNTER), 6))
        self.gain[idx] = self.params.field.wheel_gain_mean + self.params.field.wheel_bias_sigma * z[:, :2]
        rest = idx[from_rest[idx]]
        if len(rest):  # the tracker has been watching the robot at rest: a fresh measurement
            m = self.pose[rest] + z[from_rest[idx], 2:5] * self._sigma
            m[:, 2] = wrap_angle(m[:, 2])
            self.belief[rest] = m
            self.ring_ok[rest] = False

    def sense(self, step: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f = self.params.field
        rate, cam = self.params.controller.control_rate_hz, f.camera_rate_hz
        u = uniforms(self.keys, step, 8)
        z = box_muller(u[:, :6])
        self._noise = z
        frame = (step * cam) // rate != ((step - 1) * cam) // rate
        ok = frame & (u[:, 6] >= f.tracker_dropout_prob)
        meas = self._measure(z[:, :3])
        slot = self.ring_pos % (self.delay + 1)
        self.ring[self._rows, slot] = meas
        self.ring_ok[self._rows, slot] = ok
        ready = (self.ring_pos + 1) % (self.delay + 1)
        arrived = self.ring_ok[self._rows, ready]
        self.belief[arrived] = self.ring[self._rows[arrived], ready[arrived]]
        self.ring_pos += 1
        return self.belief, ok & moving, meas

    def actuate(self, cmd: np.ndarray) -> None:
        f = self.params.field
        want = body_to_tracks(cmd, self.params.wheel_base_m)
        noise = (f.wheel_noise_rel * np.abs(want) + f.wheel_noise_abs_m_s) * self._noise[:, 3:5]
        target = np.where(np.abs(want) < f.dead_band_m_s, 0.0, want * self.gain + noise)
        limit = self.params.max_accel_m_s2 * self.dt
        self.tracks += np.clip((target - self.tracks) * self._alpha, -limit, limit)
        self.tracks[np.abs(self.tracks) < 1e-5] = 0.0
        unicycle_step(self.pose, tracks_to_body(self.tracks, self.params.wheel_base_m), self.dt, out=self.pose)

    def halt(self, mask: np.ndarray) -> None:
        self.tracks[mask] = 0.0

    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        self.pose[i] = pose
        self.belief[i] = pose
        self.tracks[i] = 0.0
        self.ring_ok[i] = False

    def in_motion(self) -> np.ndarray:
        return self.tracks.any(axis=1)

    def busy(self) -> bool:
        return bool(self.tracks.any())


BACKENDS: dict[str, type[Backend]] = {"ideal": IdealBackend, "field": FieldBackend}


def make_backend(name: str, n: int, params: RobotParams) -> Backend:
    """An emulated backend by name (``ideal`` or ``field``) for ``n`` robots."""
    try:
        return BACKENDS[name](n, params)
    except KeyError:
        raise ValueError(f"unknown backend {name!r} (backends: {', '.join(BACKENDS)})") from None
