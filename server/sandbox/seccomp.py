"""The program's system-call filter: an allowlist, compiled by libseccomp (through ``pyseccomp``).

Allowed (:data:`ALLOWED`): what programs of any language need to compute and
talk to their robot port — files, memory, threads and processes, signals,
time, waiting, randomness, sockets, System V and POSIX IPC — some of it only with certain
arguments (:func:`build`): ``clone`` without namespace flags, ``socket`` of
the families ``AF_UNIX``, ``AF_INET``, ``AF_INET6`` and route netlink (C
libraries ask it which addresses exist), ``socketpair`` of ``AF_UNIX``,
``personality`` only to ask.

Refused with EPERM (:data:`DENIED`): what a planner never needs and sandbox
escapes use — namespaces, mounts, tracing other processes, keyrings, eBPF,
perf, userfaultfd, io_uring, kernel modules, kexec, the clock, swap,
reboot.  Everything else fails with ENOSYS, as on a kernel that does not
have the call, so C libraries fall back to an older call where there is one
(``clone3`` to ``clone``: its flags are out of a filter's reach).  Calls of
another ABI (i386 and x32 on x86-64, arm32 on arm64) fail with ENOSYS too.

libseccomp turns the names into this machine's numbers and checks the
architecture of every call; :func:`program` is the classic-BPF program that
bubblewrap loads (``--seccomp FD``) and :func:`load` loads it into the
calling process (the sandbox without namespaces).
"""

from __future__ import annotations

import errno
import os
import socket
from typing import Any, Optional

__all__ = ["ALLOWED", "DENIED", "UNAVAILABLE", "build", "load", "program"]

try:
    import pyseccomp as _sc
    UNAVAILABLE = ""
except (ImportError, RuntimeError, OSError) as exc:  # pragma: no cover - libseccomp.so.2 missing
    _sc = None  # type: ignore[assignment]
    UNAVAILABLE = f"libseccomp is not available ({exc})"

