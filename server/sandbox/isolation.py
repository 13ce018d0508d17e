"""Kernel interfaces of the launcher: namespaces, mounts, loopback, capabilities, ``prctl``.

Linux only; everything here is called by the launcher process (never by the
server), before the program starts.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import os
import re
import socket
import struct
from typing import Any, Optional

__all__ = ["CAP_SETGID", "CAP_SETUID", "enter_namespaces", "has_cap", "loopback_up", "prctl", "set_up_mounts"]

CLONE_NEWNS = 0x00020000
CLONE_NEWCGROUP = 0x02000000
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

libc = ctypes.CDLL(None, use_errno=True)
libc.mount.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong, ctypes.c_char_p]
libc.prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]


def _check(rc: int, what: str) -> None:
    if rc != 0:
        e = ctypes.get_errno()
        raise OSError(e, f"{what}: {os.strerror(e)}")


def _unshare(flags: int) -> None:
    _check(libc.unshare(flags), "unshare")


def _mount(source: Optional[str], target: str, fstype: Optional[str], flags: int, data: Optional[str]) -> None:
    enc = lambda s: None if s is None else s.encode()  # noqa: E731
    _check(libc.mount(enc(source), enc(target), enc(fstype), flags, enc(data)), f"mount {target}")


def prctl(option: int, arg: int) -> int:
    """``prctl(option, arg)``; 0 on success, -1 on failure (errno in ``ctypes.get_errno()``)."""
    return libc.prctl(option, arg, 0, 0, 0)


def has_cap(cap: int) -> bool:
    """Whether this process has capability ``cap`` in its effective set."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("CapEff:"):
                return bool(int(line.split()[1], 16) >> cap & 1)
    return False


def loopback_up() -> None:
    """Bring up ``lo`` of this (new) network namespace."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        ifr = fcntl.ioctl(s, SIOCGIFFLAGS, struct.pack("16sh22x", b"lo", 0))
        flags = struct.unpack("16sh22x", ifr)[1]
        fcntl.ioctl(s, SIOCSIFFLAGS, struct.pack("16sh22x", b"lo", flags | IFF_UP))
    finally:
        s.close()


def enter_namespaces(mode: str) -> dict[str, Any]:
    """Unshare what this process may; returns the isolation record (``namespaces`` empty: none).

    ``mode``: ``auto`` (fall back to none), ``required`` (OSError instead) or ``off``.
    """
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
    """Everything read-only but fresh /proc and temporary directories (``tmpfs_bytes`` each); empty tmpfs over ``hide``."""
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
