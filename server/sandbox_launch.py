"""The sandbox launcher: runs one uploaded program isolated and captures the path it sends.

The server (:mod:`server.sandbox`) starts it as ``python -m server.sandbox_launch``
with a JSON job on stdin and prints one JSON result line when everything
has ended (SIGTERM ends it early, sandbox included).
Linux only.  The wire codec (and with it numpy) is imported first, while the
project's files are still visible (the mount namespace covers ``/tmp``, where
a checkout may live), with the BLAS/OpenMP thread counts set to 1 so the
process is still single-threaded when it unshares and forks.

What it does, in order:

1. **Namespaces.**  With ``CAP_SYS_ADMIN`` (the server runs as root):
   ``unshare(NET | NS | PID | IPC | UTS)``.  Without it, the same inside a new
   *user* namespace (unprivileged user namespaces; the server's uid becomes
   root there, without capabilities for the program).  If neither works, no
   namespaces (or the job says ``"namespaces": "off"``); ``"required"`` makes
   that a launch error.
2. **PID namespace.**  The launcher forks: the child is pid 1 of the new
   namespace and gets ``SIGKILL`` when this process dies (parent-death
   signal); when pid 1 ends, the kernel kills every process of the namespace,
   so nothing the program started can outlive the sandbox.
3. **Mounts** (private propagation): every mount read-only, a fresh
   ``/proc`` (only the sandbox's processes), fresh size-limited ``tmpfs`` on
   ``/tmp``, ``/var/tmp`` and ``/dev/shm`` (the only writable places), an
   empty read-only ``tmpfs`` over every ``hide`` path (the server's data
   directory: database, token file).  **Network**: only
   loopback, brought up; the robot port listens on ``127.0.0.1`` there.
4. **The program** runs in a fresh working directory, in its own session,
   as the job's ``uid``/``gid`` with no supplementary groups (when privileged),
   with ``no_new_privs``, no capabilities, a seccomp filter denying system
   calls a planner never needs (namespaces, mounts, ptrace, keyrings, eBPF,
   perf, userfaultfd, io_uring, modules), a parent-death signal, the job's
   environment only, stdin ``/dev/null``, stdout/stderr captured (capped) and
   rlimits: CPU seconds, address space, file size, processes, open files,
   core 0.
5. **The robot port** greets like a robot (``HELLO,<robot_id>,<platform>,1``),
   answers each line like one (``ERR,...`` for a malformed line, ``ST`` for a
   query, ``OK,S`` for a stop) and takes the first valid ``T,T,P`` line
   (range-checked against the field) as the planned path: it answers
   ``OK,P,<n>``, closes the connection and gives the program ``grace_s`` to
   exit.  One connection is accepted.
6. Wall-time limit; at the end every process of the sandbox is killed and
   reaped, and the result is printed.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import json
import os
import re
import resource
import selectors
import signal
import socket
import struct
import sys
import time
from typing import Any, Optional

# ----------------------------------------------------------------------------- kernel interfaces

CLONE_NEWNS = 0x00020000
CLONE_NEWUTS = 0x04000000
CLONE_NEWIPC = 0x08000000
CLONE_NEWUSER = 0x10000000
CLONE_NEWPID = 0x20000000
CLONE_NEWNET = 0x40000000

MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC = 1, 2, 4, 8
MS_REMOUNT, MS_BIND, MS_REC, MS_PRIVATE = 32, 4096, 0x4000, 1 << 18
#: per-mount options kept when remounting read-only (a user namespace may not drop locked ones)
MOUNT_FLAGS = {"nosuid": MS_NOSUID, "nodev": MS_NODEV, "noexec": MS_NOEXEC, "noatime": 1024,
               "nodiratime": 2048, "relatime": 1 << 21, "strictatime": 1 << 24}

PR_SET_PDEATHSIG = 1
PR_CAPBSET_DROP = 24
PR_SET_CHILD_SUBREAPER = 36
PR_SET_NO_NEW_PRIVS = 38

CAP_SETGID, CAP_SETUID, CAP_SYS_ADMIN = 6, 7, 21

SIOCGIFFLAGS, SIOCSIFFLAGS, IFF_UP = 0x8913, 0x8914, 0x1

#: protocol v1 line limit (robot_agent.protocol.MAX_LINE_BYTES), terminator included
MAX_LINE_BYTES = 1 << 20

_libc = ctypes.CDLL(None, use_errno=True)
_libc.mount.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong, ctypes.c_char_p]
_libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]


def _check(rc: int, what: str) -> None:
    if rc != 0:
        e = ctypes.get_errno()
        raise OSError(e, f"{what}: {os.strerror(e)}")


def _unshare(flags: int) -> None:
    _check(_libc.unshare(flags), "unshare")


def _mount(source: Optional[str], target: str, fstype: Optional[str], flags: int, data: Optional[str]) -> None:
    enc = lambda s: None if s is None else s.encode()  # noqa: E731
    _check(_libc.mount(enc(source), enc(target), enc(fstype), flags, enc(data)), f"mount {target}")


def _prctl(option: int, arg: int) -> int:
    return _libc.prctl(option, arg, 0, 0, 0)


def _has_cap(cap: int) -> bool:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> cap & 1)
    return False


def _loopback_up() -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        ifr = fcntl.ioctl(s, SIOCGIFFLAGS, struct.pack("16sh22x", b"lo", 0))
        flags = struct.unpack("16sh22x", ifr)[1]
        fcntl.ioctl(s, SIOCSIFFLAGS, struct.pack("16sh22x", b"lo", flags | IFF_UP))
    finally:
        s.close()


# ----------------------------------------------------------------------------- isolation set-up


def enter_namespaces(mode: str) -> dict[str, Any]:
    """Unshare what this process may; returns the isolation record (``namespaces`` empty: none)."""
    iso: dict[str, Any] = {"namespaces": [], "user_namespace": False, "reason": ""}
    if mode == "off":
        iso["reason"] = "namespaces switched off (TWB_SANDBOX_NAMESPACES=off)"
        return iso
    flags = CLONE_NEWNET | CLONE_NEWNS | CLONE_NEWPID | CLONE_NEWIPC | CLONE_NEWUTS
    names = ["net", "mount", "pid", "ipc", "uts"]
    try:
        _unshare(flags)
        iso["namespaces"] = names
        return iso
    except OSError as exc:
        first = exc
    uid, gid = os.geteuid(), os.getegid()
    try:
        if uid == 0:  # root without CAP_SYS_ADMIN (a container) may not map itself (CAP_SETFCAP)
            raise OSError(errno.EPERM, "root without CAP_SYS_ADMIN")
        _unshare(flags | CLONE_NEWUSER)
    except OSError as exc:
        iso["reason"] = f"no namespaces available ({first.strerror}; user namespace: {exc.strerror})"
        if mode == "required":
            raise OSError(exc.errno, f"the sandbox needs Linux namespaces and cannot create them: {iso['reason']}")
        return iso
    for path, text in (("/proc/self/setgroups", "deny"), ("/proc/self/uid_map", f"0 {uid} 1"),
                       ("/proc/self/gid_map", f"0 {gid} 1")):
        with open(path, "w") as f:
            f.write(text)
    iso["namespaces"] = names
    iso["user_namespace"] = True
    return iso


def _read_only_everywhere() -> int:
    """Remount every mount of this (private) mount namespace read-only; returns how many refused.

    ``MS_REMOUNT | MS_BIND`` changes this namespace's mount only, never the
    file system itself (which the host keeps writable).
    """
    refused = 0
    with open("/proc/self/mountinfo") as f:
        mounts = [line.split() for line in f]
    for fields in mounts:
        target = re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), fields[4])
        flags = MS_REMOUNT | MS_BIND | MS_RDONLY
        for opt in fields[5].split(","):
            flags |= MOUNT_FLAGS.get(opt, 0)
        try:
            _mount(None, target, None, flags, None)
        except OSError:
            refused += 1
    return refused


def set_up_mounts(iso: dict[str, Any], hide: list[str], tmpfs_bytes: int) -> None:
    """Everything read-only but fresh /proc and temporary directories; empty tmpfs over ``hide``."""
    _mount(None, "/", None, MS_REC | MS_PRIVATE, None)
    iso["read_only_refused"] = _read_only_everywhere()
    try:
        _mount("proc", "/proc", "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC, None)
        iso["proc"] = "private"
    except OSError:
        # procfs refused (e.g. partly masked /proc in a container): hide it rather than show the host's
        _mount("tmpfs", "/proc", "tmpfs", MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC, "size=4k,mode=555")
        iso["proc"] = "hidden"
    for d in ("/tmp", "/var/tmp", "/dev/shm"):
        if os.path.isdir(d) and not os.path.islink(d):
            _mount("tmpfs", d, "tmpfs", MS_NOSUID | MS_NODEV, f"size={tmpfs_bytes},mode=1777")
    hidden = [h for h in hide if not os.path.exists(h)]  # already under one of the fresh tmpfs
    for h in hide:
        if h in hidden:
            continue
        if os.path.isdir(h):
            _mount("tmpfs", h, "tmpfs", MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC, "size=4k,mode=000")
            hidden.append(h)
        elif os.path.exists(h):
            _mount("/dev/null", h, None, MS_BIND, None)
            hidden.append(h)
    iso["hidden"] = hidden


def make_workdir(job: dict[str, Any], iso: dict[str, Any], uid: Optional[int], gid: Optional[int]) -> str:
    """Write the program's files into a fresh directory owned by the program's user."""
    import base64
    import tempfile

    if "mount" in iso["namespaces"]:
        work = "/tmp/twb-program"  # on this sandbox's own tmpfs
        os.mkdir(work, 0o700)
    else:
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


# ----------------------------------------------------------------------------- the program


# ----------------------------------------------------------------------------- seccomp

PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 22, 2
SECCOMP_RET_ALLOW, SECCOMP_RET_ERRNO = 0x7FFF0000, 0x00050000
#: system calls a planner never needs and that widen the kernel's attack surface: namespaces,
#: mounts, tracing other processes, keyrings, eBPF, perf, userfaultfd, io_uring, modules, kexec
DENIED = {
    "x86_64": (0xC000003E, {"unshare": 272, "setns": 308, "mount": 165, "umount2": 166, "pivot_root": 155,
                            "ptrace": 101, "process_vm_readv": 310, "process_vm_writev": 311, "keyctl": 250,
                            "add_key": 248, "request_key": 249, "bpf": 321, "perf_event_open": 298,
                            "userfaultfd": 323, "io_uring_setup": 425, "io_uring_enter": 426,
                            "io_uring_register": 427, "kexec_load": 246, "kexec_file_load": 320,
                            "init_module": 175, "finit_module": 313, "delete_module": 176,
                            "open_by_handle_at": 304, "open_tree": 428, "move_mount": 429, "fsopen": 430,
                            "fsconfig": 431, "fsmount": 432, "fspick": 433, "mount_setattr": 442},
               56, 435),
    "aarch64": (0xC00000B7, {"unshare": 97, "setns": 268, "mount": 40, "umount2": 39, "pivot_root": 41,
                             "ptrace": 117, "process_vm_readv": 270, "process_vm_writev": 271, "keyctl": 219,
                             "add_key": 217, "request_key": 218, "bpf": 280, "perf_event_open": 241,
                             "userfaultfd": 282, "io_uring_setup": 425, "io_uring_enter": 426,
                             "io_uring_register": 427, "kexec_load": 104, "kexec_file_load": 294,
                             "init_module": 105, "finit_module": 273, "delete_module": 106,
                             "open_by_handle_at": 265, "open_tree": 428, "move_mount": 429, "fsopen": 430,
                             "fsconfig": 431, "fsmount": 432, "fspick": 433, "mount_setattr": 442},
                220, 435),
}
NAMESPACE_FLAGS = CLONE_NEWNS | CLONE_NEWUTS | CLONE_NEWIPC | CLONE_NEWUSER | CLONE_NEWPID | CLONE_NEWNET | 0x02000000


def seccomp_program() -> Optional[bytes]:
    """A classic-BPF seccomp filter for this machine (None on other architectures).

    Denied calls fail with EPERM; ``clone`` with namespace flags too;
    ``clone3`` (flags out of reach of the filter) fails with ENOSYS, so C
    libraries fall back to ``clone``; other ABIs (i386, x32) get ENOSYS.
    """
    import platform

    spec = DENIED.get(platform.machine())
    if spec is None:
        return None
    arch, calls, clone_nr, clone3_nr = spec
    ld, jeq, jset, jge, ret = 0x20, 0x15, 0x45, 0x35, 0x06
    eperm, enosys = SECCOMP_RET_ERRNO | errno.EPERM, SECCOMP_RET_ERRNO | errno.ENOSYS
    prog: list[tuple[int, int, int, int]] = [
        (ld, 0, 0, 4), (jeq, 1, 0, arch), (ret, 0, 0, enosys),  # another ABI
        (ld, 0, 0, 0), (jge, 0, 1, 0x40000000), (ret, 0, 0, enosys),  # x32 numbers
    ]
    for nr in sorted(calls.values()):
        prog += [(jeq, 0, 1, nr), (ret, 0, 0, eperm)]
    prog += [(jeq, 0, 1, clone3_nr), (ret, 0, 0, enosys),
             (jeq, 0, 3, clone_nr), (ld, 0, 0, 16), (jset, 0, 1, NAMESPACE_FLAGS), (ret, 0, 0, eperm),
             (ret, 0, 0, SECCOMP_RET_ALLOW)]
    return b"".join(struct.pack("HBBI", *ins) for ins in prog)


def _install_seccomp(prog: bytes) -> int:
    buf = ctypes.create_string_buffer(prog, len(prog))
    fprog = struct.pack("HxxxxxxP", len(prog) // 8, ctypes.addressof(buf))
    arg = ctypes.create_string_buffer(fprog, len(fprog))
    return _libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.addressof(arg), 0, 0)


def _limits_preexec(limits: dict[str, Any], drop_caps: bool, nproc_extra: int,  # type: ignore[no-untyped-def]
                    seccomp: Optional[bytes]):
    """Runs in the program's process between fork and exec (the launcher has no threads then).

    ``nproc_extra``: processes of the same user that are not the program's — in
    a user namespace the launcher's two processes count against its limit.
    """

    def apply() -> None:
        def lim(res: int, soft: int, hard: Optional[int] = None) -> None:
            resource.setrlimit(res, (soft, soft if hard is None else hard))

        lim(resource.RLIMIT_CPU, int(limits["cpu_s"]), int(limits["cpu_s"]) + 1)
        lim(resource.RLIMIT_AS, int(limits["memory_bytes"]))
        lim(resource.RLIMIT_FSIZE, int(limits["file_bytes"]))
        lim(resource.RLIMIT_NPROC, int(limits["processes"]) + nproc_extra)
        lim(resource.RLIMIT_NOFILE, int(limits["open_files"]))
        lim(resource.RLIMIT_CORE, 0)
        lim(resource.RLIMIT_MEMLOCK, 0)
        lim(resource.RLIMIT_MSGQUEUE, 0)
        if drop_caps:  # root of a user namespace: no capabilities after exec
            for cap in range(64):
                if _prctl(PR_CAPBSET_DROP, cap) != 0:
                    break
        if _prctl(PR_SET_NO_NEW_PRIVS, 1) != 0:
            os._exit(126)
        _prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        for s in (signal.SIGPIPE, signal.SIGXFSZ, signal.SIGXCPU):
            signal.signal(s, signal.SIG_DFL)
        if seccomp is not None and _install_seccomp(seccomp) != 0:
            os._exit(126)

    return apply


class RobotPort:
    """The program's robot: one connection, robot-like answers, the first valid path kept."""

    def __init__(self, sock: socket.socket, job: dict[str, Any]) -> None:
        self.listener = sock
        self.job = job
        self.conn: Optional[socket.socket] = None
        self.buf = b""
        self.discarding = False
        self.path: Optional[list[list[float]]] = None
        self.path_at: Optional[float] = None
        self.log: list[list[str]] = []
        self.refused: list[str] = []
        self.connected = False

    def accept(self) -> socket.socket:
        conn, _ = self.listener.accept()
        self.listener.close()
        self.conn = conn
        self.connected = True
        self._send(f"HELLO,{self.job['robot_id']},{self.job['platform']},1")
        return conn

    def _send(self, line: str) -> None:
        self.log.append([">", line])
        try:
            assert self.conn is not None
            self.conn.setblocking(True)
            self.conn.settimeout(1.0)
            self.conn.sendall(line.encode() + b"\n")
        except OSError:
            pass
        finally:
            if self.conn is not None:
                self.conn.setblocking(False)

    def feed(self, data: bytes, now: float) -> bool:
        """New bytes from the program; True when the connection is done (path taken or closed)."""
        if not data:
            return True
        self.buf += data
        while True:
            nl = self.buf.find(b"\n")
            if nl < 0:
                if len(self.buf) > MAX_LINE_BYTES:
                    if not self.discarding:
                        self._refuse("TOOLONG", f"line longer than {MAX_LINE_BYTES} bytes")
                    self.discarding = True
                    self.buf = b""
                return False
            line, self.buf = self.buf[:nl + 1], self.buf[nl + 1:]
            if self.discarding:
                self.discarding = False
                continue
            if len(line) > MAX_LINE_BYTES:
                self._refuse("TOOLONG", f"line longer than {MAX_LINE_BYTES} bytes")
                continue
            if self._line(line, now):
                return True

    def _refuse(self, code: str, message: str) -> None:
        reply = f"ERR,{code},{message}"
        self.refused.append(reply)
        self._send(reply)

    def _line(self, raw: bytes, now: float) -> bool:
        from robot_agent.protocol import PathCommand, ProtocolError, QueryCommand, StopCommand, parse_command

        text = raw.decode("ascii", "replace").rstrip("\r\n")
        self.log.append(["<", text[:2000] + (f"... ({len(text)} characters)" if len(text) > 2000 else "")])
        field = tuple(self.job["field_size"])
        try:
            cmd = parse_command(raw, field_size=field)  # type: ignore[arg-type]
        except ProtocolError as exc:
            self._refuse(exc.code.value, exc.message)
            return False
        if isinstance(cmd, PathCommand):
            self.path = [[round(float(v), 6) + 0.0 for v in p] for p in cmd.points]
            self.path_at = now
            self._send(f"OK,P,{len(self.path)}")
            return True
        if isinstance(cmd, QueryCommand):
            x, y, a = self.job["start_pose"]
            import math

            self._send(f"ST,IDLE,{x * 1000:.1f},{y * 1000:.1f},{math.degrees(a):.2f},0")
        elif isinstance(cmd, StopCommand):
            self._send("OK,S")
        else:
            self._refuse("UNSUPPORTED", "this robot port only takes a path (T,T,P), a query or a stop")
        return False


