"""Uploaded planner programs on a real `twb up --enable-uploads`: good ones complete, bad ones fail with the reason.

Every program of the batch is uploaded and submitted at once, so the bad
ones run side by side with good jobs (a built-in planner's and the good
programs'), all under small limits (5 s wall, 1 s CPU, 160 MiB, 12
processes).
"""

from __future__ import annotations

import base64
import os
import random
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from server.sandbox import cgroups, explain
from server.sandbox.outcome import memory_full
from servers import Process, wait_for

DOCS = Path(__file__).resolve().parent.parent / "docs" / "uploads.md"
ROOT = Path(__file__).resolve().parent.parent
START, GOAL = [0.3, 0.3, 0.0], [1.5, 1.5, 1.5708]
# one block in the middle: the straight line collides, the detour along the walls is free
DETOUR = {"name": "detour", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.4, "h": 0.4, "angle": 0.0}]}
UID_BASE = 3_100_000 + random.randrange(0, 800) * 1000  # this run's sandbox uids (other test runs use others)
LIMITS = {"TWB_SANDBOX_WALL_S": "5", "TWB_SANDBOX_CPU_S": "1", "TWB_SANDBOX_MEMORY_MB": "160",
          "TWB_SANDBOX_PROCESSES": "12", "TWB_SANDBOX_WORKERS": "8", "TWB_SANDBOX_OUTPUT_KIB": "8",
          "TWB_MAX_PROGRAM_BYTES": str(256 << 10), "TWB_SANDBOX_UID_BASE": str(UID_BASE)}


def doc_example(marker: str) -> str:
    return re.search(rf"<!-- {marker} -->\s*```\w+\n(.*?)```", DOCS.read_text(), re.S).group(1)


def b64(data: str | bytes) -> str:
    return base64.b64encode(data.encode() if isinstance(data, str) else data).decode()


def sandbox_processes() -> list[str]:
    """Processes of this run's sandbox uids still alive."""
    out = subprocess.run(["ps", "-eo", "uid=,pid=,args="], capture_output=True, text=True).stdout
    return [ln for ln in out.splitlines() if UID_BASE <= int(ln.split()[0]) < UID_BASE + 4096]


@pytest.fixture(scope="module")
def testbed(testbeds, sandbox_isolation):
    """The batch tries escapes that only the sandbox's namespaces stop: it needs them (conftest.py)."""
    yield from testbeds.own("up", "--time-scale", "max", "--sim-robots", "16", "--enable-uploads", env=LIMITS)


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        assert c.post("/api/v1/environments", json=DETOUR).status_code == 201
        yield c


def upload(client, name: str, content: str | bytes, kind: str = "python", **extra) -> int:
    r = client.post("/api/v1/programs", json={"name": name, "kind": kind, "content_base64": b64(content), **extra})
    assert r.status_code == 201, r.text
    return r.json()["id"]


SEND = """
import os, socket
s = socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"])))
f = s.makefile("rw", newline="\\n")
f.readline()
f.write({line!r} + "\\n"); f.flush()
print(f.readline().strip())
"""
GOOD_LINE = "T,T,P,300,300,0;1500,300,90;1500,1500,90"  # the detour, mm and degrees


def steal(path: Path) -> str:
    """A program that sends a valid path only if it could read ``path`` (it must not)."""
    return f"""
import sys
try:
    data = open({str(path)!r}, "rb").read()
except OSError as exc:
    sys.exit(f"cannot read {{exc.filename}}: {{exc.strerror}}")
print("READ", data[:40])
""" + SEND.format(line=GOOD_LINE)


def connect_out(host: str, port: int) -> str:
    """A program that sends a valid path only if it could connect to host:port (it must not)."""
    return f"""
import socket, sys
try:
    socket.create_connection(({host!r}, {port}), timeout=2).close()
except OSError as exc:
    sys.exit(f"connection to {host}:{port} failed: {{exc}}")
print("CONNECTED")
""" + SEND.format(line=GOOD_LINE)


