"""The commands of README.md's "Without a server" and docs/sdk.md's ``send_path`` example, run as written.

Each ``console`` block is read from the Markdown: ``$ `` lines are commands, the lines under them what
they print (``...`` stands for any lines, or any text at the start of a line; numbers may differ).
The commands run with ``bash`` in a scratch directory, with this environment's ``twb`` first on PATH,
against real processes.  Two adaptations, both printed with the test's output:

- the robot port 5555 becomes a free port (tests run in parallel on shared machines);
- ``nc -q 1`` is Debian's netcat when it is installed and understands ``-q``; otherwise
  ``examples/send_lines.py``, the stand-in README.md itself names.

A command ending in ``&`` runs in the background until its printed line (the agent's port) appears.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e-?\d+)?")


@dataclass
class Step:
    """One ``$`` command of a console block and the lines printed under it."""

    command: str
    expected: list[str] = field(default_factory=list)

    @property
    def background(self) -> bool:
        return self.command.rstrip().endswith("&")


def markdown_section(path: Path, heading: str) -> str:
    """The text of the section under ``heading`` (up to the next heading of the same level)."""
    text = path.read_text()
    level = heading.split(" ")[0]
    start = text.index(heading + "\n")
    rest = text[start + len(heading) + 1:]
    nxt = re.search(rf"^{re.escape(level)} ", rest, re.M)
    return rest[: nxt.start()] if nxt else rest


def fenced_blocks(section: str, lang: str) -> list[str]:
    """The bodies of the ```` ```lang ```` blocks of a section, in order."""
    return re.findall(rf"^```{lang}\n(.*?)^```", section, re.S | re.M)


def console_steps(block: str) -> list[Step]:
    """The commands of a console block with what each prints."""
    steps: list[Step] = []
    for line in block.splitlines():
        if line.startswith("$ "):
            steps.append(Step(line[2:]))
        elif steps:
            steps[-1].expected.append(line)
    return steps


def line_pattern(expected: str) -> re.Pattern[str]:
    """A printed line as a pattern: ``...`` at its start is any text, numbers are any number."""
    prefix = ""
    if expected.startswith("... "):
        prefix, expected = ".*", expected[4:]
    parts = NUMBER.split(expected)
    body = NUMBER.pattern.join(re.escape(p) for p in parts)
    return re.compile(f"^{prefix}{body}$")


def unmatched(expected: list[str], printed: list[str]) -> list[str]:
    """Expected lines (in order; ``...`` skips any lines) not found in ``printed``; lines starting with
    ``#`` (notes on stderr, whose place among the others is not fixed) only need to appear somewhere."""
    missing, i = [], 0
    for exp in expected:
        if exp.strip() == "...":
            continue
        pat = line_pattern(exp)
        if exp.startswith("#"):
            if not any(pat.match(p) for p in printed):
                missing.append(exp)
            continue
        while i < len(printed) and not pat.match(printed[i]):
            i += 1
        if i == len(printed):
            missing.append(exp)
        else:
            i += 1
    return missing


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def netcat_understands_q() -> bool:
    nc = shutil.which("nc")
    if nc is None:
        return False
    out = subprocess.run([nc, "-h"], capture_output=True, text=True, timeout=10)
    return re.search(r"(^|[\s\[])-q\b", out.stdout + out.stderr, re.M) is not None


class Shell:
    """Runs documented commands as written in ``cwd`` (two adaptations, see the module's docstring)."""

    def __init__(self, cwd: Path, port: int) -> None:
        self.cwd, self.port = cwd, port
        self.env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", "PYTHONUNBUFFERED": "1"}
        self.env.pop("TWB_DEBUG", None)
        self.use_nc = netcat_understands_q()
        self.background: list[subprocess.Popen] = []
        print(f"docs commands: robot port 5555 -> {port}; "
              + ("nc -q 1 is Debian's netcat" if self.use_nc else "nc is absent (or has no -q): examples/send_lines.py"))

    def adapt(self, command: str) -> str:
        command = command.replace("5555", str(self.port))
        if not self.use_nc:
            command = command.replace("nc -q 1 ", f"{sys.executable} {ROOT / 'examples' / 'send_lines.py'} ")
        return command

    def run(self, step: Step, timeout: float = 180) -> list[str]:
        """Run a step; the lines it printed (stdout and stderr)."""
        command = self.adapt(step.command)
        if step.background:
            return self.start(command.rstrip().rstrip("&"), step.expected)
        r = subprocess.run(["bash", "-c", command], cwd=self.cwd, env=self.env, capture_output=True, text=True,
                           timeout=timeout)
        assert r.returncode == 0, f"`{command}` exited with {r.returncode}:\n{r.stdout}\n{r.stderr}"
        return r.stdout.splitlines() + r.stderr.splitlines()

    def start(self, command: str, expected: list[str], timeout: float = 120) -> list[str]:
        """Start a background command; return once it printed its expected lines."""
        proc = subprocess.Popen(["bash", "-c", f"exec {command}"], cwd=self.cwd, env=self.env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
        self.background.append(proc)
        printed: list[str] = []
        deadline = time.monotonic() + timeout
        while unmatched(expected, printed) and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            printed.append(line.rstrip("\n"))
        return printed

    def stop(self) -> None:
        for proc in self.background:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(30)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()


@pytest.fixture
def shell(tmp_path):
    sh = Shell(tmp_path, free_port())
    yield sh
    sh.stop()


def documented_metrics(expected: list[str]) -> dict[str, float]:
    """The numbers README.md shows in the metrics' JSON (``"key": value`` lines)."""
    out = {}
    for line in expected:
        m = re.match(r'^\s*"(\w+)": (-?[\d.]+),?$', line)
        if m:
            out[m.group(1)] = float(m.group(2))
    return out


@pytest.mark.slow
def test_readme_without_a_server(shell):
    section = markdown_section(ROOT / "README.md", "## Without a server")
    steps = console_steps(fenced_blocks(section, "console")[0])
    assert [s.command.split()[1] for s in steps] == ["demo", "agent", "T,T,I,300,300,0;", "plan", "metrics"], steps
    printed = {}
    for step in steps:
        printed[step.command] = out = shell.run(step)
        assert unmatched(step.expected, out) == [], (step.command, out)
    session = printed[steps[2].command]
    # the robot was placed at the path's start, then drove the whole path
    assert session[session.index("OK,I") + 1].startswith("OK,P,")
    assert any(line.startswith("EV,DONE,") for line in session)
    metrics = json.loads("\n".join(printed[steps[4].command]))
    assert metrics["goal_reached"] is True and metrics["collided"] is False
    assert 1.0 <= metrics["length_ratio"] < 1.15, metrics  # 1.25 when the robot drove from (0.1, 0.1) first
    assert metrics["hausdorff_m"] < 0.05, metrics  # 0.28 m then
    shown = documented_metrics(steps[4].expected)
    assert set(shown) >= {"length_m", "length_ratio", "hausdorff_m"}
    for key, value in shown.items():  # what README.md shows is what it prints
        assert metrics[key] == pytest.approx(value, rel=0.05, abs=0.005), key
    planned = (shell.cwd / "planned.csv").read_text().splitlines()
    assert planned[0] == "t,x,y,theta" and not any(line.startswith("#") for line in planned)


@pytest.mark.slow
def test_sdk_send_path_example(shell):
    section = markdown_section(ROOT / "docs" / "sdk.md", "## The raw way: a path over TCP")
    agent = console_steps(fenced_blocks(section, "console")[0])
    assert len(agent) == 1 and agent[0].background
    shell.run(Step(agent[0].command, ["... 1 field robot(s) (bebot) on 127.0.0.1 ports [5555], time scale 1.0, seed 0"]))
    code = fenced_blocks(section, "python")[0]
    comment = re.search(r"#\s*(OK,P,.*)$", code, re.M).group(1).strip()
    r = subprocess.run([sys.executable, "-c", shell.adapt(code)], capture_output=True, text=True, timeout=120,
                       cwd=shell.cwd)
    assert r.returncode == 0, r.stderr
    assert unmatched([comment], r.stdout.splitlines()) == [], (comment, r.stdout)
    documented = float(NUMBER.findall(comment)[-1])
    assert float(NUMBER.findall(r.stdout)[-1]) == pytest.approx(documented, abs=0.2), r.stdout
