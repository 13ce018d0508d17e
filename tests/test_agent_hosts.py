"""Agents on many hosts: one `twb server` on PostgreSQL, robot agents as separate processes (stand-ins for
hosts, each with its own agent token) registering over HTTP; a host that vanishes mid-run and comes back.

docs/scale-out.md, "Agents on many hosts", describes the deployment this test runs.
"""

from __future__ import annotations

import signal
import subprocess
import time

import httpx
import pytest

from servers import TWB, Process, wait_for

ROOM_JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708], "planner": "fmm", "seed": 4}


class Host:
    """One agent host: ``twb agent --server URL --token T ...`` in its own process (own session: a host)."""

    def __init__(self, url: str, token: str, *args: str) -> None:
        self.argv = [str(TWB), "agent", "--port", "0", "--time-scale", "5", "--server", url, "--token", token, *args]
        self.start()

    def start(self) -> None:
        """The host (again): its agent process, with the same robots."""
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True)

    def vanish(self) -> None:
        """The host is gone at once (power cut: SIGKILL, no goodbye to the server)."""
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)


def robots(c: httpx.Client) -> dict[str, dict]:
    return {r["robot_id"]: r for r in c.get("/api/v1/robots").json()["data"]}


def wait_until(what, timeout: float, message: str):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not (found := what()):
        assert time.monotonic() < deadline, message
        time.sleep(0.2)
    return found


@pytest.mark.slow
def test_agents_on_several_hosts_share_one_server_and_a_vanished_host_comes_back(tmp_path, postgres):
    server = Process(["server", "--time-scale", "5", "--database-url", postgres.database()], tmp_path / "server")
    hosts: dict[str, Host] = {}
    try:
        with server.client() as c:
            # the lab's hosts get agent tokens of a user of their own (an admin's token may take over any robot)
            assert c.post("/api/v1/users", json={"name": "lab-hosts"}).status_code == 201

            def agent_token() -> str:
                return c.post("/api/v1/users/lab-hosts/tokens", params={"kind": "agent"}).json()["token"]

            # host A: the field robot of sub-field 1 (emulated physical robot); hosts B and C: simulation robots
            hosts["a"] = Host(server.url, agent_token(), "--subfield", "1", "--robot-id", "field-a")
            hosts["b"] = Host(server.url, agent_token(), "--backend", "ideal", "--area", "3.6,3.6",
                              "--robots", "2", "--robot-id", "hostb")
            token_c = agent_token()
            hosts["c"] = Host(server.url, token_c, "--backend", "ideal", "--area", "3.6,3.6", "--robot-id", "hostc")
            fleet = {"field-a", "hostb-1", "hostb-2", "hostc"}
            wait_until(lambda: fleet <= robots(c).keys(), 60, "the hosts' robots did not register")
            pools = {rid: r["pool"] for rid, r in robots(c).items()}
            assert pools == {"field-a": "field", "hostb-1": "sim", "hostb-2": "sim", "hostc": "sim"}

            # a host's token cannot take over another host's robot
            taken = httpx.post(f"{server.url}/api/v1/robots", headers={"Authorization": f"Bearer {token_c}"},
                               json={"robot_id": "hostb-1", "host": "127.0.0.1", "port": 9, "backend": "ideal"})
            assert taken.status_code == 403

            # work spreads over every host: field runs on host A, simulation runs on B and C
            exp = c.post("/api/v1/experiments", json={**ROOM_JOB, "modes": ["sim", "twb"], "repetitions": 3}).json()
            done = wait_for(c, exp["id"], timeout=180)
            assert done["status"] == "completed", done
            by_mode = {m: {r["robot_id"] for r in done["runs"] if r["mode"] == m} for m in ("sim", "twb")}
            assert by_mode["twb"] == {"field-a"} and by_mode["sim"] <= {"hostb-1", "hostb-2", "hostc"}

            # host B vanishes while it runs: its runs are retried on host C, its robots go offline with the reason
            exp2 = c.post("/api/v1/experiments", json={**ROOM_JOB, "modes": ["sim"], "repetitions": 4,
                                                        "seed": 5}).json()
            wait_until(lambda: any(r["status"] == "running" and r["robot_id"].startswith("hostb")
                                   for r in c.get(f"/api/v1/experiments/{exp2['id']}").json()["runs"]),
                       60, "no run started on host B")
            hosts["b"].vanish()
            done2 = wait_for(c, exp2["id"], timeout=180)
            assert done2["status"] == "completed", done2
            retried = [r for r in done2["runs"] if r["attempt"] == 2]
            assert retried, done2["runs"]
            for r in retried:
                assert r["robot_id"] == "hostc" and r["error"].startswith("attempt 1: robot hostb-"), r
            offline = {rid: r for rid, r in robots(c).items() if r["status"] == "offline"}
            assert offline and set(offline) <= {"hostb-1", "hostb-2"}, offline
            assert all(r["status_reason"].startswith("robot hostb-") for r in offline.values()), offline

            # host B comes back (same robot names, new ports, its own token): online again and given work
            hosts["b"].start()
            wait_until(lambda: all(robots(c)[rid]["status"] != "offline" for rid in ("hostb-1", "hostb-2")),
                       60, "host B's robots did not come back online")
            hosts["c"].vanish()  # now only host B can take simulation runs
            exp3 = c.post("/api/v1/experiments", json={**ROOM_JOB, "modes": ["sim"], "repetitions": 2,
                                                        "seed": 6}).json()
            done3 = wait_for(c, exp3["id"], timeout=180)
            assert done3["status"] == "completed", done3
            assert all(r["robot_id"] in ("hostb-1", "hostb-2") for r in done3["runs"]), done3["runs"]
            # host C's going was noticed when a run was sent there: that try is the testbed's, retried
            assert all(r["error"].startswith("attempt 1: robot hostc") for r in done3["runs"] if r["attempt"] == 2)

            # nothing lost: every run of every experiment has its poses and metrics
            for e in (done, done2, done3):
                for r in e["runs"]:
                    assert r["metrics"]["goal_reached"] is True, r
                    assert c.get(f"/api/v1/runs/{r['id']}/poses").json()["count"] > 20
    finally:
        for h in hosts.values():
            h.stop()
        server.stop()

