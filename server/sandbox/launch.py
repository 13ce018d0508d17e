"""The sandbox launcher: runs one uploaded program isolated and captures the path it sends.

``python -m server.sandbox.launch`` reads a JSON job on stdin and prints one
JSON result line when everything has ended (``{"probe": true}`` instead
reports what isolation this machine gives).  The server
(:mod:`server.sandbox.service`) starts it for each program; SIGTERM ends it
early, sandbox included, and so does the server's death.  Linux only.

In order:

1. The program's cgroup (:mod:`.cgroups`): one memory limit for all its
   processes; without one, ``RLIMIT_AS`` per process.
2. Supervision (:mod:`.supervise`): the sandbox (bubblewrap, :mod:`.bwrap`,
   where the machine allows it), the program, its robot port, the wall-time
   limit, the end of every process, the result.
3. The launcher removes the cgroup.

The launcher itself stays outside every namespace (a helper process enters
the sandbox's network namespace for the robot ports); it is single-threaded
(it forks helpers and runs Python between fork and exec).
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from typing import Any, Optional

import contract.protocol  # noqa: F401 - the robot port's codec (and numpy): see _check_single_threaded

from . import bwrap, cgroups, seccomp
from .confine import confinement
from .lifetime import EndRequest
from .link import LinkKind, encode, parse
from .supervise import blank_result, program_user, supervise

__all__ = ["main", "probe"]

#: the user a probe runs bwrap as, when the server is root and names none
PROBE_UID = 65534


def main() -> int:
    """Run the job on stdin; the exit status (0 whenever a result was printed)."""
    ending = EndRequest()
    ending.listen(watch_parent=True)
    raw = sys.stdin.buffer.readline()  # the job is one link line; a controller's relay follows on stdin
    first = parse(raw)
    if first is not None and first.kind is LinkKind.JSON and first.data is not None:
        job = first.data
    else:  # a job spread over several lines (written by hand): the whole of stdin
        job = json.loads(raw + sys.stdin.buffer.read())
    if not job.get("relay"):
        sys.stdin.close()
    if job.get("probe"):
        _emit(probe(job))
        return 0
    try:
        _check_single_threaded()
    except OSError as exc:
        _emit({**blank_result(), "launch_error": exc.strerror or str(exc), "isolation": {"namespaces": []}})
        return 0
    cgroup, memory = program_cgroup(job)
    try:
        iso: dict[str, Any] = dict(memory)
        try:
            result = supervise(job, iso, cgroup=cgroup, stop=ending.check)
        except Exception as exc:  # noqa: BLE001 - report set-up failures to the server instead of a traceback
            result = {**blank_result(), "launch_error": f"sandbox set-up failed: {type(exc).__name__}: {exc}"}
        result["isolation"] = iso
        _emit(result)
        return 0
    finally:
        if cgroup is not None:
            cgroup.remove()


def program_cgroup(job: dict[str, Any]) -> tuple[Optional[cgroups.ProgramCgroup], dict[str, Any]]:
    """The program's cgroup (None: none) and how the memory limit applies, for the isolation record.

    ``memory_limit``: ``"cgroup"`` (all the program's processes together) or
    ``"per-process"`` (``RLIMIT_AS``); ``cgroup``: ``"v1"``, ``"v2"`` or None;
    ``cgroup_name``: its directory's name; ``memory_note``: why there is no
    cgroup.  ``"cgroups": "off"`` in the job switches them off.
    """
    if job.get("cgroups", "auto") == "off":
        return None, {"memory_limit": "per-process", "cgroup": None, "memory_note": "cgroups switched off"}
    limits = job["limits"]
    try:
        cg = cgroups.create(int(limits["memory_bytes"]), int(limits["processes"]))
    except (cgroups.Unavailable, OSError) as exc:
        return None, {"memory_limit": "per-process", "cgroup": None, "memory_note": str(exc)}
    return cg, {"memory_limit": "cgroup", "cgroup": f"v{cg.version}", "cgroup_name": cg.memory.name,
                "memory_note": ""}


def probe(job: dict[str, Any]) -> dict[str, Any]:
    """What isolation this machine gives: bwrap's sandbox tried on ``true``, as a program's would be made.

    As root it runs as the job's ``uid`` (else :data:`PROBE_UID`), as a program would.
    """
    mode = job.get("namespaces", "auto")
    uid, gid = program_user({"uid": job.get("uid", PROBE_UID), "gid": job.get("gid", PROBE_UID)})
    iso: dict[str, Any] = {"namespaces": [], "user_namespace": False, "sandbox": None, "reason": "",
                           "uid_switch": uid is not None, "seccomp": not seccomp.UNAVAILABLE}
    path = bwrap.find(job)
    if mode == "off":
        iso["reason"] = "namespaces switched off (TWB_SANDBOX_NAMESPACES=off)"
    elif path is None:
        iso["reason"] = "no namespaces available (bubblewrap (bwrap) is not installed)"
    else:
        limits = {"cpu_s": 5, "memory_bytes": 256 << 20, "open_files": 64}
        try:
            bubble, _ = bwrap.start(
                path, {"files": {}}, ["true"], {"PATH": "/usr/bin:/bin"}, ports=[], tmpfs_bytes=1 << 20, hide=[],
                seccomp=None if seccomp.UNAVAILABLE else seccomp.program(), nproc=8, uid=uid,
                preexec=confinement(limits, cgroup=None, uid=uid, gid=gid, nproc=None, file_bytes=1 << 20))
            _, err = bubble.proc.communicate(timeout=20)
            bubble.finish()
            if bubble.proc.returncode != 0 or not bubble.program_started():
                said = err.decode("utf-8", "replace").strip().splitlines()
                raise bwrap.SetupFailed(said[-1].removeprefix("bwrap: ") if said
                                        else f"bwrap exited with status {bubble.proc.returncode}")
            iso.update({"namespaces": bubble.namespaces, "user_namespace": True, "sandbox": bwrap.version(path)})
        except (bwrap.SetupFailed, OSError, subprocess.SubprocessError) as exc:
            iso["reason"] = f"no namespaces available ({exc})"
    if seccomp.UNAVAILABLE:
        iso["reason"] = "; ".join(filter(None, [iso["reason"], f"no seccomp filter: {seccomp.UNAVAILABLE}"]))
    cg, memory = program_cgroup({"cgroups": job.get("cgroups", "auto"),
                                 "limits": {"memory_bytes": 64 << 20, "processes": 8}})
    if cg is not None:
        cg.remove()
    return {**iso, **memory}


def _check_single_threaded() -> None:
    """Fail unless this process is single-threaded after importing the codec (with this module).

    The codec imports numpy; the server starts the launcher with
    ``OPENBLAS_NUM_THREADS=1`` (and the OpenMP/MKL equivalents) so that
    numpy starts no thread: the launcher runs Python between ``fork`` and
    ``exec`` (the confinement) and in forked helpers, which is safe only in
    a single-threaded process.
    """
    threads = len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else 1
    if threads != 1:
        raise OSError(errno.EAGAIN, f"the launcher has {threads} threads after importing the codec; "
                                    "start it with OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1")


def _emit(obj: dict[str, Any]) -> None:
    try:
        os.set_blocking(1, True)
        sys.stdout.buffer.write(encode(LinkKind.JSON, obj))
        sys.stdout.buffer.flush()
    except BrokenPipeError:  # the server is gone
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


if __name__ == "__main__":
    sys.exit(main())
