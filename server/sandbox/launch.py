"""The sandbox launcher: runs one uploaded program isolated and captures the path it sends.

``python -m server.sandbox.launch`` reads a JSON job on stdin and prints one
JSON result line when everything has ended (``{"probe": true}`` instead
reports what isolation this machine gives).  The server
(:mod:`server.sandbox.service`) starts it for each program; SIGTERM ends it
early, sandbox included, and so does the server's death.  Linux only.

In order:

1. The wire codec (and with it numpy) is imported with this module, while
   the project's files are still visible (the mount namespace covers
   ``/tmp``, where a checkout may live); the server sets the BLAS/OpenMP
   thread counts to 1, so the process is still single-threaded when it
   unshares and forks (checked).
2. The program's cgroup (:mod:`.cgroups`): one memory limit for all its
   processes; without one, ``RLIMIT_AS`` per process.
3. Namespaces (:func:`.isolation.enter_namespaces`).  With a pid namespace
   the launcher forks: the child is pid 1 of the namespace and gets SIGKILL
   when the launcher dies; when pid 1 ends, the kernel kills every process
   of the namespace, so nothing the program started outlives the sandbox.
4. Supervision (:mod:`.supervise`): mounts, the program, its robot port, the
   wall-time limit, the end of every process, the result.
5. The launcher removes the cgroup.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import sys
from typing import Any, Optional

import contract.protocol  # noqa: F401 - see _check_single_threaded

from . import cgroups
from .isolation import CAP_SETGID, CAP_SETUID, PR_SET_PDEATHSIG, enter_namespaces, has_cap, prctl
from .lifetime import EndRequest
from .link import LinkKind, encode, parse
from .seccomp import seccomp_program
from .supervise import blank_result, supervise

__all__ = ["main", "probe"]


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
    _warm_codec()
    try:
        _check_single_threaded()
    except OSError as exc:
        _emit({**blank_result(), "launch_error": exc.strerror or str(exc), "isolation": {"namespaces": []}})
        return 0
    cgroup, memory = program_cgroup(job)
    try:
        return _run(job, cgroup, memory, ending)
    finally:
        if cgroup is not None:
            cgroup.remove()


def _warm_codec() -> None:
    """Run the codec once on every kind of line the robot port answers, before any namespace.

    numpy imports some of its modules only when first used (``np.unique``
    imports ``numpy.ma``); once the mount namespace covers ``/tmp``, where a
    checkout and its virtualenv may live, such an import would fail.
    """
    for line in (b"T,T,P,300,300,0;1500,300,90", b"T,T,Q", b"T,T,S", b"T,T,I,300,300,0", b"T,T,B,900,900,100,100,0",
                 b"T,T,A,0123456789abcdef", b"T,T,L", b"T,T,P,1x,2,3", b"T,T,P," + b"1" * 40 + b",1,1", b"T,T,X",
                 b"\x01", "T,T,Q,\u00e9".encode()):
        try:
            contract.protocol.parse_command(line, field_size=(1.8, 1.8))
        except contract.protocol.ProtocolError as exc:
            exc.line()
    contract.protocol.format_status("IDLE", (0.3, 0.3, 0.0), 0.0)


def _run(job: dict[str, Any], cgroup: Optional[cgroups.ProgramCgroup], memory: dict[str, Any],
         ending: EndRequest) -> int:
    try:
        iso = enter_namespaces(job.get("namespaces", "auto"))
    except OSError as exc:
        _emit({**blank_result(), "launch_error": exc.strerror or str(exc), "isolation": {"namespaces": [], **memory}})
        return 0
    iso.update(memory)
    if "pid" not in iso["namespaces"]:
        return _supervise(job, iso, cgroup, ending)
    child = os.fork()
    if child == 0:
        code = 1
        try:
            prctl(PR_SET_PDEATHSIG, signal.SIGKILL)  # pid 1 dies with the launcher, and the namespace with it
            pid1 = EndRequest()
            pid1.listen(watch_parent=False)  # its parent is outside the namespace: getppid() is 0
            code = _supervise(job, iso, cgroup, pid1)
        finally:
            os._exit(code)
    # outside the namespace: wait; if the server stops us or dies, pid 1 (and with it the sandbox) dies too
    ending.on_end = lambda: os.kill(child, signal.SIGKILL)
    if ending.reason is not None:
        ending.on_end()
    while True:
        try:
            _, status = os.waitpid(child, 0)
            break
        except InterruptedError:
            continue
    return os.waitstatus_to_exitcode(status) & 0xFF


def _supervise(job: dict[str, Any], iso: dict[str, Any], cgroup: Optional[cgroups.ProgramCgroup],
               ending: EndRequest) -> int:
    try:
        result = supervise(job, iso, cgroup=cgroup, stop=ending.check)
    except Exception as exc:  # noqa: BLE001 - report set-up failures to the server instead of a traceback
        result = {**blank_result(), "launch_error": f"sandbox set-up failed: {type(exc).__name__}: {exc}"}
    result["isolation"] = iso
    _emit(result)
    return 0


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
    """What isolation this machine gives (the namespaces tried in a throw-away child process)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        os.close(r)
        try:
            iso = enter_namespaces(job.get("namespaces", "auto"))
            iso["uid_switch"] = not iso["user_namespace"] and has_cap(CAP_SETUID) and has_cap(CAP_SETGID)
            iso["seccomp"] = seccomp_program() is not None
        except OSError as exc:
            iso = {"namespaces": [], "user_namespace": False, "reason": str(exc), "uid_switch": False}
        os.write(w, json.dumps(iso).encode())
        os._exit(0)
    os.close(w)
    data = b""
    while chunk := os.read(r, 65536):
        data += chunk
    os.waitpid(pid, 0)
    iso = json.loads(data)
    cg, memory = program_cgroup({"cgroups": job.get("cgroups", "auto"),
                                 "limits": {"memory_bytes": 64 << 20, "processes": 8}})
    if cg is not None:
        cg.remove()
    return {**iso, **memory}


def _check_single_threaded() -> None:
    """Fail unless this process is single-threaded after importing the codec (with this module).

    The codec must be imported before the mount namespace covers ``/tmp``
    (a checkout and its virtualenv may live there), and it imports numpy;
    the server starts the launcher with ``OPENBLAS_NUM_THREADS=1`` (and the
    OpenMP/MKL equivalents) so that numpy starts no thread: ``unshare`` of a
    user namespace and ``fork`` need a single thread.
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