#: allowed system calls, by what they are for (a name this architecture does not have is skipped)
ALLOWED: dict[str, tuple[str, ...]] = {
    "files": (
        "read", "write", "readv", "writev", "pread64", "pwrite64", "preadv", "pwritev", "preadv2", "pwritev2",
        "open", "openat", "openat2", "creat", "close", "close_range", "lseek", "dup", "dup2", "dup3", "fcntl",
        "flock", "pipe", "pipe2", "stat", "fstat", "lstat", "newfstatat", "statx", "statfs", "fstatfs", "access",
        "faccessat", "faccessat2", "getdents", "getdents64", "getcwd", "chdir", "fchdir", "mkdir", "mkdirat",
        "rmdir", "rename", "renameat", "renameat2", "link", "linkat", "unlink", "unlinkat", "symlink",
        "symlinkat", "readlink", "readlinkat", "chmod", "fchmod", "fchmodat", "fchmodat2", "chown", "fchown",
        "lchown", "fchownat", "umask", "utime", "utimes", "utimensat", "futimesat", "truncate", "ftruncate",
        "fallocate", "fadvise64", "readahead", "fsync", "fdatasync", "syncfs", "sync_file_range", "mknod",
        "mknodat", "sendfile", "splice", "tee", "vmsplice", "copy_file_range", "getxattr", "lgetxattr",
        "fgetxattr", "listxattr", "llistxattr", "flistxattr", "setxattr", "lsetxattr", "fsetxattr",
        "removexattr", "lremovexattr", "fremovexattr", "inotify_init", "inotify_init1", "inotify_add_watch",
        "inotify_rm_watch", "memfd_create", "ioctl"),
    "memory": (
        "brk", "mmap", "munmap", "mremap", "mprotect", "madvise", "mincore", "msync", "mlock", "mlock2",
        "munlock", "mlockall", "munlockall", "pkey_mprotect", "pkey_alloc", "pkey_free", "mbind",
        "get_mempolicy", "set_mempolicy", "set_mempolicy_home_node", "remap_file_pages", "membarrier",
        "map_shadow_stack"),
    "waiting": (
        "poll", "ppoll", "select", "pselect6", "epoll_create", "epoll_create1", "epoll_ctl", "epoll_wait",
        "epoll_pwait", "epoll_pwait2", "eventfd", "eventfd2", "signalfd", "signalfd4", "timerfd_create",
        "timerfd_settime", "timerfd_gettime", "futex", "futex_waitv", "futex_wake", "futex_wait",
        "futex_requeue", "set_robust_list", "sched_yield", "nanosleep", "clock_nanosleep", "pause"),
    "time": (
        "clock_gettime", "clock_getres", "gettimeofday", "time", "times", "getitimer", "setitimer", "alarm",
        "timer_create", "timer_settime", "timer_gettime", "timer_getoverrun", "timer_delete"),
    "processes": (
        "fork", "vfork", "execve", "execveat", "exit", "exit_group", "wait4", "waitid", "kill", "tkill",
        "tgkill", "pidfd_open", "pidfd_send_signal", "getpid", "getppid", "gettid", "getpgid", "getpgrp",
        "setpgid", "getsid", "setsid", "getuid", "geteuid", "getgid", "getegid", "getresuid", "getresgid",
        "getgroups", "setuid", "setgid", "setreuid", "setregid", "setresuid", "setresgid", "setfsuid",
        "setfsgid", "setgroups", "capget", "capset", "prctl", "arch_prctl", "set_tid_address", "rseq",
        "get_thread_area", "set_thread_area", "getrlimit", "setrlimit", "prlimit64", "getrusage",
        "getpriority", "setpriority", "sched_getaffinity", "sched_setaffinity", "sched_getparam",
        "sched_setparam", "sched_getscheduler", "sched_setscheduler", "sched_get_priority_max",
        "sched_get_priority_min", "sched_rr_get_interval", "sched_getattr", "sched_setattr", "ioprio_get",
        "ioprio_set", "getcpu", "uname", "sysinfo", "seccomp", "restart_syscall", "landlock_create_ruleset",
        "landlock_add_rule", "landlock_restrict_self"),
    "signals": (
        "rt_sigaction", "rt_sigprocmask", "rt_sigreturn", "rt_sigpending", "rt_sigtimedwait", "rt_sigqueueinfo",
        "rt_tgsigqueueinfo", "rt_sigsuspend", "sigaltstack"),
    "sockets": (
        "connect", "bind", "listen", "accept", "accept4", "getsockname", "getpeername", "sendto", "recvfrom",
        "sendmsg", "recvmsg", "sendmmsg", "recvmmsg", "shutdown", "setsockopt", "getsockopt"),
    "randomness": ("getrandom",),
    "ipc": (
        "shmget", "shmat", "shmdt", "shmctl", "semget", "semop", "semtimedop", "semctl", "msgget", "msgsnd",
        "msgrcv", "msgctl", "mq_open", "mq_unlink", "mq_timedsend", "mq_timedreceive", "mq_notify",
        "mq_getsetattr"),
}

#: refused with EPERM: sandbox escapes and the machine's administration (the rest of what is not allowed: ENOSYS)
DENIED = (
    "unshare", "setns", "mount", "umount2", "pivot_root", "chroot", "open_tree", "move_mount", "fsopen", "fsconfig",
    "fsmount", "fspick", "mount_setattr", "ptrace", "process_vm_readv", "process_vm_writev", "kcmp", "pidfd_getfd",
    "process_madvise", "process_mrelease", "get_robust_list", "keyctl", "add_key", "request_key", "bpf",
    "perf_event_open", "userfaultfd", "io_uring_setup", "io_uring_enter", "io_uring_register", "kexec_load",
    "kexec_file_load", "init_module", "finit_module", "delete_module", "open_by_handle_at", "name_to_handle_at",
    "fanotify_init", "quotactl", "quotactl_fd", "swapon", "swapoff", "reboot", "acct", "syslog", "settimeofday",
    "clock_settime", "adjtimex", "clock_adjtime", "sethostname", "setdomainname", "iopl", "ioperm", "modify_ldt",
    "vhangup", "lookup_dcookie", "move_pages", "migrate_pages", "memfd_secret", "uselib",
)

