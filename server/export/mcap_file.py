"""A run (or an experiment's runs) as an MCAP file with Foxglove's well-known schemas, protobuf-encoded.

What goes where (names: :mod:`.layout`), each message's log and publish time
the experiment time it belongs to (ns on the run's clock):

- ``/tf`` ``foxglove.FrameTransforms``: ``map`` → the robot's ``base_link``, one per stored pose;
- ``/robot/pose`` ``foxglove.PoseInFrame``: the same poses in ``map``;
- ``/robot/planned_path`` and ``/robot/driven_path`` ``foxglove.SceneUpdate``: each path as a line
  strip, the plan at the run's start, the driven path (every stored pose) at its end;
- ``/scene`` ``foxglove.SceneUpdate``: the field's boundary and blocks at the start (entity
  ``environment``), then each moving obstacle as a cylinder (entity ``obstacle_<k>``) at each of its poses;
- ``/log`` ``foxglove.Log``: the run's protocol lines;
- ``/metrics`` (JSON, schema ``twb.RunMetrics``): the run's metrics, once, at its end.

Needs the ``export`` extra (``mcap``, ``mcap-protobuf-support``, ``foxglove-schemas-protobuf``).
"""

from __future__ import annotations

import json
import math
from typing import IO, Any, Sequence

import numpy as np

from .layout import BLOCK_HEIGHT_M, MAP_FRAME, Names, log_times, ns, ns_array, yaw_quaternion
from .record import RunRecord

__all__ = ["MCAP_PROFILE", "METRICS_SCHEMA", "write_mcap"]

#: the MCAP header's profile: none of the registered ones (``ros1``, ``ros2``), as Foxglove's own SDK writes
MCAP_PROFILE = ""
#: the schema name of the ``/metrics`` channel (JSON)
METRICS_SCHEMA = "twb.RunMetrics"
_METRICS_JSONSCHEMA = {"title": METRICS_SCHEMA, "type": "object", "properties": {
    "run_id": {"type": "integer"}, "experiment_id": {"type": "integer"}, "mode": {"type": "string"},
    "repetition": {"type": "integer"}, "status": {"type": "string"}, "metrics": {"type": "object"}}}
_LEVELS = {"info": 2, "warning": 3, "error": 4}
_PLANNED_RGBA = (0.12, 0.47, 0.71, 1.0)
_DRIVEN_RGBA = (0.84, 0.15, 0.16, 1.0)
_BLOCK_RGBA = (0.35, 0.35, 0.35, 1.0)
_OBSTACLE_RGBA = (1.0, 0.5, 0.05, 0.9)
_LINE_WIDTH_M = 0.006


def write_mcap(records: Sequence[RunRecord], out: IO[bytes], *, experiment: bool = False) -> None:
    """Write ``records`` to ``out`` (a binary file, written in order: it may be a pipe) as one MCAP file.

    ``experiment``: the runs are an experiment's, each under its ``run_<id>`` prefix (:class:`~.layout.Names`).
    Times are the runs' experiment clocks, in nanoseconds (seconds x 1e9).
    """
    writer = _McapOut(out)
    for record in records:
        _write_run(writer, record, Names.of(record, experiment))
    writer.writer.add_metadata("teleworkbench", {
        "runs": ",".join(str(r.run_id) for r in records),
        "experiments": ",".join(sorted({str(r.experiment_id) for r in records})),
        "clock": "experiment seconds on each run's clock (log time = t x 1e9 ns)",
        "frame": f"{MAP_FRAME}: the experiment's field, origin at its lower-left corner (m, rad)"})
    writer.writer.finish()


