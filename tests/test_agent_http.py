"""The agent's HTTP contract with the testbed server, against a real HTTP server on 127.0.0.1."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
from agent_support import LineClient, running_agents

from contract.protocol import encode_path, encode_place
from robot_agent.host.server_link import ServerLink

TOKEN = "s3cret-token"


class Recorder:
    """A stdlib HTTP server in a thread that records POSTs and answers with scripted statuses."""

    def __init__(self, statuses: list[int] | None = None) -> None:
        self.requests: list[tuple[str, dict, dict]] = []
        self.statuses = list(statuses or [])
        rec = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 - stdlib API
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                status = rec.statuses.pop(0) if rec.statuses else 202
                if status < 300:
                    rec.requests.append((self.path, dict(self.headers), body))
                self.send_response(status)
                self.send_header("Content-Length", "2")
                self.end_headers()
                self.wfile.write(b"{}")

            def log_message(self, *args: object) -> None:
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True)

    def __enter__(self) -> "Recorder":
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def bodies(self, path: str) -> list[dict]:
        return [b for p, _, b in self.requests if p == path]


async def test_registration_and_tracker_batches_reach_the_server():
    with Recorder() as server:
        async with running_agents(backend="field", robots=2, tracker_sink=None, server_url=server.url + "/",
                                  token=TOKEN) as agents:
            c = await LineClient.connect(agents.ports[1])
            assert await c.ask("T,T,A," + agents.robots[1].control_key) == "OK,A"  # as the server does
            await c.ask(encode_place((0.3, 0.3, 0.0)))
            await c.ask(encode_path(np.array([[0.3, 0.3, 0.0], [0.7, 0.3, 0.0]])))
            await c.until("EV,DONE")
            await c.close()
            await agents.flush_tracker()
        regs = server.bodies("/api/v1/robots")
        assert sorted(r["robot_id"] for r in regs) == ["robot-1", "robot-2"]
        r2 = next(r for r in regs if r["robot_id"] == "robot-2")
        assert r2 == {"robot_id": "robot-2", "host": "127.0.0.1", "port": agents.ports[1], "platform": "BeBot",
                      "backend": "field", "profile": "bebot", "origin": [1.8, 0.0], "area": [1.8, 1.8]}
        assert all(h["Authorization"] == f"Bearer {TOKEN}" for _, h, _ in server.requests)
        batches = server.bodies("/api/v1/tracker/poses")
        assert batches and {b["robot_id"] for b in batches} == {"robot-2"}
        poses = np.array([p for b in batches for p in b["poses"]])
        assert poses.shape[1] == 4 and (np.diff(poses[:, 0]) > 0).all()
        assert 0.25 < poses[:, 1].min() and poses[:, 1].max() < 0.75  # metres, robot frame


async def test_server_errors_are_retried_and_refusals_dropped(caplog):
    caplog.set_level(logging.WARNING, "robot_agent.host.server_link")
    with Recorder(statuses=[503, 500, 202, 401]) as server:
        link = ServerLink(server.url, TOKEN, retry_initial_s=0.01)
        link.register({"robot_id": "r"})
        await link.send("r", np.array([[0.0, 0.1, 0.2, 0.3]]))
        assert await link.flush(5.0)
        await link.aclose()
    assert server.bodies("/api/v1/robots") == [{"robot_id": "r"}]
    assert server.bodies("/api/v1/tracker/poses") == []  # 401: refused for good, dropped
    assert link.registered == {"r"}
    assert "HTTP 503 (will retry)" in caplog.text and "refused: HTTP 401" in caplog.text


async def test_unreachable_server_never_crashes_the_agent(caplog):
    caplog.set_level(logging.WARNING, "robot_agent.host.server_link")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{s.getsockname()[1]}"
    async with running_agents(backend="ideal", tracker_sink=None, server_url=dead, token=TOKEN) as agents:
        c = await LineClient.connect(agents.ports[0])
        assert await c.ask("T,T,A," + agents.robots[0].control_key) == "OK,A"
        await c.ask(encode_path(np.array([[0.1, 0.1, 0.0], [0.3, 0.1, 0.0]])))
        await c.until("EV,DONE")
        assert (await c.ask("T,T,Q")).startswith("ST,DONE")
        await c.close()
        await asyncio.sleep(0.05)
        assert agents.link is not None and not agents.link.registered
    assert "will retry" in caplog.text


def test_server_url_needs_a_token():
    from robot_agent.host import AgentHost

    with pytest.raises(ValueError, match="token"):
        AgentHost(server_url="http://127.0.0.1:9")
