"""The program's sandbox, made by bubblewrap (``bwrap``: Debian's ``bubblewrap``, Flatpak's sandbox).

The launcher runs ``bwrap`` as the program's user (as root: the program's
own uid, switched to before ``exec``; else the server's), so bwrap works as
for any unprivileged user: it makes a user namespace first, and everything
else inside it, owned by it:

- **namespaces**: user, network (only loopback, which bwrap brings up),
  mount, pid, ipc, uts (host name ``twb-sandbox``) and, where the kernel has
  it, cgroup; no further user namespaces inside (``--disable-userns``);
- **file system**: the host's ``/`` read-only; a fresh ``/proc`` for the pid
  namespace and a minimal ``/dev``; ``/tmp``, ``/var/tmp`` and ``/dev/shm``
  empty tmpfs of ``tmpfs_bytes`` each; ``/run`` empty and read-only (no host
  sockets such as D-Bus's); the server's data directory (and the SQLite
  database's) covered by an empty read-only tmpfs (a file: by ``/dev/null``);
- **the working directory** ``/tmp/twb-program`` (0700, the program's user)
  on that ``/tmp``, with the job's files copied in by bwrap (``--file``);
- **the process**: no capabilities, ``no_new_privs``, a session of its own
  (``--new-session``), the seccomp filter (:mod:`.seccomp`, ``--seccomp``),
  killed with its launcher (``--die-with-parent``); the pid namespace's
  first process is bwrap's (it reaps, and all ends when it does).

The robot ports must listen inside the sandbox's network namespace, yet be
served by the launcher outside: bwrap reports the pid of the sandbox's first
process as soon as it exists (``--json-status-fd``) and waits before it
starts the program (``--block-fd``); meanwhile a short-lived helper process
of the launcher enters that network namespace, opens the listening sockets
on ports chosen beforehand (every port is free in a new namespace, and the
program's environment names them) and hands them back over a Unix socket.
The process limit goes onto that first process the same way (``prlimit``),
so that it counts only the processes of the sandbox.

bwrap's exit status is the program's, or 128 + the signal that killed it
(bash's convention); it reports the status only when it started the
program (``--json-status-fd``), so a sandbox that could not be set up is
told apart from a program that failed.
"""

from __future__ import annotations

import base64
import json
import os
import resource
import secrets
import select
import shutil
import signal
import socket
import subprocess
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional

from .isolation import enter_network_namespace

__all__ = ["NAMESPACES", "WORKDIR", "Bubble", "SetupFailed", "arguments", "choose_ports", "exit_status", "find",
           "inside", "start", "version"]

#: the program's working directory inside the sandbox (on its own /tmp)
WORKDIR = "/tmp/twb-program"
#: fresh, writable tmpfs of the sandbox
PRIVATE_TMP = ("/tmp", "/var/tmp", "/dev/shm")
#: empty and read-only in the sandbox
EMPTY = ("/run",)
#: robot ports are chosen from here (any port is free in a new network namespace)
PORTS = (20000, 60000)
#: namespaces bwrap makes (the cgroup namespace only where the kernel has it)
NAMESPACES = ["user", "net", "mount", "pid", "ipc", "uts"]
#: how long bwrap may take to make the sandbox before the program starts, s
SETUP_S = 20.0


class SetupFailed(Exception):
    """bubblewrap could not make the sandbox; the message is why (bwrap's own words)."""


def find(job: dict[str, Any]) -> Optional[str]:
    """The ``bwrap`` to run: the job's ``bwrap`` (a path) or the one on ``PATH``; None if there is none."""
    path = job.get("bwrap") or shutil.which("bwrap")
    return path if path and os.access(path, os.X_OK) else None


