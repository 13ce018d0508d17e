"""Real testbed processes for tests: `twb server` / `twb up` on 127.0.0.1 with a temporary data dir."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx

TWB = Path(sys.executable).with_name("twb")
TOKEN = "test-admin-token"


class Process:
    """A running `twb` server; ``url``, ``token``, ``client()``; ``stop()`` sends SIGINT like Ctrl-C."""

    def __init__(self, args: list[str], data_dir: Path, timeout: float = 60.0) -> None:
        self.data_dir = data_dir
        self.token = TOKEN
        self.log = data_dir / "stdout.log"
        data_dir.mkdir(parents=True, exist_ok=True)
        self._out = open(self.log, "w")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen([str(TWB), *args, "--port", "0", "--data-dir", str(data_dir), "--token", TOKEN],
                                     stdout=self._out, stderr=subprocess.STDOUT, env=env)
        deadline = time.monotonic() + timeout
        self.url = ""
        while time.monotonic() < deadline:
            text = self.log.read_text()
            m = re.search(r"(http://127\.0\.0\.1:\d+)", text)
            if m and ("Ctrl-C" in text or "API docs" in text):
                self.url = m.group(1)
                break
            if self.proc.poll() is not None:
                raise RuntimeError(f"twb {args[0]} exited with {self.proc.returncode}:\n{text}")
            time.sleep(0.1)
        else:
            self.stop()
            raise RuntimeError(f"twb {args[0]} did not start within {timeout} s:\n{self.log.read_text()}")

    def client(self, token: str | None = TOKEN, **kw) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30, **kw)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._out.close()
        return self.proc.returncode

    def output(self) -> str:
        return self.log.read_text()


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
