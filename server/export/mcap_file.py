"""A run (or an experiment's runs) as an MCAP file with Foxglove's well-known schemas, written by Foxglove's SDK.

What goes where (names: :mod:`.layout`), each message's log time the
experiment time it belongs to (ns on the run's clock; the messages'
``timestamp`` the same):

- ``/tf`` ``foxglove.FrameTransforms``: ``map`` → the robot's ``base_link``, one per stored pose;
- ``/robot/pose`` ``foxglove.PoseInFrame``: the same poses in ``map``;
- ``/robot/planned_path`` and ``/robot/driven_path`` ``foxglove.SceneUpdate``: each path as a line
  strip, the plan at the run's start, the driven path (every stored pose) at its end;
- ``/scene`` ``foxglove.SceneUpdate``: the field's boundary and blocks at the start (entity
  ``environment``), then each moving obstacle as a cylinder (entity ``obstacle_<k>``) at each of its poses;
- ``/log`` ``foxglove.Log``: the run's protocol lines;
- ``/metrics`` (JSON, schema ``twb.RunMetrics``): the run's metrics, once, at its end.

The schemas are protobuf-encoded (as Foxglove's SDK writes them); the ``mcap`` package with
``mcap-protobuf-support``'s decoder reads them.  Needs the ``export`` extra (``foxglove-sdk``).
"""

from __future__ import annotations

import json
import math
from typing import IO, Any, Sequence

import numpy as np

from .layout import BLOCK_HEIGHT_M, MAP_FRAME, Names, log_times, ns, ns_array, yaw_quaternion
from .record import RunRecord

__all__ = ["METRICS_SCHEMA", "write_mcap"]

#: the schema name of the ``/metrics`` channel (JSON)
METRICS_SCHEMA = "twb.RunMetrics"
_METRICS_JSONSCHEMA = {"title": METRICS_SCHEMA, "type": "object", "properties": {
    "run_id": {"type": "integer"}, "experiment_id": {"type": "integer"}, "mode": {"type": "string"},
    "repetition": {"type": "integer"}, "status": {"type": "string"}, "metrics": {"type": "object"}}}
_PLANNED_RGBA = (0.12, 0.47, 0.71, 1.0)
_DRIVEN_RGBA = (0.84, 0.15, 0.16, 1.0)
_BLOCK_RGBA = (0.35, 0.35, 0.35, 1.0)
_OBSTACLE_RGBA = (1.0, 0.5, 0.05, 0.9)
_LINE_WIDTH_M = 0.006


def write_mcap(records: Sequence[RunRecord], out: IO[bytes], *, experiment: bool = False) -> None:
    """Write ``records`` to ``out`` (a binary file that can ``seek`` and ``flush``) as one MCAP file.

    ``experiment``: the runs are an experiment's, each under its ``run_<id>`` prefix (:class:`~.layout.Names`).
    Times are the runs' experiment clocks, in nanoseconds (seconds x 1e9).
    """
    import foxglove
    from foxglove.mcap import MCAPCompression, MCAPWriteOptions

    context = foxglove.Context()  # this export's own: exports may run in parallel threads
    options = MCAPWriteOptions(compression=MCAPCompression.Zstd, compression_threads=0)
    with foxglove.open_mcap(out, context=context, writer_options=options) as writer:
        channels = _Channels(context)
        for record in records:
            _write_run(channels, record, Names.of(record, experiment))
        writer.write_metadata("teleworkbench", {
            "runs": ",".join(str(r.run_id) for r in records),
            "experiments": ",".join(sorted({str(r.experiment_id) for r in records})),
            "clock": "experiment seconds on each run's clock (log time = t x 1e9 ns)",
            "frame": f"{MAP_FRAME}: the experiment's field, origin at its lower-left corner (m, rad)"})
        channels.close()


class _Channels:
    """One channel per topic in the export's context, made at first use."""

    def __init__(self, context: Any) -> None:
        self.context = context
        self._open: dict[str, Any] = {}

    def typed(self, topic: str, kind: str) -> Any:
        """The channel of ``topic`` for Foxglove's ``kind`` (``FrameTransforms``, ``SceneUpdate``, ...)."""
        if topic not in self._open:
            from foxglove import channels

            self._open[topic] = getattr(channels, f"{kind}Channel")(topic, context=self.context)
        return self._open[topic]

    def json(self, topic: str) -> Any:
        if topic not in self._open:
            import foxglove

            self._open[topic] = foxglove.Channel(topic, schema=_METRICS_JSONSCHEMA, message_encoding="json",
                                                 context=self.context)
        return self._open[topic]

    def close(self) -> None:
        for channel in self._open.values():
            channel.close()


def _write_run(out: _Channels, record: RunRecord, names: Names) -> None:
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
    out.json(names.topic("metrics")).log(json.dumps(body).encode(), log_time=t1)


def _stamp(t_ns: int) -> Any:
    from foxglove.messages import Timestamp

    sec, nsec = divmod(t_ns, 1_000_000_000)
    return Timestamp(sec=sec, nsec=nsec)


def _pose(x: float, y: float, z: float, qz: float, qw: float) -> Any:
    from foxglove.messages import Pose, Quaternion, Vector3

    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=0.0, y=0.0, z=qz, w=qw))


def _color(rgba: tuple[float, float, float, float]) -> Any:
    from foxglove.messages import Color

    r, g, b, a = rgba
    return Color(r=r, g=g, b=b, a=a)


