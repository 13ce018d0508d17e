"""The local Ray cluster of a testbed (``twb up --sim-engine ray``), as a process that ends with the server.

``python -m server.pipeline.ray_head --server-pid PID -- <ray start arguments>``
runs ``ray start --head --block`` in its own process group (the server
starts it in a new session) and ends the whole group — Ray's GCS, raylet,
workers and agents — when the server is gone, however it ended, or when it
is told to stop (SIGTERM).  Ray's own fate-sharing does not cover a killed
driver: its agents outlive it.  The cluster holds nothing worth draining
(the server keeps every result), so the group is killed at once.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys

from ..core.lifeline import exit_with_parent

__all__ = ["main"]


def _end(*_: object) -> None:
    os.killpg(0, signal.SIGKILL)  # this process is the group's leader: it ends too


def main(argv: list[str] | None = None) -> int:
    """Start ``ray start --head --block`` with the arguments after ``--``; end with the server."""
    parser = argparse.ArgumentParser(prog="python -m server.pipeline.ray_head")
    parser.add_argument("--server-pid", type=int, required=True)
    parser.add_argument("ray_args", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    ray_args = args.ray_args[1:] if args.ray_args[:1] == ["--"] else args.ray_args
    signal.signal(signal.SIGTERM, _end)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the server decides when the cluster stops
    exit_with_parent(args.server_pid, action=_end)
    child = subprocess.Popen([sys.executable, "-c", "from ray.scripts.scripts import main; main()",
                              "start", "--head", "--block", *ray_args])
    child.wait()
    _end()
    return 0


if __name__ == "__main__":
    sys.exit(main())