def cases(testbed) -> dict[str, dict]:
    """name -> upload, job changes, expected status and reason (regex on the run's error)."""
    port = int(testbed.url.rsplit(":", 1)[1])
    bash = doc_example("upload-bash")
    c = {
        "python_astar": dict(content=doc_example("upload-python"), env="room", modes=["sim", "twb"]),
        "bash_waypoints": dict(content=bash, kind="executable", interpreter="bash", args=["1.5,0.3"]),
        "crash": dict(content="import sys\nprint('giving up', file=sys.stderr)\nsys.exit(3)", modes=["sim", "twb"],
                      reason=r"^program crashed: exit code 3 \(giving up\)"),
        "segfault": dict(content="import ctypes\nctypes.string_at(0)",
                         reason=r"^program crashed: killed by signal SIGSEGV"),
        "cpu_loop": dict(content="while True:\n    pass", reason=r"^program CPU limit: .* 1 s of CPU"),
        "sleeps": dict(content="import time\ntime.sleep(600)", reason=r"^program time limit: no path within 5 s"),
        "memory_bomb": dict(content="blocks = []\nwhile True:\n    blocks.append(bytearray(8 << 20))",
                            reason=r"^program memory limit: .* 160 MiB"),
        "fork_bomb": dict(content=":(){ :|:& };:\n:\nsleep 600", kind="executable", interpreter="bash",
                          reason=r"^program process limit: .* 12 processes"),
        "net_outside": dict(content=connect_out("1.1.1.1", 53),
                            reason=r"^program crashed: exit code 1 \(connection to 1\.1\.1\.1:53 failed"),
        "net_server": dict(content=connect_out("127.0.0.1", port),
                           reason=rf"^program crashed: exit code 1 \(connection to 127\.0\.0\.1:{port} failed"),
        "read_db": dict(content=steal(testbed.data_dir / "twb.db"),
                        reason=r"^program crashed: exit code 1 \(cannot read .*twb\.db: (No such file|Permission)"),
        "read_token": dict(content=steal(testbed.data_dir / "token"),
                           reason=r"^program crashed: exit code 1 \(cannot read .*token: (No such file|Permission)"),
        "garbage": dict(content=SEND.format(line="T,T,P,300,300"),
                        reason=r"^program sent an invalid path: ERR,SYNTAX,"),
        "out_of_range": dict(content=SEND.format(line="T,T,P,300,300,0;2500,300,0;1500,1500,90"),
                             reason=r"^program sent an invalid path: ERR,RANGE,point 2 \(2500, 300\) mm is outside"),
        "silent": dict(content="print('I plan nothing')",
                       reason=r"^program sent no path: it exited without connecting to the robot port"),
        "collides": dict(content=bash, kind="executable", interpreter="bash",
                         reason=r"^program's path is unusable: path segment 0 .* passes closer than the robot radius"),
        "flood": dict(content="import sys\nfor _ in range(20000):\n    print('x' * 100)\n"
                              "print('e' * 100000, file=sys.stderr)\n" + SEND.format(line=GOOD_LINE)),
    }
    if shutil.which("cc"):
        c["c_binary"] = dict(content="C", kind="executable",
                             args=["{robot_host}", "{robot_port}", "0.3", "0.3", "1.5", "0.3", "1.5", "1.5"])
    return c


@pytest.fixture(scope="module")
def batch(testbed, client, tmp_path_factory):
    """Upload and submit every case at once (plus a built-in planner's job), wait for all."""
    specs = cases(testbed)
    if "c_binary" in specs:
        d = tmp_path_factory.mktemp("cc")
        subprocess.run(["cc", "-O2", "-o", str(d / "planner"), str(ROOT / "examples/c_planner/ttp_planner.c"),
                        "-lm"], check=True)
        specs["c_binary"]["content"] = (d / "planner").read_bytes()
    ids = {}
    for name, spec in specs.items():
        extra = {k: spec[k] for k in ("interpreter", "args") if k in spec}
        pid = upload(client, name.replace("_", "-"), spec["content"], spec.get("kind", "python"), **extra)
        job = {"environment": spec.get("env", "detour"), "start": START, "goal": GOAL, "program": pid,
               "modes": spec.get("modes", ["sim"]), "seed": 3}
        r = client.post("/api/v1/experiments", json=job)
        assert r.status_code == 202, r.text
        ids[name] = r.json()["id"]
    builtin = client.post("/api/v1/experiments", json={"environment": "room", "start": START, "goal": GOAL,
                                                       "planner": "fmm", "modes": ["sim", "twb"]}).json()["id"]
    t0 = time.monotonic()
    done = {name: wait_for(client, eid, timeout=90) for name, eid in ids.items()}
    done["builtin"] = wait_for(client, builtin, timeout=60)
    return {"specs": specs, "done": done, "seconds": time.monotonic() - t0}


