"""Shared fixtures: running the real ``twb`` console script, the session's testbeds, PostgreSQL, Ray, the
sandbox's probe; the markers that follow from them (docs/design.md, "Tests").

Markers (registered in pyproject.toml, ``--strict-markers``; ``make test-fast`` runs the tests without any of them):

- ``browser``: the test uses the ``browser`` fixture (Chromium through Playwright; tests/test_dashboard.py);
- ``postgres``: it uses the ``postgres`` fixture, or the ``postgresql`` kind of ``database_url``;
- ``ray``: it uses the ``ray`` fixture;
- ``slow``: it uses the ``testbeds`` factory, or is marked by hand (``@pytest.mark.slow``, or its module's
  ``pytestmark``) because it starts a ``servers.Process`` itself.  tests/servers.Process refuses to start a
  testbed for a test without it, so a forgotten mark fails ``make test-fast`` at once.

The markers are applied here from the fixtures a test uses (directly or through other fixtures), so that a new
test cannot forget them.

A new test module that needs a running testbed takes it from the factory (tests/servers.Testbeds), never with
its own ``Process`` in a module fixture::

    from servers import STANDARD

    @pytest.fixture(scope="module")
    def testbed(testbeds):
        yield from testbeds.module(*STANDARD)   # shared: the worker's `twb up --time-scale max --sim-robots 2`

    @pytest.fixture(scope="module")
    def uploads(testbeds):                      # its own, with these flags, stopped when the module ends
        yield from testbeds.own("up", "--time-scale", "max", "--sim-robots", "4", "--enable-uploads")

On a shared testbed a module names its environments and users uniquely, finds its experiments by id and counts
only what it made (other modules of the same worker ran on it before); the factory cancels what a module leaves
queued or running and fails the module if the testbed wrote a traceback.
"""
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


#: a fixture a test uses (directly or through other fixtures) -> the marker it gets
MARKED_FIXTURES = {"browser": "browser", "postgres": "postgres", "ray": "ray", "testbeds": "slow"}


#: the modules that take longest (``pytest --durations``, 2 cores; test_calibration is the longest since its latency
#: checks, 156 s of the suite's 1916 s on 2026-11-28, and runs third), longest first: they run first, so that the
#: parallel workers end together instead of one of them finishing a long module alone (``make test`` runs
#: ``-n 2 --dist loadfile --no-loadscope-reorder``: without that flag xdist sorts modules by test count instead)
LONGEST_FIRST = ("test_api_fuzz", "test_testbed", "test_calibration", "test_lifecycle", "test_controller_programs",
                 "test_study", "test_ray", "test_postgres", "test_dashboard", "test_uploads", "test_agent_hosts",
                 "test_lockstep_programs", "test_docs_commands", "test_dashboard_newuser", "test_controller_flood",
                 "test_per_run_plans", "test_world_studies", "test_fleet_rest", "test_study_fleet", "test_security")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        used = set(getattr(item, "fixturenames", ()))
        for fixture, marker in MARKED_FIXTURES.items():
            if fixture in used:
                item.add_marker(marker)
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    # a stable sort: every module's tests stay together and in their order; the rest keep theirs after these
    items.sort(key=lambda item: rank.get(item.path.stem, len(rank)))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem):  # type: ignore[no-untyped-def]
    """Note the running test for tests/servers.Process (module fixtures start during a test's set-up)."""
    import servers

    servers.current_test = item
    try:
        return (yield)
    finally:
        servers.current_test = None


@pytest.fixture(scope="session")
def testbeds(tmp_path_factory):
    """The session's shared testbeds (tests/servers.Testbeds): ``testbeds.module("up", "--time-scale", "max",
    ...)`` in a module fixture yields the one running ``twb up`` with those flags on this worker, started at first
    use; all stop at the end of the session (cleanly, or the last test errors)."""
    from servers import Testbeds

    started = Testbeds(tmp_path_factory.mktemp)
    yield started
    started.stop_all()


@pytest.fixture(scope="session")
def ray():
    """The ``ray`` package, for the tests of the simulation pool on Ray; skipped where it is not installed (an
    optional extra; ``make test`` installs it with the dev extra)."""
    return pytest.importorskip("ray", reason="Ray is an optional extra (make test installs it with the dev extra)")


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


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
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
