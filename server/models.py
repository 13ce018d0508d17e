"""Database tables (SQLAlchemy 2, portable SQL: SQLite by default, PostgreSQL next).

Units are SI (docs/design.md, "Units and frames"): metres, radians, seconds.
Times named ``t*`` are experiment time on the robot agent's clock; ``*_at``
are wall-clock UTC.  Statuses are the values of :mod:`server.status`.
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any, Optional

from sqlalchemy import (JSON, BigInteger, Boolean, DateTime, Float, ForeignKey, Index, Integer, LargeBinary, String,
                        Text, UniqueConstraint)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from .status import RobotStatus, RunStatus, SubfieldState

__all__ = [
    "Base",
    "Environment",
    "Experiment",
    "Message",
    "Pose",
    "Program",
    "Robot",
    "Run",
    "Subfield",
    "Token",
    "User",
    "utcnow",
]


def utcnow() -> datetime:
    return datetime.now(timezone.utc)


class Base(DeclarativeBase):
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}


class User(Base):
    __tablename__ = "users"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    is_admin: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    tokens: Mapped[list["Token"]] = relationship(back_populates="user", cascade="all, delete-orphan")


class Token(Base):
    """A bearer token, stored hashed. ``kind``: user, admin or agent (tracker ingestion)."""

    __tablename__ = "tokens"

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    kind: Mapped[str] = mapped_column(String(16), default="user")
    label: Mapped[str] = mapped_column(String(64), default="")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    user: Mapped[User] = relationship(back_populates="tokens")


class Environment(Base):
    """An environment file (docs/design.md, "Environment file") stored as JSON; built-ins have no owner."""

    __tablename__ = "environments"
    #: names are unique per owner; built-in names (owner none) are reserved for everyone
    __table_args__ = (UniqueConstraint("owner_id", "name", name="uq_environments_owner_name"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(100))
    owner_id: Mapped[Optional[int]] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"), nullable=True)
    builtin: Mapped[bool] = mapped_column(Boolean, default=False)
    data: Mapped[dict[str, Any]] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Program(Base):
    """An uploaded planner program (docs/uploads.md); run sandboxed once per experiment that names it (a
    stochastic one: once per repetition)."""

    __tablename__ = "programs"

    id: Mapped[int] = mapped_column(primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(100))
    #: "python" (run by the testbed's python3) or "executable" (a binary, or a script for ``interpreter``)
    kind: Mapped[str] = mapped_column(String(16))
    interpreter: Mapped[Optional[str]] = mapped_column(String(32), nullable=True)
    args: Mapped[list[Any]] = mapped_column(JSON, default=list)
    content: Mapped[bytes] = mapped_column(LargeBinary)
    size: Mapped[int] = mapped_column(Integer)
    sha256: Mapped[str] = mapped_column(String(64))
    #: declared at upload: its path depends on the seed it gets, so it runs once per repetition (with that
    #: repetition's planner seed) instead of once per experiment
    stochastic: Mapped[bool] = mapped_column(Boolean, default=False, server_default="0")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)

    owner: Mapped[User] = relationship(lazy="joined", innerjoin=True)

    @property
    def owner_name(self) -> str:
        return self.owner.name


class Experiment(Base):
    """A planning job: its path planned (once, or once per repetition for a randomised planner) and run
    ``repetitions`` times in each of ``modes``."""

    __tablename__ = "experiments"

    id: Mapped[int] = mapped_column(primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    status: Mapped[str] = mapped_column(String(16), default=RunStatus.QUEUED, index=True)
    environment: Mapped[str] = mapped_column(String(100))
    environment_data: Mapped[dict[str, Any]] = mapped_column(JSON)
    #: robot 0's start and goal for a multi-robot job
    start: Mapped[list[Any]] = mapped_column(JSON)
    goal: Mapped[list[Any]] = mapped_column(JSON)
    #: a multi-robot job's robots, ``[{"start", "goal", "path"?}, ...]`` (m, rad); None for one robot
    robots: Mapped[Optional[list[Any]]] = mapped_column(JSON, nullable=True)
    planner: Mapped[Optional[str]] = mapped_column(String(64), nullable=True)
    planner_params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    explicit_path: Mapped[Optional[list[Any]]] = mapped_column(JSON, nullable=True)
    #: an uploaded planner program computes the path (instead of ``planner`` or ``explicit_path``)
    program_id: Mapped[Optional[int]] = mapped_column(ForeignKey("programs.id", ondelete="SET NULL"),
                                                      nullable=True)
    modes: Mapped[list[Any]] = mapped_column(JSON)
    repetitions: Mapped[int] = mapped_column(Integer, default=1)
    seed: Mapped[int] = mapped_column(BigInteger, default=0)
    #: the job's planner seed, from which each repetition's derives (None: the job's ``seed``)
    planner_seed: Mapped[Optional[int]] = mapped_column(BigInteger, nullable=True)
    #: its planner (or program) is randomised: planned once per repetition, with that repetition's planner seed
    planner_stochastic: Mapped[bool] = mapped_column(Boolean, default=False, server_default="0")
    field: Mapped[str] = mapped_column(String(8), default="sub")
    robot_radius: Mapped[float] = mapped_column(Float)
    #: clearance kept beyond the robot radius when planning (m)
    planning_margin: Mapped[float] = mapped_column(Float, default=0.0, server_default="0")
    #: repetition 1's plan (every run has its own: :attr:`Run.planned_path`)
    planned_path: Mapped[Optional[list[Any]]] = mapped_column(JSON, nullable=True)
    planning_time_s: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    planning_info: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    #: start-pose jitter of every run, ``{"xy_m", "theta_rad"}`` (standard deviations), or None
    jitter: Mapped[Optional[dict[str, Any]]] = mapped_column(JSON, nullable=True)
    #: field parameters of the robot profile for the field runs, ``{"tracker_noise_xy_m": 0.003}`` (SI), or None
    profile_overrides: Mapped[Optional[dict[str, Any]]] = mapped_column(JSON, nullable=True)
    #: the robots' path-tracking controller (docs/controllers.md) and its parameters, defaults filled in (SI)
    controller: Mapped[str] = mapped_column(String(64), default="schema", server_default="schema")
    controller_params: Mapped[Optional[dict[str, Any]]] = mapped_column(JSON, default=dict, nullable=True)
    #: an uploaded program drives the robots along the planned path instead of a built-in controller
    controller_program_id: Mapped[Optional[int]] = mapped_column(
        ForeignKey("programs.id", ondelete="SET NULL"), nullable=True)
    #: the configuration's name (the job's ``label``, or derived: planners.compared.job_configuration) and the
    #: problem's (the job's ``problem``, or derived: planners.compared.problem_label); what comparisons group by
    label: Mapped[Optional[str]] = mapped_column(String(64), nullable=True)
    problem: Mapped[Optional[str]] = mapped_column(String(100), nullable=True)
    error: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    started_at: Mapped[Optional[datetime]] = mapped_column(DateTime(timezone=True), nullable=True)
    finished_at: Mapped[Optional[datetime]] = mapped_column(DateTime(timezone=True), nullable=True)

    runs: Mapped[list["Run"]] = relationship(
        back_populates="experiment", cascade="all, delete-orphan", order_by="Run.id"
    )
    owner: Mapped[User] = relationship(lazy="joined", innerjoin=True)

    @property
    def owner_name(self) -> str:
        return self.owner.name


class Run(Base):
    """One execution of an experiment's path in one mode (sim or twb), one repetition."""

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(primary_key=True)
    experiment_id: Mapped[int] = mapped_column(ForeignKey("experiments.id", ondelete="CASCADE"), index=True)
    mode: Mapped[str] = mapped_column(String(8))
    repetition: Mapped[int] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(16), default=RunStatus.QUEUED, index=True)
    #: the seed of the run's random elements (noise, dropouts, start jitter): its own per mode
    seed: Mapped[int] = mapped_column(BigInteger, default=0)
    #: the seed its repetition's planner plans with (both modes of a repetition share it, and the plan)
    planner_seed: Mapped[Optional[int]] = mapped_column(BigInteger, nullable=True)
    #: the path the run drove (m, m, rad): its repetition's plan
    planned_path: Mapped[Optional[list[Any]]] = mapped_column(JSON, nullable=True)
    #: its planning: the median wall and CPU seconds of ``planning_repeats`` planner calls in a warmed worker,
    #: and the machine's load per CPU then (docs/study.md, "Planning time"); None: no planner (an explicit path)
    planning_time_s: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    planning_cpu_s: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    planning_repeats: Mapped[Optional[int]] = mapped_column(Integer, nullable=True)
    planning_load: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    #: an anytime planner's best path length so far against its planning time, ``[[t_s, length_m], ...]``, of
    #: the repetition's own planning (OMPL's progress properties); None: the planner reports none
    planning_progress: Mapped[Optional[list[Any]]] = mapped_column(JSON, nullable=True)
    attempt: Mapped[int] = mapped_column(Integer, default=1)
    #: how its robot's clock treated a closed-loop controller: ``lockstep`` or ``free`` (None: before migration 0015)
    clock: Mapped[Optional[str]] = mapped_column(String(8), nullable=True)
    #: experiment seconds per wall second it ran at (None: as fast as possible, or not recorded)
    time_scale: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    subfield: Mapped[Optional[int]] = mapped_column(Integer, nullable=True)
    robot_id: Mapped[Optional[str]] = mapped_column(String(64), nullable=True)
    t_start: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    t_end: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    error: Mapped[str] = mapped_column(Text, default="")
    #: why a ``failed`` run failed (a :class:`server.errors.FailureKind` value)
    failure: Mapped[Optional[str]] = mapped_column(String(24), nullable=True)
    #: where a run that failed on a robot stopped, ``[x, y]`` (m, the experiment's frame)
    stopped_at: Mapped[Optional[list[Any]]] = mapped_column(JSON, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    started_at: Mapped[Optional[datetime]] = mapped_column(DateTime(timezone=True), nullable=True)
    finished_at: Mapped[Optional[datetime]] = mapped_column(DateTime(timezone=True), nullable=True)

    experiment: Mapped[Experiment] = relationship(back_populates="runs")


class Pose(Base):
    """A logged pose of a run: tracker measurement (twb) or ground truth (sim); ``robot`` is the fleet member
    of a multi-robot run (its index in the job's ``robots``), None for a single robot's; ``obstacle``: not the
    run's robot but one of a field run's obstacle robots (its index in the environment's
    ``moving_obstacles``), None for the run's own robots."""

    __tablename__ = "poses"
    __table_args__ = (Index("ix_poses_run_t", "run_id", "t"),)

    id: Mapped[int] = mapped_column(BigInteger().with_variant(Integer, "sqlite"), primary_key=True)
    #: no foreign key: PostgreSQL would look the run up once per pose (more than half of what storing a run's
    #: poses costs it); the testbed writes poses only for runs it holds, and a trigger deletes a run's poses
    #: with it (migration 0012)
    run_id: Mapped[int] = mapped_column(Integer)
    t: Mapped[float] = mapped_column(Float)
    x: Mapped[float] = mapped_column(Float)
    y: Mapped[float] = mapped_column(Float)
    theta: Mapped[float] = mapped_column(Float)
    robot: Mapped[Optional[int]] = mapped_column(Integer, nullable=True)
    obstacle: Mapped[Optional[int]] = mapped_column(Integer, nullable=True)


class Message(Base):
    """A protocol line sent to (``>``) or received from (``<``) a robot during a run."""

    __tablename__ = "messages"
    __table_args__ = (Index("ix_messages_run", "run_id", "id"),)

    id: Mapped[int] = mapped_column(BigInteger().with_variant(Integer, "sqlite"), primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"))
    t: Mapped[Optional[float]] = mapped_column(Float, nullable=True)
    #: True when ``t`` is extrapolated from the agent's last reported time (lines without a time)
    t_estimated: Mapped[bool] = mapped_column(Boolean, default=False, server_default="0")
    direction: Mapped[str] = mapped_column(String(1))
    line: Mapped[str] = mapped_column(Text)


class Robot(Base):
    """A registered robot agent endpoint (field robots on sub-fields, ideal robots in the pool)."""

    __tablename__ = "robots"

    id: Mapped[int] = mapped_column(primary_key=True)
    robot_id: Mapped[str] = mapped_column(String(64), unique=True)
    host: Mapped[str] = mapped_column(String(255))
    port: Mapped[int] = mapped_column(Integer)
    platform: Mapped[str] = mapped_column(String(64), default="")
    backend: Mapped[str] = mapped_column(String(16))
    profile: Mapped[str] = mapped_column(String(32), default="bebot")
    origin: Mapped[list[Any]] = mapped_column(JSON)
    area: Mapped[list[Any]] = mapped_column(JSON)
    subfield: Mapped[Optional[int]] = mapped_column(Integer, nullable=True)
    #: the token that registered the robot: only it (or an admin) may register it again or post its poses;
    #: the robot's control key derives from it (contract.auth); none for robots in the server's process
    token_id: Mapped[Optional[int]] = mapped_column(ForeignKey("tokens.id", ondelete="SET NULL", name="fk_robots_token_id"),
                                                    nullable=True)
    status: Mapped[str] = mapped_column(String(16), default=RobotStatus.IDLE)
    registered_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    last_seen: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Subfield(Base):
    """One of the four 1.8 m sub-fields: what is built on it and what runs there."""

    __tablename__ = "subfields"

    id: Mapped[int] = mapped_column(primary_key=True)
    state: Mapped[str] = mapped_column(String(16), default=SubfieldState.IDLE)
    environment: Mapped[Optional[str]] = mapped_column(String(100), nullable=True)
    robot_id: Mapped[Optional[str]] = mapped_column(String(64), nullable=True)
    run_id: Mapped[Optional[int]] = mapped_column(Integer, nullable=True)
    updated_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
