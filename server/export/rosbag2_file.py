"""A run (or an experiment's runs) as a ROS 2 bag, written by ``rosbags`` with ROS 2 Jazzy's standard types.

What goes where (names: :mod:`.layout`), each message's time the experiment
time it belongs to (ns on the run's clock; headers carry the same stamp):

- ``/tf`` ``tf2_msgs/msg/TFMessage``: ``map`` → the robot's ``base_link``, one per stored pose;
- ``/robot/pose`` ``geometry_msgs/msg/PoseStamped``: the same poses in ``map``;
- ``/robot/planned_path``, ``/robot/driven_path`` ``nav_msgs/msg/Path``: the plan at the run's start (its
  poses without times of their own, stamped with it), the driven path (every stored pose, each stamped) at its end;
- ``/scene`` ``visualization_msgs/msg/MarkerArray``: the blocks as cubes (namespace ``blocks``) at the
  start, then each moving obstacle as a cylinder (namespace ``obstacles``, id its index) at each of its poses;
- ``/rosout`` ``rcl_interfaces/msg/Log``: the run's protocol lines (ROS 2's log type; ``rosgraph_msgs/Log``
  is ROS 1's and ROS 2 has none);
- ``/metrics`` ``diagnostic_msgs/msg/DiagnosticArray``: the run's metrics as key-value pairs, once, at its end.

The bag is a directory (``metadata.yaml`` and one SQLite ``.db3`` file, rosbag2 format version 8); for a
download it travels as a zip of that directory (:func:`write_rosbag2_zip`).  Needs the ``export`` extra
(``rosbags``).
"""

from __future__ import annotations

import math
import tempfile
import zipfile
from pathlib import Path
from typing import IO, Any, Sequence

import numpy as np

from .layout import BLOCK_HEIGHT_M, MAP_FRAME, Names, flat_metrics, log_times, ns, ns_array, yaw_quaternion
from .record import RunRecord

__all__ = ["BAG_VERSION", "ROS_DISTRO", "write_rosbag2", "write_rosbag2_zip"]

#: the typestore the messages are defined by (a ROS 2 LTS distribution) and the bag's format version
ROS_DISTRO = "jazzy"
BAG_VERSION = 8
_LEVELS = {"info": 20, "warning": 30, "error": 40}
_PLANNED_RGBA = (0.12, 0.47, 0.71, 1.0)
_BLOCK_RGBA = (0.35, 0.35, 0.35, 1.0)
_OBSTACLE_RGBA = (1.0, 0.5, 0.05, 0.9)

TF = "tf2_msgs/msg/TFMessage"
POSE = "geometry_msgs/msg/PoseStamped"
PATH = "nav_msgs/msg/Path"
MARKERS = "visualization_msgs/msg/MarkerArray"
LOG = "rcl_interfaces/msg/Log"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"


