"""Supervising one program: spawn it, pump its output and robot port, reap every process, report.

Runs in the launcher.  The program runs in bubblewrap's sandbox
(:mod:`.bwrap`) where the machine allows it (``namespaces``: ``auto``, or
``required``: else it does not run), else directly, confined by its user,
rlimits, cgroup and seccomp filter only.  The end comes when the program
exited (its last output drained), ``grace_s`` after its path (a multi-robot
job's: after the last robot port's path), at the wall-time limit, or when
the launcher must end early (:class:`~.lifetime.EndRequest`).

A job has one robot port, or one per robot of a multi-robot job
(``start_poses``: one pose per robot); each listens on its own port, takes
one connection and keeps the first valid path sent on it.
"""

from __future__ import annotations

import base64
import errno
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

from . import bwrap, seccomp
from .cgroups import ProgramCgroup
from .confine import confinement
from .isolation import CAP_SETGID, CAP_SETUID, PR_SET_CHILD_SUBREAPER, has_cap, prctl
from .link import LinkKind, encode, parse
from .processes import count_descendants, count_uid, kill_uid
from .robot_port import RobotPort, send
from .workdir import make_workdir, program_command

__all__ = ["blank_result", "pump", "reap", "report", "spawn", "supervise"]

#: how long the pipes of an exited program are still read (its children may hold them), s
DRAIN_S = 0.3
#: how often the program's processes are counted, s
COUNT_EVERY_S = 0.05
#: processes of bwrap's in the program's cgroup: bwrap itself and the sandbox's first process
BWRAP_PROCESSES = 2


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

    proc: subprocess.Popen  # type: ignore[type-arg]  # the program, or bwrap running it
    ports: list[PortLink]  # robot 0's first
    work: Optional[str]  # its working directory on the host (None: in the sandbox)
    bubble: Optional[bwrap.Bubble]  # its sandbox (None: it runs without)
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
            "memory_limit_hits": None, "memory_cache_kib": None, "fork_refusals": None,
            "stdout": "", "stderr": "", "stdout_dropped": 0, "stderr_dropped": 0}


def supervise(job: dict[str, Any], iso: dict[str, Any], *, cgroup: Optional[ProgramCgroup],
              stop: Callable[[], Optional[str]]) -> dict[str, Any]:
    """Everything from the sandbox to the end of the program; the result (``iso`` completed on the way).

    ``stop()`` says why to end early (None: carry on).
    """
    uid, gid = program_user(job)
    iso.update({"uid": uid, "namespaces": [], "user_namespace": False, "sandbox": None, "proc": "host",
                "hidden": [], "reason": ""})
    mode = job.get("namespaces", "auto")
    if mode == "off":  # switched off, or none here (the server's probe found none: why)
        iso["reason"] = job.get("no_namespaces") or "namespaces switched off (TWB_SANDBOX_NAMESPACES=off)"
    else:
        path = bwrap.find(job)
        why = "bubblewrap (bwrap) is not installed"
        if path is not None:
            try:
                return _run(job, iso, cgroup=cgroup, stop=stop, uid=uid, gid=gid, bwrap_path=path)
            except bwrap.SetupFailed as exc:
                why = str(exc)
        iso.update({"namespaces": [], "user_namespace": False, "sandbox": None, "proc": "host", "hidden": [],
                    "reason": f"no namespaces available ({why})"})
        if mode == "required":
            return {**blank_result(), "sandbox_error": True,
                    "launch_error": f"the sandbox needs Linux namespaces and cannot create them: {why}"}
    return _run(job, iso, cgroup=cgroup, stop=stop, uid=uid, gid=gid, bwrap_path=None)


def _run(job: dict[str, Any], iso: dict[str, Any], *, cgroup: Optional[ProgramCgroup],
         stop: Callable[[], Optional[str]], uid: Optional[int], gid: Optional[int],
         bwrap_path: Optional[str]) -> dict[str, Any]:
    """One try: in bwrap's sandbox (``bwrap_path``) or without; raises :class:`~.bwrap.SetupFailed` if bwrap
    could not make the sandbox (the program never ran)."""
    limits = job["limits"]
    try:
        prog = spawn(job, iso, cgroup=cgroup, uid=uid, gid=gid, bwrap_path=bwrap_path)
    except (OSError, subprocess.SubprocessError) as exc:
        return {**blank_result(), "launch_error": f"{type(exc).__name__}: {exc}"}
    if prog.bubble is not None:
        bubble = prog.bubble
        count: Callable[[], int] = lambda: count_descendants(bubble.pid1) if bubble.alive() else 0  # noqa: E731
    else:
        me = os.getpid()
        count = (lambda: -1) if uid is None else (lambda: count_uid(uid, me))
    timed_out, stopped = pump(prog, wall_s=float(limits["wall_s"]), grace_s=float(job.get("grace_s", 1.0)),
                              stop=stop, count=count)
    wall = time.monotonic() - prog.t0
    ended_itself = reap(prog, cgroup=cgroup)
    launch_error = stopped
    # bwrap reports the program's exit code only when the program exits: one still running when the run
    # ended, its grace ran out or it was stopped was killed here, which is not a sandbox that failed to start
    if prog.bubble is not None and ended_itself and not prog.bubble.program_started():
        why = _bwrap_said(prog)
        if not why.startswith("execvp "):
            raise bwrap.SetupFailed(why)
        launch_error = why  # the program's file could not be executed
        prog.out["stderr"].clear()
    return {**report(prog, ended_itself=ended_itself, wall_s=wall, cgroup=cgroup),
            "timed_out": timed_out, "launch_error": launch_error}


