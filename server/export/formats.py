"""The export formats: names, file names, media types, and whether the optional packages they need are there."""

from __future__ import annotations

import importlib
from enum import Enum

__all__ = ["INSTALL_HINT", "ExportFormat", "missing_packages"]

#: how to install what the exports need (the project's optional extra)
INSTALL_HINT = "pip install 'teleworkbench[export]'"


class ExportFormat(str, Enum):
    """``mcap``: one MCAP file with Foxglove's schemas; ``rosbag2``: a ROS 2 bag directory, zipped."""

    MCAP = "mcap"
    ROSBAG2 = "rosbag2"

    @property
    def media_type(self) -> str:
        return "application/octet-stream" if self is ExportFormat.MCAP else "application/zip"

    @property
    def suffix(self) -> str:
        return ".mcap" if self is ExportFormat.MCAP else ".zip"

    @property
    def requirements(self) -> tuple[tuple[str, str], ...]:
        """What the format is written with: ``(module, distribution)`` pairs."""
        if self is ExportFormat.MCAP:
            return (("foxglove.channels", "foxglove-sdk"),)
        return (("rosbags.rosbag2", "rosbags"),)

    def filename(self, stem: str) -> str:
        """The download's file name: ``run-12.mcap``, ``experiment-3.zip`` (holding the bag ``experiment-3/``)."""
        return f"{stem}{self.suffix}"


def missing_packages(fmt: ExportFormat) -> list[str]:
    """The distributions :class:`ExportFormat` ``fmt`` needs whose modules cannot be imported (empty: it can be
    written)."""
    out = []
    for module, distribution in fmt.requirements:
        try:
            importlib.import_module(module)
        except ImportError:
            out.append(distribution)
    return out
