"""Real testbed processes for tests: `twb server` / `twb up` on 127.0.0.1 with a temporary data dir."""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

import httpx

from contract.vocabulary import TERMINAL
from twb.launch import LocalTestbed

TWB = Path(sys.executable).with_name("twb")
TOKEN = "test-admin-token"
#: the flags of the testbed most modules share (:class:`Testbeds`): four field robots, two simulated, at full speed
STANDARD = ("up", "--time-scale", "max", "--sim-robots", "2")


#: the test being set up or run (tests/conftest.py keeps it): a testbed process started for a test that is not
#: marked ``slow`` is refused, so that ``make test-fast`` (``-m "not slow ..."``) cannot start one by mistake
current_test = None


class Process(LocalTestbed):
    """A running `twb` server for tests (the project's :class:`~twb.launch.LocalTestbed`), token ``TOKEN``."""

    def __init__(self, args: list[str], data_dir: Path, timeout: float = 300.0, env: dict | None = None) -> None:
        if current_test is not None and current_test.get_closest_marker("slow") is None:
            raise RuntimeError(f"{current_test.nodeid} starts `twb {' '.join(args)}`, a real testbed process: mark it "
                               "slow (@pytest.mark.slow, or use the `testbeds` fixture), `make test-fast` leaves "
                               "those out")
        super().__init__(data_dir, *args[1:], command=args[0], token=TOKEN, timeout=timeout, env=env)

    def client(self, token: str | None = TOKEN, **kw) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30, **kw)


def serve(args: list[str], data_dir: Path, **kw):  # type: ignore[no-untyped-def]
    """A module fixture's body: the testbed ``args`` start in ``data_dir`` and are yielded; afterwards they must
    stop cleanly, without a traceback in their output."""
    p = Process(args, data_dir, **kw)
    yield p
    assert p.stop() == 0, p.output()
    assert "Traceback" not in p.output(), p.output()


class Testbeds:
    """The session's shared testbeds (the ``testbeds`` fixture of tests/conftest.py): one started process per set of
    flags (``twb`` arguments and environment variables), reused by every module of this pytest worker that asks for
    the same flags.

    A module's fixture takes one with :meth:`module`::

        @pytest.fixture(scope="module")
        def testbed(testbeds):
            yield from testbeds.module("up", "--time-scale", "max", "--sim-robots", "2")

    Modules share it one after the other (a worker runs one test at a time), so a module must not depend on being
    alone on it: it names its users and environments uniquely, finds its experiments by id, and counts only what it
    made.  A module that changes the testbed for everyone after it (its robots, its time scale, its settings) or
    needs it empty starts its own with :meth:`own` (stopped at the end of the module) and says why::

        @pytest.fixture(scope="module")
        def testbed(testbeds):  # its own: uploads enabled, sixteen simulated robots
            yield from testbeds.own("up", "--time-scale", "max", "--sim-robots", "16", "--enable-uploads")
    """

    def __init__(self, make_dir) -> None:  # type: ignore[no-untyped-def]
        self._make_dir = make_dir
        self._started: dict[tuple, Process] = {}

    def get(self, *args: str, env: dict[str, str] | None = None, timeout: float = 300.0) -> Process:
        """The running testbed ``twb ARGS`` (``env`` added to its environment), started on first use."""
        key = (args, tuple(sorted((env or {}).items())))
        p = self._started.get(key)
        if p is None:
            p = self._started[key] = Process(list(args), self._make_dir("testbed"), timeout=timeout, env=env)
        assert p.proc.poll() is None, f"the shared testbed `twb {' '.join(args)}` has ended: {p.output()}"
        return p

    def module(self, *args: str, env: dict[str, str] | None = None, timeout: float = 300.0):  # type: ignore[no-untyped-def]
        """A module fixture's body: the shared testbed ``twb ARGS`` is yielded; afterwards its output since then
        must hold no traceback, and the experiments the module left queued or running are cancelled, so that the
        next module finds the testbed idle."""
        p = self.get(*args, env=env, timeout=timeout)
        start = len(p.output())
        yield p
        assert p.proc.poll() is None, f"the shared testbed `twb {' '.join(args)}` has ended: {p.output()}"
        with p.client() as c:
            active = [e["id"] for e in c.get("/api/v1/experiments", params={"limit": 500}).json()["data"]
                      if e["status"] not in TERMINAL]
            if active:
                c.post("/api/v1/experiments/cancel", json={"ids": active}).raise_for_status()
        tail = p.output()[start:]
        assert "Traceback" not in tail, tail

    def own(self, *args: str, env: dict[str, str] | None = None, timeout: float = 300.0):  # type: ignore[no-untyped-def]
        """A module fixture's body for a testbed this module does not share (unusual flags, or it changes the
        testbed for everyone after it): ``twb ARGS`` starts in a fresh data directory and is yielded; afterwards it
        must stop cleanly, without a traceback in its output.  Through this factory the module's tests are marked
        ``slow`` like those of a shared testbed."""
        yield from serve(list(args), self._make_dir("own-testbed"), timeout=timeout, env=env)

    def stop_all(self) -> None:
        """Stop every testbed started; each must stop cleanly, without a traceback in its output."""
        failed = []
        for args, env in self._started:
            p = self._started[args, env]
            if p.stop() != 0 or "Traceback" in p.output():
                failed.append(f"`twb {' '.join(args)}` (exit {p.proc.returncode}):\n{p.output()}")
        self._started.clear()
        assert not failed, "\n".join(failed)


