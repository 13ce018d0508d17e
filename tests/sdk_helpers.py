"""Helpers of the SDK, study and job-command tests: ``twb`` in-process, a real ``twb agent`` process."""

from __future__ import annotations

import contextlib
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from twb.main import main

TWB = Path(sys.executable).with_name("twb")


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


def invoke(capsys, monkeypatch, *args: str, env: dict[str, str | None] | None = None) -> Result:  # type: ignore[no-untyped-def]
    """``twb ARGS`` through the console entry point; ``env`` values None are unset."""
    monkeypatch.delenv("TWB_DEBUG", raising=False)
    for key, value in (env or {}).items():
        if value is None:
            monkeypatch.delenv(key, raising=False)
        else:
            monkeypatch.setenv(key, value)
    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return Result(code, out.out, out.err)


def study_process(testbed, spec: dict, directory: Path, *options: str) -> tuple[subprocess.CompletedProcess, Path]:  # type: ignore[no-untyped-def]
    """``twb study`` of the study file ``spec`` (written to ``directory``) on ``testbed`` (a tests.servers
    Process), its output in ``directory/out``, as a child process; returns the finished process and ``out``."""
    import json
    import os

    path = directory / f"{spec.get('name', 'study')}.json"
    path.write_text(json.dumps(spec))
    out = directory / "out"
    r = subprocess.run([str(TWB), "study", str(path), "--out", str(out), "--url", testbed.url, "--token",
                        testbed.token, *options], capture_output=True, text=True, timeout=300,
                       env={k: v for k, v in os.environ.items() if k != "TWB_DEBUG"})
    return r, out


@contextlib.contextmanager
def agent_process(robot_id: str, *options: str) -> Iterator[int]:
    """One ideal robot (``twb agent --port 0 --time-scale max [options]``); yields its TCP port, stops it
    with Ctrl-C."""
    proc = subprocess.Popen([str(TWB), "agent", "--port", "0", "--backend", "ideal", "--time-scale", "max",
                             "--robot-id", robot_id, *options], stderr=subprocess.PIPE, text=True)
    try:
        port = None
        while port is None:
            line = proc.stderr.readline()
            if not line:
                raise RuntimeError(f"twb agent exited early with {proc.poll()}")
            m = re.search(r"ports? \[(\d+)", line)
            port = int(m.group(1)) if m else None
        yield port
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(30)
        finally:  # a test that fails here leaves no agent behind
            proc.kill()
            proc.wait()
