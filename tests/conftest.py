"""Shared fixtures: running the real ``twb`` console script."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TWB = Path(sys.executable).with_name("twb")


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the simulation kernels once, before any test starts agent processes: on a fresh
    checkout every process would otherwise compile them at the same time (numba's cache)."""
    from robot_agent.sim import warm_up

    warm_up()


@pytest.fixture
def twb():
    """Run the installed ``twb`` command; returns the CompletedProcess (text mode)."""

    def run(*args: str, timeout: float = 120, env: dict | None = None, **kw) -> subprocess.CompletedProcess:
        full_env = {**os.environ, **(env or {})}
        full_env.pop("TWB_DEBUG", None)
        return subprocess.run(
            [str(TWB), *args], capture_output=True, text=True, timeout=timeout, env=full_env, **kw
        )

    return run