def wait_for(client: httpx.Client, experiment_id: int, timeout: float = 60.0, terminal=None) -> dict:
    """Poll an experiment until it reaches a terminal state."""
    terminal = terminal or TERMINAL
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        exp = client.get(f"/api/v1/experiments/{experiment_id}").json()
        if exp["status"] in terminal:
            return exp
        time.sleep(0.1)
    raise AssertionError(f"experiment {experiment_id} still {exp['status']} after {timeout} s: {exp}")


def submit_watched(testbed, client: httpx.Client, job: dict, timeout: float = 120.0) -> tuple[dict, list[dict]]:  # type: ignore[no-untyped-def]
    """Submit ``job`` with the event stream read from before it is queued, and wait for it to end: the
    experiment and every event seen until its end (:class:`EventListener`)."""
    submitted: dict = {}
    listener = EventListener(testbed.url, testbed.token,
                             until=lambda e: e["event"] == "experiment" and e["experiment"]["id"] == submitted.get("id")
                             and e["experiment"]["status"] in TERMINAL)
    submitted.update(client.post("/api/v1/experiments", json=job).json())
    exp = wait_for(client, submitted["id"], timeout=timeout)
    listener.join(10)
    listener.stop()
    return exp, listener.seen


class EventListener:
    """``GET /api/v1/events`` read in a thread: every event in ``seen`` (``{"event": kind, **data}``) until
    ``until(event)`` says so or :meth:`stop` is called (it returns at the next event)."""

    def __init__(self, url: str, token: str, until=lambda event: False) -> None:  # type: ignore[no-untyped-def]
        self.seen: list[dict] = []
        self.ready, self._done = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._listen, args=(url, token, until), daemon=True)
        self._thread.start()
        assert self.ready.wait(10), "the event stream did not start"

    def _listen(self, url: str, token: str, until) -> None:  # type: ignore[no-untyped-def]
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=60) as c:
            with c.stream("GET", "/api/v1/events") as resp:
                kind = None
                for line in resp.iter_lines():
                    self.ready.set()
                    if line.startswith("event: "):
                        kind = line[7:]
                    elif line.startswith("data: "):
                        self.seen.append({"event": kind, **json.loads(line[6:])})
                        if until(self.seen[-1]):
                            return
                    if self._done.is_set():
                        return

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)

    def stop(self) -> None:
        self._done.set()