#: clone's namespace flags (CLONE_NEWNS, NEWCGROUP, NEWUTS, NEWIPC, NEWUSER, NEWPID, NEWNET, and NEWTIME)
CLONE_NAMESPACE_FLAGS = 0x00020000 | 0x02000000 | 0x04000000 | 0x08000000 | 0x10000000 | 0x20000000 \
    | 0x40000000 | 0x00000080
NETLINK_ROUTE = 0
#: personality(0xffffffff) only asks for the current persona; personality(PER_LINUX) sets the default one
PERSONALITY_QUERY, PER_LINUX = 0xFFFFFFFF, 0


def build() -> Any:
    """The filter (a ``pyseccomp.SyscallFilter`` for this machine's architecture); RuntimeError without libseccomp."""
    if _sc is None:
        raise RuntimeError(UNAVAILABLE)
    sc = _sc
    f = sc.SyscallFilter(sc.ERRNO(errno.ENOSYS))
    f.set_attr(sc.Attr.ACT_BADARCH, sc.ERRNO(errno.ENOSYS))
    try:
        f.set_attr(sc.Attr.CTL_OPTIMIZE, 2)  # a binary tree of the calls (libseccomp 2.5+), not a linear list
    except OSError:
        pass

    def add(action: int, name: str, *args: Any) -> None:
        nr = sc.resolve_syscall(sc.Arch.NATIVE, name)
        if nr == -10101:  # __NR_SCMP_ERROR: a name this libseccomp does not know
            return
        f.add_rule(action, nr, *args)

    for names in ALLOWED.values():
        for name in names:
            add(sc.ALLOW, name)
    for name in DENIED:
        add(sc.ERRNO(errno.EPERM), name)
    # clone: new threads and processes, no new namespaces (the flags are its first argument on x86-64 and arm64,
    # its second on s390); clone3 passes them in memory a filter cannot read, so it looks absent
    flags = 1 if sc.system_arch() in (sc.Arch.S390, sc.Arch.S390X) else 0
    add(sc.ALLOW, "clone", sc.Arg(flags, sc.MASKED_EQ, CLONE_NAMESPACE_FLAGS, 0))
    for bit in (1 << b for b in range(32) if CLONE_NAMESPACE_FLAGS >> b & 1):
        add(sc.ERRNO(errno.EPERM), "clone", sc.Arg(flags, sc.MASKED_EQ, bit, bit))
    assert "clone3" not in DENIED and all("clone3" not in names for names in ALLOWED.values())  # ENOSYS
    for family in (socket.AF_UNIX, socket.AF_INET, socket.AF_INET6):
        add(sc.ALLOW, "socket", sc.Arg(0, sc.EQ, family))
    add(sc.ALLOW, "socket", sc.Arg(0, sc.EQ, socket.AF_NETLINK), sc.Arg(2, sc.EQ, NETLINK_ROUTE))
    add(sc.ALLOW, "socketpair", sc.Arg(0, sc.EQ, socket.AF_UNIX))
    for persona in (PER_LINUX, PERSONALITY_QUERY):
        add(sc.ALLOW, "personality", sc.Arg(0, sc.EQ, persona))
    return f


def program() -> bytes:
    """The filter as a classic-BPF program (``struct sock_filter`` array), for ``bwrap --seccomp``."""
    f = build()
    fd = os.memfd_create("twb-seccomp", os.MFD_CLOEXEC)
    try:
        f.export_bpf(_Fd(fd))
        os.lseek(fd, 0, os.SEEK_SET)
        data = b""
        while chunk := os.read(fd, 65536):
            data += chunk
        return data
    finally:
        os.close(fd)


def load() -> None:
    """Load the filter into this process (``no_new_privs`` must be set, or CAP_SYS_ADMIN held)."""
    build().load()


class _Fd:
    """A file descriptor as the file object ``pyseccomp`` exports to."""

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def fileno(self) -> int:
        return self.fd


def available() -> Optional[str]:
    """None if the filter can be built here, else why not."""
    try:
        build()
    except (RuntimeError, OSError) as exc:
        return str(exc)
    return None