def messages(client, run_id: int) -> list[dict]:
    return client.get(f"/api/v1/runs/{run_id}/messages").json()["data"]


GOOD = ["python_astar", "bash_waypoints", "flood", "c_binary"]
BAD = ["crash", "segfault", "cpu_loop", "sleeps", "memory_bomb", "fork_bomb", "net_outside", "net_server",
       "read_db", "read_token", "garbage", "out_of_range", "silent", "collides"]


@pytest.mark.parametrize("name", GOOD)
def test_good_programs_complete(client, batch, name):
    if name not in batch["done"]:
        pytest.skip("no C compiler")
    exp = batch["done"][name]
    assert exp["status"] == "completed", exp
    assert exp["program"] is not None and exp["planner"] is None
    assert all(r["status"] == "completed" and r["metrics"]["goal_reached"] for r in exp["runs"])
    path = exp["planned_path"]
    assert path[0][:2] == pytest.approx(START[:2], abs=1e-3) and path[-1][:2] == pytest.approx(GOAL[:2], abs=1e-3)
    info = exp["planning_info"]["program"]
    assert info["isolation"]["namespaces"][:6] == ["user", "net", "mount", "pid", "ipc", "uts"]
    assert exp["planning_time_s"] is not None and 0 < exp["planning_time_s"] < 5
    log = messages(client, info["run_id"])
    kinds = {m["direction"] for m in log}
    assert {"s", "o"} <= kinds
    port = [m["line"] for m in log if m["direction"] == "s" and m["line"].startswith("robot port")]
    assert re.match(r"robot port > HELLO,(sim|field)-\d+,", port[0]) and port[1].startswith("robot port < T,T,P,")
    assert re.match(r"robot port > OK,P,\d+", port[2])


def test_the_python_example_plans_around_the_walls_and_runs_on_the_field(client, batch):
    exp = batch["done"]["python_astar"]
    assert len(exp["planned_path"]) >= 3  # the room's walls are in the way of the straight line
    assert {r["mode"] for r in exp["runs"]} == {"sim", "twb"}
    log = [m["line"] for m in messages(client, exp["planning_info"]["program"]["run_id"])]
    assert any(re.match(r"planned \d+ points", line) for line in log)


def test_the_bash_example_takes_its_waypoints_from_the_arguments(batch):
    path = batch["done"]["bash_waypoints"]["planned_path"]
    assert [p[:2] for p in path] == [[0.3, 0.3], [1.5, 0.3], [1.5, 1.5]]
    assert path[-1][2] == pytest.approx(1.5708, abs=1e-3)


def test_an_output_flood_is_truncated_not_fatal(client, batch):
    exp = batch["done"]["flood"]
    assert exp["status"] == "completed"
    info = exp["planning_info"]["program"]
    assert info["stdout_dropped_bytes"] > 1_000_000 and info["stderr_dropped_bytes"] > 90_000
    log = messages(client, info["run_id"])
    out = [m for m in log if m["direction"] == "o"]
    assert 8000 / 101 - 2 <= len(out) <= 8192 / 101 + 1  # 8 KiB kept
    assert any("stdout truncated" in m["line"] for m in log if m["direction"] == "s")


@pytest.mark.parametrize("name", BAD)
def test_bad_programs_fail_with_the_reason(client, batch, name):
    exp = batch["done"][name]
    reason = batch["specs"][name]["reason"]
    assert exp["status"] == "failed", exp
    for r in exp["runs"]:
        assert r["status"] == "failed" and re.search(reason, r["error"]), (r["error"], reason)
    assert exp["planned_path"] is None
    info = exp["planning_info"]["program"]
    log = messages(client, info["run_id"])
    assert log[-1]["direction"] == "s" and log[-1]["line"].startswith("program")
    # the program ran once per experiment, even with runs of both modes under way at the same time
    ran = [r["id"] for r in exp["runs"] if any(m["direction"] in "oes" for m in messages(client, r["id"]))]
    assert ran == [info["run_id"]]