class _McapOut:
    """An MCAP writer with one schema per message type and one channel per topic."""

    def __init__(self, out: IO[bytes]) -> None:
        from mcap.writer import CompressionType, Writer

        self.writer = Writer(out, compression=CompressionType.ZSTD)
        self.writer.start(profile=MCAP_PROFILE, library="teleworkbench")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}

    def channel(self, topic: str, message_class: Any) -> int:
        """The channel of ``topic`` carrying ``message_class`` (a protobuf class), registered at first use."""
        if topic not in self._channels:
            from mcap_protobuf.schema import register_schema

            name = message_class.DESCRIPTOR.full_name
            if name not in self._schemas:
                self._schemas[name] = register_schema(self.writer, message_class)
            self._channels[topic] = self.writer.register_channel(topic=topic, message_encoding="protobuf",
                                                                 schema_id=self._schemas[name])
        return self._channels[topic]

    def json_channel(self, topic: str) -> int:
        if topic not in self._channels:
            if METRICS_SCHEMA not in self._schemas:
                self._schemas[METRICS_SCHEMA] = self.writer.register_schema(
                    name=METRICS_SCHEMA, encoding="jsonschema", data=json.dumps(_METRICS_JSONSCHEMA).encode())
            self._channels[topic] = self.writer.register_channel(topic=topic, message_encoding="json",
                                                                 schema_id=self._schemas[METRICS_SCHEMA])
        return self._channels[topic]

    def add(self, channel: int, t_ns: int, data: bytes) -> None:
        self.writer.add_message(channel_id=channel, log_time=t_ns, publish_time=t_ns, data=data)


def _write_run(out: _McapOut, record: RunRecord, names: Names) -> None:
    t0, t1 = ns(record.t0), ns(record.t1)
    _scene(out, record, names, t0)
    for robot in record.robots:
        _poses(out, names, robot.index, robot.poses)
        if robot.planned is not None and len(robot.planned):
            _line(out, names.robot_topic(robot.index, "planned_path"), f"{names.robot(robot.index)}/planned_path",
                  robot.planned[:, :2], t0, _PLANNED_RGBA)
        if len(robot.poses):
            _line(out, names.robot_topic(robot.index, "driven_path"), f"{names.robot(robot.index)}/driven_path",
                  robot.poses[:, 1:3], t1, _DRIVEN_RGBA)
    _log(out, record, names)
    body = {"run_id": record.run_id, "experiment_id": record.experiment_id, "mode": record.mode,
            "repetition": record.repetition, "status": record.status, "metrics": _finite(record.metrics)}
    out.add(out.json_channel(names.topic("metrics")), t1, json.dumps(body).encode())


def _poses(out: _McapOut, names: Names, index: int, poses: np.ndarray) -> None:
    """Each pose as a ``map`` → base frame transform on ``/tf`` and a pose on the robot's ``pose`` topic."""
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

    if not len(poses):
        return
    tf_channel = out.channel("/tf", FrameTransforms)
    pose_channel = out.channel(names.robot_topic(index, "pose"), PoseInFrame)
    tfs = FrameTransforms(transforms=[FrameTransform(parent_frame_id=MAP_FRAME, child_frame_id=names.base_frame(index))])
    tf = tfs.transforms[0]
    pose = PoseInFrame(frame_id=MAP_FRAME)
    times = ns_array(poses[:, 0])
    z, w = yaw_quaternion(poses[:, 3])
    for t_ns, x, y, qz, qw in zip(times.tolist(), poses[:, 1].tolist(), poses[:, 2].tolist(), z.tolist(), w.tolist()):
        secs, nanos = divmod(t_ns, 1_000_000_000)
        tf.timestamp.seconds, tf.timestamp.nanos = secs, nanos
        tf.translation.x, tf.translation.y = x, y
        tf.rotation.z, tf.rotation.w = qz, qw
        out.add(tf_channel, t_ns, tfs.SerializeToString())
        pose.timestamp.seconds, pose.timestamp.nanos = secs, nanos
        pose.pose.position.x, pose.pose.position.y = x, y
        pose.pose.orientation.z, pose.pose.orientation.w = qz, qw
        out.add(pose_channel, t_ns, pose.SerializeToString())


def _stamp(message: Any, t_ns: int) -> None:
    message.timestamp.seconds, message.timestamp.nanos = divmod(t_ns, 1_000_000_000)


