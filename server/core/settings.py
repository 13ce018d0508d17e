"""Server settings: one ``Settings`` object read from ``TWB_*`` environment variables.

``TWB_DATA_DIR`` is where the SQLite database, the admin token file and logs
live; ``TWB_DATABASE_URL`` overrides the database (keep SQL portable:
PostgreSQL is next).
"""

from __future__ import annotations

from pathlib import Path

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
    max_body_bytes: int = Field(default=4 << 20, gt=0, description="Largest accepted request body.")
    max_queued_per_user: int = Field(default=200, gt=0, description="Queued experiments per user (429 beyond).")
    max_repetitions: int = Field(default=20, gt=0)
    run_timeout_factor: float = Field(default=4.0, gt=1, description="Timeout = factor x expected run time.")
    run_timeout_min_s: float = Field(default=30.0, gt=0, description="Shortest run timeout, experiment seconds.")
    tracker_grace_s: float = Field(default=0.5, ge=0, description="Wall seconds to wait for late tracker poses.")
    planning_workers: int = Field(default=2, gt=0, description="Processes planning and computing metrics.")
    robot_radius_m: float = Field(default=0.045, gt=0, description="Robot radius: validation, metrics (collided).")
    planning_margin_m: float = Field(
        default=0.02, ge=0,
        description="Extra clearance the testbed's planners keep beyond the robot radius: field robots "
                    "track a path only to within a few centimetres, and a path grazing a block at exactly "
                    "the radius would make collisions, not comparisons.")
    uploads_enabled: bool = False

    @model_validator(mode="after")
    def _default_database(self) -> "Settings":
        if not self.database_url:
            self.database_url = f"sqlite:///{(self.data_dir / 'twb.db').resolve()}"
        return self

    @property
    def token_file(self) -> Path:
        return self.data_dir / "token"