def _bwrap_said(prog: Program) -> str:
    """bwrap's last words on stderr (``bwrap: ...`` without the prefix): why it did not start the program."""
    lines = [ln.strip() for ln in prog.out["stderr"].decode("utf-8", "replace").splitlines() if ln.strip()]
    last = lines[-1] if lines else f"bwrap exited with status {prog.proc.returncode}"
    return last[len("bwrap: "):] if last.startswith("bwrap: ") else last


#: ELF ``e_machine`` of the machines ``os.uname().machine`` names
ELF_MACHINES = {"x86_64": 62, "aarch64": 183, "i686": 3, "armv7l": 40, "riscv64": 243, "ppc64le": 21, "s390x": 22}


def _exec_format_error(job: dict[str, Any], path: str) -> Optional[str]:
    """Why the kernel would refuse to execute the job's file ``path`` (None: it would, or it is not the job's).

    bwrap starts the program with ``execvp``, which hands a file the kernel
    refuses (ENOEXEC) to ``/bin/sh``; a file that is neither a script with a
    ``#!`` line nor an ELF binary for this machine is refused here instead,
    as the kernel would (and as a program without bwrap is).
    """
    spec = job["files"].get(os.path.basename(path)) if os.path.dirname(path) == bwrap.WORKDIR else None
    if spec is None:
        return None
    head = base64.b64decode(spec["base64"][:32])
    if head.startswith(b"#!"):
        return None
    if not head.startswith(b"\x7fELF"):
        return "Exec format error"
    machine = ELF_MACHINES.get(os.uname().machine)
    if machine is not None and len(head) >= 20 and head[18] | head[19] << 8 != machine \
            and head[18] << 8 | head[19] != machine:
        return f"Exec format error (an ELF binary for another machine than {os.uname().machine})"
    if len(head) < 20:
        return "Exec format error"
    return None


def program_user(job: dict[str, Any]) -> tuple[Optional[int], Optional[int]]:
    """(uid, gid) of the program: the job's when this process may switch to it (root), else (None, None)."""
    if job.get("uid") is not None and has_cap(CAP_SETUID) and has_cap(CAP_SETGID):
        return int(job["uid"]), int(job["gid"])
    return None, None