def _poses(out: _Channels, names: Names, index: int, poses: np.ndarray) -> None:
    """Each pose as a ``map`` → base frame transform on ``/tf`` and a pose on the robot's ``pose`` topic."""
    from foxglove.messages import FrameTransform, FrameTransforms, PoseInFrame, Quaternion, Timestamp, Vector3

    if not len(poses):
        return
    tf_log = out.typed("/tf", "FrameTransforms").log
    pose_log = out.typed(names.robot_topic(index, "pose"), "PoseInFrame").log
    child = names.base_frame(index)
    z, w = yaw_quaternion(poses[:, 3])
    for t_ns, x, y, qz, qw in zip(ns_array(poses[:, 0]).tolist(), poses[:, 1].tolist(), poses[:, 2].tolist(),
                                  z.tolist(), w.tolist()):
        sec, nsec = divmod(t_ns, 1_000_000_000)
        stamp = Timestamp(sec=sec, nsec=nsec)
        position = Vector3(x=x, y=y, z=0.0)
        rotation = Quaternion(x=0.0, y=0.0, z=qz, w=qw)
        tf_log(FrameTransforms(transforms=[FrameTransform(timestamp=stamp, parent_frame_id=MAP_FRAME,
                                                          child_frame_id=child, translation=position,
                                                          rotation=rotation)]), log_time=t_ns)
        pose_log(PoseInFrame(timestamp=stamp, frame_id=MAP_FRAME, pose=_pose(x, y, 0.0, qz, qw)), log_time=t_ns)


def _line(out: _Channels, topic: str, entity_id: str, xy: np.ndarray, t_ns: int,
          rgba: tuple[float, float, float, float]) -> None:
    """A path ``xy`` ``(K, 2)`` (m) as a line strip in one scene update on ``topic``."""
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, Point3, SceneEntity, SceneUpdate

    line = LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose(0.0, 0.0, 0.0, 0.0, 1.0),
                         thickness=_LINE_WIDTH_M, color=_color(rgba),
                         points=[Point3(x=x, y=y, z=0.0) for x, y in np.asarray(xy, dtype=float).tolist()])
    entity = SceneEntity(timestamp=_stamp(t_ns), frame_id=MAP_FRAME, id=entity_id, lines=[line])
    out.typed(topic, "SceneUpdate").log(SceneUpdate(entities=[entity]), log_time=t_ns)


def _scene(out: _Channels, record: RunRecord, names: Names, t0: int) -> None:
    """The field's boundary and blocks at ``t0``, then each moving obstacle at each of its poses."""
    from foxglove.messages import (CubePrimitive, CylinderPrimitive, LinePrimitive, LinePrimitiveLineType, Point3,
                                   SceneEntity, SceneUpdate, Vector3)

    log = out.typed(names.topic("scene"), "SceneUpdate").log
    w, h = record.size
    border = LinePrimitive(type=LinePrimitiveLineType.LineLoop, pose=_pose(0.0, 0.0, 0.0, 0.0, 1.0),
                           thickness=_LINE_WIDTH_M, color=_color(_BLOCK_RGBA),
                           points=[Point3(x=0.0, y=0.0, z=0.0), Point3(x=w, y=0.0, z=0.0), Point3(x=w, y=h, z=0.0),
                                   Point3(x=0.0, y=h, z=0.0)])
    cubes = [CubePrimitive(pose=_pose(bx, by, BLOCK_HEIGHT_M / 2, math.sin(a / 2), math.cos(a / 2)),
                           size=Vector3(x=bw, y=bh, z=BLOCK_HEIGHT_M), color=_color(_BLOCK_RGBA))
             for bx, by, bw, bh, a in np.asarray(record.blocks, dtype=float).reshape(-1, 5).tolist()]
    log(SceneUpdate(entities=[SceneEntity(timestamp=_stamp(t0), frame_id=MAP_FRAME, id="environment",
                                          lines=[border], cubes=cubes)]), log_time=t0)
    for obstacle in record.obstacles:
        d = 2 * obstacle.radius
        size, color, entity_id = Vector3(x=d, y=d, z=BLOCK_HEIGHT_M), _color(_OBSTACLE_RGBA), f"obstacle_{obstacle.index}"
        for t_ns, (x, y, a) in zip(ns_array(obstacle.poses[:, 0]).tolist(), obstacle.poses[:, 1:4].tolist()):
            disc = CylinderPrimitive(pose=_pose(x, y, BLOCK_HEIGHT_M / 2, math.sin(a / 2), math.cos(a / 2)), size=size,
                                     bottom_scale=1.0, top_scale=1.0, color=color)
            log(SceneUpdate(entities=[SceneEntity(timestamp=_stamp(t_ns), frame_id=MAP_FRAME, id=entity_id,
                                                  cylinders=[disc])]), log_time=t_ns)


_LEVELS = {"info": "Info", "warning": "Warning", "error": "Error"}


def _log(out: _Channels, record: RunRecord, names: Names) -> None:
    from foxglove.messages import Log, LogLevel

    if not record.log:
        return
    log = out.typed("/log", "Log").log
    for t_ns, level, text in log_times(record):
        log(Log(timestamp=_stamp(t_ns), level=getattr(LogLevel, _LEVELS[level]), message=text, name=names.log_name),
            log_time=t_ns)


def _finite(value: Any) -> Any:
    """JSON-safe: NaN and infinities become None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value
