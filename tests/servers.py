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


class Process(LocalTestbed):
    """A running `twb` server for tests (the project's :class:`~twb.launch.LocalTestbed`), token ``TOKEN``."""

    def __init__(self, args: list[str], data_dir: Path, timeout: float = 300.0, env: dict | None = None) -> None:
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
