"""A cgroup per program: one memory limit for all its processes together, a process limit, a clean end.

The launcher makes the program's cgroup as a child of the cgroup it runs in
(bubblewrap has none of its own):

- **cgroup v2** (the unified hierarchy): ``memory.max`` = the limit,
  ``memory.swap.max`` = 0, ``memory.oom.group`` = 1 (an out-of-memory kill
  ends the whole program), ``pids.max`` = the process limit.  A cgroup with
  processes may not hand controllers to its children ("no internal
  processes"): when enabling them in ``cgroup.subtree_control`` is refused
  (EBUSY), the processes of the launcher's cgroup (the server's among them)
  move into its child ``twb-processes`` first, as container entry points do.
- **cgroup v1** (legacy and hybrid hosts, where the memory controller is
  bound to a v1 hierarchy): ``memory.limit_in_bytes`` and
  ``memory.memsw.limit_in_bytes`` (no swap either) in the memory hierarchy,
  ``pids.max`` in the pids hierarchy.

It keeps directory descriptors to it.  The process that becomes bwrap (or,
without it, the program) enters the cgroup between fork and exec, so that
everything the program starts is in it, and the launcher (which stays
outside the sandbox's namespaces) reads its counters and removes it at the
end.
"""

from __future__ import annotations

import errno
import os
import re
import secrets
import signal
import time
from dataclasses import dataclass
from typing import ClassVar, Optional

__all__ = ["LEAF", "PREFIX", "CgroupV1", "CgroupV2", "ProgramCgroup", "Unavailable", "cgroup_dirs", "create",
           "own_dirs"]

#: names of program cgroups: twb-program-<launcher pid>-<random>
PREFIX = "twb-program-"
#: where the processes of a v2 cgroup go so that it may enable controllers for its children
LEAF = "twb-processes"
_DIR = os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC


class Unavailable(Exception):
    """No cgroup for the program; the message says why."""


@dataclass
class _Node:
    """One directory of a program cgroup: its descriptor, and its parent's (to remove it)."""

    parent: int
    fd: int
    name: str


class ProgramCgroup:
    """One program's cgroup: enter it, read why the kernel intervened, end everything in it, remove it."""

    version: ClassVar[int]
    #: (file, key) of the count of out-of-memory kills, and the file of the peak memory (bytes)
    OOM_EVENTS: ClassVar[tuple[str, str]]
    PEAK: ClassVar[str]
    #: (file, key) of the count of charges that met the memory limit (key None: the file is the number)
    LIMIT_EVENTS: ClassVar[tuple[str, Optional[str]]]

    def __init__(self, memory: _Node, pids: Optional[_Node]) -> None:
        self.memory = memory
        self.pids = pids
        self.nodes = [memory] + ([pids] if pids is not None and pids is not memory else [])

    def join(self) -> None:
        """Move the calling process into the cgroup (run between fork and exec; ``0`` means the writer)."""
        for node in self.nodes:
            _write(node.fd, "cgroup.procs", "0")

    def limit_processes(self, processes: int) -> None:
        """Set the process limit (``pids.max``), where the pids controller is there."""
        if self.pids is not None:
            _write(self.pids.fd, "pids.max", str(processes))

    def oom_kills(self) -> int:
        """Processes the kernel killed because the program used all its memory."""
        return _key(self.memory.fd, *self.OOM_EVENTS)

    def limit_hits(self) -> int:
        """Times the program's memory reached its limit (the kernel then reclaims, and kills if it cannot).

        v2 ``memory.events`` ``max``; v1 ``memory.failcnt`` (some kernels keep it at 0: the peak tells then).
        """
        name, key = self.LIMIT_EVENTS
        return _key(self.memory.fd, name, key) if key is not None else _number(self.memory.fd, name) or 0

    def page_cache_bytes(self) -> Optional[int]:
        """The page cache of files charged to the program now (bytes; not tmpfs: without swap the kernel cannot
        reclaim that); None if unknown.  Its processes gone, what is left is what it had read or written."""
        stat = _keys(self.memory.fd, "memory.stat")
        if stat is None or "active_file" not in stat or "inactive_file" not in stat:
            return None
        return stat["active_file"] + stat["inactive_file"]

    def fork_refusals(self) -> int:
        """Forks refused because the program had all its processes (0 without the pids controller)."""
        return 0 if self.pids is None else _key(self.pids.fd, "pids.events", "max")

    def peak_bytes(self) -> Optional[int]:
        """The most memory the program's processes used together (bytes, page cache included); None if unknown."""
        return _number(self.memory.fd, self.PEAK)

    def kill_all(self) -> None:
        """SIGKILL every process in the cgroup, until none is left (at most about a second)."""
        me = os.getpid()
        for _ in range(100):
            try:
                pids = [int(p) for p in _read(self.memory.fd, "cgroup.procs").split()]
            except OSError:
                return
            pids = [p for p in pids if p > 0 and p != me]  # 0: a process outside this pid namespace
            if not pids:
                return
            for pid in pids:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            time.sleep(0.01)

    def remove(self) -> bool:
        """Kill what is left and remove the cgroup; whether every directory is gone."""
        self.kill_all()
        removed = True
        for node in self.nodes:
            os.close(node.fd)
            for _ in range(200):  # an exiting process may keep the cgroup busy for a moment
                try:
                    os.rmdir(node.name, dir_fd=node.parent)
                    break
                except FileNotFoundError:
                    break
                except OSError as exc:
                    if exc.errno != errno.EBUSY:
                        removed = False
                        break
                    time.sleep(0.01)
            else:
                removed = False
            os.close(node.parent)
        return removed