def test_the_failures_ran_beside_good_jobs_within_their_limits(batch):
    assert batch["done"]["builtin"]["status"] == "completed"
    assert batch["done"]["sleeps"]["planning_info"]["program"]["timed_out"] is True
    assert batch["done"]["cpu_loop"]["planning_info"]["program"]["cpu_s"] == pytest.approx(1, abs=0.5)
    assert batch["done"]["fork_bomb"]["planning_info"]["program"]["processes_max"] <= 12
    bomb = batch["done"]["memory_bomb"]["planning_info"]["program"]
    if bomb["isolation"]["memory_limit"] == "cgroup":  # the kernel's count of all its processes
        assert bomb["memory_peak_kib"] <= 160 << 10
        # its counters say its own memory filled the limit: had its CPU limit ended it first, the memory limit
        # would still be the reason (test_a_program_at_its_memory_limit_ended_by_cpu_fails_by_memory)
        assert memory_full(bomb, {"memory_bytes": 160 << 20}), bomb
    assert sandbox_processes() == []


#: the batch's limits, as a job has them (bytes, s)
JOB_LIMITS = {"wall_s": 5, "cpu_s": 1, "memory_bytes": 160 << 20, "processes": 12, "file_bytes": 1 << 20}
MEMORY_REASON = r"^program memory limit: .* 160 MiB"  # memory_bomb's
CPU_REASON = r"^program CPU limit: .* 1 s of CPU"  # cpu_loop's


@pytest.mark.parametrize("counters, reason", [
    # the memory bomb, ended by RLIMIT_CPU (SIGXCPU) before the out-of-memory killer came, as it once was under
    # load (the kernel reclaims at the limit in the program's own time): at its limit, no page cache left
    ({"signal": signal.SIGXCPU, "cpu_s": 1.02, "memory_peak_kib": 160 << 10, "memory_oom_kills": 0,
      "memory_limit_hits": 0, "memory_cache_kib": 4}, MEMORY_REASON),
    # ... by the hard CPU limit (SIGKILL), a cgroup v2 counting the charges that met memory.max
    ({"signal": signal.SIGKILL, "cpu_s": 2.0, "memory_peak_kib": (160 << 10) - 100, "memory_oom_kills": 0,
      "memory_limit_hits": 37, "memory_cache_kib": 300}, MEMORY_REASON),
    # read a 300 MiB file (the limit full of page cache), then looped: measured on this machine's cgroup v1
    ({"signal": signal.SIGXCPU, "cpu_s": 1.01, "memory_peak_kib": 163816, "memory_oom_kills": 0,
      "memory_limit_hits": 0, "memory_cache_kib": 157772}, CPU_REASON),
    ({"signal": signal.SIGXCPU, "cpu_s": 1.0, "memory_peak_kib": 9000, "memory_oom_kills": 0,
      "memory_limit_hits": 0, "memory_cache_kib": 0}, CPU_REASON),
    ({"signal": signal.SIGXCPU, "cpu_s": 1.0, "memory_peak_kib": None, "memory_oom_kills": None,
      "memory_limit_hits": None, "memory_cache_kib": None}, CPU_REASON),  # no cgroup
    ({"signal": signal.SIGKILL, "cpu_s": 0.1, "memory_peak_kib": 160 << 10, "memory_oom_kills": 1,
      "memory_limit_hits": 0, "memory_cache_kib": 0}, MEMORY_REASON + r" .* and was killed$"),
])
def test_a_program_at_its_memory_limit_ended_by_cpu_fails_by_memory(counters, reason):
    """The reason follows the cgroup's counters, not only the signal: a program whose own memory filled its
    limit fails by the memory limit even when its CPU limit ended it first."""
    r = {"exit_code": None, "path": None, "stderr": "", "procs_max": 1, **counters}
    assert re.search(reason, explain(r, JOB_LIMITS)), explain(r, JOB_LIMITS)


@pytest.mark.parametrize("version, files, hits, cache, peak", [
    (2, {"memory.events": "low 0\nhigh 0\nmax 12\noom 1\noom_kill 1\noom_group_kill 1\n",
         "memory.stat": "anon 1000\nfile 9000\nactive_file 4096\ninactive_file 8192\nshmem 4096\n",
         "memory.peak": "167772160\n"}, 12, 12288, 167772160),
    (1, {"memory.failcnt": "3\n", "memory.max_usage_in_bytes": "167772160\n",
         "memory.stat": "cache 12288\nrss 0\nshmem 0\ninactive_file 8192\nactive_file 4096\n"
                        "total_inactive_file 8192\n"}, 3, 12288, 167772160),
    (2, {}, 0, None, None),  # files missing: nothing known
])
def test_the_cgroup_counters_the_reason_needs(tmp_path, version, files, hits, cache, peak):
    (tmp_path / "cg").mkdir()
    for name, text in files.items():
        (tmp_path / "cg" / name).write_text(text)
    parent = os.open(tmp_path, os.O_RDONLY | os.O_DIRECTORY)
    fd = os.open(tmp_path / "cg", os.O_RDONLY | os.O_DIRECTORY)
    try:
        node = cgroups._Node(parent, fd, "cg")
        cg = (cgroups.CgroupV2 if version == 2 else cgroups.CgroupV1)(node, None)
        assert (cg.limit_hits(), cg.page_cache_bytes(), cg.peak_bytes()) == (hits, cache, peak)
    finally:
        os.close(fd)
        os.close(parent)