def _count_processes(iso: dict[str, Any], uid: Optional[int], me: int) -> int:
    """Processes of the sandbox now (its pid namespace, or its dedicated uid); -1 if unknown."""
    pid_ns = "pid" in iso["namespaces"] and iso.get("proc") == "private"
    if not pid_ns and uid is None:
        return -1
    n = 0
    try:
        entries = os.listdir("/proc")
    except OSError:
        return -1
    for e in entries:
        if not e.isdigit() or int(e) == me:
            continue
        if pid_ns:
            n += 1
            continue
        try:
            if os.stat(f"/proc/{e}").st_uid == uid:
                n += 1
        except OSError:
            pass
    return n


def _kill_uid(uid: int) -> None:
    """Kill every process of the dedicated ``uid``: kill(-1) from a helper running as that uid."""
    for _ in range(20):
        pid = os.fork()
        if pid == 0:  # pragma: no cover - child
            try:
                os.setgroups([])
                os.setresgid(uid, uid, uid)
                os.setresuid(uid, uid, uid)
                os.kill(-1, signal.SIGKILL)
            except OSError:
                pass
            os._exit(0)
        os.waitpid(pid, 0)
        if _count_processes({"namespaces": []}, uid, os.getpid()) <= 0:
            return
        time.sleep(0.01)


