"""Supervising one program: spawn it, pump its output and robot port, reap every process, report.

Runs as pid 1 of the sandbox's pid namespace, or in the launcher itself
when there is none.  The end comes when the program exited (its last output
drained), ``grace_s`` after its path (a multi-robot job's: after the last
robot port's path), at the wall-time limit, or when the launcher must end
early (:class:`~.lifetime.EndRequest`).

A job has one robot port, or one per robot of a multi-robot job
(``start_poses``: one pose per robot); each listens on its own loopback
port, takes one connection and keeps the first valid path sent on it.
"""

from __future__ import annotations

import os
import resource
import selectors
import shutil
import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from .cgroups import ProgramCgroup
from .confine import confinement
from .isolation import CAP_SETGID, CAP_SETUID, PR_SET_CHILD_SUBREAPER, has_cap, loopback_up, prctl, set_up_mounts
from .link import LinkKind, encode, parse
from .processes import count_processes, kill_uid
from .robot_port import RobotPort, send
from .seccomp import seccomp_program
from .workdir import make_workdir, program_command

__all__ = ["blank_result", "pump", "reap", "report", "spawn", "supervise"]

#: how long the pipes of an exited program are still read (its children may hold them), s
DRAIN_S = 0.3
#: how often the program's processes are counted, s
COUNT_EVERY_S = 0.05


@dataclass
class PortLink:
    """One robot port: its conversation, its TCP port number and sockets (None once closed)."""

    robot: RobotPort
    number: int
    listener: Optional[socket.socket]
    conn: Optional[socket.socket] = None


@dataclass
class Program:
    """A running program and what its supervision gathered."""

    proc: subprocess.Popen  # type: ignore[type-arg]
    ports: list[PortLink]  # robot 0's first
    work: str
    private_tmp: bool
    uid: Optional[int]
    output_bytes: int  # kept of each of stdout and stderr
    t0: float  # monotonic s at the start
    out: dict[str, bytearray] = field(default_factory=lambda: {"stdout": bytearray(), "stderr": bytearray()})
    dropped: dict[str, int] = field(default_factory=lambda: {"stdout": 0, "stderr": 0})
    procs_max: int = 0
    exited_at: Optional[float] = None
    path_mono: Optional[float] = None
    pipes_open: int = 2
    relay_buf: bytes = b""  # relay: a partial line from the server
    run_ended: Optional[str] = None  # relay: the server ended the run (why)

    @property
    def port(self) -> RobotPort:
        """Robot 0's port (the only one of a single-robot job)."""
        return self.ports[0].robot


def blank_result() -> dict[str, Any]:
    """A result with every field, for a program that never ran."""
    return {"exit_code": None, "signal": None, "timed_out": False, "launch_error": None, "procs_max": 0,
            "robot_port": None, "path": None, "path_at_s": None, "connected": False, "port_log": [], "refused": [],
            "port_unlogged": 0, "run_ended": None, "ports": [],
            "wall_s": 0.0, "cpu_s": 0.0, "max_rss_kib": 0, "memory_peak_kib": None, "memory_oom_kills": None,
            "fork_refusals": None, "stdout": "", "stderr": "", "stdout_dropped": 0, "stderr_dropped": 0}


def supervise(job: dict[str, Any], iso: dict[str, Any], *, cgroup: Optional[ProgramCgroup],
              stop: Callable[[], Optional[str]]) -> dict[str, Any]:
    """Everything from the mounts to the end of the program; the result (``iso`` completed on the way).

    ``stop()`` says why to end early (None: carry on).
    """
    limits = job["limits"]
    uid, gid = _program_user(job, iso)
    iso["uid"] = uid
    _prepare(job, iso)
    listeners = [_listen() for _ in job.get("start_poses") or [job["start_pose"]]]
    work = make_workdir(job, private_tmp="mount" in iso["namespaces"], uid=uid, gid=gid)
    try:
        prog = spawn(job, iso, listeners, work, cgroup=cgroup, uid=uid, gid=gid)
    except (OSError, subprocess.SubprocessError) as exc:
        numbers = [sock.getsockname()[1] for sock in listeners]
        for sock in listeners:
            sock.close()
        return {**blank_result(), "launch_error": f"{type(exc).__name__}: {exc}", "robot_port": numbers[0]}
    pid_namespace = "pid" in iso["namespaces"] and iso.get("proc") == "private"
    me = os.getpid()
    timed_out, stopped = pump(prog, wall_s=float(limits["wall_s"]), grace_s=float(job.get("grace_s", 1.0)),
                              stop=stop, count=lambda: count_processes(pid_namespace=pid_namespace, uid=uid, me=me))
    wall = time.monotonic() - prog.t0
    ended_itself = reap(prog, is_pid1="pid" in iso["namespaces"] and me == 1, cgroup=cgroup)
    return {**report(prog, ended_itself=ended_itself, wall_s=wall, cgroup=cgroup),
            "timed_out": timed_out, "launch_error": stopped}


