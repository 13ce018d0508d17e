"""Backends: the physical side of a fleet of robots, behind one interface.

The simulation core (:mod:`robot_agent.engine.sim`) runs the path follower for all
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
Their per-robot physics is compiled (:mod:`robot_agent.engine.physics`); they are
also :class:`Emulated`: the simulation core runs them many steps at a time
inside compiled code (:mod:`robot_agent.engine.stepper`), which only works for
backends whose whole physics is such code.  Any other backend is stepped
through the methods below, one step at a time.

**A real robot plugs in here**: subclass :class:`Backend`, send the commands
of :meth:`actuate` to the robots (radio/Bluetooth), fill the beliefs and
logged poses of :meth:`sense` from the real overhead tracker (the field
backend's latency compensation, :func:`robot_agent.engine.physics.localise` with
:func:`robot_agent.engine.physics.odometry`, works on late fixes from any tracker),
report :attr:`pose` from the tracker too, and refuse :meth:`place` (no emulated
gripper) by raising ``NotImplementedError``.  No such driver ships.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from contract.params import RobotParams

from .compiled import kernel
from .physics import (
    BIAS_FEATURES,
    FIELD,
    IDEAL,
    FieldGains,
    field_actuate,
    field_begin,
    field_gains,
    field_sense,
    ideal_actuate,
)

__all__ = ["BACKENDS", "Backend", "Emulated", "FieldBackend", "IdealBackend", "make_backend"]

_U64 = (1 << 64) - 1


def _bias_at(features: np.ndarray, x: float, y: float, bias_xy: float) -> tuple[float, float]:
    """:func:`~.physics.tracker_bias` in numpy (m at ``(x, y)`` m; ``features`` one robot's ``(2F, 3)``): the
    same smooth field, without compiling a kernel for a call from Python."""
    if bias_xy == 0.0:
        return 0.0, 0.0
    f = features.shape[0] // 2
    c = np.cos(features[:, 0] * x + features[:, 1] * y + features[:, 2])
    scale = bias_xy * math.sqrt(2.0 / f)
    return scale * float(c[:f].sum()), scale * float(c[f:].sum())


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
        ``moving`` marks robots following a path.  Returns the poses the
        controller acts on ``(N, 3)`` (the beliefs, or a prediction from
        them), the mask of robots whose pose the tracker logs now and those
        logged poses ``(N, 3)``.
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

    #: tracker latency in control steps (a measurement taken at step s arrives at step s + latency_steps)
    latency_steps: int = 0

    def frame(self, step: int) -> bool:
        """Whether the tracker takes a frame at global control step ``step`` (every step unless a backend
        has a slower camera)."""
        return True

    def measure(self, i: int, step: int, key: int) -> tuple[bool, np.ndarray]:
        """The tracker's measurement of robot ``i`` outside a path (standing, or coasting after one) at
        global control step ``step``: (whether it saw the robot, the pose ``(3,)`` m/rad); ``key`` the
        robot's noise key for such frames.  The backend's exact pose unless a backend measures with noise."""
        return True, self.pose[i].copy()


class Emulated(Backend):
    """A backend the compiled simulation loop can run: its state is plain arrays.

    ``kind`` selects the physics in :func:`robot_agent.engine.stepper.run`
    (``physics.IDEAL`` or ``physics.FIELD``); :attr:`arrays` hands over the
    state, in place.
    """

    kind: int = IDEAL

    def __init__(self, n: int, params: RobotParams) -> None:
        super().__init__(n, params)
        self.fg: FieldGains = field_gains(params)
        self.tracks = np.zeros((n, 2))  # actual left/right track speeds, m/s
        self.gain = np.ones((n, 2))  # per-run track gains
        self.keys = np.zeros(n, dtype=np.uint64)
        self.ring = np.zeros((n, self.fg.delay + 1, 3))  # tracker measurements in flight
        self.ring_ok = np.zeros((n, self.fg.delay + 1), dtype=bool)
        self.ring_pos = np.zeros(n, dtype=np.int64)
        self.noise = np.zeros((n, 2))  # this step's track noise (standard normals)
        self.odo = np.zeros((n, 2))  # the localisation's model of the track speeds, m/s
        self.odo_ring = np.zeros((n, self.fg.predict + 1, 2))  # ... of the last steps (latency compensation)
        self.bias = np.zeros((n, 2 * BIAS_FEATURES, 3))  # the tracker's bias field of each robot's run
        self.ctl = self.belief  #: the poses the controller acts on (the field robot predicts them ahead)

    @property
    def arrays(self) -> tuple:
        """``(pose, belief, ctl, tracks, gain, keys, ring, ring_ok, ring_pos, noise, odo, odo_ring, bias)``,
        the arrays themselves."""
        return (self.pose, self.belief, self.ctl, self.tracks, self.gain, self.keys, self.ring, self.ring_ok,
                self.ring_pos, self.noise, self.odo, self.odo_ring, self.bias)


@kernel
def _ideal_actuate_all(cmd: np.ndarray, pose: np.ndarray, dt: float) -> None:
    for i in range(len(pose)):
        ideal_actuate(i, cmd[i, 0], cmd[i, 1], pose, dt)


class IdealBackend(Emulated):
    """Player/Stage-like: commands are executed exactly; the belief is the true pose."""

    name = "ideal"
    kind = IDEAL

    def begin_path(self, mask: np.ndarray, keys: np.ndarray, from_rest: np.ndarray) -> None:
        pass

    def sense(self, step: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.pose, moving, self.pose

    def actuate(self, cmd: np.ndarray) -> None:
        _ideal_actuate_all(np.ascontiguousarray(cmd, dtype=float), self.pose, self.dt)

    def halt(self, mask: np.ndarray) -> None:
        pass

    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        self.pose[i] = pose

    def in_motion(self) -> np.ndarray:
        return np.zeros(self.n, dtype=bool)

    def busy(self) -> bool:
        return False


@kernel
def _field_sense_all(step: np.ndarray, keys: np.ndarray, pose: np.ndarray, belief: np.ndarray, ctl: np.ndarray,
                     ring: np.ndarray, ring_ok: np.ndarray, ring_pos: np.ndarray, noise: np.ndarray, odo: np.ndarray,
                     odo_ring: np.ndarray, bias: np.ndarray, fg: FieldGains) -> tuple[np.ndarray, np.ndarray]:
    seen = np.zeros(len(pose), dtype=np.bool_)
    meas = np.empty((len(pose), 3))
    for i in range(len(pose)):
        seen[i] = field_sense(i, step[i], keys[i], pose, belief, ctl, ring, ring_ok, ring_pos, noise, meas[i], odo,
                              odo_ring, bias, fg)
    return seen, meas


@kernel
def _field_actuate_all(cmd: np.ndarray, pose: np.ndarray, tracks: np.ndarray, gain: np.ndarray,
                       noise: np.ndarray, ring_pos: np.ndarray, odo: np.ndarray, odo_ring: np.ndarray,
                       fg: FieldGains) -> None:
    for i in range(len(pose)):
        field_actuate(i, cmd[i, 0], cmd[i, 1], pose, tracks, gain, noise, ring_pos, odo, odo_ring, fg)


class FieldBackend(Emulated):
    """The emulated physical robot on the field (see :mod:`robot_agent.engine.physics`).

    Tracker: each robot is measured at ``camera_rate_hz`` (frames timed from
    the path start, on the control grid) with a smooth position error over
    the field (``tracker_bias_xy_m``), per-frame jitter, dropped frames and
    ``tracker_latency_s`` delay (rounded to control steps).  Localisation: a
    fix that arrives is moved forward over ``latency_compensation_s`` with
    the robot's odometry (its commands through its model of the tracks) and
    the belief is dead-reckoned between fixes; the controller steers by the
    pose predicted ``control_lead_s`` ahead (:attr:`ctl`, what :meth:`sense`
    returns).  Actuation: body commands become track speeds, scaled by a
    per-run gain per track (bias), perturbed by speed noise, zeroed below the
    dead band, then the tracks follow with a first-order lag
    (``motor_time_constant_s``) and at most ``max_accel_m_s2``.
    """

    name = "field"
    kind = FIELD

    def __init__(self, n: int, params: RobotParams) -> None:
        super().__init__(n, params)
        self.belief = np.zeros((n, 3))
        self.ctl = np.zeros((n, 3))

    def begin_path(self, mask: np.ndarray, keys: np.ndarray, from_rest: np.ndarray) -> None:
        for i in np.flatnonzero(mask):
            self.keys[i] = keys[i]
            field_begin(int(i), self.keys[i], bool(from_rest[i]), self.pose, self.belief, self.ctl, self.gain,
                        self.ring_ok, self.odo, self.odo_ring, self.bias, self.noise, self.fg)

    def sense(self, step: np.ndarray, moving: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        seen, meas = _field_sense_all(np.asarray(step, dtype=np.int64), self.keys, self.pose, self.belief, self.ctl,
                                      self.ring, self.ring_ok, self.ring_pos, self.noise, self.odo, self.odo_ring,
                                      self.bias, self.fg)
        return self.ctl, seen & moving, meas

    def actuate(self, cmd: np.ndarray) -> None:
        _field_actuate_all(np.ascontiguousarray(cmd, dtype=float), self.pose, self.tracks, self.gain,
                           self.noise, self.ring_pos, self.odo, self.odo_ring, self.fg)

    def halt(self, mask: np.ndarray) -> None:
        self.tracks[mask] = 0.0

    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        self.pose[i] = pose
        self.belief[i] = pose
        self.ctl[i] = pose
        self.tracks[i] = 0.0
        self.ring_ok[i] = False
        self.odo[i] = 0.0
        self.odo_ring[i] = 0.0

    def in_motion(self) -> np.ndarray:
        return self.tracks.any(axis=1)

    def busy(self) -> bool:
        return bool(self.tracks.any())

    @property
    def latency_steps(self) -> int:  # type: ignore[override]
        return int(self.fg.delay)

    def frame(self, step: int) -> bool:
        fg = self.fg
        return (step * fg.camera_rate) // fg.control_rate != ((step - 1) * fg.camera_rate) // fg.control_rate

    def measure(self, i: int, step: int, key: int) -> tuple[bool, np.ndarray]:
        """As the tracker measures a robot during a path (:func:`~.physics.field_sense`): the pose plus the
        bias field of the robot's last run and per-frame jitter, on the camera's frames, with dropouts;
        the noise is drawn from ``key`` and the global step (a Philox stream of its own, apart from the paths';
        plain numpy, so that no kernel is compiled for a call from Python)."""
        fg = self.fg
        rng = np.random.Generator(np.random.Philox(key=np.array([key & _U64, step & _U64], dtype=np.uint64)))
        z0, z1, z2 = rng.standard_normal(3)
        seen = rng.random() >= fg.dropout
        bx, by = _bias_at(self.bias[i], float(self.pose[i, 0]), float(self.pose[i, 1]), fg.bias_xy)
        meas = np.array([self.pose[i, 0] + bx + z0 * fg.sigma_xy, self.pose[i, 1] + by + z1 * fg.sigma_xy,
                         math.remainder(self.pose[i, 2] + z2 * fg.sigma_theta, math.tau)])
        return self.frame(step) and bool(seen), meas


BACKENDS: dict[str, type[Backend]] = {"ideal": IdealBackend, "field": FieldBackend}


def make_backend(name: str, n: int, params: RobotParams) -> Backend:
    """An emulated backend by name (``ideal`` or ``field``) for ``n`` robots."""
    try:
        return BACKENDS[name](n, params)
    except KeyError:
        raise ValueError(f"unknown backend {name!r} (backends: {', '.join(BACKENDS)})") from None