class CgroupV2(ProgramCgroup):
    """A cgroup of the unified hierarchy (memory and pids controllers in one directory)."""

    version = 2
    OOM_EVENTS = ("memory.events", "oom_kill")
    PEAK = "memory.peak"
    LIMIT_EVENTS = ("memory.events", "max")

    def kill_all(self) -> None:
        try:
            _write(self.memory.fd, "cgroup.kill", "1")  # Linux 5.14+
        except OSError:
            pass
        super().kill_all()


class CgroupV1(ProgramCgroup):
    """Cgroups of the v1 memory hierarchy and, where mounted, the v1 pids hierarchy."""

    version = 1
    OOM_EVENTS = ("memory.oom_control", "oom_kill")
    PEAK = "memory.max_usage_in_bytes"
    LIMIT_EVENTS = ("memory.failcnt", None)


def create(memory_bytes: int, processes: int) -> ProgramCgroup:
    """The program's cgroup with its limits (bytes; processes); raises :class:`Unavailable` saying why not.

    v2 first, then v1.  Call it before unsharing any namespace.
    """
    name = f"{PREFIX}{os.getpid()}-{secrets.token_hex(4)}"
    try:
        return _create_v2(name, memory_bytes, processes)
    except Unavailable as exc:
        v2 = str(exc)
    try:
        return _create_v1(name, memory_bytes, processes)
    except Unavailable as exc:
        raise Unavailable(f"{v2}; {exc}") from None


def _create_v2(name: str, memory_bytes: int, processes: int) -> ProgramCgroup:
    own = own_dirs().get("")
    if own is None:
        raise Unavailable("cgroup v2: not mounted")
    base = os.path.dirname(own) if os.path.basename(own) == LEAF else own
    try:
        offered = _read_path(os.path.join(base, "cgroup.controllers")).split()
        if "memory" not in offered:
            raise Unavailable(f"cgroup v2: no memory controller in {base} (offered: {' '.join(offered) or 'none'})")
        wanted = ["memory"] + (["pids"] if "pids" in offered else [])
        _enable(base, wanted)
        node = _make(base, name)
    except OSError as exc:
        raise Unavailable(f"cgroup v2 in {base}: {exc.strerror}") from None
    cg = CgroupV2(node, node if "pids" in wanted else None)
    try:
        _write(node.fd, "memory.max", str(memory_bytes))
        _write_if_there(node.fd, "memory.swap.max", "0")  # absent without swap accounting
        _write_if_there(node.fd, "memory.oom.group", "1")
        if cg.pids is not None:
            _write(node.fd, "pids.max", str(processes))
    except OSError as exc:
        cg.remove()
        raise Unavailable(f"cgroup v2: cannot set the limits in {base}/{name}: {exc.strerror}") from None
    return cg


def _enable(base: str, controllers: list[str]) -> None:
    """Enable ``controllers`` for the children of ``base``, moving its processes into a leaf if it must."""
    control = os.path.join(base, "cgroup.subtree_control")
    for _ in range(5):
        missing = [c for c in controllers if c not in _read_path(control).split()]
        if not missing:
            return
        try:
            _write_path(control, " ".join("+" + c for c in missing))
            return
        except OSError as exc:
            if exc.errno != errno.EBUSY:
                raise
        leaf = os.path.join(base, LEAF)
        os.makedirs(leaf, exist_ok=True)
        for pid in _read_path(os.path.join(base, "cgroup.procs")).split():
            try:
                _write_path(os.path.join(leaf, "cgroup.procs"), pid)
            except OSError:
                pass  # exited, or not movable (a kernel thread)
    raise Unavailable(f"cgroup v2: cannot enable {' '.join(controllers)} in {base}: processes keep appearing there")


def _create_v1(name: str, memory_bytes: int, processes: int) -> ProgramCgroup:
    dirs = own_dirs()
    if "memory" not in dirs:
        raise Unavailable("cgroup v1: no memory hierarchy mounted")
    try:
        memory = _make(dirs["memory"], name)
    except OSError as exc:
        raise Unavailable(f"cgroup v1 in {dirs['memory']}: {exc.strerror}") from None
    try:
        pids: Optional[_Node] = _make(dirs["pids"], name) if "pids" in dirs else None
    except OSError:
        pids = None  # RLIMIT_NPROC still bounds the processes
    cg = CgroupV1(memory, pids)
    try:
        _write(memory.fd, "memory.limit_in_bytes", str(memory_bytes))
        _write_if_there(memory.fd, "memory.memsw.limit_in_bytes", str(memory_bytes))  # memory + swap: no swap
        if pids is not None:
            _write(pids.fd, "pids.max", str(processes))
    except OSError as exc:
        cg.remove()
        raise Unavailable(f"cgroup v1: cannot set the limits in {dirs['memory']}/{name}: {exc.strerror}") from None
    return cg