def _listen() -> socket.socket:
    """A robot port's listening socket on a free loopback port."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    return listener


def _program_user(job: dict[str, Any], iso: dict[str, Any]) -> tuple[Optional[int], Optional[int]]:
    """(uid, gid) of the program: the job's when this process may switch to it, else (None, None)."""
    if not iso["user_namespace"] and job.get("uid") is not None and has_cap(CAP_SETUID) and has_cap(CAP_SETGID):
        return int(job["uid"]), int(job["gid"])
    return None, None


def _prepare(job: dict[str, Any], iso: dict[str, Any]) -> None:
    """Mounts and loopback inside the namespaces; without a pid namespace, orphans come back to us."""
    if "mount" in iso["namespaces"]:
        set_up_mounts(iso, job.get("hide", []), int(job["limits"]["tmpfs_bytes"]))
    else:
        iso["proc"] = "host"
        iso["hidden"] = []
    if "net" in iso["namespaces"]:
        loopback_up()
    if not ("pid" in iso["namespaces"] and os.getpid() == 1):
        prctl(PR_SET_CHILD_SUBREAPER, 1)  # orphans of the program come back to us, to be reaped and killed


def spawn(job: dict[str, Any], iso: dict[str, Any], listeners: list[socket.socket], work: str, *,
          cgroup: Optional[ProgramCgroup], uid: Optional[int], gid: Optional[int]) -> Program:
    """Start the program in ``work``, confined, with a robot port on each of ``listeners`` (robot 0's first);
    raises OSError or SubprocessError if it cannot."""
    limits = job["limits"]
    private_tmp = "mount" in iso["namespaces"]
    numbers = [sock.getsockname()[1] for sock in listeners]
    argv, env = program_command(job, work, numbers)
    seccomp = seccomp_program() if job.get("seccomp", True) else None
    iso["seccomp"] = seccomp is not None
    in_userns = iso["user_namespace"]
    t0 = time.monotonic()
    try:
        proc = subprocess.Popen(
            argv, cwd=work, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            close_fds=True, start_new_session=True,
            preexec_fn=confinement(limits, cgroup=cgroup, uid=uid, gid=gid, drop_caps=in_userns,
                                   nproc_extra=2 if in_userns else 0, seccomp=seccomp))
    except BaseException:
        if not private_tmp:
            shutil.rmtree(work, ignore_errors=True)
        raise
    fleet = job.get("start_poses")
    poses = fleet or [job["start_pose"]]
    ports = [PortLink(RobotPort(robot_id=f"{job['robot_id']}/{k}" if fleet else job["robot_id"],
                                platform=job["platform"], field_size=tuple(job["field_size"]),
                                start_pose=tuple(pose), relay=bool(job.get("relay"))), number, sock)
             for k, (pose, number, sock) in enumerate(zip(poses, numbers, listeners))]
    return Program(proc, ports, work, private_tmp, uid, int(limits["output_bytes"]), t0)


