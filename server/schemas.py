"""Request and response bodies of the REST API (docs/design.md, "REST API"), kept apart from the tables.

SI units throughout: metres, radians, seconds.  NaN and infinity are refused
everywhere (``allow_inf_nan=False``).  Public models are built from table rows
(``from_attributes``): ``RunPublic.model_validate(run)``.
"""

from __future__ import annotations

import ipaddress
import re
from datetime import datetime, timezone
from typing import Annotated, Any, Generic, Literal, Optional, TypeVar, Union

from pydantic import AfterValidator, AliasChoices, BaseModel, ConfigDict, Field, field_validator, model_validator

from contract.frames import FIELD_SIZE
from contract.frames import MAX_ROBOTS  # robots a multi-robot job may have (docs/server.md, "Multi-robot jobs")
from planners.moving import (MAX_DELAY_S, MAX_MOVING_OBSTACLES, MAX_OBSTACLE_RADIUS_M, MAX_OBSTACLE_SPEED_M_S,
                             MAX_WAYPOINTS, REPEAT_MODES)

from .status import RunStatus

__all__ = [
    "ComparisonRow",
    "ComparisonsPublic",
    "ComputePublic",
    "ControllerPublic",
    "DirectComparisonPublic",
    "EnvironmentCreate",
    "EnvironmentPublic",
    "ExperimentCreate",
    "ExperimentMetricsPublic",
    "ExperimentPublic",
    "ExperimentSummary",
    "HealthPublic",
    "LoadErrorPublic",
    "MessagePublic",
    "MetricSummaryPublic",
    "ModeAggregatePublic",
    "ModeOutcomesPublic",
    "ObstacleTrackPublic",
    "Page",
    "ParamPublic",
    "PlanPublic",
    "PlannerPublic",
    "PluginPage",
    "ProgramCreate",
    "ProgramPublic",
    "ProportionPublic",
    "RobotIn",
    "RobotPublic",
    "RobotRegister",
    "RunMetricsPublic",
    "RunObstaclesPublic",
    "RunPosesPublic",
    "RunPublic",
    "SandboxIsolationPublic",
    "SandboxLimitsPublic",
    "SandboxPublic",
    "SubfieldPublic",
    "TrackerBatch",
    "TrackerBatchResult",
    "UserCreate",
    "UserPublic",
    "UserWithToken",
]

T = TypeVar("T")


def _utc(v: datetime) -> datetime:
    return v.replace(tzinfo=timezone.utc) if v.tzinfo is None else v


#: wall-clock times are UTC; SQLite hands them back without a zone
UTCDateTime = Annotated[datetime, AfterValidator(_utc)]

Mode = Literal["sim", "twb"]
#: the owner's name, from a row's ``owner_name`` (or a plain ``owner`` key)
_OWNER = AliasChoices("owner_name", "owner")


class Strict(BaseModel):
    """Request bodies: unknown keys refused, no coercion (``false`` is not 0, ``1.0`` is not an integer)."""

    model_config = ConfigDict(allow_inf_nan=False, extra="forbid", strict=True)


class Public(BaseModel):
    """Response bodies: every field is always sent, so the OpenAPI document lists each one as required
    (a body that leaves out unset fields, ``response_model_exclude_unset``, is a plain ``BaseModel``)."""

    model_config = ConfigDict(json_schema_serialization_defaults_required=True)


class FromRow(Public):
    """A response body built from a table row (``model_validate(row)``)."""

    model_config = ConfigDict(from_attributes=True)


class Page(BaseModel, Generic[T]):
    """A page of a list: ``data`` and the total ``count`` of matching items."""

    data: list[T]
    count: int


# --------------------------------------------------------------------------- users


#: names of users and environments: letters, digits, ``_ . -``, starting with a letter or digit
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"


class UserCreate(Strict):
    name: str = Field(min_length=1, max_length=64, pattern=NAME_PATTERN)
    is_admin: bool = False


class UserPublic(FromRow):
    id: int
    name: str
    is_admin: bool
    created_at: UTCDateTime


class UserWithToken(UserPublic):
    token: str = Field(description="Bearer token; shown once, stored only as a hash.")


# --------------------------------------------------------------------------- environments


class BlockIn(Strict):
    """A rectangular block: centre ``x``, ``y``, size ``w``, ``h`` (m), rotation ``angle`` (rad)."""

    x: float
    y: float
    w: float = Field(gt=0)
    h: float = Field(gt=0)
    angle: float = 0.0


class PlanIn(Strict):
    """A named start/goal pair, poses ``[x, y]`` or ``[x, y, theta]`` (m, rad)."""

    name: str = Field(min_length=1, max_length=64)
    start: list[float] = Field(min_length=2, max_length=3)
    goal: list[float] = Field(min_length=2, max_length=3)


