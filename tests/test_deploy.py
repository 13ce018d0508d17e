"""Deployment files: docker-compose.yml is valid, and its agent command lines work for real."""

import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from servers import TOKEN, TWB, Process

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("docker-compose") is None,
                    reason="docker-compose is not installed (Debian: apt-get install --no-install-recommends docker-compose)")
@pytest.mark.slow
def test_compose_file_is_valid():
    out = subprocess.run(["docker-compose", "-f", "docker-compose.yml", "config"], cwd=ROOT, capture_output=True,
                         text=True, env={**os.environ, "TWB_TOKEN": "compose-test-token"}, timeout=60)
    assert out.returncode == 0, out.stderr
    for service in ("postgres", "server", "field-1", "field-2", "field-3", "field-4", "sim"):
        assert re.search(rf"^  {re.escape(service)}:$", out.stdout, re.M), service
    assert "compose-test-token" in out.stdout
    # the server stores on PostgreSQL and waits until it is healthy
    assert "TWB_DATABASE_URL: postgresql+psycopg://twb:" in out.stdout and "@postgres:5432/twb" in out.stdout
    assert re.search(r"depends_on:\s+postgres:\s+condition: service_healthy", out.stdout)
    assert "pg_isready" in out.stdout
    missing = subprocess.run(["docker-compose", "-f", "docker-compose.yml", "config"], cwd=ROOT,
                             capture_output=True, text=True, env={k: v for k, v in os.environ.items()
                                                                   if k != "TWB_TOKEN"}, timeout=60)
    assert missing.returncode != 0 and "TWB_TOKEN" in missing.stderr


def compose_commands() -> dict[str, list[str]]:
    """Each service's command list, read from docker-compose.yml (flow-style lists)."""
    text = (ROOT / "docker-compose.yml").read_text()
    services = text[text.index("\nservices:\n"):text.index("\nvolumes:")]
    out = {}
    for chunk in re.split(r"^  (?=[\w-]+:$)", services, flags=re.M)[1:]:
        name = chunk.split(":", 1)[0]
        m = re.search(r"command: \[(.*?)\]", chunk, re.S)
        if m:
            out[name] = [a.replace("${TWB_TIME_SCALE:-1}", "max") for a in re.findall(r'"([^"]*)"', m.group(1))]
    return out


@pytest.mark.slow
def test_compose_agent_commands_register_on_their_subfields(tmp_path):
    cmds = compose_commands()
    assert set(cmds) == {"server", "field-1", "field-2", "field-3", "field-4", "sim"}
    server = Process(["server"], tmp_path)
    agents = []
    try:
        for name in ("field-2", "sim"):
            args = cmds[name]
            args = [server.url if a == "http://server:8000" else a for a in args]
            args[args.index("--port") + 1] = "0"
            args[args.index("--advertise-host") + 1] = "127.0.0.1"
            args[args.index("--host") + 1] = "127.0.0.1"
            agents.append(subprocess.Popen([str(TWB), *args], env={**os.environ, "TWB_TOKEN": TOKEN},
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with server.client() as c:
            deadline = time.monotonic() + 30
            while len(robots := c.get("/api/v1/robots").json()["data"]) < 5:
                assert time.monotonic() < deadline, robots
                time.sleep(0.2)
            by_id = {r["robot_id"]: r for r in robots}
            assert by_id["field-2"]["subfield"] == 2 and by_id["field-2"]["origin"] == [1.8, 0.0]
            assert sorted(r for r in by_id if r.startswith("sim")) == ["sim-1", "sim-2", "sim-3", "sim-4"]
            assert all(by_id[f"sim-{i}"]["area"] == [3.6, 3.6] for i in range(1, 5))
            job = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0], "modes": ["twb", "sim"]}
            exp = c.post("/api/v1/experiments", json=job).json()
            from servers import wait_for

            done = wait_for(c, exp["id"], timeout=60)
            assert done["status"] == "completed", done["runs"]
            assert {r["robot_id"] for r in done["runs"]} <= {"field-2", "sim-1", "sim-2", "sim-3", "sim-4"}
    finally:
        for a in agents:
            a.terminate()
            a.wait(10)
        server.stop()