def test_uploads_are_owner_only(testbed, client, batch):
    alice = client.post("/api/v1/users", json={"name": "alice-up"}).json()["token"]
    theirs = batch["done"]["crash"]["program"]
    with testbed.client(alice) as c:
        assert c.get(f"/api/v1/programs/{theirs}").status_code == 404
        assert c.get(f"/api/v1/programs/{theirs}/content").status_code == 404
        assert c.get("/api/v1/programs").json() == {"data": [], "count": 0}
        r = c.post("/api/v1/experiments", json={"environment": "detour", "start": START, "goal": GOAL,
                                                "program": theirs, "modes": ["sim"]})
        assert r.status_code == 422 and r.json()["detail"] == f"unknown program {theirs}"
        mine = upload(c, "mine", "print(1)")
        assert [p["id"] for p in c.get("/api/v1/programs").json()["data"]] == [mine]
    mine_for_admin = client.get(f"/api/v1/programs/{mine}").json()  # admins see everything
    assert mine_for_admin["owner"] == "alice-up" and mine_for_admin["size"] == 8
    got = client.get(f"/api/v1/programs/{theirs}")
    assert got.status_code == 200 and got.json()["name"] == "crash"
    content = client.get(f"/api/v1/programs/{theirs}/content")
    assert content.content == batch["specs"]["crash"]["content"].encode()


def test_upload_limits_and_validation(client):
    big = client.post("/api/v1/programs", json={"name": "big", "content_base64": b64(b"#" * ((256 << 10) + 1))})
    assert big.status_code == 413 and "larger than 262144 bytes" in big.json()["detail"]
    huge = client.post("/api/v1/programs", json={"name": "huge", "content_base64": "A" * (5 << 20)})
    assert huge.status_code == 413
    for body, message in [
        ({"name": "x", "content_base64": "not base64!"}, "not valid base64"),
        ({"name": "x", "kind": "executable", "interpreter": "perl", "content_base64": b64("1")}, "not available"),
        ({"name": "x", "kind": "python", "interpreter": "bash", "content_base64": b64("1")}, "python3"),
        ({"name": "a b", "content_base64": b64("1")}, "name"),
        ({"name": "x", "content_base64": b64("1"), "args": ["a\x00b"]}, "NUL"),
    ]:
        r = client.post("/api/v1/programs", json=body)
        assert r.status_code == 422 and message in r.json()["detail"], r.text
    pid = upload(client, "p", "print(1)")
    for job, message in [
        ({"program": pid, "planner": "fmm"}, "one of"),
        ({"program": pid, "planner_params": {"a": 1}}, "planner_params"),
        ({"program": 999999}, "unknown program 999999"),
    ]:
        body = {"environment": "detour", "start": START, "goal": GOAL, "modes": ["sim"], **job}
        r = client.post("/api/v1/experiments", json=body)
        assert r.status_code == 422 and message in r.json()["detail"], r.text
    info = client.get("/api/v1/programs/sandbox").json()
    assert info["uploads_enabled"] is True and "python3" in info["interpreters"]
    assert info["limits"]["wall_s"] == 5 and info["limits"]["processes"] == 12
    assert info["isolation"]["memory_limit"] in ("cgroup", "per-process")  # which one: docs/uploads.md
    assert info["isolation"]["network"] == "loopback only" and info["isolation"]["seccomp"] is True
    assert info["isolation"]["sandbox"].startswith("bubblewrap ") and info["isolation"]["user_namespace"] is True
    assert info["isolation"]["runs_as"] == ("a uid of its own" if os.geteuid() == 0
                                            else "the server's uid, in a user namespace")


