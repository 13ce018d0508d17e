"""Exports of runs and experiments (docs/exports.md) through a real `twb up`: each format read back with its own
library (MCAP: ``mcap`` and ``mcap-protobuf-support``; ROS 2 bags: ``rosbags``) and compared with what the API
serves of the same run — message counts, timestamps, poses, paths, obstacles, log lines, metrics; a fleet's
topics per robot; an experiment's runs under their prefixes; 404 for unknown ids; the SDK and `twb export`;
a server without the `export` extra answers 501 naming the install command.

(At the end, the conversion alone on a made-up run; the benchmark's figure: bench/export.py.)
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from client_sdk import ApiError, Client, NotFound
from server.export import ExportFormat, Names, RobotTrack, RunRecord, quaternion_yaw
from server.export.convert import write_export
from server.export.layout import flat_metrics, log_level
from server.export.rosbag2_file import typestore
from servers import STANDARD, TOKEN, wait_for

ROOT = Path(__file__).resolve().parents[1]
FLEET = json.loads((ROOT / "examples" / "fleet" / "swap-prioritized.json").read_text())
#: two discs beside the straight way from (0.3, 0.3) to (1.5, 0.3) (tests/test_obstacle_tracks.py's)
SIDE = {"name": "export-movers", "size": [1.8, 1.8],
        "blocks": [{"x": 0.9, "y": 1.4, "w": 0.3, "h": 0.06, "angle": 0.3}], "moving_obstacles": [
            {"radius": 0.04, "waypoints": [[1.1, 0.9], [1.5, 0.9], [1.5, 1.2]], "speed": 0.1, "repeat": "pingpong"},
            {"radius": 0.05, "waypoints": [[0.3, 1.1], [0.3, 0.9]], "speed": 0.08, "delay_s": 1.0}]}


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


@pytest.fixture(scope="module")
def client(testbed):
    with testbed.client() as c:
        assert c.post("/api/v1/environments", json=SIDE).status_code == 201
        yield c


@pytest.fixture(scope="module")
def jobs(client) -> dict[str, dict]:
    """Both experiments, submitted together and completed: ``single``, a sim + field run among moving obstacles
    (the field run's obstacle robots tracked), and ``fleet``, the prioritized four-robot swap."""
    job = {"environment": SIDE["name"], "start": [0.3, 0.3, 0.0], "goal": [1.5, 0.3, 0.0], "planner": "fmm",
           "modes": ["sim", "twb"], "seed": 4}
    ids = {"single": client.post("/api/v1/experiments", json=job).json()["id"],
           "fleet": client.post("/api/v1/experiments", json=FLEET).json()["id"]}
    out = {k: wait_for(client, i, timeout=180) for k, i in ids.items()}
    assert all(e["status"] == "completed" for e in out.values()), out
    return out


@pytest.fixture(scope="module")
def single(jobs) -> dict:
    return jobs["single"]


@pytest.fixture(scope="module")
def fleet(jobs) -> dict:
    return jobs["fleet"]


# --------------------------------------------------------------------------- what the API has of a run


def stored(client, run_id: int) -> dict[str, Any]:
    """What the API serves of a run: the run, its poses, obstacles and messages."""
    poses = client.get(f"/api/v1/runs/{run_id}/poses").json()
    return {"run": client.get(f"/api/v1/runs/{run_id}").json(),
            "poses": np.asarray(poses["poses"], dtype=float).reshape(-1, len(poses["columns"])),
            "obstacles": client.get(f"/api/v1/runs/{run_id}/obstacles").json()["obstacles"],
            "messages": client.get(f"/api/v1/runs/{run_id}/messages", params={"limit": 10000}).json()["data"]}


def ns(t: np.ndarray) -> np.ndarray:
    return np.rint(np.asarray(t, dtype=float) * 1e9).astype(np.int64)


def wrapped(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def check_log(exported: list, messages: list[dict], text) -> None:  # type: ignore[no-untyped-def]
    """Every protocol line is in the exported log, and each line the API gives a time at that time (lines without
    one take their neighbour's)."""
    want = [f"{m['direction']} {m['line']}" for m in messages]
    assert sorted(text(m) for _, m in exported) == sorted(want) and len(want) > 5
    got = {(t, text(m)) for t, m in exported}
    assert all((round(m["t"] * 1e9), w) in got for m, w in zip(messages, want) if m["t"] is not None)


# --------------------------------------------------------------------------- reading each format back


def read_mcap(data: bytes) -> dict[str, list[tuple[int, Any]]]:
    """Every message of an MCAP file per topic, ``(log time ns, decoded)``: protobuf through
    mcap-protobuf-support's decoder, JSON as JSON."""
    decoders = DecoderFactory()
    out: dict[str, list[tuple[int, Any]]] = {}
    reader = make_reader(io.BytesIO(data))
    for schema, channel, message in reader.iter_messages(log_time_order=True):
        if channel.message_encoding == "json":
            value = json.loads(message.data)
        else:
            value = decoders.decoder_for(channel.message_encoding, schema)(message.data)
        out.setdefault(channel.topic, []).append((message.log_time, value))
    return out


def read_bag(data: bytes, where: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every message of a zipped ROS 2 bag per topic, ``(time ns, deserialized)``, read by rosbags."""
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        names = zf.namelist()
        zf.extractall(where)
    bag = where / names[0].split("/")[0]
    store = typestore()
    out: dict[str, list[tuple[int, Any]]] = {}
    with Reader(bag) as reader:
        for connection, t, raw in reader.messages():
            out.setdefault(connection.topic, []).append((t, store.deserialize_cdr(raw, connection.msgtype)))
        out["__types__"] = [(0, {c.topic: c.msgtype for c in reader.connections})]
    for rows in out.values():
        rows.sort(key=lambda r: r[0])
    return out


def export(client, what: str, ident: int, fmt: str) -> bytes:
    r = client.get(f"/api/v1/{what}/{ident}/export", params={"format": fmt})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == ("application/octet-stream" if fmt == "mcap" else "application/zip")
    stem = "run" if what == "runs" else "experiment"
    assert r.headers["content-disposition"] == \
        f'attachment; filename="{stem}-{ident}.{"mcap" if fmt == "mcap" else "zip"}"'
    assert int(r.headers["content-length"]) == len(r.content)
    return r.content


# --------------------------------------------------------------------------- MCAP


def check_mcap_robot(topics: dict, poses: np.ndarray, planned: Any, ns_robot: str, frame: str) -> None:
    """A robot's poses, transforms and paths in an MCAP export equal the stored ones."""
    got = topics[f"{ns_robot}/pose"]
    assert len(got) == len(poses) > 10
    times = np.array([t for t, _ in got])
    assert np.array_equal(times, ns(poses[:, 0]))
    assert [m.timestamp.seconds * 10**9 + m.timestamp.nanos for _, m in got] == times.tolist()
    xy = np.array([[m.pose.position.x, m.pose.position.y] for _, m in got])
    assert np.array_equal(xy, poses[:, 1:3])  # doubles, exactly
    yaw = np.array([quaternion_yaw(m.pose.orientation.z, m.pose.orientation.w) for _, m in got])
    assert np.allclose(wrapped(yaw - poses[:, 3]), 0.0, atol=1e-12)
    assert {m.frame_id for _, m in got} == {"map"}
    tf = [(t, tr) for t, m in topics["/tf"] for tr in m.transforms if tr.child_frame_id == frame]
    assert len(tf) == len(poses)
    assert [t for t, _ in tf] == times.tolist()
    assert np.array_equal([[tr.translation.x, tr.translation.y] for _, tr in tf], poses[:, 1:3])
    assert {tr.parent_frame_id for _, tr in tf} == {"map"}
    (t_end, driven), = topics[f"{ns_robot}/driven_path"]
    assert np.array_equal([[p.x, p.y] for p in driven.entities[0].lines[0].points], poses[:, 1:3])
    if planned is not None:
        (_, plan), = topics[f"{ns_robot}/planned_path"]
        assert np.array_equal([[p.x, p.y] for p in plan.entities[0].lines[0].points],
                              np.asarray(planned, dtype=float)[:, :2])


def test_a_runs_mcap_export_reads_back_equal_to_what_is_stored(client, single):
    for run in single["runs"]:
        have = stored(client, run["id"])
        topics = read_mcap(export(client, "runs", run["id"], "mcap"))
        assert set(topics) == {"/tf", "/robot/pose", "/robot/planned_path", "/robot/driven_path", "/scene", "/log",
                               "/metrics"}
        check_mcap_robot(topics, have["poses"], have["run"]["planned_path"], "/robot", "base_link")
        # the scene: the environment at the start, then every obstacle pose the API serves
        scene = topics["/scene"]
        first = scene[0][1].entities[0]
        assert first.id == "environment" and len(first.cubes) == 1 and first.cubes[0].size.x == 0.3
        assert scene[0][0] == round(have["run"]["t_start"] * 1e9)
        for o in have["obstacles"]:
            mine = [(t, m.entities[0]) for t, m in scene if m.entities[0].id == f"obstacle_{o['index']}"]
            rows = np.asarray(o["poses"], dtype=float)
            assert len(mine) == o["count"] == len(rows) > 10
            assert [t for t, _ in mine] == ns(rows[:, 0]).tolist()
            assert np.allclose([[e.cylinders[0].pose.position.x, e.cylinders[0].pose.position.y] for _, e in mine],
                               rows[:, 1:3], atol=0, rtol=0)
            assert mine[0][1].cylinders[0].size.x == pytest.approx(2 * o["radius"])
        # the log: every protocol line, each that has a time at its time
        check_log(topics["/log"], have["messages"], lambda m: m.message)
        # the metrics: once, at the end, equal to the run's
        (t_metrics, metrics), = topics["/metrics"]
        assert t_metrics == round(have["run"]["t_end"] * 1e9)
        assert metrics["metrics"] == have["run"]["metrics"] and metrics["run_id"] == run["id"]
    field = next(r for r in single["runs"] if r["mode"] == "twb")
    assert stored(client, field["id"])["obstacles"]  # the field's obstacle robots were in the export above


def test_a_fleets_mcap_export_has_a_topic_and_a_frame_per_robot(client, fleet):
    run = fleet["runs"][0]
    have = stored(client, run["id"])
    topics = read_mcap(export(client, "runs", run["id"], "mcap"))
    plans = [r["path"] for r in fleet["planning_info"]["robots"]]
    assert len(plans) == 4
    for k in range(4):
        check_mcap_robot(topics, have["poses"][have["poses"][:, 4] == k, :4], plans[k], f"/robot_{k}",
                         f"robot_{k}/base_link")
    assert len(topics["/tf"]) == len(have["poses"])


def test_an_experiments_mcap_export_has_each_run_under_its_prefix(client, single):
    topics = read_mcap(export(client, "experiments", single["id"], "mcap"))
    for run in single["runs"]:
        have = stored(client, run["id"])
        check_mcap_robot(topics, have["poses"], have["run"]["planned_path"], f"/run_{run['id']}/robot",
                         f"run_{run['id']}/base_link")
        assert topics[f"/run_{run['id']}/metrics"][0][1]["run_id"] == run["id"]
    assert sum(len(stored(client, r["id"])["messages"]) for r in single["runs"]) == len(topics["/log"])
    assert {m.name for _, m in topics["/log"]} == {f"run_{r['id']}" for r in single["runs"]}


# --------------------------------------------------------------------------- ROS 2 bags


def check_bag_robot(topics: dict, poses: np.ndarray, planned: Any, ns_robot: str, frame: str) -> None:
    got = topics[f"{ns_robot}/pose"]
    assert len(got) == len(poses) > 10
    times = np.array([t for t, _ in got])
    assert np.array_equal(times, ns(poses[:, 0]))
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got] == times.tolist()
    assert np.array_equal([[m.pose.position.x, m.pose.position.y] for _, m in got], poses[:, 1:3])
    yaw = np.array([quaternion_yaw(m.pose.orientation.z, m.pose.orientation.w) for _, m in got])
    assert np.allclose(wrapped(yaw - poses[:, 3]), 0.0, atol=1e-12)
    tf = [(t, tr) for t, m in topics["/tf"] for tr in m.transforms if tr.child_frame_id == frame]
    assert [t for t, _ in tf] == times.tolist()
    assert {tr.header.frame_id for _, tr in tf} == {"map"}
    (_, driven), = topics[f"{ns_robot}/driven_path"]
    assert np.array_equal([[p.pose.position.x, p.pose.position.y] for p in driven.poses], poses[:, 1:3])
    assert [p.header.stamp.sec * 10**9 + p.header.stamp.nanosec for p in driven.poses] == times.tolist()
    if planned is not None:
        (_, plan), = topics[f"{ns_robot}/planned_path"]
        assert np.array_equal([[p.pose.position.x, p.pose.position.y] for p in plan.poses],
                              np.asarray(planned, dtype=float)[:, :2])


def test_a_runs_ros2_bag_reads_back_equal_to_what_is_stored(client, single, tmp_path):
    run = next(r for r in single["runs"] if r["mode"] == "twb")
    have = stored(client, run["id"])
    topics = read_bag(export(client, "runs", run["id"], "rosbag2"), tmp_path)
    assert topics.pop("__types__")[0][1] == {
        "/tf": "tf2_msgs/msg/TFMessage", "/robot/pose": "geometry_msgs/msg/PoseStamped",
        "/robot/planned_path": "nav_msgs/msg/Path", "/robot/driven_path": "nav_msgs/msg/Path",
        "/scene": "visualization_msgs/msg/MarkerArray", "/rosout": "rcl_interfaces/msg/Log",
        "/metrics": "diagnostic_msgs/msg/DiagnosticArray"}
    check_bag_robot(topics, have["poses"], have["run"]["planned_path"], "/robot", "base_link")
    scene = topics["/scene"]
    assert [m.ns for m in scene[0][1].markers] == ["blocks"]
    obstacles = [(t, m.markers[0]) for t, m in scene[1:]]
    assert len(obstacles) == sum(o["count"] for o in have["obstacles"])
    for o in have["obstacles"]:
        mine = [(t, m) for t, m in obstacles if m.id == o["index"]]
        assert [t for t, _ in mine] == ns(np.asarray(o["poses"])[:, 0]).tolist()
        assert np.array_equal([[m.pose.position.x, m.pose.position.y] for _, m in mine], np.asarray(o["poses"])[:, 1:3])
    check_log(topics["/rosout"], have["messages"], lambda m: m.msg)
    (t_metrics, diag), = topics["/metrics"]
    values = {kv.key: kv.value for kv in diag.status[0].values}
    assert float(values["length_m"]) == have["run"]["metrics"]["length_m"]
    assert float(values["planned.length_m"]) == have["run"]["metrics"]["planned"]["length_m"]
    assert t_metrics == round(have["run"]["t_end"] * 1e9) and diag.status[0].message == "completed"


def test_a_fleets_ros2_bag_has_a_topic_per_robot(client, fleet, tmp_path):
    run = fleet["runs"][0]
    have = stored(client, run["id"])
    topics = read_bag(export(client, "runs", run["id"], "rosbag2"), tmp_path)
    for k in range(4):
        check_bag_robot(topics, have["poses"][have["poses"][:, 4] == k, :4], fleet["planning_info"]["robots"][k]["path"],
                        f"/robot_{k}", f"robot_{k}/base_link")


# --------------------------------------------------------------------------- errors, SDK, CLI


@pytest.mark.parametrize("path", ["/api/v1/runs/999999/export", "/api/v1/experiments/999999/export"])
def test_an_unknown_id_is_404(client, path):
    r = client.get(path, params={"format": "mcap"})
    assert r.status_code == 404
    assert r.json()["detail"] in ("Run not found", "Experiment not found")
    assert client.get(path.replace("999999", "1"), params={"format": "gif"}).status_code == 422


def test_the_sdk_downloads_each_format(testbed, client, single, tmp_path):
    run = single["runs"][0]
    with Client(testbed.url, TOKEN) as twb:
        mcap_file = twb.export(run["id"], out=tmp_path / "a.mcap")
        bag = twb.export(experiment_id=single["id"], format="rosbag2", out=tmp_path / "bag")
        zipped = twb.export(run["id"], format="rosbag2", out=tmp_path / "bag.zip")
        with pytest.raises(NotFound, match="Run not found"):
            twb.export(999999, out=tmp_path / "none.mcap")
        with pytest.raises(FileExistsError):
            twb.export(run["id"], out=mcap_file)
    assert not (tmp_path / "none.mcap").exists() and not (tmp_path / "none.mcap.part").exists()
    assert len(read_mcap(mcap_file.read_bytes())["/robot/pose"]) == len(stored(client, run["id"])["poses"])
    assert sorted(p.name for p in bag.iterdir()) == ["experiment-%d.db3" % single["id"], "metadata.yaml"]
    with Reader(bag) as reader:
        assert {f"/run_{r['id']}/robot/pose" for r in single["runs"]} <= {c.topic for c in reader.connections}
    assert zipfile.is_zipfile(zipped)


async def test_the_async_sdk_downloads_too(testbed, single, tmp_path):
    from client_sdk import AsyncClient

    run = single["runs"][0]
    async with AsyncClient(testbed.url, TOKEN) as twb:
        got = await twb.export(run["id"], format="rosbag2", out=tmp_path / "bag")
        with pytest.raises(NotFound):
            await twb.export(999999, out=tmp_path / "none.mcap")
    with Reader(got) as reader:
        assert "/robot/pose" in {c.topic for c in reader.connections}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]


def test_twb_export_writes_the_file(testbed, twb, single, tmp_path):
    run = single["runs"][0]
    env = {"TWB_URL": testbed.url, "TWB_TOKEN": TOKEN}
    done = twb("export", str(run["id"]), "--out", str(tmp_path / "r.mcap"), env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"{tmp_path / 'r.mcap'}: run {run['id']} as MCAP")
    done = twb("export", "--experiment", str(single["id"]), "--format", "rosbag2", "--out", str(tmp_path / "b"),
               env=env)
    assert done.returncode == 0 and (tmp_path / "b" / "metadata.yaml").exists(), done.stderr
    bad = twb("export", "999999", "--out", str(tmp_path / "x.mcap"), env=env)
    assert bad.returncode != 0 and "Run not found" in bad.stderr and "Traceback" not in bad.stderr
    both = twb("export", "1", "--experiment", "1", env=env)
    assert both.returncode == 2 and "one of them" in both.stderr


# --------------------------------------------------------------------------- without the extra


@pytest.fixture(scope="module")
def bare(testbeds, tmp_path_factory):
    """A `twb server` that cannot import the export packages (stand-ins that raise ImportError shadow them)."""
    stubs = tmp_path_factory.mktemp("no-export-extra")
    for name in ("foxglove", "rosbags"):
        (stubs / name).mkdir()
        (stubs / name / "__init__.py").write_text(f"raise ImportError('{name} is not installed (test stand-in)')\n")
    path = os.pathsep.join([str(stubs), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    yield from testbeds.own("server", "--port", "0", env={"PYTHONPATH": path})


@pytest.mark.parametrize("fmt, missing", [("mcap", "foxglove-sdk"), ("rosbag2", "rosbags")])
def test_without_the_extra_the_answer_is_501_naming_the_install_command(bare, twb, fmt, missing, tmp_path):
    with bare.client() as c:
        r = c.get("/api/v1/runs/1/export", params={"format": fmt})
    assert r.status_code == 501
    detail = r.json()["detail"]
    assert f"missing: {missing}" in detail and "pip install 'teleworkbench[export]'" in detail
    with Client(bare.url, TOKEN) as sdk, pytest.raises(ApiError) as err:
        sdk.export(1, format=fmt, out=tmp_path / "never-written.zip")
    assert err.value.status == 501 and str(err.value).startswith("501 Not Implemented: exporting")
    assert "teleworkbench[export]" in str(err.value)
    assert list(tmp_path.iterdir()) == []
    done = twb("export", "1", "--format", fmt, "--out", str(tmp_path / "x"), env={"TWB_URL": bare.url, "TWB_TOKEN": TOKEN})
    assert done.returncode == 2 and "pip install 'teleworkbench[export]'" in done.stderr, done.stderr


def test_quaternion_yaw_inverts_the_export_rotation():
    for theta in (-math.pi + 1e-9, -1.0, 0.0, 0.5, math.pi - 1e-9):
        assert quaternion_yaw(math.sin(theta / 2), math.cos(theta / 2)) == pytest.approx(theta, abs=1e-12)


def test_the_python_examples_of_docs_exports_run_as_written(testbed, single, tmp_path, monkeypatch, capsys):
    """docs/exports.md's Python blocks, in order, in a scratch directory against this testbed (its run and
    experiment ids in place of the page's)."""
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "exports.md").read_text(), re.S)
    assert len(blocks) == 3
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TWB_URL", testbed.url)
    monkeypatch.setenv("TWB_TOKEN", TOKEN)
    ids = "run_id, experiment_id = 2, 1"
    assert ids in blocks[0]
    blocks[0] = blocks[0].replace(ids, f"run_id, experiment_id = {single['runs'][0]['id']}, {single['id']}")
    for code in blocks:
        exec(compile(code, "docs/exports.md", "exec"), {})  # noqa: S102 - the page's own examples
    printed = capsys.readouterr().out.splitlines()
    assert printed[0] == "run.mcap run-bag experiment.mcap"
    assert len(printed) == 4 and printed[1] == printed[3]  # the first pose, from the MCAP file and from the bag
    assert ("/robot/pose", "geometry_msgs/msg/PoseStamped") in [c[:2] for c in eval(printed[2])]  # noqa: S307


# --------------------------------------------------------------------------- the conversion alone


def _record(**kw: Any) -> RunRecord:
    """A run that never drove (no poses, no times), with ``kw`` changed."""
    base: dict[str, Any] = dict(run_id=5, experiment_id=2, mode="sim", repetition=1, status="queued",
                                environment="room", size=(1.8, 1.8), blocks=np.zeros((0, 5)), robot_radius=0.045,
                                robots=(RobotTrack(0, np.zeros((0, 4))),))
    return RunRecord(**{**base, **kw})


@pytest.mark.parametrize("fmt", ["mcap", "rosbag2"])
def test_a_run_that_never_drove_exports_its_scene_and_metrics_only(fmt, tmp_path):
    buf = io.BytesIO()
    write_export([_record()], ExportFormat(fmt), buf, name="run-5")
    topics = read_mcap(buf.getvalue()) if fmt == "mcap" else read_bag(buf.getvalue(), tmp_path)
    topics.pop("__types__", None)
    assert {k: len(v) for k, v in topics.items()} == {"/scene": 1, "/metrics": 1}
    assert all(t == 0 for rows in topics.values() for t, _ in rows)  # no clock: time 0


def test_names_levels_and_flat_metrics():
    alone, fleet = Names.of(_record(), False), Names.of(_record(fleet=True), True)
    assert (alone.robot_topic(0, "pose"), alone.base_frame(0), alone.topic("scene")) == \
        ("/robot/pose", "base_link", "/scene")
    assert (fleet.robot_topic(3, "pose"), fleet.base_frame(3), fleet.topic("scene"), fleet.log_name) == \
        ("/run_5/robot_3/pose", "run_5/robot_3/base_link", "/run_5/scene", "run_5")
    assert [log_level(d, x) for d, x in [("<", "EV,FAIL,12.0,stalled"), ("<", "robot 2: EV,FAIL,1"),
                                         ("<", "ERR,RANGE,x"), ("e", "Traceback"), ("<", "EV,DONE,4")]] == \
        ["error", "error", "warning", "warning", "info"]
    assert flat_metrics({"length_m": 0.1 + 0.2, "goal_reached": True, "planned": {"length_m": 1.5},
                         "robots": [{"length_m": 2.0}], "poses": [1, 2], "deadlock": None}) == [
        ("length_m", repr(0.1 + 0.2)), ("goal_reached", "true"), ("planned.length_m", "1.5"),
        ("robots.0.length_m", "2.0"), ("poses", "[1, 2]"), ("deadlock", "null")]