def _rgba(target: Any, rgba: tuple[float, float, float, float]) -> None:
    target.r, target.g, target.b, target.a = rgba


def _line(out: _McapOut, topic: str, entity_id: str, xy: np.ndarray, t_ns: int,
          rgba: tuple[float, float, float, float]) -> None:
    """A path ``xy`` ``(K, 2)`` (m) as a line strip in one scene update on ``topic``."""
    from foxglove_schemas_protobuf.Point3_pb2 import Point3
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    update = SceneUpdate()
    entity = update.entities.add(frame_id=MAP_FRAME, id=entity_id)
    _stamp(entity, t_ns)
    line = entity.lines.add(type=0, thickness=_LINE_WIDTH_M)  # LINE_STRIP
    line.pose.orientation.w = 1.0
    line.points.extend(Point3(x=x, y=y) for x, y in np.asarray(xy, dtype=float).tolist())
    _rgba(line.color, rgba)
    out.add(out.channel(topic, SceneUpdate), t_ns, update.SerializeToString())


def _scene(out: _McapOut, record: RunRecord, names: Names, t0: int) -> None:
    """The field's boundary and blocks at ``t0``, then each moving obstacle at each of its poses."""
    from foxglove_schemas_protobuf.Point3_pb2 import Point3
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    channel = out.channel(names.topic("scene"), SceneUpdate)
    update = SceneUpdate()
    env = update.entities.add(frame_id=MAP_FRAME, id="environment")
    _stamp(env, t0)
    w, h = record.size
    border = env.lines.add(type=1, thickness=_LINE_WIDTH_M)  # LINE_LOOP
    border.pose.orientation.w = 1.0
    border.points.extend([Point3(x=0.0, y=0.0), Point3(x=w, y=0.0), Point3(x=w, y=h), Point3(x=0.0, y=h)])
    _rgba(border.color, _BLOCK_RGBA)
    for bx, by, bw, bh, angle in np.asarray(record.blocks, dtype=float).reshape(-1, 5).tolist():
        cube = env.cubes.add()
        cube.pose.position.x, cube.pose.position.y, cube.pose.position.z = bx, by, BLOCK_HEIGHT_M / 2
        cube.pose.orientation.z, cube.pose.orientation.w = math.sin(angle / 2), math.cos(angle / 2)
        cube.size.x, cube.size.y, cube.size.z = bw, bh, BLOCK_HEIGHT_M
        _rgba(cube.color, _BLOCK_RGBA)
    out.add(channel, t0, update.SerializeToString())
    for obstacle in record.obstacles:
        update = SceneUpdate()
        entity = update.entities.add(frame_id=MAP_FRAME, id=f"obstacle_{obstacle.index}")
        disc = entity.cylinders.add()
        disc.size.x = disc.size.y = 2 * obstacle.radius
        disc.size.z = BLOCK_HEIGHT_M
        disc.bottom_scale = disc.top_scale = 1.0
        _rgba(disc.color, _OBSTACLE_RGBA)
        times = ns_array(obstacle.poses[:, 0]).tolist()
        for t_ns, (x, y, a) in zip(times, obstacle.poses[:, 1:4].tolist()):
            _stamp(entity, t_ns)
            disc.pose.position.x, disc.pose.position.y, disc.pose.position.z = x, y, BLOCK_HEIGHT_M / 2
            disc.pose.orientation.z, disc.pose.orientation.w = math.sin(a / 2), math.cos(a / 2)
            out.add(channel, t_ns, update.SerializeToString())


def _log(out: _McapOut, record: RunRecord, names: Names) -> None:
    from foxglove_schemas_protobuf.Log_pb2 import Log

    if not record.log:
        return
    channel = out.channel("/log", Log)
    message = Log(name=names.log_name)
    for t_ns, level, text, _ in log_times(record):
        _stamp(message, t_ns)
        message.level, message.message = _LEVELS[level], text
        out.add(channel, t_ns, message.SerializeToString())


def _finite(value: Any) -> Any:
    """JSON-safe: NaN and infinities become None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value