_XY = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}
#: what the planners' model checks of a moving obstacle (planners/moving.py), as far as a schema can say it
#: (its points must also lie inside the environment's `size`)
MOVING_OBSTACLE_SCHEMA: dict[str, Any] = {
    "type": "object", "additionalProperties": False, "required": ["radius", "speed"],
    "properties": {
        "radius": {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_OBSTACLE_RADIUS_M, "description": "m"},
        "speed": {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_OBSTACLE_SPEED_M_S, "description": "m/s"},
        "repeat": {"enum": list(REPEAT_MODES), "default": "once"},
        "delay_s": {"type": "number", "minimum": 0, "maximum": MAX_DELAY_S, "default": 0},
        "waypoints": {"type": "array", "items": _XY, "minItems": 1, "maxItems": MAX_WAYPOINTS,
                      "description": "[x, y] points, m, inside the environment"},
        "random_walk": {
            "type": "object", "additionalProperties": False, "required": ["seed", "start", "steps", "step_m"],
            "properties": {"seed": {"type": "integer", "minimum": 0, "exclusiveMaximum": 2**63},
                           "start": _XY,
                           "steps": {"type": "integer", "minimum": 1, "maximum": MAX_WAYPOINTS - 1},
                           "step_m": {"type": "number", "exclusiveMinimum": 0,
                                      "description": "m, at most the environment's larger side"}}},
    },
    "oneOf": [{"required": ["waypoints"]}, {"required": ["random_walk"]}],
}


class EnvironmentCreate(Strict):
    """An environment file (docs/design.md, "Environment file"); then checked by the planners' model
    (blocks inside the field, and the like)."""

    name: str = Field(min_length=1, max_length=100, pattern=NAME_PATTERN)
    # at most the whole field (documented; the route says so in its own words for anything up to 100 m)
    size: list[Annotated[float, Field(gt=0, le=100, json_schema_extra={"maximum": FIELD_SIZE[0]})]] = Field(
        min_length=2, max_length=2, description="[width, height], m: at most the whole field.")
    blocks: list[BlockIn] = Field(default_factory=list, max_length=1000)
    plans: list[PlanIn] = Field(default_factory=list, max_length=100)
    description: str = Field(default="", max_length=10_000)
    moving_obstacles: list[dict[str, Any]] = Field(
        default_factory=list, max_length=MAX_MOVING_OBSTACLES, json_schema_extra={"items": MOVING_OBSTACLE_SCHEMA},
        description="Discs moving in experiment time: radius (m), waypoints or random_walk, speed (m/s), repeat, "
                    "delay_s (s); see docs/planners.md.")

    def to_data(self) -> dict[str, Any]:
        return self.model_dump()


class PlanPublic(Public):
    """A named start/goal pair of an environment, poses ``[x, y, theta]`` (m, rad)."""

    name: str
    start: list[float]
    goal: list[float]


class EnvironmentPublic(Public):
    """An environment: its file (docs/design.md, "Environment file") and who owns it."""

    name: str
    size: list[float] = Field(description="[width, height], m.")
    blocks: list[dict[str, float]] = Field(description="Rectangular blocks: centre x, y, size w, h (m), angle (rad).")
    plans: list[PlanPublic] = []
    description: str = ""
    moving_obstacles: list[dict[str, Any]] = []
    moving_tracks: list[dict[str, Any]] = Field(default_factory=list, description=(
        "Derived, for drawing: each moving obstacle as it moves — radius (m), speed (m/s), repeat, delay_s (s) "
        "and its waypoints (m), a random walk's expanded with its seed."))
    builtin: bool
    owner: Optional[str] = None


# --------------------------------------------------------------------------- experiments

#: ``[x, y]`` or ``[x, y, theta]`` (m, rad); the length is checked by the models' validators (for their
#: message), the schema says it too
Pose = Annotated[list[float], Field(json_schema_extra={"minItems": 2, "maxItems": 3})]
#: an explicit path: at least two poses
PATH_SCHEMA = {"minItems": 2}


class Jitter(Strict):
    """Standard deviations of a run's start pose around the job's start: ``xy_m`` per axis (m), ``theta_rad``."""

    xy_m: float = Field(default=0.0, ge=0, le=0.05)
    theta_rad: float = Field(default=0.0, ge=0, le=0.5)


#: the planner that plans a multi-robot job's robots together (timed paths, robots hold where it waits)
FLEET_PLANNER = "prioritized"
#: every planner that plans a multi-robot job's robots together (and only such jobs): prioritized planning and
#: LaCAM* on a grid (planners.lacam)
FLEET_PLANNERS = (FLEET_PLANNER, "lacam")


def _check_pose(v: Optional[Pose]) -> Optional[Pose]:
    if v is not None and len(v) not in (2, 3):
        raise ValueError("must be [x, y] or [x, y, theta]")
    return v


def _check_path(v: Optional[list[Pose]]) -> Optional[list[Pose]]:
    if v is None:
        return v
    if len(v) < 2:
        raise ValueError("needs at least 2 points")
    for i, p in enumerate(v):
        if len(p) not in (2, 3):
            raise ValueError(f"point {i} must be [x, y] or [x, y, theta]")
    return v


class RobotIn(Strict):
    """One robot of a multi-robot job: its ``start`` and ``goal`` (``[x, y]`` or ``[x, y, theta]``, m, rad)
    and, instead of being planned, an explicit ``path`` (points from the start to the goal, m, rad)."""

    model_config = ConfigDict(allow_inf_nan=False, extra="forbid", strict=True)

    start: Pose
    goal: Pose
    path: Optional[list[Pose]] = Field(default=None, max_length=10_000, json_schema_extra=PATH_SCHEMA)

    _pose = field_validator("start", "goal")(_check_pose)
    _path = field_validator("path")(_check_path)