def supervise(job: dict[str, Any], iso: dict[str, Any]) -> dict[str, Any]:
    """Everything from the mounts to the end of the program (pid 1 of the sandbox, or the launcher)."""
    import subprocess

    limits = job["limits"]
    in_userns = iso["user_namespace"]
    uid = gid = None
    if not in_userns and job.get("uid") is not None and _has_cap(CAP_SETUID) and _has_cap(CAP_SETGID):
        uid, gid = int(job["uid"]), int(job["gid"])
    iso["uid"] = uid
    if "mount" in iso["namespaces"]:
        set_up_mounts(iso, job.get("hide", []), int(limits["tmpfs_bytes"]))
    else:
        iso["proc"] = "host"
        iso["hidden"] = []
    if "net" in iso["namespaces"]:
        _loopback_up()
    is_pid1 = "pid" in iso["namespaces"] and os.getpid() == 1
    if not is_pid1:
        _prctl(PR_SET_CHILD_SUBREAPER, 1)  # orphans of the program come back to us, to be reaped and killed
    work = make_workdir(job, iso, uid, gid)
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    port_no = listener.getsockname()[1]
    env = {k: str(v) for k, v in job["env"].items()}
    env.update({"TWB_ROBOT_HOST": "127.0.0.1", "TWB_ROBOT_PORT": str(port_no), "HOME": work, "TMPDIR": work,
                "TWB_WORKDIR": work})
    env["TWB_ENV_FILE"] = os.path.join(work, env.get("TWB_ENV_FILE", "environment.json"))
    # arguments may name the inputs: {robot_port}, {env_file}, {start}, ... (TWB_<NAME> in lower case)
    subst = {"{" + k[4:].lower() + "}": v for k, v in env.items() if k.startswith("TWB_")}
    argv = []
    for a in job["argv"]:
        for key, value in subst.items():
            a = a.replace(key, value)
        argv.append(a)
    result: dict[str, Any] = {"exit_code": None, "signal": None, "timed_out": False, "launch_error": None,
                              "procs_max": 0, "robot_port": port_no}
    seccomp = seccomp_program() if job.get("seccomp", True) else None
    iso["seccomp"] = seccomp is not None
    t0 = time.monotonic()
    try:
        proc = subprocess.Popen(
            argv, cwd=work, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            close_fds=True, start_new_session=True,
            user=uid, group=gid, extra_groups=[] if uid is not None else None,
            preexec_fn=_limits_preexec(limits, in_userns, 2 if in_userns else 0, seccomp),
        )
    except (OSError, subprocess.SubprocessError) as exc:
        listener.close()
        result["launch_error"] = f"{type(exc).__name__}: {exc}"
        result.update(_empty_outputs())
        return result

    robot = RobotPort(listener, job)
    outs = {"stdout": bytearray(), "stderr": bytearray()}
    dropped = {"stdout": 0, "stderr": 0}
    cap = int(limits["output_bytes"])
    sel = selectors.DefaultSelector()
    for name in ("stdout", "stderr"):
        pipe = getattr(proc, name)
        os.set_blocking(pipe.fileno(), False)
        sel.register(pipe, selectors.EVENT_READ, name)
    listener.setblocking(False)
    sel.register(listener, selectors.EVENT_READ, "listen")
    deadline = t0 + float(limits["wall_s"])
    grace_s = float(job.get("grace_s", 1.0))
    exited_at: Optional[float] = None
    path_mono: Optional[float] = None
    stop = {"term": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__("term", True))
    me = os.getpid()
    next_count = 0.0
    pipes_open = 2
    while True:
        now = time.monotonic()
        if stop["term"]:
            result["launch_error"] = "stopped by the server"
            break
        # the end: the program exited (drain its last output), or the path came (grace to exit), or time is up
        ends = [deadline] if path_mono is None else [path_mono + grace_s]
        if exited_at is not None:  # drain the pipes (no longer once nobody holds them)
            ends.append(exited_at + (0.3 if pipes_open else 0.0))
        end_at = min(ends)
        if now >= end_at:
            result["timed_out"] = path_mono is None and exited_at is None
            break
        if now >= next_count:
            result["procs_max"] = max(result["procs_max"], _count_processes(iso, uid, me))
            next_count = now + 0.05
        # reap: the program, and (as pid 1 or sub-reaper) every orphan it left
        while True:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                break
            if pid == 0:
                break
            if pid == proc.pid:
                proc.returncode = os.waitstatus_to_exitcode(status)
                exited_at = now
        for key, _ in sel.select(max(0.0, min(0.05, end_at - now))):
            what = key.data
            if what == "listen":
                try:
                    conn = robot.accept()
                except OSError:
                    continue
                sel.unregister(listener)
                conn.setblocking(False)
                sel.register(conn, selectors.EVENT_READ, "conn")
            elif what == "conn":
                try:
                    data = robot.conn.recv(65536)  # type: ignore[union-attr]
                except BlockingIOError:
                    continue
                except OSError:
                    data = b""
                if robot.feed(data, time.monotonic() - t0):
                    sel.unregister(robot.conn)
                    robot.conn.close()  # type: ignore[union-attr]
                    if robot.path is not None:
                        path_mono = time.monotonic()
            else:
                try:
                    data = os.read(key.fileobj.fileno(), 65536)  # type: ignore[union-attr]
                except BlockingIOError:
                    continue
                if not data:
                    sel.unregister(key.fileobj)
                    pipes_open -= 1
                    continue
                room = max(cap - len(outs[what]), 0)
                outs[what] += data[:room]
                dropped[what] += len(data) - min(len(data), room)
    wall = time.monotonic() - t0
    ended_itself = proc.returncode is not None
    # no process of the sandbox survives
    if is_pid1:
        try:
            os.kill(-1, signal.SIGKILL)  # pid 1 of our own pid namespace: every other process in it
        except ProcessLookupError:
            pass  # nothing left
    else:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        if uid is not None:
            _kill_uid(uid)
    if proc.returncode is None:
        try:
            _, status = os.waitpid(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)
        except ChildProcessError:
            proc.returncode = -signal.SIGKILL
    while True:  # zombies left to us (pid 1, sub-reaper)
        try:
            pid, _ = os.waitpid(-1, 0 if is_pid1 else os.WNOHANG)
        except ChildProcessError:
            break
        if pid == 0:
            break
    if ended_itself:
        if proc.returncode < 0:
            result["signal"] = -proc.returncode
        else:
            result["exit_code"] = proc.returncode
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    for f in (proc.stdout, proc.stderr):
        try:
            f.close()  # type: ignore[union-attr]
        except OSError:
            pass
    if "mount" not in iso["namespaces"]:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
    result.update({
        "path": robot.path, "path_at_s": robot.path_at, "connected": robot.connected, "port_log": robot.log,
        "refused": robot.refused, "wall_s": round(wall, 3), "cpu_s": round(ru.ru_utime + ru.ru_stime, 3),
        "max_rss_kib": ru.ru_maxrss,
        "stdout": outs["stdout"].decode("utf-8", "replace"), "stderr": outs["stderr"].decode("utf-8", "replace"),
        "stdout_dropped": dropped["stdout"], "stderr_dropped": dropped["stderr"],
    })
    return result


