"""Shared fixtures: running the real ``twb`` console script."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TWB = Path(sys.executable).with_name("twb")


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile the simulation kernels (and the fast-marching planners') once, before any test starts agent
    processes: on a fresh checkout every process would otherwise compile them at the same time (numba's cache).

    Also: a test run started as a background job of a script inherits SIGINT ignored, and every
    process a test starts would inherit that too and never stop on the Ctrl-C the tests send it;
    with a handler here, children start with the default again."""
    import signal

    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    from planners.fast_marching import warm_up as warm_up_planners
    from robot_agent.engine.sim import warm_up

    warm_up()
    warm_up_planners()


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


@pytest.fixture(scope="session")
def postgres():
    """A PostgreSQL server for the session (tests/pg_support.py); skipped with the reason where PostgreSQL is
    not installed, except in CI (TWB_REQUIRE_POSTGRES=1), where that fails."""
    import tempfile

    from pg_support import PostgresServer, postgres_bin

    if postgres_bin() is None:
        reason = "PostgreSQL is not installed (Debian: apt-get install -y --no-install-recommends postgresql)"
        if os.environ.get("TWB_REQUIRE_POSTGRES"):
            pytest.fail(reason)
        pytest.skip(reason)
    server = PostgresServer(Path(tempfile.mkdtemp(prefix="twb-pg-")))
    yield server
    server.stop()


@pytest.fixture(scope="session")
def sandbox_isolation():
    """What the sandbox of uploaded programs gives here (the launcher's probe); skipped with the reason where
    bubblewrap cannot make its namespaces (not installed: Debian ``apt-get install -y bubblewrap``; or user
    namespaces refused), except in CI (TWB_REQUIRE_SANDBOX=1), where that fails."""
    import json

    from server.sandbox import launcher_env

    r = subprocess.run([sys.executable, "-m", "server.sandbox.launch"], input=b'{"probe": true}', capture_output=True,
                       timeout=60, cwd=Path(__file__).resolve().parent.parent, env=launcher_env())
    probe = json.loads(r.stdout.decode().splitlines()[-1])
    if "net" not in probe["namespaces"] or not probe["seccomp"]:
        reason = f"the sandbox has no namespaces or no seccomp filter here: {probe['reason']}"
        if os.environ.get("TWB_REQUIRE_SANDBOX"):
            pytest.fail(reason)
        pytest.skip(reason)
    return probe


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request, tmp_path):
    """A fresh, empty store of each kind: a SQLite file, or a database on the session's PostgreSQL server."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'store.db'}"
    return request.getfixturevalue("postgres").database()


@pytest.fixture
def run_store(database_url):
    """A migrated store of each kind (:func:`database_url`) holding user 1, experiment 1 and its runs 1 and 2:
    its session factory (the engine disposed after the test)."""
    from server.core.db import make_engine, make_session_factory, migrate
    from server.models import Experiment, Run, User

    engine = make_engine(database_url)
    migrate(engine)
    sessions = make_session_factory(engine)
    with sessions.begin() as s:
        s.add(User(id=1, name="u"))
        s.add(Experiment(id=1, owner_id=1, environment="e", environment_data={}, start=[0, 0], goal=[1, 1],
                         modes=["sim", "twb"], robot_radius=0.045))
        s.add_all([Run(id=k, experiment_id=1, mode="sim", repetition=k) for k in (1, 2)])
    yield sessions
    engine.dispose()
