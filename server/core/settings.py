"""Server settings: one ``Settings`` object read from ``TWB_*`` environment variables.

``TWB_DATA_DIR`` is where the SQLite database, the admin token file and logs
live; ``TWB_DATABASE_URL`` overrides the database (keep SQL portable:
PostgreSQL is next).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings"]


class Settings(BaseSettings):
    """Configuration of one testbed server; every field can be set as ``TWB_<NAME>``."""

    model_config = SettingsConfigDict(env_prefix="TWB_", extra="ignore")

    data_dir: Path = Field(default=Path("twb-data"), description="Database, token file and logs.")
    database_url: str = Field(default="", description="SQLAlchemy URL; default: SQLite in data_dir.")
    admin_token: str = Field(default="", description="Fixed admin token; generated when empty.")
    time_scale: float = Field(default=1.0, gt=0, description="Experiment seconds per wall second.")
    clock: Literal["lockstep", "free"] = Field(default="lockstep", description=(
        "How a robot's clock treats a closed-loop controller (docs/protocol.md, \"Lockstep\"): 'lockstep' waits for "
        "its answer to every pose (results independent of the time scale and the host's speed), 'free' runs on."))
    lockstep_wait_s: float = Field(default=3.0, gt=0, le=600, description=(
        "Wall seconds a lockstep clock waits for a controller's answer before it runs on without it (the "
        "controller has lapsed; its robot's watchdog stops it after 0.5 s of experiment time). Raise it for "
        "controllers slower than that on a loaded host."))
    max_body_bytes: int = Field(default=12 << 20, gt=0, description=(
        "Largest accepted request body (at least what an upload of the largest program takes, base64)."))
    # the API's HTTP connections (docs/security.md, "HTTP connections")
    http_header_timeout_s: float = Field(default=10.0, gt=0, description=(
        "Wall seconds a request's line and headers may take to arrive: from a new connection's start, or a "
        "following request's first byte (then 408 and the connection is closed)."))
    http_body_timeout_s: float = Field(default=30.0, gt=0, description=(
        "Longest pause, wall seconds, in a request body the server is reading (then the connection is closed)."))
    http_keep_alive_s: float = Field(default=5.0, gt=0, description=(
        "Wall seconds an idle connection is kept open after a response for the client's next request."))
    http_max_header_bytes: int = Field(default=64 << 10, ge=1024, description=(
        "Largest request line and headers, bytes (431 beyond)."))
    http_max_connections: int = Field(default=2048, ge=16, description=(
        "HTTP connections open at once (within the open-file limit, leaving the robots their own budget): when "
        "all are taken, the one idle longest is closed for a newcomer, or with every one busy the newcomer gets 503."))
    http_max_connections_per_peer: int = Field(default=256, ge=1, description=(
        "HTTP connections open at once from one IP address (503 beyond)."))
    max_queued_per_user: int = Field(default=200, gt=0, description="Queued experiments per user (429 beyond).")
    auth_failures_per_minute: int = Field(
        default=30, gt=0, description="Unknown tokens a client may present per minute; then 429 until a minute passed.")
    max_repetitions: int = Field(default=20, gt=0)
    run_timeout_factor: float = Field(default=4.0, gt=1, description="Timeout = factor x expected run time.")
    run_timeout_min_s: float = Field(default=30.0, gt=0, description="Shortest run timeout, experiment seconds.")
    resume_interrupted: bool = Field(
        default=True, description="At start, queue again the runs that a stop or a crash of the testbed interrupted.")
    run_log_lines: int = Field(default=20_000, ge=100, description=(
        "Protocol-log lines a run keeps (its first ones; then one line says how many were dropped)."))
    tracker_grace_s: float = Field(default=0.5, ge=0, description="Wall seconds to wait for late tracker poses.")
    run_slack_s: float = Field(
        default=10.0, gt=0, description="Wall seconds a run waits for a robot beyond the time an answer takes at the "
                                        "time scale (then a run in progress asks the robot's own clock).")
    planning_workers: int = Field(default=2, gt=0, description="Processes planning and computing metrics.")
    sim_engine: Literal["local", "ray"] = Field(
        default="local", description="Where simulation-mode runs go: the registered simulation robots (`local`) or "
                                     "Ray tasks (`ray`: planning and metrics run on Ray too; docs/scale-out.md).")
    ray_address: str = Field(default="", description="host:port of an existing Ray cluster's head (GCS); empty: "
                                                     "start a local Ray cluster with the testbed.")
    ray_cpus: int = Field(default=0, ge=0, description="CPUs of the local Ray cluster (0: this machine's).")
    ray_slots: int = Field(default=0, ge=0, description="Simulation runs at once on Ray (0: three times the cluster's CPUs).")
    robot_radius_m: float = Field(default=0.045, gt=0, description="Robot radius: validation, metrics (collided).")
    planning_margin_m: float = Field(
        default=0.02, ge=0,
        description="Extra clearance the testbed's planners keep beyond the robot radius: field robots "
                    "track a path only to within a few centimetres, and a path grazing a block at exactly "
                    "the radius would make collisions, not comparisons.")
    planning_memory_mb: int = Field(default=2048, ge=0, description=(
        "Memory of each planning worker process, MiB (its data segment, RLIMIT_DATA; 0: no cap): a job asking for "
        "more fails `planning` with the reason instead of taking the machine's memory (docs/security.md)."))
    planning_timeout_s: float = Field(default=120.0, ge=0, description=(
        "Wall seconds a plan may take in a worker (0: no limit): beyond it the run fails `planning` with the reason "
        "(a plan stuck in compiled code ends when it returns to Python; the server's own watchdog ends the workers "
        "30 s later)."))
    planning_timing_budget_s: float = Field(default=0.05, ge=0, le=10, description=(
        "A fast plan is timed again while its calls together took less than this (s; at most 5 calls), its "
        "planning time the median: steadier times for about 25 ms of CPU per repetition; 0: one call, for "
        "sweeps of many cheap runs where that CPU counts (docs/study.md, \"Planning time\")."))
    uploads_enabled: bool = Field(default=False, description="Accept uploaded planner programs (`--enable-uploads`).")
    max_program_bytes: int = Field(default=8 << 20, gt=0, description=(
        "Largest uploaded program (413 beyond); static binaries of a C planner are a megabyte or two."))
    # the sandbox of uploaded programs (docs/uploads.md)
    sandbox_wall_s: float = Field(default=30.0, gt=0, description="Wall-clock seconds a program may run.")
    sandbox_cpu_s: int = Field(default=20, gt=0, description="CPU seconds per process (RLIMIT_CPU).")
    sandbox_memory_mb: int = Field(default=512, gt=0, description="Memory of a program, MiB: all its processes together (cgroup) "
                                                                 "where the machine allows, else per process (RLIMIT_AS).")
    sandbox_file_mb: int = Field(default=16, gt=0, description="Largest file a program may write, MiB.")
    sandbox_processes: int = Field(default=32, gt=0, description="Processes a program may have at once.")
    sandbox_open_files: int = Field(default=64, gt=3, description="Open files per process.")
    sandbox_output_kib: int = Field(default=64, gt=0, description="Kept stdout and stderr each, KiB.")
    sandbox_tmpfs_mb: int = Field(default=64, gt=0, description="Size of the program's /tmp (namespaces only), MiB.")
    sandbox_workers: int = Field(default=2, gt=0, description="Programs running at the same time.")
    sandbox_uid_base: int = Field(default=3_000_000, gt=0,
                                  description="As root, each running program gets a uid/gid of its own from this one upwards.")
    sandbox_namespaces: Literal["auto", "required", "off"] = Field(
        default="auto", description="Linux namespaces for programs: use when available, require, or never.")
    controller_max_backlog: int = Field(default=1000, ge=1, description=(
        "Lines a controller program may have waiting for its robot (sent, not yet answered); more: the "
        "program floods its robot port and the run fails (program)."))
    sandbox_interpreters: dict[str, str] = Field(
        default_factory=lambda: _interpreters(),
        description="Interpreters programs may name: name -> absolute path (JSON in the environment).")

    @model_validator(mode="after")
    def _room_for_programs(self) -> "Settings":
        """A request body must fit the largest program, base64-encoded (4/3), with its JSON around it."""
        self.max_body_bytes = max(self.max_body_bytes, (self.max_program_bytes + 2) // 3 * 4 + (64 << 10))
        return self

    @model_validator(mode="after")
    def _ray_address_means_ray(self) -> "Settings":
        if self.ray_address:
            self.sim_engine = "ray"
        return self

    @model_validator(mode="after")
    def _default_database(self) -> "Settings":
        if not self.database_url:
            self.database_url = f"sqlite:///{(self.data_dir / 'twb.db').resolve()}"
        return self

    @property
    def token_file(self) -> Path:
        return self.data_dir / "token"


def _interpreters() -> dict[str, str]:
    """The machine's system interpreters (not a virtualenv's: its files may be unreadable to the sandbox)."""
    candidates = {
        "python3": ("/usr/local/bin/python3", "/usr/bin/python3"),
        "sh": ("/bin/sh", "/usr/bin/sh"),
        "bash": ("/bin/bash", "/usr/bin/bash"),
    }
    return {name: next(p for p in paths if os.access(p, os.X_OK))
            for name, paths in candidates.items() if any(os.access(p, os.X_OK) for p in paths)}
