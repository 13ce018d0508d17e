"""Exports of runs and experiments for the tools researchers already use: MCAP (Foxglove) and ROS 2 bags.

The writers are pure conversions: a :class:`RunRecord` (a run's stored data
as plain values) in, a file out (docs/exports.md).  Loading the records from
the database is :mod:`server.export.load`'s job; serving them the API's.
"""

from .formats import INSTALL_HINT, ExportFormat, missing_packages
from .layout import MAP_FRAME, Names, quaternion_yaw
from .mcap_file import write_mcap
from .record import LogLine, ObstacleTrack, RobotTrack, RunRecord
from .rosbag2_file import write_rosbag2, write_rosbag2_zip

__all__ = ["INSTALL_HINT", "MAP_FRAME", "ExportFormat", "LogLine", "Names", "ObstacleTrack", "RobotTrack", "RunRecord",
           "missing_packages", "quaternion_yaw", "write_mcap", "write_rosbag2", "write_rosbag2_zip"]
