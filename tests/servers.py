"""Real testbed processes for tests: `twb server` / `twb up` on 127.0.0.1 with a temporary data dir."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import httpx

from twb.launch import LocalTestbed

TWB = Path(sys.executable).with_name("twb")
TOKEN = "test-admin-token"


class Process(LocalTestbed):
    """A running `twb` server for tests (the project's :class:`~twb.launch.LocalTestbed`), token ``TOKEN``."""

    def __init__(self, args: list[str], data_dir: Path, timeout: float = 60.0, env: dict | None = None) -> None:
        super().__init__(data_dir, *args[1:], command=args[0], token=TOKEN, timeout=timeout, env=env)

    def client(self, token: str | None = TOKEN, **kw) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30, **kw)


def wait_for(client: httpx.Client, experiment_id: int, timeout: float = 60.0, terminal=None) -> dict:
    """Poll an experiment until it reaches a terminal state."""
    terminal = terminal or {"completed", "failed", "error", "cancelled", "interrupted"}
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        exp = client.get(f"/api/v1/experiments/{experiment_id}").json()
        if exp["status"] in terminal:
            return exp
        time.sleep(0.1)
    raise AssertionError(f"experiment {experiment_id} still {exp['status']} after {timeout} s: {exp}")