def test_cancelling_a_running_program_kills_it(client):
    pid = upload(client, "waits", "import subprocess, time\nsubprocess.Popen(['sleep', '300'], start_new_session=True)"
                                  "\ntime.sleep(300)")
    eid = client.post("/api/v1/experiments", json={"environment": "detour", "start": START, "goal": GOAL,
                                                   "program": pid, "modes": ["sim"]}).json()["id"]
    deadline = time.monotonic() + 20
    while not sandbox_processes():
        assert time.monotonic() < deadline, "the program never started"
        time.sleep(0.05)
    time.sleep(0.3)
    assert client.post(f"/api/v1/experiments/{eid}/cancel").status_code == 200
    assert wait_for(client, eid, timeout=20)["status"] == "cancelled"
    deadline = time.monotonic() + 5
    while sandbox_processes():
        assert time.monotonic() < deadline, sandbox_processes()
        time.sleep(0.05)


#: a planner whose path depends on its seed: the detour by the lower-right corner for an even TWB_SEED, by the
#: upper-left for an odd one
BY_SEED = """
import os
seed = int(os.environ["TWB_SEED"])
print("SEED", seed)
""" + SEND.format(line="PLACEHOLDER").replace("'PLACEHOLDER'", """("T,T,P,300,300,0;1500,300,90;1500,1500,90" if seed % 2 == 0
         else "T,T,P,300,300,90;300,1500,0;1500,1500,90")""")


@pytest.mark.parametrize("stochastic", [True, False])
def test_a_stochastic_program_runs_once_per_repetition_with_its_planner_seed(client, stochastic):
    """Declared stochastic at upload: it runs once per repetition with the repetition's planner seed (the
    simulated and the field run of a repetition drive what it sent then); undeclared, once per experiment, its
    one path and timing reused by every run."""
    from server.store.experiments import planner_seed

    pid = upload(client, f"by-seed-{stochastic}", BY_SEED, **({"stochastic": True} if stochastic else {}))
    assert client.get(f"/api/v1/programs/{pid}").json()["stochastic"] is stochastic
    job = {"environment": "detour", "start": START, "goal": GOAL, "program": pid, "modes": ["sim", "twb"],
           "repetitions": 3, "seed": 3}
    exp = wait_for(client, client.post("/api/v1/experiments", json=job).json()["id"], timeout=120)
    assert exp["status"] == "completed" and exp["planner_stochastic"] is stochastic, exp
    seeds = {r["id"]: [int(m["line"].split()[1]) for m in messages(client, r["id"])
                       if m["direction"] == "o" and m["line"].startswith("SEED")] for r in exp["runs"]}
    ran = [r for r in exp["runs"] if seeds[r["id"]]]
    if not stochastic:  # once, with the job's seed, for every run
        assert len(ran) == 1 and seeds[ran[0]["id"]] == [3]
        assert all(r["planned_path"] == exp["planned_path"] and r["planning_time_s"] == exp["planning_time_s"]
                   for r in exp["runs"])
        return
    assert sorted(r["repetition"] for r in ran) == [1, 2, 3]  # once per repetition, in one of its runs
    for r in ran:
        seed = planner_seed(3, r["repetition"])
        assert seeds[r["id"]] == [seed] and r["planner_seed"] == seed
        corner = [1.5, 0.3] if seed % 2 == 0 else [0.3, 1.5]
        for mine in (x for x in exp["runs"] if x["repetition"] == r["repetition"]):
            assert mine["planned_path"] == r["planned_path"] and mine["planned_path"][1][:2] == corner
            assert mine["planning_time_s"] == r["planning_time_s"] > 0 and mine["planning_repeats"] == 1
    assert len({repr(r["planned_path"]) for r in ran}) == 2  # the seeds of repetitions 1-3 are even, even, odd


@pytest.mark.slow
def test_uploads_are_refused_unless_enabled(tmp_path, twb):
    p = Process(["server"], tmp_path)
    try:
        with p.client() as c:
            r = c.post("/api/v1/programs", json={"name": "x", "content_base64": b64("print(1)")})
            assert r.status_code == 403 and r.json()["detail"] == "uploads are disabled on this testbed"
            r = c.post("/api/v1/experiments", json={"environment": "room", "start": START, "goal": GOAL,
                                                    "program": 1})
            assert r.status_code == 403 and r.json()["detail"] == "uploads are disabled on this testbed"
            info = c.get("/api/v1/programs/sandbox").json()
            assert info["uploads_enabled"] is False and info["isolation"] is None
        prog = tmp_path / "p.py"
        prog.write_text("print(1)")
        r = twb("upload", str(prog), "--url", p.url, "--token", p.token)
        assert r.returncode != 0 and "uploads are disabled on this testbed" in r.stderr and "Traceback" not in r.stderr
    finally:
        assert p.stop() == 0, p.output()


