"""The program's working directory, environment and command line."""

from __future__ import annotations

import base64
import os
import tempfile
from typing import Any, Optional

__all__ = ["make_workdir", "program_command"]


def make_workdir(job: dict[str, Any], *, uid: Optional[int], gid: Optional[int]) -> str:
    """Write the job's files into a fresh directory owned by the program's user; its path.

    For a program without namespaces: in a sandbox, bwrap copies the files
    into the sandbox's own /tmp (:mod:`.bwrap`).
    """
    work = tempfile.mkdtemp(prefix="twb-program-", dir=job.get("tmp_dir") or None)
    for name, spec in job["files"].items():
        path = os.path.join(work, name)
        data = base64.b64decode(spec["base64"])
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(path, spec.get("mode", 0o400))
        if uid is not None:
            os.chown(path, uid, gid)
    if uid is not None:
        os.chown(work, uid, gid)
    return work


def program_command(job: dict[str, Any], work: str, ports: list[int]) -> tuple[list[str], dict[str, str]]:
    """(argv, environment) of the program whose robot ports are 127.0.0.1:``ports`` (robot 0's first).

    Arguments may name the inputs: ``{robot_port}``, ``{env_file}``, ``{start}``,
    ... (each ``TWB_<NAME>`` of the environment, in lower case).  A multi-robot
    job (``start_poses`` in the job) also gets ``TWB_ROBOT_PORTS``, every port
    in robot order, comma-separated; ``TWB_ROBOT_PORT`` is robot 0's.
    """
    env = {k: str(v) for k, v in job["env"].items()}
    env.update({"TWB_ROBOT_HOST": "127.0.0.1", "TWB_ROBOT_PORT": str(ports[0]), "HOME": work, "TMPDIR": work,
                "TWB_WORKDIR": work})
    if job.get("start_poses"):
        env["TWB_ROBOT_PORTS"] = ",".join(map(str, ports))
    env["TWB_ENV_FILE"] = os.path.join(work, env.get("TWB_ENV_FILE", "environment.json"))
    if "TWB_PATH_FILE" in env:  # a controller program's planned path
        env["TWB_PATH_FILE"] = os.path.join(work, env["TWB_PATH_FILE"])
    subst = {"{" + k[4:].lower() + "}": v for k, v in env.items() if k.startswith("TWB_")}
    argv = []
    for a in job["argv"]:
        for key, value in subst.items():
            a = a.replace(key, value)
        argv.append(a)
    return argv, env