class ExperimentCreate(Strict):
    """A job: plan with ``planner`` (or send the explicit ``path``, or run the uploaded ``program``), run it in ``modes``.

    Poses are ``[x, y]`` or ``[x, y, theta]`` (m, rad) in the frame of the
    sub-field (``field: "sub"``) or of the whole 3.6 m field (``"full"``).
    A multi-robot job gives ``robots`` instead of ``start``/``goal``
    (docs/server.md, "Multi-robot jobs").
    """

    model_config = ConfigDict(
        allow_inf_nan=False,
        extra="forbid",
        json_schema_extra={
            "examples": [
                {
                    "environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708],
                    "planner": "fm2", "planner_params": {}, "modes": ["sim", "twb"],
                    "repetitions": 2, "seed": 0, "field": "sub",
                }
            ]
        },
    )

    environment: str = Field(min_length=1, max_length=100)
    start: Optional[Pose] = None
    goal: Optional[Pose] = None
    robots: Optional[list[RobotIn]] = Field(default=None, min_length=2, max_length=MAX_ROBOTS, description=(
        "A multi-robot job instead of `start`/`goal`: 2 to 16 robots on a sub-field, to 64 on the whole field "
        "(`field: \"full\"`), in one world on one clock, each "
        "{\"start\", \"goal\", \"path\"?} (m, rad). Planners `prioritized` and `lacam` plan them together; any other "
        "planner plans each robot alone (uncoordinated); a robot's `path` is driven as given; an uploaded "
        "`program` sends every robot's path, one T,T,P per robot port (docs/uploads.md)."))
    planner: Optional[str] = Field(default=None, max_length=64)
    planner_params: dict[str, Any] = Field(default_factory=dict)
    path: Optional[list[Pose]] = Field(default=None, max_length=10_000, json_schema_extra=PATH_SCHEMA)
    program: Optional[int] = Field(default=None, ge=1, description="An uploaded program's id (docs/uploads.md).")
    modes: list[Mode] = Field(default_factory=lambda: ["sim", "twb"], min_length=1, max_length=2)
    repetitions: int = Field(default=1, ge=1)
    seed: int = Field(default=0, ge=0, lt=2**63, description=(
        "The seed every run's noise derives from (its own per mode and repetition), and, without "
        "`planner_seed`, its repetition's planner seed."))
    planner_seed: Optional[int] = Field(default=None, ge=0, lt=2**63, description=(
        "The seed each repetition's planner seed derives from (default: `seed`): a randomised planner (PRM, a "
        "stochastic program) plans once per repetition with it; the simulated and the field run of a repetition "
        "share that plan."))
    field: Literal["sub", "full"] = "sub"
    jitter: Optional[Jitter] = Field(default=None, description=(
        "Seeded start-pose jitter for every run, both modes: repetitions then start a little apart, as on a "
        "real field (the ideal simulation is otherwise deterministic)."))
    profile_overrides: Optional[dict[str, Any]] = Field(default=None, description=(
        "Field parameters of the robot profile for this job's field runs, e.g. {\"tracker_noise_xy_m\": 0.003} "
        "(SI units; names and physical ranges: contract/overrides.py, docs/fidelity.md \"Noise studies\"): "
        "its field runs are the emulated field robot with these values."))

    @field_validator("profile_overrides")
    @classmethod
    def _overrides(cls, v: Optional[dict[str, Any]]) -> Optional[dict[str, float]]:
        from contract.overrides import check_overrides

        return check_overrides(v) or None if v is not None else None

    controller: str = Field(default="schema", min_length=1, max_length=64, description=(
        "The robots' path-tracking controller (`GET /api/v1/controllers`; docs/controllers.md)."))
    controller_params: dict[str, float] = Field(default_factory=dict, max_length=16, description=(
        "The controller's parameters (SI units, as each name says); the others keep their defaults."))
    controller_program: Optional[int] = Field(default=None, ge=1, description=(
        "An uploaded program's id that drives the robot along the planned path over its robot port "
        "(T,T,O / T,T,V; docs/controllers.md \"Your own controller program\") instead of `controller`."))
    label: Optional[str] = Field(default=None, min_length=1, max_length=64, description=(
        "The configuration's name in comparisons (GET /api/v1/comparisons groups runs by it). Default: the "
        "planner with the parameters given (`fm2(saturation=0.1)`), `/controller` when not `schema`, "
        "` · ` and the profile overrides when given."))
    problem: Optional[str] = Field(default=None, min_length=1, max_length=100, description=(
        "The problem's name in comparisons (the unit of inference). Default: `<environment> <plan>` when the "
        "start and goal are one of the environment's plans, else `<environment> (x,y)→(x,y)` (m, to the cm); "
        "a multi-robot job's `<environment> <n> robots`."))

    @field_validator("label", "problem")
    @classmethod
    def _name(cls, v: Optional[str]) -> Optional[str]:
        if v is not None and (not v.strip() or any(ord(c) < 32 for c in v)):
            raise ValueError("must be a name: not blank, no control characters")
        return v

    _pose = field_validator("start", "goal")(_check_pose)
    _path = field_validator("path")(_check_path)

    @field_validator("modes")
    @classmethod
    def _modes(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("modes must not repeat")
        return v

    @model_validator(mode="after")
    def _planner_or_path(self) -> "ExperimentCreate":
        if self.profile_overrides and "twb" not in self.modes:
            raise ValueError("profile_overrides change the emulated field robot: they need mode \"twb\"")
        if self.robots is not None:
            return self._fleet()
        if self.planner in FLEET_PLANNERS:
            raise ValueError(f"planner: `{self.planner}` plans several robots together; give `robots` (a "
                             "multi-robot job) instead of `start`/`goal`, or a single-robot planner")
        if self.path is not None and self.planner is not None:
            raise ValueError("give either `planner` or `path`, not both")
        if self.controller_program is not None:
            if self.controller != "schema" or self.controller_params:
                raise ValueError("controller_program: give either `controller_program` or a `controller` "
                                 "(with `controller_params`), not both")
            if self.profile_overrides:
                raise ValueError("controller_program: a controller program drives the robot itself; "
                                 "it cannot run with `profile_overrides`")
        if self.program is not None:
            if self.path is not None or self.planner is not None:
                raise ValueError("give one of `planner`, `path` or `program`")
            if self.planner_params:
                raise ValueError("`planner_params` needs a `planner`")
            if self.start is None or self.goal is None:
                raise ValueError("`start` and `goal` are required with a program")
            return self
        if self.path is None:
            if self.planner is None:
                self.planner = "fmm"
            if self.start is None or self.goal is None:
                raise ValueError("`start` and `goal` are required with a planner")
        else:
            if self.planner_params:
                raise ValueError("`planner_params` needs a `planner`")
            self.start = self.start or list(self.path[0])
            self.goal = self.goal or list(self.path[-1])
        return self

    def _fleet(self) -> "ExperimentCreate":
        """A multi-robot job: ``robots`` alone say where the robots go; what it cannot have is refused."""
        assert self.robots is not None
        for name in ("start", "goal", "path", "controller_program", "jitter"):
            if getattr(self, name) is not None:
                why = {"start": "give either `start`/`goal` or `robots`, not both",
                       "goal": "give either `start`/`goal` or `robots`, not both",
                       "path": "a multi-robot job takes each robot's path as `robots[i].path`",
                       "controller_program": "a controller program drives one robot; it cannot drive a "
                                             "multi-robot job",
                       "jitter": "start-pose jitter is not available for multi-robot jobs"}[name]
                raise ValueError(f"{name}: {why}")
        explicit = [r.path is not None for r in self.robots]
        if self.program is not None:  # it sends every robot's path, one T,T,P per robot port
            if self.planner is not None:
                raise ValueError("give either `planner` or `program`, not both")
            if self.planner_params:
                raise ValueError("`planner_params` needs a `planner`")
            if any(explicit):
                raise ValueError(f"robots[{explicit.index(True)}].path: the program sends every robot's path; "
                                 "give no `path`")
            return self
        if self.planner in FLEET_PLANNERS and any(explicit):
            i = explicit.index(True)
            raise ValueError(f"robots[{i}].path: `{self.planner}` plans every robot together; it cannot keep "
                             "a robot's explicit path (give no planner, or a single-robot one, to mix them)")
        if all(explicit):
            if self.planner is not None:
                raise ValueError("give either `planner` or a `path` for every robot, not both")
            if self.planner_params:
                raise ValueError("`planner_params` needs a `planner`")
        elif self.planner is None:
            self.planner = "fmm"
        return self


class RunPublic(FromRow):
    id: int
    experiment_id: int
    mode: str
    repetition: int
    status: RunStatus
    seed: int = Field(description="The seed of the run's noise, dropouts and start jitter (its own per mode).")
    planner_seed: Optional[int] = Field(default=None, description=(
        "The seed its repetition's planner planned with (the same for both modes of a repetition)."))
    planned_path: Optional[list[list[float]]] = Field(default=None, description=(
        "The path the run drove, [[x, y, theta], ...] (m, rad): its repetition's plan (null until planned)."))
    planning_time_s: Optional[float] = Field(default=None, description=(
        "Wall seconds of its repetition's planner call in a warmed worker (the median of `planning_repeats` "
        "calls for a fast planner); an uploaded program's own time; null for an explicit path."))
    planning_cpu_s: Optional[float] = Field(default=None, description="CPU seconds of the same call (median).")
    planning_repeats: Optional[int] = Field(default=None, description="How many calls the planning times are the median of.")
    planning_load: Optional[float] = Field(default=None, description=(
        "The machine's 1-minute load average per CPU when the planning was timed."))
    planning_progress: Optional[list[list[float]]] = Field(default=None, description=(
        "An anytime planner's best path length so far against its planning time, [[t s, length m], ...], of this "
        "run's repetition (OMPL's planners; the curve of Planner Arena's progress page); null: none reported."))
    attempt: int
    clock: Optional[str] = Field(default=None, description=(
        "How its robot's clock treated a closed-loop controller: `lockstep` (the clock waited for the controller's "
        "answer to every pose: the result does not depend on the time scale) or `free` (it ran on at the time "
        "scale); null: not recorded (runs before the testbed stored it)."))
    time_scale: Optional[float] = Field(default=None, description=(
        "Experiment seconds per wall second the run ran at; null: as fast as possible (`max`), or not recorded "
        "(then `clock` is null too)."))
    subfield: Optional[int]
    robot_id: Optional[str]
    t_start: Optional[float]
    t_end: Optional[float]
    metrics: dict[str, Any] = Field(default_factory=dict)
    error: str
    failure: Optional[str] = Field(default=None, description=(
        "Why a `failed` run failed: planning, program, collision, timeout, controller_timeout, stalled or other."))
    stopped_at: Optional[list[float]] = Field(default=None, description=(
        "Where a run that failed on its robot stopped, [x, y] (m, the experiment's frame)."))

    @field_validator("metrics", mode="before")
    @classmethod
    def _metrics(cls, v: Any) -> Any:
        return v or {}
    created_at: UTCDateTime
    started_at: Optional[UTCDateTime]
    finished_at: Optional[UTCDateTime]


class ExperimentSummary(FromRow):
    id: int
    owner: str = Field(validation_alias=_OWNER)
    status: RunStatus
    environment: str
    planner: Optional[str]
    program: Optional[int] = Field(default=None, validation_alias=AliasChoices("program_id", "program"),
                                   description="The uploaded program planning this job, if any.")
    modes: list[str]
    repetitions: int
    field: str
    controller: str = "schema"
    controller_program: Optional[int] = Field(
        default=None, validation_alias=AliasChoices("controller_program_id", "controller_program"),
        description="The uploaded program driving the robots (instead of `controller`), if any.")
    label: str = Field(default="", description="The configuration's name in comparisons (the job's, or derived).")
    problem: str = Field(default="", description="The problem's name in comparisons (the job's, or derived).")

    @field_validator("label", "problem", mode="before")
    @classmethod
    def _names(cls, v: Any) -> Any:
        return v or ""
    error: str
    created_at: UTCDateTime
    finished_at: Optional[UTCDateTime]
    estimated_start_s: Optional[float] = Field(
        default=None, description="Queued jobs: estimated wall seconds until the first run starts."
    )


class ExperimentPublic(ExperimentSummary):
    start: list[float] = Field(description="The start (m, rad); robot 0's in a multi-robot job.")
    goal: list[float] = Field(description="The goal (m, rad); robot 0's in a multi-robot job.")
    robots: Optional[list[dict[str, Any]]] = Field(default=None, description=(
        "A multi-robot job's robots, {\"start\", \"goal\", \"path\"?} each (m, rad); null for one robot."))
    planner_params: dict[str, Any]
    seed: int
    planner_seed: Optional[int] = Field(default=None, description=(
        "The job's planner seed (null: its `seed` is the base of every repetition's planner seed)."))
    planner_stochastic: bool = Field(default=False, description=(
        "Its planner (or program) is randomised: planned once per repetition, each run driving its repetition's "
        "plan; else one path for every run."))
    robot_radius: float
    planning_margin: float = Field(description="Clearance kept beyond the robot radius when planning (m).")
    planned_path: Optional[list[list[float]]] = Field(description=(
        "Repetition 1's planned path (every run has its own: `runs[].planned_path`)."))
    planning_time_s: Optional[float] = Field(description="Repetition 1's planning time (s).")
    planning_info: dict[str, Any]
    jitter: Optional[dict[str, float]] = None
    profile_overrides: Optional[dict[str, float]] = Field(default=None, description=(
        "The field parameters this job's field runs had instead of the robot profile's (None: the profile's)."))
    controller_params: dict[str, float] = Field(default_factory=dict, description=(
        "The controller's parameters, defaults filled in (SI units)."))
    started_at: Optional[UTCDateTime]
    runs: list[RunPublic]

    @field_validator("planner_params", "planning_info", "controller_params", mode="before")
    @classmethod
    def _dicts(cls, v: Any) -> Any:
        return v or {}


class CancelMany(Strict):
    """Experiments to cancel in one request."""

    ids: list[Annotated[int, Field(ge=1, lt=2**63)]] = Field(min_length=1, max_length=1000)


class NotCancelled(Public):
    id: int
    reason: str = Field(description="`not found` (unknown, or not yours) or `already <status>`.")


class CancelledMany(Public):
    cancelled: list[int] = Field(description="Experiments whose queued runs were cancelled and running ones stopped.")
    not_cancelled: list[NotCancelled]


# --------------------------------------------------------------------------- results (docs/metrics.md)

#: a JSON number as sent: an integer stays an integer (a parameter's default 0 is sent as 0, not 0.0)
Number = Union[int, float]


class RunMetricsPublic(Public):
    """One run's metrics as the experiment's metrics list them (a failed run's too, flagged by ``outcome``)."""

    run_id: int
    mode: str
    repetition: int
    status: RunStatus
    outcome: str = Field(description=(
        "success, why it failed (collision, timeout ...), or its status (error, cancelled, interrupted; pending "
        "while it has not ended)."))
    stopped_at: Optional[list[float]] = Field(description="Where a run that failed on its robot stopped, [x, y] (m).")
    metrics: dict[str, Any] = Field(description="The run's metrics (docs/metrics.md; SI units).")


class ProportionPublic(Public):
    """A rate ``k / n`` with its Wilson interval (None while ``n`` is 0)."""

    n: int
    k: int
    rate: Optional[float]
    ci_low: Optional[float]
    ci_high: Optional[float]
    confidence: float


class ModeOutcomesPublic(Public):
    """How one mode's runs ended: ``counts`` per outcome and the success rate over the job's own outcomes."""

    runs: int
    counts: dict[str, int]
    success: ProportionPublic


class MetricSummaryPublic(Public):
    """Mean, sample std and Student-t interval of one metric over ``n`` runs (None where undefined)."""

    n: int
    mean: Optional[float]
    std: Optional[float]
    ci_low: Optional[float]
    ci_high: Optional[float]
    confidence: float


class ModeAggregatePublic(Public):
    """One mode's completed runs: how many, and a summary per numeric metric."""

    runs: int
    metrics: dict[str, MetricSummaryPublic]


class DirectComparisonPublic(Public):
    """The paper's direct comparison "ST" of one repetition: the field path against the simulated one (m)."""

    repetition: int
    sim_run_id: int
    twb_run_id: int
    deviation_mean_m: Optional[float]
    deviation_max_m: Optional[float]
    hausdorff_m: Optional[float]
    frechet_m: Optional[float]


class ExperimentMetricsPublic(Public):
    """An experiment's metrics: per run, outcomes and aggregates per mode, direct sim-vs-twb per repetition."""

    experiment_id: int
    status: RunStatus
    planned: Optional[dict[str, Any]] = Field(description="The planned path's own metrics (None before planning).")
    runs: list[RunMetricsPublic]
    outcomes: dict[str, ModeOutcomesPublic] = Field(description="Per mode.")
    aggregates: dict[str, ModeAggregatePublic] = Field(description="Per mode, over its completed runs.")
    direct: list[DirectComparisonPublic] = Field(description="Not for multi-robot jobs.")


# --------------------------------------------------------------------------- runs' logs


class RunPosesPublic(Public):
    """A run's logged poses: rows of ``columns`` (t s, x m, y m, theta rad; a multi-robot run's with ``robot``)."""

    run_id: int
    count: int
    columns: list[str]
    poses: list[list[Number]] = Field(description="Rows [t, x, y, theta] or [t, x, y, theta, robot], oldest first.")


class ObstacleTrackPublic(Public):
    """Where one moving obstacle was: ``poses`` ``[t, x, y, theta]`` rows (s, m, m, rad), oldest first."""

    index: int = Field(description="Its index in the environment's `moving_obstacles`.")
    radius: float = Field(description="m.")
    count: int
    poses: list[list[float]]


class RunObstaclesPublic(Public):
    """Where a run's moving obstacles were: tracked (``exact`` false) or their exact tracks (true)."""

    run_id: int
    columns: list[str]
    exact: bool
    obstacles: list[ObstacleTrackPublic]


class MessagePublic(FromRow):
    """A protocol line sent to (``>``) or received from (``<``) the robot; ``o``/``e``/``s``: a program's."""

    t: Optional[float] = Field(description="Experiment time on the agent's clock (s).")
    t_estimated: bool = Field(description="`t` extrapolated from the agent's last report.")
    direction: str
    line: str
# --------------------------------------------------------------------------- comparisons


class ComparedExperiment(Public):
    """One experiment of a comparison: its label and problem, and the ``configuration`` its runs are compared
    as (the label, or ``#<id> <label>`` where two selected experiments share the label and the problem)."""

    id: int
    label: str
    problem: str
    configuration: str
    status: str
    environment: str
    planner: Optional[str] = None
    modes: list[str]
    repetitions: int
    seed: int
    robots: int = Field(description="How many robots (1, or a multi-robot job's).")


class SuccessRate(Public):
    """Successes ``k`` of ``n`` distinct counted runs, the ``rate`` and its Wilson interval (None without runs)."""

    n: int
    k: int
    rate: Optional[float] = None
    ci_low: Optional[float] = None
    ci_high: Optional[float] = None
    confidence: float


class ConfigurationOutcomes(Public):
    """How the runs of one configuration in one mode ended, over its experiments (all problems)."""

    configuration: str
    mode: str
    experiments: list[int]
    runs: int
    counts: dict[str, int] = Field(description="Runs per outcome (success, collision, timeout, ..., error, "
                                               "cancelled, interrupted, pending).")
    counted: int = Field(description="Runs that ended in the job's own outcome (success or a failure).")
    success: SuccessRate = Field(description="The success rate over the distinct counted runs: identical "
                                             "repetitions of a problem count once (`identical`).")
    identical: bool


class ComparisonRow(Public):
    """One comparison of configurations ``a`` and ``b`` on ``metric`` in ``mode``: on ``problem``, or pooled
    over ``n_problems`` problems (``problem`` empty).  The columns of a study's ``comparisons.csv``
    (``planners.comparisons.COLUMNS``); numbers that are undefined (no test, no interval) are null."""

    metric: str
    mode: str
    a: str
    b: str
    n_a: int
    n_b: int
    mean_a: Optional[float] = None
    mean_b: Optional[float] = None
    diff: Optional[float] = Field(default=None, description="a − b (a rate: a fraction); pooled: the mean of the "
                                                            "problems' differences.")
    ci_low: Optional[float] = None
    ci_high: Optional[float] = None
    test: str
    p: Optional[float] = None
    p_holm: Optional[float] = None
    effect: str
    effect_size: Optional[float] = None
    paired: bool
    runs_a: int
    runs_b: int
    family_size: int
    problem: str
    n_problems: int
    favour_a: Optional[int] = None
    favour_b: Optional[int] = None
    heterogeneity_i2: Optional[float] = None
    heterogeneity_p: Optional[float] = None
    n_needed: Optional[int] = None
    needed_unit: str
    note: str


class ComparisonsPublic(Public):
    """``GET /api/v1/comparisons``: the experiments, how each configuration's runs ended, and the comparisons
    (pooled over problems first, then each problem's, per metric, mode and pair) with how to read them."""

    experiments: list[ComparedExperiment]
    configurations: list[str]
    problems: list[str]
    metrics: list[str] = Field(description="Compared after the success rate (which always comes first).")
    test: str
    family: str
    confidence: float
    n_resamples: int
    seed: int
    min_problems: int = Field(description="Problems needed for a comparison over problems.")
    outcomes: list[ConfigurationOutcomes]
    rows: list[ComparisonRow]
    method: str = Field(description="How to read this.")


# --------------------------------------------------------------------------- uploaded programs


class ProgramCreate(Strict):
    """An uploaded planner program (docs/uploads.md): its file, base64-encoded, and how to run it."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"name": "my-planner", "kind": "python", "args": ["--fast"],
                                         "content_base64": "aW1wb3J0IG9zCg=="}],
                           # a python program names no interpreter but python3 (_interpreter below)
                           "anyOf": [{"required": ["kind"], "properties": {"kind": {"const": "executable"}}},
                                     {"properties": {"interpreter": {"anyOf": [{"type": "null"},
                                                                               {"const": "python3"}]}}}]},
    )

    name: str = Field(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.+-]+$")
    kind: Literal["python", "executable"] = Field(
        default="python", description="python: run by the testbed's python3; executable: a binary or a script.")
    interpreter: Optional[str] = Field(
        default=None, max_length=32, json_schema_extra={"minLength": 1},
        description="executable only: run the file with this interpreter (GET /programs/sandbox lists them); "
                    "none: the file itself is executed (an ELF binary or a script with #!).")
    args: list[str] = Field(default_factory=list, max_length=64, description="Command-line arguments.")
    content_base64: str = Field(min_length=1, description="The file, base64-encoded.", json_schema_extra={
        "pattern": r"^(?:[A-Za-z0-9+/]{4})*(?:[A-Za-z0-9+/]{2}==|[A-Za-z0-9+/]{3}=)?$"})  # checked by the route
    stochastic: bool = Field(default=False, description=(
        "Its path depends on the seed it gets (TWB_SEED): it then runs once per repetition with that "
        "repetition's planner seed; else once per experiment, its one path and time reused by every run."))

    @field_validator("args")
    @classmethod
    def _args(cls, v: list[str]) -> list[str]:
        for i, a in enumerate(v):
            if "\x00" in a or len(a) > 4096:
                raise ValueError(f"argument {i} must be at most 4096 characters without NUL")
        return v

    @model_validator(mode="after")
    def _interpreter(self) -> "ProgramCreate":
        if self.kind == "python" and self.interpreter not in (None, "python3"):
            raise ValueError("a python program runs with python3; give no `interpreter`")
        return self


class ProgramPublic(FromRow):
    id: int
    name: str
    owner: str = Field(validation_alias=_OWNER)
    kind: str
    interpreter: Optional[str]
    args: list[str]
    size: int = Field(description="Bytes.")
    sha256: str
    stochastic: bool = Field(default=False, description="Runs once per repetition, with its planner seed.")
    created_at: UTCDateTime


# --------------------------------------------------------------------------- robots, tracker


_HOST_LABEL = r"(?:[A-Za-z0-9]|[^\x00-\x7F])(?:(?:[A-Za-z0-9-]|[^\x00-\x7F]){0,61}(?:[A-Za-z0-9]|[^\x00-\x7F]))?"
#: what :func:`host_name` takes, as far as a pattern says it: dot-separated labels of 1 to 63 letters, digits
#: (or non-ASCII: IDNA) and inner hyphens, a trailing dot allowed; or an IPv6 address (it has a colon)
HOST_PATTERN = (rf"^(?:{_HOST_LABEL}\.)*{_HOST_LABEL}\.?$"
                r"|^(?:[0-9A-Fa-f]{0,4}:){2,7}(?:[0-9A-Fa-f]{0,4}|[0-9]{1,3}(?:\.[0-9]{1,3}){3})(?:%[A-Za-z0-9_.-]+)?$")


class RobotRegister(Strict):
    """What an agent sends to ``POST /api/v1/robots`` when it starts."""

    model_config = ConfigDict(allow_inf_nan=False, extra="ignore")

    robot_id: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.:-]+$")
    host: str = Field(min_length=1, max_length=253, json_schema_extra={"pattern": HOST_PATTERN},
                      description="Host name (IDNA is converted) or IP address.")  # checked by _host
    port: int = Field(ge=1, le=65535)
    platform: str = Field(default="", max_length=64, pattern=r"^[A-Za-z0-9_. ()+-]*$")
    backend: Literal["ideal", "field"]
    profile: str = Field(default="bebot", max_length=32, pattern=r"^[A-Za-z0-9_.-]+$")
    origin: list[Annotated[float, Field(ge=0, le=100)]] = Field(default_factory=lambda: [0.0, 0.0], min_length=2,
                                                                max_length=2)
    area: list[Annotated[float, Field(gt=0, le=100)]] = Field(default_factory=lambda: [1.8, 1.8], min_length=2,
                                                              max_length=2)

    @field_validator("host")
    @classmethod
    def _host(cls, v: str) -> str:
        return host_name(v)


_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")


def host_name(text: str) -> str:
    """``text`` as an ASCII host name (IDNA-encoded) or IP address; ValueError for anything else (URLs, ports)."""
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        pass
    try:
        ascii_name = text.encode("idna").decode("ascii")
    except UnicodeError:
        raise ValueError("must be a host name or an IP address") from None
    labels = ascii_name[:-1].split(".") if ascii_name.endswith(".") else ascii_name.split(".")
    if len(ascii_name) > 253 or not all(_LABEL.fullmatch(label) for label in labels):
        raise ValueError("must be a host name or an IP address (no scheme, port or path)")
    return ascii_name


class RobotPublic(Public):
    robot_id: str
    host: str
    port: int
    platform: str
    backend: str
    profile: str
    origin: list[float]
    area: list[float]
    subfield: Optional[int]
    pool: str
    status: str
    status_reason: Optional[str] = Field(default=None, description="Why an offline robot is offline.")
    last_seen: UTCDateTime
    last_pose: Optional[list[float]] = Field(
        default=None, description="Last tracked pose [t, x, y, theta] in field coordinates (s, m, rad), if any.")


class SubfieldPublic(Public):
    id: int
    state: str
    environment: Optional[str]
    robot_id: Optional[str]
    run_id: Optional[int]
    last_run_id: Optional[int] = Field(default=None, description=(
        "The last run that drove on the sub-field since the testbed started (the one under way, or the one "
        "whose robot and environment it still shows), if it is yours; null after a restart."))
    origin: list[float]
    size: list[float]


class TrackerBatch(BaseModel):
    """Tracker poses of one robot: ``[t, x, y, theta]`` rows (s, m, m, rad), robot frame.

    Rows are checked one by one: a row that is not four finite numbers
    (``NaN``, a short row, ``true``) is left out and counted in ``rejected``,
    the others are kept, so a bad row never costs a batch.  (The route parses
    the body itself, faster than this model would; the model documents it.)
    """

    model_config = ConfigDict(allow_inf_nan=True, extra="ignore")

    robot_id: str = Field(min_length=1, max_length=64)
    poses: list[Any] = Field(max_length=100_000, description="Rows [t, x, y, theta] (s, m, m, rad); "
                                                              "rows that are not four finite numbers are counted "
                                                              "in `rejected`.")


class TrackerBatchResult(Public):
    """What became of a tracker batch: rows received, accepted, rejected and stored with a run."""

    received: int
    accepted: int
    rejected: int
    stored: int = Field(description="Accepted rows stored with the robot's current run.")
    run_id: Optional[int] = Field(description="That run, if the robot runs one.")


# --------------------------------------------------------------------------- the testbed


class ComputePublic(BaseModel):
    """The compute pool (planning, metrics, simulation tasks): its workers, whether they have run a job, how
    often a broken pool was replaced and why it last broke."""

    workers: int
    ready: bool
    restarts: int
    last_failure: Optional[str]
    engine: Optional[str] = Field(default=None, description="`ray` for the Ray pool (absent: the local workers).")


class HealthPublic(BaseModel):
    """Liveness; with a valid token also the queue, the fleet and the compute pool (absent without one).
    ``degraded``: the compute pool was restarted and its fresh workers have not run a job yet."""

    status: Literal["ok", "degraded"]
    version: str
    queued_runs: Optional[int] = None
    running_runs: Optional[int] = None
    field_robots: Optional[int] = None
    sim_robots: Optional[int] = None
    time_scale: Optional[float] = Field(default=None, description=(
        "Experiment seconds per wall second; null: as fast as possible (`max`)."))
    compute: Optional[ComputePublic] = None


class ParamPublic(BaseModel):
    """A planner's or controller's parameter (contract/parameters.py): unit, default and range [low, high]
    (null: unbounded; SI units); ``type`` only when not a number, ``integer`` and ``low_exclusive`` only when
    true."""

    name: str
    unit: str
    default: Any
    range: list[Optional[Number]] = Field(min_length=2, max_length=2)
    description: str
    type: Optional[Literal["integer", "boolean", "string"]] = None
    integer: Optional[bool] = None
    low_exclusive: Optional[bool] = None


class LoadErrorPublic(BaseModel):
    """An installed plug-in that does not load, as data (docs/planners.md, "When a plug-in does not load")."""

    name: str
    kind: str
    source: str
    error_type: str
    message: str
    distribution: str


class PluginPage(Page[T], Generic[T]):
    """A page of plug-ins and built-ins, with the installed plug-ins that fail to load (not in ``data``)."""

    load_errors: list[LoadErrorPublic]


class PlannerPublic(BaseModel):
    """A selectable planner: parameter defaults and declarations (null: any parameters), multi-robot jobs only
    or not."""

    name: str
    description: str
    defaults: Optional[dict[str, Any]]
    parameters: Optional[list[ParamPublic]]
    fleet_only: bool


class ControllerPublic(BaseModel):
    """A selectable path-tracking controller (docs/controllers.md)."""

    name: str
    description: str
    source: str = Field(description="Where it comes from in the literature.")
    compiled: bool = Field(description="Runs inside the compiled core (built-ins), not in Python (plug-ins).")
    parameters: list[ParamPublic]


class SandboxLimitsPublic(Public):
    """The limits an uploaded program runs under, in the units their names say."""

    wall_s: float
    cpu_s: int
    memory_mb: int
    file_mb: int
    processes: int
    open_files: int
    output_kib: int
    tmp_mb: int
    max_program_bytes: int
    concurrent_programs: int


class SandboxIsolationPublic(Public):
    """The isolation uploaded programs get on this machine (docs/uploads.md)."""

    namespaces: list[str]
    user_namespace: bool
    sandbox: str = Field(description="What makes the namespaces: bwrap's version (`bubblewrap 0.8.0`), or `none`.")
    network: str
    seccomp: bool
    runs_as: str
    memory_limit: str
    cgroup: Optional[str]
    memory_note: str
    note: str


class SandboxPublic(Public):
    """Whether uploads are enabled, the interpreters, the limits and the isolation (null: uploads disabled)."""

    uploads_enabled: bool
    interpreters: list[str]
    limits: SandboxLimitsPublic
    isolation: Optional[SandboxIsolationPublic]