def typestore() -> Any:
    """rosbags' typestore of :data:`ROS_DISTRO`."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def write_rosbag2(records: Sequence[RunRecord], path: Path, *, experiment: bool = False) -> None:
    """Write ``records`` as a ROS 2 bag in the new directory ``path`` (it must not exist).

    ``experiment``: the runs are an experiment's, each under its ``run_<id>`` prefix (:class:`~.layout.Names`).
    Times are the runs' experiment clocks, in nanoseconds (seconds x 1e9).
    """
    from rosbags.rosbag2 import Writer

    with Writer(path, version=BAG_VERSION) as writer:
        bag = _Bag(writer, typestore())
        for record in records:
            _write_run(bag, record, Names.of(record, experiment))


def write_rosbag2_zip(records: Sequence[RunRecord], out: IO[bytes], name: str, *, experiment: bool = False) -> None:
    """:func:`write_rosbag2` into a temporary directory, then that directory (named ``name``) zipped to ``out``
    (deflated; ``out`` may be a pipe)."""
    with tempfile.TemporaryDirectory(prefix="twb-export-") as tmp:
        bag = Path(tmp) / name
        write_rosbag2(records, bag, experiment=experiment)
        with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
            for f in sorted(bag.iterdir()):
                zf.write(f, f"{name}/{f.name}")


class _Bag:
    """A bag writer with one connection per topic and the typestore's message classes at hand."""

    def __init__(self, writer: Any, store: Any) -> None:
        self.writer, self.store = writer, store
        self.types = store.types
        self._connections: dict[str, Any] = {}

    def add(self, topic: str, msgtype: str, t_ns: int, message: Any) -> None:
        if topic not in self._connections:
            self._connections[topic] = self.writer.add_connection(topic, msgtype, typestore=self.store)
        self.writer.write(self._connections[topic], t_ns, self.store.serialize_cdr(message, msgtype))

    def time(self, t_ns: int) -> Any:
        sec, nanosec = divmod(t_ns, 1_000_000_000)
        return self.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)

    def header(self, t_ns: int, frame: str = MAP_FRAME) -> Any:
        return self.types["std_msgs/msg/Header"](stamp=self.time(t_ns), frame_id=frame)

    def pose(self, x: float, y: float, qz: float, qw: float, z: float = 0.0) -> Any:
        t = self.types
        return t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                           orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=qz, w=qw))

    def color(self, rgba: tuple[float, float, float, float]) -> Any:
        r, g, b, a = rgba
        return self.types["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a)


def _write_run(bag: _Bag, record: RunRecord, names: Names) -> None:
    t0, t1 = ns(record.t0), ns(record.t1)
    _scene(bag, record, names, t0)
    for robot in record.robots:
        _poses(bag, names, robot.index, robot.poses)
        if robot.planned is not None and len(robot.planned):
            planned = np.column_stack([np.full(len(robot.planned), record.t0), robot.planned[:, :3]])
            _path(bag, names.robot_topic(robot.index, "planned_path"), planned, t0, stamped=False)
        if len(robot.poses):
            _path(bag, names.robot_topic(robot.index, "driven_path"), robot.poses, t1, stamped=True)
    _log(bag, record, names)
    _metrics(bag, record, names, t1)


def _poses(bag: _Bag, names: Names, index: int, poses: np.ndarray) -> None:
    """Each pose as a ``map`` → base frame transform on ``/tf`` and a ``PoseStamped`` on the robot's topic."""
    t = bag.types
    child = names.base_frame(index)
    topic = names.robot_topic(index, "pose")
    z, w = yaw_quaternion(poses[:, 3])
    for t_ns, x, y, qz, qw in zip(ns_array(poses[:, 0]).tolist(), poses[:, 1].tolist(), poses[:, 2].tolist(),
                                  z.tolist(), w.tolist()):
        header = bag.header(t_ns)
        transform = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=qz, w=qw))
        bag.add("/tf", TF, t_ns, t[TF](transforms=[
            t["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id=child, transform=transform)]))
        bag.add(topic, POSE, t_ns, t[POSE](header=header, pose=bag.pose(x, y, qz, qw)))


def _path(bag: _Bag, topic: str, rows: np.ndarray, t_ns: int, *, stamped: bool) -> None:
    """``rows`` ``(K, 4)`` t, x, y, theta as a ``nav_msgs/Path`` at ``t_ns``; ``stamped``: each pose carries its
    own time, else the path's."""
    t = bag.types
    z, w = yaw_quaternion(rows[:, 3])
    times = ns_array(rows[:, 0]).tolist() if stamped else [t_ns] * len(rows)
    poses = [t[POSE](header=bag.header(ti), pose=bag.pose(x, y, qz, qw))
             for ti, x, y, qz, qw in zip(times, rows[:, 1].tolist(), rows[:, 2].tolist(), z.tolist(), w.tolist())]
    bag.add(topic, PATH, t_ns, t[PATH](header=bag.header(t_ns), poses=poses))


def _marker(bag: _Bag, t_ns: int, ns_name: str, marker_id: int, kind: int, pose: Any,
            scale: tuple[float, float, float], rgba: tuple[float, float, float, float]) -> Any:
    """A ``visualization_msgs/Marker`` (action ADD, no lifetime: it stays until replaced)."""
    t = bag.types
    return t["visualization_msgs/msg/Marker"](
        header=bag.header(t_ns), ns=ns_name, id=marker_id, type=kind, action=0, pose=pose,
        scale=t["geometry_msgs/msg/Vector3"](x=scale[0], y=scale[1], z=scale[2]), color=bag.color(rgba),
        lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False, points=[], colors=[],
        texture_resource="", texture=t["sensor_msgs/msg/CompressedImage"](
            header=bag.header(0, ""), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text="", mesh_resource="",
        mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False)


def _scene(bag: _Bag, record: RunRecord, names: Names, t0: int) -> None:
    """The blocks at ``t0``, then each moving obstacle at each of its poses."""
    t = bag.types
    topic = names.topic("scene")
    cubes = [_marker(bag, t0, "blocks", k, 1, bag.pose(bx, by, math.sin(a / 2), math.cos(a / 2), BLOCK_HEIGHT_M / 2),
                     (bw, bh, BLOCK_HEIGHT_M), _BLOCK_RGBA)
             for k, (bx, by, bw, bh, a) in enumerate(np.asarray(record.blocks, dtype=float).reshape(-1, 5).tolist())]
    bag.add(topic, MARKERS, t0, t[MARKERS](markers=cubes))
    for obstacle in record.obstacles:
        d = 2 * obstacle.radius
        for t_ns, (x, y, a) in zip(ns_array(obstacle.poses[:, 0]).tolist(), obstacle.poses[:, 1:4].tolist()):
            disc = _marker(bag, t_ns, "obstacles", obstacle.index, 3,
                           bag.pose(x, y, math.sin(a / 2), math.cos(a / 2), BLOCK_HEIGHT_M / 2),
                           (d, d, BLOCK_HEIGHT_M), _OBSTACLE_RGBA)
            bag.add(topic, MARKERS, t_ns, t[MARKERS](markers=[disc]))


def _log(bag: _Bag, record: RunRecord, names: Names) -> None:
    for t_ns, level, text in log_times(record):
        bag.add("/rosout", LOG, t_ns, bag.types[LOG](stamp=bag.time(t_ns), level=_LEVELS[level], name=names.log_name,
                                                     msg=text, file="", function="", line=0))


def _metrics(bag: _Bag, record: RunRecord, names: Names, t1: int) -> None:
    t = bag.types
    values = [t["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in flat_metrics(record.metrics)]
    level = 0 if record.status == "completed" else 2  # OK, ERROR
    status = t["diagnostic_msgs/msg/DiagnosticStatus"](
        level=level, name=f"run {record.run_id}", message=record.status,
        hardware_id=f"{record.mode} #{record.repetition}", values=values)
    bag.add(names.topic("metrics"), DIAGNOSTICS, t1, t[DIAGNOSTICS](header=bag.header(t1), status=[status]))