def _listen() -> socket.socket:
    """A robot port's listening socket on a free loopback port (no sandbox: on the machine's loopback)."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    return listener


def spawn(job: dict[str, Any], iso: dict[str, Any], *, cgroup: Optional[ProgramCgroup], uid: Optional[int],
          gid: Optional[int], bwrap_path: Optional[str]) -> Program:
    """Start the program, confined, with a robot port for each robot (robot 0's first), in bwrap's sandbox
    (``bwrap_path``) or without; raises OSError or SubprocessError if it cannot, SetupFailed if bwrap cannot."""
    limits = job["limits"]
    poses = job.get("start_poses") or [job["start_pose"]]
    want_seccomp = job.get("seccomp", True)
    largest = max((len(spec["base64"]) * 3 // 4 for spec in job["files"].values()), default=0)
    file_bytes = max(int(limits["file_bytes"]), largest + 1)  # bwrap copies the job's files under this limit
    bubble: Optional[bwrap.Bubble] = None
    work: Optional[str] = None
    prctl(PR_SET_CHILD_SUBREAPER, 1)  # orphans come back to us, to be reaped: the program's, or bwrap's first process
    if cgroup is not None:  # bwrap's two processes run in the program's cgroup too
        cgroup.limit_processes(int(limits["processes"]) + (BWRAP_PROCESSES if bwrap_path is not None else 0))
    if bwrap_path is not None:
        numbers = bwrap.choose_ports(len(poses))
        argv, env = program_command(job, bwrap.WORKDIR, numbers)
        not_runnable = _exec_format_error(job, argv[0])
        if not_runnable:
            raise OSError(errno.ENOEXEC, f"execvp {argv[0]}: {not_runnable}")
        program = seccomp.program() if want_seccomp and not seccomp.UNAVAILABLE else None
        preexec = confinement(limits, cgroup=cgroup, uid=uid, gid=gid, nproc=None, file_bytes=file_bytes)
        bubble, hidden = bwrap.start(
            bwrap_path, job, argv, env, ports=numbers, tmpfs_bytes=int(limits["tmpfs_bytes"]),
            hide=job.get("hide", []), seccomp=program, preexec=preexec, uid=uid,
            nproc=int(limits["processes"]) + 1)  # + the sandbox's first process (bwrap's)
        t0 = time.monotonic()  # the sandbox is made: the program starts now (planning time, wall limit)
        proc, listeners = bubble.proc, bubble.listeners
        iso.update({"namespaces": bubble.namespaces, "user_namespace": True, "sandbox": "bubblewrap",
                    "proc": "private", "hidden": hidden, "seccomp": program is not None})
    else:
        listeners = [_listen() for _ in poses]
        numbers = [sock.getsockname()[1] for sock in listeners]
        work = make_workdir(job, uid=uid, gid=gid)
        argv, env = program_command(job, work, numbers)
        filt = seccomp.build() if want_seccomp and not seccomp.UNAVAILABLE else None
        iso["seccomp"] = filt is not None
        t0 = time.monotonic()
        try:
            proc = subprocess.Popen(
                argv, cwd=work, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                close_fds=True, start_new_session=True,
                preexec_fn=confinement(limits, cgroup=cgroup, uid=uid, gid=gid, nproc=int(limits["processes"]),
                                       file_bytes=file_bytes, seccomp=filt))
        except BaseException:
            shutil.rmtree(work, ignore_errors=True)
            for sock in listeners:
                sock.close()
            raise
    fleet = job.get("start_poses")
    ports = [PortLink(RobotPort(robot_id=f"{job['robot_id']}/{k}" if fleet else job["robot_id"],
                                platform=job["platform"], field_size=tuple(job["field_size"]),
                                start_pose=tuple(pose), relay=bool(job.get("relay"))), number, sock)
             for k, (pose, number, sock) in enumerate(zip(poses, numbers, listeners))]
    return Program(proc, ports, work, bubble, uid, int(limits["output_bytes"]), t0)


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


def reap(prog: Program, *, cgroup: Optional[ProgramCgroup]) -> bool:
    """Kill and reap every process of the sandbox, close everything; whether the program had ended by itself."""
    ended_itself = prog.proc.returncode is not None
    if cgroup is not None:
        cgroup.kill_all()
    if prog.bubble is not None:
        prog.bubble.kill()  # its first process: the kernel ends every process of its pid namespace
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
    deadline = time.monotonic() + 2.0
    while True:  # zombies left to us (sub-reaper): the sandbox's first process among them, once bwrap is gone
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            break
        if pid == 0:
            if prog.bubble is None or not prog.bubble.alive() or time.monotonic() > deadline:
                break
            time.sleep(0.005)
    if prog.bubble is not None:
        prog.bubble.finish()
    for f in (prog.proc.stdout, prog.proc.stderr, *(s for p in prog.ports for s in (p.conn, p.listener))):
        try:
            f.close()  # type: ignore[union-attr]
        except (OSError, AttributeError):
            pass
    if prog.work is not None:
        shutil.rmtree(prog.work, ignore_errors=True)
    return ended_itself


def report(prog: Program, *, ended_itself: bool, wall_s: float, cgroup: Optional[ProgramCgroup]) -> dict[str, Any]:
    """The result of a reaped program (all but ``timed_out`` and ``launch_error``); times in s, sizes in KiB.

    The robot port's fields (``robot_port``, ``path``, ``path_at_s``, ``connected``, ``port_log``,
    ``refused``, ``port_unlogged``) are robot 0's; ``ports`` has them for each robot port.
    """
    rc = prog.proc.returncode
    code, sig = (None, None) if rc is None else bwrap.exit_status(rc) if prog.bubble is not None \
        else (rc, None) if rc >= 0 else (None, -rc)
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    peak = cgroup.peak_bytes() if cgroup is not None else None
    cache = cgroup.page_cache_bytes() if cgroup is not None else None  # its processes are gone: what they left
    ports = [{"robot_port": p.number, "path": p.robot.path, "path_at_s": p.robot.path_at,
              "connected": p.robot.connected, "port_log": p.robot.log, "refused": p.robot.refused,
              "port_unlogged": p.robot.unlogged} for p in prog.ports]
    return {
        "exit_code": code if ended_itself else None,
        "signal": sig if ended_itself else None,
        "procs_max": prog.procs_max, **ports[0], "ports": ports, "run_ended": prog.run_ended,
        "wall_s": round(wall_s, 3), "cpu_s": round(ru.ru_utime + ru.ru_stime, 3), "max_rss_kib": ru.ru_maxrss,
        "memory_peak_kib": None if peak is None else peak >> 10,
        "memory_oom_kills": cgroup.oom_kills() if cgroup is not None else None,
        "memory_limit_hits": cgroup.limit_hits() if cgroup is not None else None,
        "memory_cache_kib": None if cache is None else cache >> 10,
        "fork_refusals": cgroup.fork_refusals() if cgroup is not None else None,
        "stdout": prog.out["stdout"].decode("utf-8", "replace"), "stderr": prog.out["stderr"].decode("utf-8", "replace"),
        "stdout_dropped": prog.dropped["stdout"], "stderr_dropped": prog.dropped["stderr"],
    }
