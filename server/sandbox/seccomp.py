"""The program's seccomp filter: system calls a planner never needs fail.

Denied: namespaces, mounts, tracing other processes, keyrings, eBPF, perf,
userfaultfd, io_uring, kernel modules, kexec (EPERM); ``clone`` with
namespace flags (EPERM); ``clone3`` (ENOSYS: its flags are out of the
filter's reach, and C libraries then fall back to ``clone``); other ABIs
(i386, x32) get ENOSYS.
"""

from __future__ import annotations

import ctypes
import errno
import platform
import struct
from typing import Optional

from .isolation import (CLONE_NEWCGROUP, CLONE_NEWIPC, CLONE_NEWNET, CLONE_NEWNS, CLONE_NEWPID, CLONE_NEWUSER,
                        CLONE_NEWUTS, libc)

__all__ = ["DENIED", "install_seccomp", "seccomp_program"]

PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 22, 2
SECCOMP_RET_ALLOW, SECCOMP_RET_ERRNO = 0x7FFF0000, 0x00050000
#: architecture -> (its AUDIT_ARCH value, {denied call: number}, clone's number, clone3's number)
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
NAMESPACE_FLAGS = (CLONE_NEWNS | CLONE_NEWUTS | CLONE_NEWIPC | CLONE_NEWUSER | CLONE_NEWPID | CLONE_NEWNET
                   | CLONE_NEWCGROUP)


def seccomp_program() -> Optional[bytes]:
    """The classic-BPF filter for this machine's architecture (None on others)."""
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


def install_seccomp(prog: bytes) -> int:
    """Load ``prog`` for this thread (needs ``no_new_privs`` or CAP_SYS_ADMIN); 0 on success."""
    buf = ctypes.create_string_buffer(prog, len(prog))
    fprog = struct.pack("HxxxxxxP", len(prog) // 8, ctypes.addressof(buf))
    arg = ctypes.create_string_buffer(fprog, len(fprog))
    return libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.addressof(arg), 0, 0)