def _empty_outputs() -> dict[str, Any]:
    return {"path": None, "path_at_s": None, "connected": False, "port_log": [], "refused": [], "wall_s": 0.0,
            "cpu_s": 0.0, "max_rss_kib": 0, "stdout": "", "stderr": "", "stdout_dropped": 0, "stderr_dropped": 0}


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def probe(mode: str) -> dict[str, Any]:
    """What isolation this machine gives (run in a throw-away child process)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - child
        os.close(r)
        try:
            iso = enter_namespaces(mode)
            iso["uid_switch"] = not iso["user_namespace"] and _has_cap(CAP_SETUID) and _has_cap(CAP_SETGID)
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
    return json.loads(data)


def _preload_codec() -> None:
    """Import the wire codec now, while the project's files are still visible.

    The mount namespace covers ``/tmp`` with a fresh tmpfs, and a checkout
    (with its virtualenv) may well live under ``/tmp``: a later import would
    not find it.  The server starts the launcher with ``OPENBLAS_NUM_THREADS=1``
    (and the OpenMP/MKL equivalents), so importing numpy starts no thread and
    the process is still single-threaded when it unshares and forks; that is
    checked here.
    """
    import robot_agent.protocol  # noqa: F401

    threads = len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else 1
    if threads != 1:
        raise OSError(errno.EAGAIN, f"the launcher has {threads} threads after importing the codec; "
                                    "start it with OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1")


def main() -> int:
    job = json.loads(sys.stdin.buffer.read())
    sys.stdin.close()
    if job.get("probe"):
        _emit(probe(job.get("namespaces", "auto")))
        return 0
    try:
        _preload_codec()
    except OSError as exc:
        _emit({"launch_error": exc.strerror or str(exc), **_empty_outputs(), "exit_code": None, "signal": None,
               "timed_out": False, "procs_max": 0, "isolation": {"namespaces": []}})
        return 0
    try:
        iso = enter_namespaces(job.get("namespaces", "auto"))
    except OSError as exc:
        _emit({"launch_error": exc.strerror or str(exc), **_empty_outputs(), "exit_code": None, "signal": None,
               "timed_out": False, "procs_max": 0, "isolation": {"namespaces": []}})
        return 0
    if "pid" in iso["namespaces"]:
        child = os.fork()
        if child != 0:
            # outside the namespace: wait; if the server stops us, pid 1 (and with it the sandbox) dies too
            signal.signal(signal.SIGTERM, lambda *_: os.kill(child, signal.SIGKILL))
            while True:
                try:
                    _, status = os.waitpid(child, 0)
                    break
                except InterruptedError:
                    continue
            return os.waitstatus_to_exitcode(status) & 0xFF
        _prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    try:
        result = supervise(job, iso)
    except Exception as exc:  # noqa: BLE001 - report set-up failures to the server instead of a traceback
        result = {"launch_error": f"sandbox set-up failed: {type(exc).__name__}: {exc}", **_empty_outputs(),
                  "exit_code": None, "signal": None, "timed_out": False, "procs_max": 0}
    result["isolation"] = iso
    _emit(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