def test_sdk_and_cli_upload_and_submit(testbed, client, tmp_path, twb):
    import asyncio

    from client_sdk import AsyncClient, Client, NotFound

    planner = tmp_path / "detour_planner.sh"
    planner.write_text(doc_example("upload-bash"))
    with Client(testbed.url, testbed.token) as c:
        prog = c.upload_program(planner, interpreter="bash", args=["1.5,0.3"])
        assert (prog.name, prog.kind, prog.interpreter, prog.args) == ("detour_planner.sh", "executable", "bash",
                                                                        ["1.5,0.3"])
        assert c.get_program(prog.id).sha256 == prog.sha256 and prog.id in [p.id for p in c.list_programs()]
        exp = c.wait(c.submit("detour", START, GOAL, program=prog.id, modes=["sim"]).id, timeout=60)
        assert exp.status == "completed" and exp.program == prog.id
        assert exp.planned_path[:, :2].tolist() == [[0.3, 0.3], [1.5, 0.3], [1.5, 1.5]]
        assert c.sandbox_info()["uploads_enabled"] is True
        with pytest.raises(NotFound):
            c.get_program(999999)

    async def upload_bytes() -> int:
        async with AsyncClient(testbed.url, testbed.token) as ac:
            p = await ac.upload_program(b"print('hi')", name="hi")
            assert p.kind == "executable" and (await ac.get_program(p.id)).size == 11
            return p.id

    assert asyncio.run(upload_bytes()) > 0

    py = tmp_path / "astar.py"
    py.write_text(doc_example("upload-python"))
    r = twb("upload", str(py), "--url", testbed.url, "--token", testbed.token)
    assert r.returncode == 0, r.stderr
    m = re.fullmatch(r'Uploaded program (\d+): astar\.py, python, \d+ bytes\. Use it in a job as "program": \1\.\n',
                     r.stdout)
    assert m, r.stdout
    r = twb("submit", "--env", "detour", "--start", "0.3,0.3,0", "--goal", "1.5,1.5", "--program", m.group(1),
            "--modes", "sim", "--wait", "--url", testbed.url, "--token", testbed.token)
    assert r.returncode == 0 and "completed (1/1 runs completed)" in r.stderr, r.stderr
    exp_id, prog_id = r.stdout.strip(), m.group(1)
    # a program job is labelled as the dashboard does, never "planner explicit path"
    r = twb("status", exp_id, "--url", testbed.url, "--token", testbed.token)
    assert f"program #{prog_id}" in r.stdout and "explicit path" not in r.stdout, r.stdout
    r = twb("status", "--url", testbed.url, "--token", testbed.token, env={"COLUMNS": "200"})
    assert re.search(rf"\b{exp_id}\b .*detour .*program #{prog_id}", r.stdout), r.stdout
    r = twb("results", exp_id, "--url", testbed.url, "--token", testbed.token)
    assert f"experiment {exp_id}: completed (detour, program #{prog_id})" in r.stdout, r.stdout
    r = twb("upload", str(tmp_path / "missing.py"), "--url", testbed.url, "--token", testbed.token)
    assert r.returncode != 0 and r.stderr.strip().endswith("missing.py") and "Traceback" not in r.stderr


@pytest.mark.slow
def test_a_static_binary_of_a_megabyte_or_two_fits_the_default_limit(tmp_path):
    """The docs recommend static binaries; a stripped static C planner is about 1.1 MB."""
    import base64

    from server.core.settings import Settings

    assert Settings(max_program_bytes=8 << 20).max_body_bytes >= (8 << 20) * 4 // 3  # the body fits the upload
    p = Process(["server", "--enable-uploads"], tmp_path)
    try:
        with p.client() as c:
            body = {"name": "static-planner", "kind": "executable", "content_base64": ""}
            for size, status in ((1_200_000, 201), ((8 << 20) + 1, 413)):
                body["content_base64"] = base64.b64encode(b"\x7fELF" + bytes(size - 4)).decode()
                r = c.post("/api/v1/programs", json=body)
                assert r.status_code == status, (size, r.status_code, r.text[:200])
    finally:
        p.stop()
