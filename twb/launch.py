"""A local testbed as a child process: `twb up` (or `twb server`) on 127.0.0.1 and a free port.

Used by ``twb study --embedded``, the benchmarks and the tests::

    with LocalTestbed(Path("data"), "--time-scale", "max") as tb:
        print(tb.url, tb.token)
"""

from __future__ import annotations

import os
import re
import secrets
import signal
import subprocess
import sys
import time
import weakref
from pathlib import Path
from typing import Optional

from .datadir import make_data_dir

__all__ = ["LaunchError", "LocalTestbed"]


class LaunchError(RuntimeError):
    """The testbed process exited or did not come up in time; the message says why."""


class LocalTestbed:
    """``twb <command> --port 0 --data-dir DATA_DIR --token TOKEN *args`` as a child process.

    ``env``: variables added to this process's environment for it.  ``url`` is
    known once the process printed it; a process that exits first is reported at once, one that prints no
    address within ``timeout`` seconds (300: a first start compiles kernels, slowly on a busy machine) is
    stopped.  ``stop()`` sends SIGINT (Ctrl-C) and waits, killing it after ``timeout`` seconds.
    """

    def __init__(self, data_dir: Path, *args: str, command: str = "up", token: Optional[str] = None,
                 timeout: float = 300.0, env: Optional[dict[str, str]] = None) -> None:
        self.data_dir = make_data_dir(Path(data_dir))
        self.token = token or secrets.token_urlsafe(24)
        self.log = self.data_dir / "stdout.log"
        self._out = open(self.log, "w")
        cmd = [sys.executable, "-m", "twb", command, "--port", "0", "--data-dir", str(self.data_dir),
               "--token", self.token, *args]
        # the testbed ends with this process, however this one ends (TWB_EXIT_WITH_PARENT), and at the
        # latest when this object is collected or the interpreter exits
        self.proc = subprocess.Popen(cmd, stdout=self._out, stderr=subprocess.STDOUT,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1", "TWB_EXIT_WITH_PARENT": "1",
                                          **(env or {})})
        weakref.finalize(self, _kill, self.proc)
        self.url = ""
        deadline = time.monotonic() + timeout
        while not self.url:
            text = self.output()
            m = re.search(r"(http://127\.0\.0\.1:\d+)", text)
            if m and ("Ctrl-C" in text or "API docs" in text):
                self.url = m.group(1)
            elif self.proc.poll() is not None:
                self._out.close()
                raise LaunchError(f"twb {command} exited with status {self.proc.returncode}: "
                                  f"{_last_line(text)} (log: {self.log})")
            elif time.monotonic() > deadline:
                self.stop()
                raise LaunchError(f"twb {command} did not start within {timeout:g} s (log: {self.log})")
            else:
                time.sleep(0.1)

    def output(self) -> str:
        """Everything the process printed so far."""
        return self.log.read_text()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        """Stop the process (Ctrl-C by default); returns its exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if not self._out.closed:
            self._out.close()
        return self.proc.returncode

    def __enter__(self) -> "LocalTestbed":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _kill(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def _last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "(no output)"