def own_dirs() -> dict[str, str]:
    """Directories of this process's cgroups: ``""`` (v2) and each mounted v1 controller -> path.

    Raises :class:`Unavailable` when neither is mounted where this process can see it.
    """
    with open("/proc/self/cgroup") as f, open("/proc/self/mountinfo") as g:
        found = cgroup_dirs(f.read(), g.read())
    if not found:
        raise Unavailable("no cgroup file system mounted")
    return found


def cgroup_dirs(proc_cgroup: str, mountinfo: str) -> dict[str, str]:
    """Where a process's cgroups are: ``""`` (v2) and each v1 controller -> directory.

    ``proc_cgroup`` and ``mountinfo`` are the texts of its ``/proc/<pid>/cgroup``
    and ``/proc/<pid>/mountinfo``; a cgroup outside every mount's root is not
    visible (and left out).
    """
    member: dict[str, str] = {}
    for line in proc_cgroup.splitlines():
        _, controllers, path = line.split(":", 2)
        for c in controllers.split(",") if controllers else [""]:
            member[c] = path
    found: dict[str, str] = {}
    for line in mountinfo.splitlines():
        left, _, right = line.partition(" - ")
        fields, fs = left.split(), right.split()
        if len(fs) < 3 or fs[0] not in ("cgroup", "cgroup2"):
            continue
        root, point = _unescape(fields[3]), _unescape(fields[4])
        for c in ([""] if fs[0] == "cgroup2" else fs[2].split(",")):
            path = member.get(c)
            if path is not None and c not in found and (path == root or path.startswith(root.rstrip("/") + "/")):
                found[c] = os.path.normpath(os.path.join(point, os.path.relpath(path, root)))
    return found


def _make(parent: str, name: str) -> _Node:
    """Create the cgroup ``parent/name`` (after removing ones left by killed launchers)."""
    pfd = os.open(parent, _DIR)
    try:
        _sweep(pfd)
        os.mkdir(name, 0o755, dir_fd=pfd)
        return _Node(pfd, os.open(name, _DIR, dir_fd=pfd), name)
    except OSError:
        os.close(pfd)
        raise


def _sweep(parent: int) -> None:
    """Remove empty program cgroups whose launcher is gone (it was killed before it could)."""
    for entry in os.listdir(parent):
        if not entry.startswith(PREFIX):
            continue
        try:
            pid = int(entry[len(PREFIX):].split("-")[0])
            os.kill(pid, 0)
            continue
        except ValueError:
            continue
        except PermissionError:
            continue  # alive, another user's
        except ProcessLookupError:
            pass
        try:
            os.rmdir(entry, dir_fd=parent)
        except OSError:
            pass  # not empty: not ours to judge


def _keys(fd: int, name: str) -> Optional[dict[str, int]]:
    """A flat-keyed cgroup file (``key value`` lines) as a dict, lines whose value is not a number left out;
    None if it cannot be read."""
    try:
        text = _read(fd, name)
    except OSError:
        return None
    out = {}
    for line in text.splitlines():
        k, _, v = line.partition(" ")
        try:
            out[k] = int(v)
        except ValueError:
            pass
    return out


def _key(fd: int, name: str, key: str) -> int:
    """The value of ``key`` in a flat-keyed cgroup file (``key value`` lines); 0 if absent."""
    return (_keys(fd, name) or {}).get(key, 0)


def _number(fd: int, name: str) -> Optional[int]:
    """A cgroup file holding one number; None if it cannot be read or holds none."""
    try:
        return int(_read(fd, name))
    except (OSError, ValueError):
        return None


def _read(dirfd: int, name: str) -> str:
    fd = os.open(name, os.O_RDONLY | os.O_CLOEXEC, dir_fd=dirfd)
    try:
        return os.read(fd, 65536).decode()
    finally:
        os.close(fd)


def _write(dirfd: int, name: str, text: str) -> None:
    """One ``write`` (a cgroup file takes each write as one command; errors come from it)."""
    fd = os.open(name, os.O_WRONLY | os.O_CLOEXEC, dir_fd=dirfd)
    try:
        os.write(fd, text.encode())
    finally:
        os.close(fd)


def _write_if_there(dirfd: int, name: str, text: str) -> None:
    try:
        _write(dirfd, name, text)
    except FileNotFoundError:
        pass


def _read_path(path: str) -> str:
    with open(path) as f:
        return f.read()


def _write_path(path: str, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CLOEXEC)
    try:
        os.write(fd, text.encode())
    finally:
        os.close(fd)


def _unescape(s: str) -> str:
    return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), s)
