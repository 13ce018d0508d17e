"""An agent host in a process of its own for the live benchmarks: ``twb agent`` started, its ports read, its CPU.

The host is the real command line (``python -m twb agent ...``); its log goes to a temporary file, read
for the ports line, so that a long run never fills a pipe nobody reads.  CPU time is read from
``/proc/<pid>/stat`` (user + system, every thread of the process).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["AgentProcess", "cpu_seconds"]

ROOT = Path(__file__).resolve().parents[1]
_PORTS = re.compile(r"ports \[([\d, ]+)\]")


def cpu_seconds(pid: int) -> float:
    """CPU time (s, user + system) process ``pid`` has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class AgentProcess:
    """``twb agent`` with ``args`` (``--port 0`` is added) as a child process; a context manager.

    ``ports`` are its robots' ports once started; :meth:`cpu` its CPU seconds so far.
    """

    def __init__(self, args: list[str], *, ready_timeout_s: float = 120.0) -> None:
        self.args = args
        self.ready_timeout_s = ready_timeout_s
        self.ports: list[int] = []
        self._log = tempfile.NamedTemporaryFile("w+", prefix="twb-agent-", suffix=".log", delete=False)
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> "AgentProcess":
        self.proc = subprocess.Popen([sys.executable, "-m", "twb", "agent", "--port", "0", *self.args],
                                     stdout=subprocess.DEVNULL, stderr=self._log, cwd=ROOT)
        deadline = time.monotonic() + self.ready_timeout_s
        while not self.ports:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                text = self.log()[-2000:]
                self.__exit__(None, None, None)
                raise SystemExit(f"the agent did not start: {text}")
            m = _PORTS.search(self.log())
            if m:
                self.ports = [int(p) for p in m.group(1).split(",")]
            else:
                time.sleep(0.1)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        os.unlink(self._log.name)

    def log(self) -> str:
        """The host's log so far."""
        return Path(self._log.name).read_text(errors="replace")

    def cpu(self) -> float:
        """CPU seconds the host has used so far."""
        assert self.proc is not None
        return cpu_seconds(self.proc.pid)
