"""Typed robot parameters built from a profile (``contract/profiles/*.json``).

A profile is data; this module turns it into frozen dataclasses that the
pure controller and the simulation core take, checking that every value is
present, finite and positive where it must be.  All values are SI units
(metres, radians, seconds); the reasons for each value live in the profile's
``notes``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

from .robot_profile import DEFAULT_PROFILE, load_profile

__all__ = ["ControllerParams", "FieldParams", "GripperParams", "RobotParams", "robot_params"]


def _section(cls: type, data: Mapping[str, Any], where: str) -> Any:
    """Build dataclass ``cls`` from ``data``; ``ValueError`` naming a missing or bad key."""
    values = {}
    for f in fields(cls):
        if f.name not in data:
            if f.metadata.get("optional"):
                continue
            raise ValueError(f"profile {where}: missing `{f.name}`")
        v = data[f.name]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ValueError(f"profile {where}: `{f.name}` must be a finite number >= 0, got {v!r}")
        values[f.name] = type(f.default)(v) if f.default is not None else v
    return cls(**values)


@dataclass(frozen=True)
class ControllerParams:
    """Motor-schema path follower gains and limits (SI units; see the profile notes)."""

    control_rate_hz: int = 0
    heading_gain_1_s: float = 0.0
    switch_radius_m: float = 0.0
    goal_tolerance_m: float = 0.0
    angle_tolerance_rad: float = 0.0
    arrive_gain_1_s: float = 0.0
    min_speed_m_s: float = 0.0
    min_turn_rate_rad_s: float = 0.0
    turn_in_place_rad: float = 0.0
    accel_limit_m_s2: float = 0.0
    angular_accel_limit_rad_s2: float = 0.0
    stall_time_s: float = 0.0
    stall_distance_m: float = 0.0
    stall_angle_rad: float = 0.0
    timeout_base_s: float = 0.0
    timeout_factor: float = 0.0


@dataclass(frozen=True)
class FieldParams:
    """Emulated physical effects of the field backend: tracker and actuation (SI units)."""

    camera_rate_hz: int = 0
    tracker_latency_s: float = 0.0
    tracker_noise_xy_m: float = 0.0
    tracker_noise_theta_rad: float = 0.0
    tracker_bias_xy_m: float = 0.0
    tracker_bias_length_m: float = 0.0
    tracker_dropout_prob: float = 0.0
    latency_compensation_s: float = 0.0
    control_lead_s: float = 0.0
    motor_time_constant_s: float = 0.0
    wheel_noise_rel: float = 0.0
    wheel_noise_abs_m_s: float = 0.0
    wheel_noise_corr_s: float = 0.0
    wheel_gain_mean: float = 0.0
    wheel_bias_sigma: float = 0.0
    dead_band_m_s: float = 0.0
    #: skid steering (optional in a profile; 1: the tracks turn the robot as their kinematics say)
    track_width_factor: float = field(default=1.0, metadata={"optional": True})


@dataclass(frozen=True)
class GripperParams:
    """Durations (experiment seconds) of the testbed's emulated gripper."""

    seconds_per_block: float = 0.0
    seconds_per_placement: float = 0.0


@dataclass(frozen=True)
class RobotParams:
    """Everything the agent needs about one kind of robot."""

    name: str
    platform: str
    radius_m: float
    collision_radius_m: float
    wheel_base_m: float
    max_speed_m_s: float
    max_angular_speed_rad_s: float
    max_accel_m_s2: float
    controller: ControllerParams
    field: FieldParams
    gripper: GripperParams

    @property
    def dt(self) -> float:
        """Control (and simulation) step in seconds."""
        return 1.0 / self.controller.control_rate_hz

    @classmethod
    def from_profile(cls, profile: Mapping[str, Any]) -> "RobotParams":
        """Typed parameters of a profile dict (as :func:`load_profile` returns)."""
        name = str(profile.get("name", "?"))
        top = {}
        for key in ("radius_m", "collision_radius_m", "wheel_base_m", "max_speed_m_s",
                    "max_angular_speed_rad_s", "max_accel_m_s2"):
            v = profile.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"profile {name}: `{key}` must be a finite number > 0, got {v!r}")
            top[key] = float(v)
        ctrl = _section(ControllerParams, profile.get("controller", {}), f"{name}.controller")
        fld = _section(FieldParams, profile.get("field", {}), f"{name}.field")
        grip = _section(GripperParams, profile.get("gripper", {}), f"{name}.gripper")
        if ctrl.control_rate_hz < 1 or fld.camera_rate_hz < 1:
            raise ValueError(f"profile {name}: control and camera rates must be >= 1 Hz")
        if fld.tracker_dropout_prob >= 1:
            raise ValueError(f"profile {name}: `field.tracker_dropout_prob` must be < 1")
        if fld.track_width_factor < 1:
            raise ValueError(f"profile {name}: `field.track_width_factor` must be >= 1 (1: no skid), got "
                             f"{fld.track_width_factor!r}")
        if fld.tracker_bias_xy_m > 0 and fld.tracker_bias_length_m <= 0:
            raise ValueError(f"profile {name}: `field.tracker_bias_length_m` must be > 0 with a tracker bias")
        return cls(name=name, platform=str(profile.get("platform", name)), controller=ctrl, field=fld,
                   gripper=grip, **top)


def robot_params(profile: str | Mapping[str, Any] = DEFAULT_PROFILE) -> RobotParams:
    """:class:`RobotParams` of a shipped profile name or a profile dict."""
    return RobotParams.from_profile(load_profile(profile) if isinstance(profile, str) else profile)