def pump(prog: Program, *, wall_s: float, grace_s: float, stop: Callable[[], Optional[str]],
         count: Callable[[], int]) -> tuple[bool, Optional[str]]:
    """Serve the robot port and collect the output until the end; (timed out, why stopped early or None).

    ``count()`` gives the number of the program's processes now (polled every ``COUNT_EVERY_S``).
    """
    sel = selectors.DefaultSelector()
    for name in ("stdout", "stderr"):
        pipe = getattr(prog.proc, name)
        os.set_blocking(pipe.fileno(), False)
        sel.register(pipe, selectors.EVENT_READ, name)
    for k, link in enumerate(prog.ports):
        assert link.listener is not None
        link.listener.setblocking(False)
        sel.register(link.listener, selectors.EVENT_READ, ("listen", k))
    if prog.port.relay:  # the server's lines for the program come on stdin
        os.set_blocking(0, False)
        sel.register(0, selectors.EVENT_READ, "relay")
    deadline = prog.t0 + wall_s
    next_count = 0.0
    try:
        while True:
            now = time.monotonic()
            stopped = stop()
            if stopped:
                return False, stopped
            if prog.run_ended is not None:
                return False, None
            ends = [deadline] if prog.path_mono is None else [prog.path_mono + grace_s]
            if prog.exited_at is not None:  # drain the pipes (no longer once nobody holds them)
                ends.append(prog.exited_at + (DRAIN_S if prog.pipes_open else 0.0))
            end_at = min(ends)
            if now >= end_at:
                return prog.path_mono is None and prog.exited_at is None, None
            if now >= next_count:
                prog.procs_max = max(prog.procs_max, count())
                next_count = now + COUNT_EVERY_S
            _reap_exited(prog, now)
            for key, _ in sel.select(max(0.0, min(0.05, end_at - now))):
                if isinstance(key.data, tuple):  # ("listen" | "conn", robot k)
                    (_accept if key.data[0] == "listen" else _converse)(prog, sel, prog.ports[key.data[1]])
                else:
                    (_relay_in if key.data == "relay" else _collect)(prog, sel, key)
    finally:
        sel.close()


def _reap_exited(prog: Program, now: float) -> None:
    """Reap the program, and (as pid 1 or sub-reaper) every orphan it left; note when the program exited."""
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        if pid == prog.proc.pid:
            prog.proc.returncode = os.waitstatus_to_exitcode(status)
            prog.exited_at = now


def _accept(prog: Program, sel: selectors.BaseSelector, link: PortLink) -> None:
    """The program connects to a robot port: greet it; no other connection is taken on that port."""
    assert link.listener is not None
    try:
        conn, _ = link.listener.accept()
    except OSError:
        return
    sel.unregister(link.listener)
    link.listener.close()
    link.listener = None
    link.conn = conn
    conn.setblocking(False)
    send(conn, link.robot.greeting())
    sel.register(conn, selectors.EVENT_READ, ("conn", prog.ports.index(link)))
    if link.robot.relay:
        _to_server(encode(LinkKind.CONNECTED))


def _to_server(data: bytes) -> None:
    """Relay: link lines (:mod:`.link`) for the server on stdout: the program connected, lines for the robot."""
    while data:
        try:
            data = data[os.write(1, data):]
        except BlockingIOError:
            selectors.DefaultSelector().select(0.01)
        except OSError:  # the server is gone: the end request follows
            return


def _relay_in(prog: Program, sel: selectors.BaseSelector, key: selectors.SelectorKey) -> None:
    """Relay: the server's link lines (:mod:`.link`) on stdin: robot lines for the program, or (also EOF) the
    run's end."""
    try:
        data = os.read(0, 65536)
    except BlockingIOError:
        return
    if not data:
        sel.unregister(0)
        prog.run_ended = prog.run_ended or "the server closed the relay"
        return
    prog.relay_buf += data
    *lines, prog.relay_buf = prog.relay_buf.split(b"\n")
    out = b""
    for line in lines:
        msg = parse(line)
        if msg is None:
            continue
        if msg.kind is LinkKind.ROBOT:
            out += prog.port.from_robot(msg.text)
        elif msg.kind is LinkKind.END:
            prog.run_ended = msg.text
    conn = prog.ports[0].conn
    if conn is not None and out:
        send(conn, out)


def _converse(prog: Program, sel: selectors.BaseSelector, link: PortLink) -> None:
    """Bytes from the program on a robot port: answer; hang up once the path came or the program did.
    Every port's path in: the end is near (``grace_s``)."""
    assert link.conn is not None
    port = link.robot
    try:
        data = link.conn.recv(65536)
    except BlockingIOError:
        return
    except OSError:
        data = b""
    replies, done = port.feed(data, time.monotonic() - prog.t0)
    send(link.conn, replies)
    if port.forward:
        _to_server(b"".join(encode(LinkKind.ROBOT, line) for line in port.forward))
        port.forward.clear()
    if done:
        sel.unregister(link.conn)
        link.conn.close()
        link.conn = None
        if all(p.robot.path is not None for p in prog.ports):
            prog.path_mono = time.monotonic()