def version(bwrap: str) -> str:
    """``bubblewrap 0.8.0``, or what ``bwrap --version`` says."""
    try:
        out = subprocess.run([bwrap, "--version"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.strip()


def arguments(hide: list[str], tmpfs_bytes: int) -> tuple[list[str], list[str]]:
    """bwrap's namespace and file-system options (before the job's files), and the paths it hides."""
    args = ["--unshare-user", "--unshare-net", "--unshare-pid", "--unshare-ipc", "--unshare-uts",
            "--unshare-cgroup-try", "--disable-userns", "--hostname", "twb-sandbox", "--die-with-parent",
            "--new-session", "--cap-drop", "ALL", "--ro-bind", "/", "/", "--proc", "/proc", "--dev", "/dev"]
    covered = []
    for d in PRIVATE_TMP:
        if os.path.isdir(d) and not os.path.islink(d):
            args += ["--size", str(tmpfs_bytes), "--perms", "1777", "--tmpfs", d]
            covered.append(d)
    for d in EMPTY:
        if os.path.isdir(d) and not os.path.islink(d):
            args += ["--size", "4096", "--perms", "0755", "--tmpfs", d, "--remount-ro", d]
            covered.append(d)
    hidden = []
    for h in hide:
        real = os.path.realpath(h)
        if not os.path.exists(real):
            continue
        if not any(real == c or real.startswith(c.rstrip("/") + "/") for c in covered):  # else: hidden already
            if os.path.isdir(real):
                args += ["--size", "4096", "--perms", "0000", "--tmpfs", real, "--remount-ro", real]
            else:
                args += ["--ro-bind", "/dev/null", real]
        hidden.append(h)
    return args, hidden


@dataclass
class Bubble:
    """A running sandbox: bwrap's process (it exits with the program), the sandbox's first process, more."""

    proc: subprocess.Popen  # type: ignore[type-arg]
    pid1: int  # the sandbox's first process (pid 1 inside), as this process sees it
    pidfd: int  # a pidfd of it: signals reach it, never a process that later gets its pid
    namespaces: list[str]
    listeners: list[socket.socket]
    status_fd: int  # the rest of bwrap's JSON status: the program's exit code, once it started
    status: bytes = b""

    def alive(self) -> bool:
        """Whether the sandbox's first process still runs (while it does, the sandbox exists)."""
        return self.pidfd >= 0 and not select.select([self.pidfd], [], [], 0)[0]

    def finish(self) -> None:
        """Read the rest of bwrap's status and let go of the first process (call once bwrap has exited)."""
        if self.pidfd >= 0:
            os.close(self.pidfd)
            self.pidfd = -1
        if self.status_fd < 0:
            return
        os.set_blocking(self.status_fd, False)
        try:
            while chunk := os.read(self.status_fd, 4096):
                self.status += chunk
        except BlockingIOError:
            pass
        os.close(self.status_fd)
        self.status_fd = -1

    def program_started(self) -> bool:
        """Whether bwrap started the program (its exit code came): else the sandbox or the ``exec`` failed."""
        return b'"exit-code"' in self.status

    def kill(self) -> None:
        """End the sandbox: its first process, and with it every process in its pid namespace; and bwrap."""
        try:
            if self.pidfd >= 0:
                signal.pidfd_send_signal(self.pidfd, signal.SIGKILL)
        except OSError:
            pass
        if self.proc.returncode is None:  # not reaped yet: the pid is still bwrap's
            try:
                os.kill(self.proc.pid, signal.SIGKILL)
            except OSError:
                pass


def start(bwrap: str, job: dict[str, Any], argv: list[str], env: dict[str, str], *, ports: list[int],
          tmpfs_bytes: int, hide: list[str], seccomp: Optional[bytes], nproc: int, uid: Optional[int],
          preexec: Callable[[], None]) -> tuple[Bubble, list[str]]:
    """Start ``argv`` in a new sandbox, the job's files in :data:`WORKDIR`, a robot port listening on each of
    ``ports``; (the sandbox, the paths hidden).  ``preexec`` runs in bwrap's process before ``exec`` (cgroup,
    user ``uid``, rlimits); ``nproc`` becomes the sandbox's process limit.  Raises :class:`SetupFailed`."""
    options, hidden = arguments(hide, tmpfs_bytes)
    fds: list[int] = []

    def memfd(name: str, data: bytes) -> int:
        fd = os.memfd_create(name, os.MFD_CLOEXEC)
        fds.append(fd)
        os.write(fd, data)
        os.lseek(fd, 0, os.SEEK_SET)
        return fd

    status_r, status_w = os.pipe2(os.O_CLOEXEC)
    block_r, block_w = os.pipe2(os.O_CLOEXEC)
    fds += [status_w, block_r]
    try:
        args = [bwrap, *options, "--perms", "0700", "--dir", WORKDIR]
        for name, spec in job["files"].items():
            fd = memfd(name, base64.b64decode(spec["base64"]))
            args += ["--perms", f"{spec.get('mode', 0o400):04o}", "--file", str(fd), f"{WORKDIR}/{name}"]
        if seccomp is not None:
            args += ["--seccomp", str(memfd("twb-seccomp", seccomp))]
        args += ["--chdir", WORKDIR, "--json-status-fd", str(status_w), "--block-fd", str(block_r), "--", *argv]
        proc = subprocess.Popen(args, cwd="/", env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, close_fds=True, pass_fds=fds, start_new_session=True,
                                preexec_fn=preexec)
    except BaseException as exc:
        for fd in fds + [status_r, block_w]:
            os.close(fd)
        if isinstance(exc, OSError):  # bwrap itself cannot run
            raise SetupFailed(f"cannot run {bwrap}: {exc.strerror or exc}") from None
        raise
    for fd in fds:
        os.close(fd)
    bubble: Optional[Bubble] = None
    try:
        first = _first_status(status_r, proc)
        pid1 = int(first["child-pid"])
        namespaces = NAMESPACES + (["cgroup"] if "cgroup-namespace" in first else [])
        try:  # bwrap, its parent, reaps it only once it died, and exits then: the pid is still its
            pidfd = os.pidfd_open(pid1)
        except OSError:
            raise SetupFailed(_why(proc)) from None
        bubble = Bubble(proc, pid1, pidfd, namespaces, [], status_r)
        try:
            bubble.listeners = inside(pid1, ports, nproc=nproc, uid=uid)
        except OSError as exc:
            bubble.kill()
            said = _why(proc)  # bwrap gave up (its words), or its sandbox was killed for this
            raise SetupFailed(said if said.startswith("bwrap: ") else
                              f"the sandbox's robot ports and process limit: {exc}") from None
        try:
            os.write(block_w, b"x")  # the program may start
        except OSError:
            pass  # bwrap is gone: its status and stderr say why
    except SetupFailed as exc:
        if proc.returncode is None:
            _wait_out(proc)
        os.close(status_r)
        if bubble is not None:
            os.close(bubble.pidfd)
        raise SetupFailed(str(exc).removeprefix("bwrap: ")) from None
    finally:
        os.close(block_w)
    return bubble, hidden


def _first_status(fd: int, proc: subprocess.Popen) -> dict[str, Any]:  # type: ignore[type-arg]
    """bwrap's first JSON status line (the sandbox's first process and namespaces); SetupFailed if it exits first."""
    data, deadline = b"", time.monotonic() + SETUP_S
    while b"\n" not in data:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            proc.kill()
            raise SetupFailed(f"bwrap did not start the sandbox within {SETUP_S:.0f} s")
        chunk = os.read(fd, 4096)
        if not chunk:
            raise SetupFailed(_why(proc))
        data += chunk
    try:
        return json.loads(data.split(b"\n", 1)[0])
    except ValueError:
        raise SetupFailed(f"bwrap's status is not JSON: {data[:200]!r}") from None


def _why(proc: subprocess.Popen) -> str:  # type: ignore[type-arg]
    """What a bwrap that exited without starting the program said."""
    _, err = _wait_out(proc)
    lines = [ln.strip() for ln in err.decode("utf-8", "replace").splitlines() if ln.strip()]
    return lines[-1] if lines else f"bwrap exited with status {proc.returncode}"


def _wait_out(proc: subprocess.Popen) -> tuple[bytes, bytes]:  # type: ignore[type-arg]
    """bwrap's output once it has exited (killed after 10 s)."""
    if proc.returncode is not None:
        return b"", b""
    try:
        return proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()


def inside(pid: int, ports: list[int], *, nproc: int, uid: Optional[int]) -> list[socket.socket]:
    """Listening sockets on ``ports`` in the network namespace of ``pid``, and ``RLIMIT_NPROC`` = ``nproc`` on
    ``pid``: done by a helper process, which enters that namespace and then (as root) becomes ``uid``, the
    sandbox's user, whose processes it may limit.  The limit is set on the sandbox's first process, after
    its user namespace exists, so that it counts the sandbox's processes only."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    child = os.fork()
    if child == 0:  # pragma: no cover - child
        code = 1
        try:
            ours.close()
            if ports:
                enter_network_namespace(pid)
            listeners = [_listen(port) for port in ports]
            if uid is not None:
                os.setgroups([])
                os.setresgid(uid, uid, uid)
                os.setresuid(uid, uid, uid)
            resource.prlimit(pid, resource.RLIMIT_NPROC, (nproc, nproc))
            socket.send_fds(theirs, [b"ok"], [s.fileno() for s in listeners])
            code = 0
        except OSError as exc:
            try:
                theirs.sendall(f"{exc}".encode()[:1000])
            except OSError:
                pass
        finally:
            os._exit(code)
    theirs.close()
    try:
        msg, fds, _, _ = socket.recv_fds(ours, 1024, max(1, len(ports)))
    finally:
        ours.close()
        os.waitpid(child, 0)
    if msg != b"ok" or len(fds) != len(ports):
        for fd in fds:
            os.close(fd)
        raise OSError(msg.decode("utf-8", "replace") or "the helper ended without them")
    return [socket.socket(fileno=fd) for fd in fds]


def _listen(port: int) -> socket.socket:
    """A listening socket on ``port`` of every address of this (new) network namespace: only loopback has one."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("0.0.0.0", port))  # bwrap may not have brought up loopback yet: 127.0.0.1 may not exist so far
    s.listen(1)
    return s


def choose_ports(n: int) -> list[int]:
    """``n`` distinct port numbers for the robot ports inside a new network namespace."""
    chosen: list[int] = []
    while len(chosen) < n:
        port = PORTS[0] + secrets.randbelow(PORTS[1] - PORTS[0])
        if port not in chosen:
            chosen.append(port)
    return chosen


def exit_status(code: int) -> tuple[Optional[int], Optional[int]]:
    """(exit code, signal) of the program from bwrap's exit status (128 + n: killed by signal n)."""
    if code < 0:  # bwrap itself was killed (the sandbox with it)
        return None, -code
    if 128 < code <= 128 + 64:
        return None, code - 128
    return code, None