def _collect(prog: Program, sel: selectors.BaseSelector, key: selectors.SelectorKey) -> None:
    """Output on stdout or stderr: keep up to ``output_bytes``, count the rest."""
    name = key.data
    try:
        data = os.read(key.fileobj.fileno(), 65536)  # type: ignore[union-attr]
    except BlockingIOError:
        return
    if not data:
        sel.unregister(key.fileobj)
        prog.pipes_open -= 1
        return
    room = max(prog.output_bytes - len(prog.out[name]), 0)
    prog.out[name] += data[:room]
    prog.dropped[name] += len(data) - min(len(data), room)


def reap(prog: Program, *, is_pid1: bool, cgroup: Optional[ProgramCgroup]) -> bool:
    """Kill and reap every process of the sandbox, close everything; whether the program had ended by itself."""
    ended_itself = prog.proc.returncode is not None
    if cgroup is not None:
        cgroup.kill_all()
    if is_pid1:
        try:
            os.kill(-1, signal.SIGKILL)  # pid 1 of our own pid namespace: every other process in it
        except ProcessLookupError:
            pass  # nothing left
    else:
        try:
            os.killpg(prog.proc.pid, signal.SIGKILL)
        except OSError:
            pass
        if prog.uid is not None:
            kill_uid(prog.uid)
    if prog.proc.returncode is None:
        try:
            _, status = os.waitpid(prog.proc.pid, 0)
            prog.proc.returncode = os.waitstatus_to_exitcode(status)
        except ChildProcessError:
            prog.proc.returncode = -signal.SIGKILL
    while True:  # zombies left to us (pid 1, sub-reaper)
        try:
            pid, _ = os.waitpid(-1, 0 if is_pid1 else os.WNOHANG)
        except ChildProcessError:
            break
        if pid == 0:
            break
    for f in (prog.proc.stdout, prog.proc.stderr, *(s for p in prog.ports for s in (p.conn, p.listener))):
        try:
            f.close()  # type: ignore[union-attr]
        except (OSError, AttributeError):
            pass
    if not prog.private_tmp:
        shutil.rmtree(prog.work, ignore_errors=True)
    return ended_itself


def report(prog: Program, *, ended_itself: bool, wall_s: float, cgroup: Optional[ProgramCgroup]) -> dict[str, Any]:
    """The result of a reaped program (all but ``timed_out`` and ``launch_error``); times in s, sizes in KiB.

    The robot port's fields (``robot_port``, ``path``, ``path_at_s``, ``connected``, ``port_log``,
    ``refused``, ``port_unlogged``) are robot 0's; ``ports`` has them for each robot port.
    """
    rc = prog.proc.returncode
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    peak = cgroup.peak_bytes() if cgroup is not None else None
    ports = [{"robot_port": p.number, "path": p.robot.path, "path_at_s": p.robot.path_at,
              "connected": p.robot.connected, "port_log": p.robot.log, "refused": p.robot.refused,
              "port_unlogged": p.robot.unlogged} for p in prog.ports]
    return {
        "exit_code": rc if ended_itself and rc is not None and rc >= 0 else None,
        "signal": -rc if ended_itself and rc is not None and rc < 0 else None,
        "procs_max": prog.procs_max, **ports[0], "ports": ports, "run_ended": prog.run_ended,
        "wall_s": round(wall_s, 3), "cpu_s": round(ru.ru_utime + ru.ru_stime, 3), "max_rss_kib": ru.ru_maxrss,
        "memory_peak_kib": None if peak is None else peak >> 10,
        "memory_oom_kills": cgroup.oom_kills() if cgroup is not None else None,
        "fork_refusals": cgroup.fork_refusals() if cgroup is not None else None,
        "stdout": prog.out["stdout"].decode("utf-8", "replace"), "stderr": prog.out["stderr"].decode("utf-8", "replace"),
        "stdout_dropped": prog.dropped["stdout"], "stderr_dropped": prog.dropped["stderr"],
    }
