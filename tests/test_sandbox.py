"""The sandbox launcher on its own: what each isolation level enforces.

docs/uploads.md, "The sandbox: what is enforced where", describes each level.

Jobs go straight to ``python -m server.sandbox.launch``.  The unprivileged
cases run the launcher as uid 65534 without capabilities (``setpriv``) in a
private mount namespace where this Python stays reachable — a non-root
server, simulated on a root machine.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import random
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from contract.protocol import MAX_LINE_BYTES, RobotState, format_hello, format_ok, format_status
from server.sandbox import cgroups, explain, launcher_env, robot_port, service
from server.sandbox.robot_port import RobotPort

ROOT = Path(__file__).resolve().parent.parent
NOBODY = 65534
LIMITS = {"wall_s": 5, "cpu_s": 2, "memory_bytes": 256 << 20, "file_bytes": 1 << 20, "processes": 8,
          "open_files": 64, "output_bytes": 1 << 16, "tmpfs_bytes": 16 << 20}
PYTHON = next((p for p in ("/usr/local/bin/python3", "/usr/bin/python3") if os.access(p, os.X_OK)), None)
is_root = os.geteuid() == 0
#: what bubblewrap makes (and, where the kernel has it, a cgroup namespace)
NAMESPACES = ["user", "net", "mount", "pid", "ipc", "uts"]
needs_root = pytest.mark.skipif(not is_root or PYTHON is None, reason="needs root and a system python3")

SEND_PATH = """
import os, socket
s = socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"])))
f = s.makefile("rwb")
f.readline()
f.write(b"T,T,P," + b"1" * (MAX + 10) + b"\\n")  # too long: ERR,TOOLONG, then the good line
f.write(b"T,T,P,300,300,0;1500,300,90\\n")
f.flush()
print(f.readline().decode().strip(), f.readline().decode().strip())
""".replace("MAX", str(MAX_LINE_BYTES))


def job(program: str, *, data_dir: Path, namespaces: str = "auto", interpreter: str | None = None,
        uid: int = 3_950_000, limits: dict | None = None) -> dict:
    return {
        "files": {"program.py": {"base64": base64.b64encode(program.encode()).decode(), "mode": 0o444},
                  "environment.json": {"base64": base64.b64encode(b'{"size": [1.8, 1.8], "blocks": []}').decode(),
                                       "mode": 0o444}},
        "argv": [interpreter or PYTHON, "{workdir}/program.py", "{robot_port}"],
        "env": {"PATH": "/usr/bin:/bin", "PYTHONUNBUFFERED": "1", "TWB_ENV_FILE": "environment.json",
                "TWB_START": "0.3,0.3,0", "TWB_GOAL": "1.5,0.3"},
        "uid": uid, "gid": uid, "namespaces": namespaces, "hide": [str(data_dir)], "limits": limits or LIMITS,
        "field_size": [1.8, 1.8], "robot_id": "sim-1", "platform": "BeBot", "start_pose": [0.3, 0.3, 0.0],
        "grace_s": 1.0,
    }


def launch(spec: dict, prefix: list[str] = ()) -> dict:
    r = subprocess.run([*prefix, sys.executable, "-m", "server.sandbox.launch"], input=json.dumps(spec).encode(),
                       capture_output=True, timeout=60, cwd=ROOT, env=launcher_env())
    assert r.returncode == 0, r.stderr.decode()
    return json.loads(r.stdout.decode().splitlines()[-1])


def processes_of(uid: int) -> list[str]:
    out = subprocess.run(["ps", "-eo", "uid=,args="], capture_output=True, text=True).stdout
    return [ln for ln in out.splitlines() if int(ln.split()[0]) == uid]


@pytest.fixture
def data_dir():
    """A server data dir outside /tmp (so only the mount over it can hide it), with a database file.

    The sandbox covers /tmp and /var/tmp with fresh tmpfs, which would hide a data dir there anyway;
    when the checkout itself lives there (a clean clone in /tmp), the data dir goes to /var/lib.
    """
    base = ROOT / "tests" / "output"
    if base.resolve().is_relative_to("/tmp") or base.resolve().is_relative_to("/var/tmp"):
        base = Path("/var/lib/twb-tests") if os.geteuid() == 0 else Path.home() / ".cache" / "twb-tests"
    base.mkdir(parents=True, exist_ok=True)
    d = Path(tempfile.mkdtemp(prefix="sandbox-data-", dir=base))
    (d / "twb.db").write_text("SECRET DATABASE")
    d.chmod(0o700)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def read_attempt(path: Path) -> str:
    return f"""
try:
    print("READ", open({str(path / 'twb.db')!r}).read())
except OSError as exc:
    print("refused", exc.strerror)
"""


# --------------------------------------------------------------------------- pure


def test_the_launcher_keeps_the_protocol_line_limit():
    assert robot_port.MAX_LINE_BYTES == MAX_LINE_BYTES


@pytest.mark.parametrize("result, reason", [
    ({"launch_error": "OSError: [Errno 8] Exec format error"}, "program could not start: OSError"),
    ({"path": [[0, 0, 0]]}, None),
    ({"procs_max": 8}, "program process limit: it reached its limit of 8 processes"),
    ({"stderr": "x: fork: retry: Resource temporarily unavailable", "timed_out": True}, "program process limit"),
    ({"stderr": "Traceback...\nMemoryError\n", "exit_code": 1}, "program memory limit: it ran out of its 256 MiB"),
    ({"signal": signal.SIGXCPU}, "program CPU limit: it used more than 2 s"),
    ({"signal": signal.SIGKILL, "cpu_s": 2.1}, "program CPU limit"),
    ({"signal": signal.SIGXFSZ}, "program file size limit: it wrote a file larger than 1 MiB"),
    ({"timed_out": True, "refused": ["ERR,SYNTAX,empty line"]},
     "program time limit: no path within 5 s (its last line was refused: ERR,SYNTAX,empty line)"),
    ({"refused": ["ERR,RANGE,far"], "exit_code": 2}, "program sent an invalid path: ERR,RANGE,far; it then exited with code 2"),
    ({"exit_code": 3, "stderr": "a\nlast words\n"}, "program crashed: exit code 3 (last words)"),
    ({"signal": signal.SIGSEGV}, "program crashed: killed by signal SIGSEGV"),
    ({"exit_code": 0, "connected": True}, "program sent no path: it exited without sending a T,T,P line"),
    ({"exit_code": 0}, "program sent no path: it exited without connecting to the robot port"),
    ({"memory_oom_kills": 1, "signal": signal.SIGKILL, "exit_code": None},
     "program memory limit: it used all of its 256 MiB of memory (all its processes together) and was killed"),
    ({"fork_refusals": 3, "exit_code": 1}, "program process limit: it reached its limit of 8 processes"),
])
def test_explain_names_the_reason(result, reason):
    got = explain({"path": None, **result}, LIMITS)
    assert got is None if reason is None else got.startswith(reason), got


def test_the_robot_port_answers_with_the_protocol_codec():
    port = RobotPort(robot_id="sim-1", platform="BeBot", field_size=(1.8, 1.8), start_pose=(0.3, 0.3, 0.0))
    assert port.greeting() == (format_hello("sim-1", "BeBot") + "\n").encode() and port.connected
    out, done = port.feed(b"T,T,Q\r\nT,T,S\nT,T,B\nT,T,P,300,300\nT,T,", 0.5)
    assert out.decode().splitlines() == [
        format_status(RobotState.IDLE, (0.3, 0.3, 0.0), 0.0), format_ok("S"),
        "ERR,UNSUPPORTED,this robot port only takes a path (T,T,P), a query or a stop",
        "ERR,SYNTAX,point 1: expected 3 fields, got 2"] and not done
    out, done = port.feed(b"P," + b"1" * MAX_LINE_BYTES, 0.6)  # still no newline: refused once, dropped
    assert out == f"ERR,TOOLONG,line longer than {MAX_LINE_BYTES} bytes\n".encode() and not done
    out, done = port.feed(b"1" * 10 + b"\nT,T,P,300,300,0;1500,300,90\nT,T,Q\n", 0.7)
    assert out == b"OK,P,2\n" and done  # the rest of the long line is dropped; nothing after the path
    assert port.path == [[0.3, 0.3, 0.0], [1.5, 0.3, 1.570796]] and port.path_at == 0.7
    assert len(port.refused) == 3 and port.log[-1] == [">", "OK,P,2"]
    assert port.feed(b"", 0.8) == (b"", True)  # the program hung up


HYBRID_MOUNTS = """\
31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755
35 31 0:32 / /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory
36 31 0:33 / /sys/fs/cgroup/cpu,cpuacct rw,relatime - cgroup cgroup rw,cpu,cpuacct
39 31 0:36 / /sys/fs/cgroup/pids rw,relatime - cgroup cgroup rw,pids
41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw
"""


@pytest.mark.parametrize("proc_cgroup, mountinfo, dirs", [
    # this machine: v1 memory and pids, cgroup2 with no controllers beside them
    ("8:pids:/\n4:memory:/process_api/abc\n2:cpu,cpuacct:/\n0::/\n", HYBRID_MOUNTS,
     {"memory": "/sys/fs/cgroup/memory/process_api/abc", "pids": "/sys/fs/cgroup/pids",
      "cpu": "/sys/fs/cgroup/cpu,cpuacct", "cpuacct": "/sys/fs/cgroup/cpu,cpuacct", "": "/sys/fs/cgroup/unified"}),
    # a systemd service on a cgroup v2 host
    ("0::/system.slice/twb.service\n", "30 23 0:26 / /sys/fs/cgroup rw - cgroup2 cgroup2 rw,nsdelegate\n",
     {"": "/sys/fs/cgroup/system.slice/twb.service"}),
    # a container with its own cgroup namespace, and a mount point with a space in its name
    ("0::/\n", "5 1 0:26 / /sys/fs/cgroup ro - cgroup2 cgroup2 rw\n6 1 0:26 / /mnt/a\\040b rw - cgroup2 c rw\n",
     {"": "/sys/fs/cgroup"}),
    # only a subtree mounted, the process's cgroup outside it: not visible
    ("0::/user.slice\n", "30 23 0:26 /system.slice /sys/fs/cgroup rw - cgroup2 cgroup2 rw\n", {}),
    ("0::/system.slice/x\n", "30 23 0:26 /system.slice /cg rw - cgroup2 cgroup2 rw\n", {"": "/cg/x"}),
])
def test_cgroup_directories_come_from_proc(proc_cgroup, mountinfo, dirs):
    assert cgroups.cgroup_dirs(proc_cgroup, mountinfo) == dirs


async def test_sandbox_uids_are_locked_off_the_event_loop_and_freed_when_cancelled(monkeypatch):
    base = 3_990_000 + random.randrange(0, 900) * 10
    threads = []
    take = service.take_uid

    def take_uid(b: int) -> tuple[int, int]:
        threads.append(threading.get_ident())
        time.sleep(0.2)  # slow lock files: the event loop must not wait for them
        return take(b)

    monkeypatch.setattr(service, "take_uid", take_uid)
    (uid, lock), (uid2, lock2) = await asyncio.gather(service._take_uid_off_loop(base),
                                                      service._take_uid_off_loop(base))
    assert sorted([uid, uid2]) == [base, base + 1] and len(threads) == 2
    assert threading.get_ident() not in threads  # the lock files were handled in threads, not on the loop
    os.close(lock)
    os.close(lock2)
    task = asyncio.create_task(service._take_uid_off_loop(base))
    await asyncio.sleep(0.05)  # the thread has started and takes the lock after its caller is gone
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    deadline = time.monotonic() + 10
    while True:  # the cancelled caller's lock is freed once its thread is done
        uid, lock = take(base)
        os.close(lock)
        if uid == base:
            break
        assert time.monotonic() < deadline, "the lock taken for a cancelled caller was never freed"
        await asyncio.sleep(0.05)


async def test_the_server_decides_auto_once_by_its_probe(monkeypatch, tmp_path):
    """Where the probe found bwrap's namespaces, every program must have them (a failure to set its sandbox
    up is the testbed's error, never an unisolated run); where it found none, programs run without, saying why."""
    from server.core.settings import Settings
    from server.sandbox import ProgramSpec

    box = service.Sandbox(Settings(data_dir=tmp_path, sandbox_uid_base=3_980_000 + random.randrange(0, 900) * 10))
    jobs, results = [], []

    async def fake_launch(spec: dict, timeout_s: float):
        jobs.append(spec)
        return results.pop(0), ""

    monkeypatch.setattr(box, "_launch", fake_launch)
    program = ProgramSpec(1, "p", "python", None, [], b"print(1)")
    kw = dict(env_data={"size": [1.8, 1.8], "blocks": []}, start=[0.3, 0.3, 0.0], goal=[1.5, 0.3],
              field_size=(1.8, 1.8), seed=1, robot_radius=0.045, planning_margin=0.02, robot_id="sim-1",
              platform="BeBot")
    box._probe = {"namespaces": NAMESPACES, "note": ""}
    results.append({"exit_code": 0, "path": None, "stdout": "", "stderr": ""})
    await box.run(program, **kw)
    assert jobs[-1]["namespaces"] == "required"
    results.append({"sandbox_error": True, "launch_error": "the sandbox needs Linux namespaces and cannot create "
                                                          "them: the robot ports: no"})
    with pytest.raises(RuntimeError, match="the sandbox could not be set up: the sandbox needs"):
        await box.run(program, **kw)
    box._probe = {"namespaces": [], "note": "no namespaces available (bubblewrap (bwrap) is not installed)"}
    results.append({"exit_code": 0, "path": None, "stdout": "", "stderr": ""})
    await box.run(program, **kw)
    assert jobs[-1]["namespaces"] == "off"
    assert jobs[-1]["no_namespaces"] == "no namespaces available (bubblewrap (bwrap) is not installed)"


# --------------------------------------------------------------------------- as root


@needs_root
def test_root_with_namespaces_hides_the_data_dir_and_refuses_long_lines(sandbox_isolation, data_dir):
    shared = data_dir.with_name(data_dir.name + "-shared")  # writable for everybody, outside /tmp
    shared.mkdir(mode=0o1777)
    shared.chmod(0o1777)
    write = f"""
import ctypes
libc = ctypes.CDLL(None, use_errno=True)
print("unshare", libc.unshare(0x10000000), ctypes.get_errno())  # a user namespace: seccomp says EPERM
for d in [{str(shared)!r}, "/tmp"]:
    try:
        open(d + "/planted", "w").write("x")
        print("wrote", d)
    except OSError as exc:
        print("cannot write", d, exc.strerror)
"""
    try:
        r = launch(job(read_attempt(data_dir) + write + SEND_PATH, data_dir=data_dir))
        assert not (shared / "planted").exists()
    finally:
        shutil.rmtree(shared)
    iso = r["isolation"]
    assert iso["namespaces"][:6] == NAMESPACES and iso["uid"] == 3_950_000 and iso["sandbox"] == "bubblewrap"
    assert iso["hidden"] == [str(data_dir)] and iso["proc"] == "private"
    assert "READ" not in r["stdout"] and "refused Permission denied" in r["stdout"]
    assert f"cannot write {shared} Read-only file system" in r["stdout"] and "wrote /tmp" in r["stdout"]
    assert iso["seccomp"] is True and "unshare -1 1" in r["stdout"]
    assert r["refused"] == [f"ERR,TOOLONG,line longer than {MAX_LINE_BYTES} bytes"]
    assert r["path"] == [[0.3, 0.3, 0.0], [1.5, 0.3, 1.570796]]
    assert f"ERR,TOOLONG,line longer than {MAX_LINE_BYTES} bytes OK,P,2" in r["stdout"]


def syscall_numbers(*names: str) -> dict[str, int]:
    """This machine's numbers of system calls (libseccomp's table)."""
    import pyseccomp

    return {n: pyseccomp.resolve_syscall(pyseccomp.Arch.NATIVE, n) for n in names}


ESCAPES = """
import ctypes, errno, os, socket
libc = ctypes.CDLL(None, use_errno=True)
libc.syscall.restype = ctypes.c_long
NR = {nr}
def call(name, *args, nr=None):
    rc = libc.syscall(ctypes.c_long(NR[name] if nr is None else nr), *[ctypes.c_long(a) for a in args])
    e = ctypes.get_errno()
    if rc >= 0 and name in ("clone",) and rc == 0:
        os._exit(0)  # a child that got through: gone at once
    return "ok" if rc >= 0 else errno.errorcode.get(e, str(e))
out = {{}}
out["clone newuser"] = call("clone", 0x10000000 | 17, 0, 0, 0, 0)
out["clone newnet"] = call("clone", 0x40000000 | 17, 0, 0, 0, 0)
out["clone3"] = call("clone3", 0, 0)
for name in ("unshare", "setns", "mount", "umount2", "ptrace", "keyctl", "bpf", "perf_event_open", "userfaultfd",
             "io_uring_setup", "init_module", "kexec_load", "open_by_handle_at", "process_vm_readv", "chroot",
             "sethostname", "settimeofday", "reboot", "swapon", "acct"):
    out[name] = call(name, 0, 0, 0, 0, 0)
out["a call unknown to the filter"] = call("x", 0, nr=1000)
out["x32 getpid"] = call("x", nr=0x40000000 | NR["getpid"]) if NR["getpid"] < 1024 and os.uname().machine == "x86_64" else "ENOSYS"
out["personality query"] = call("personality", 0xFFFFFFFF)
out["personality no-aslr"] = call("personality", 0x0040000)
for fam, proto, name in ((socket.AF_PACKET, 0, "packet"), (socket.AF_NETLINK, 9, "netlink audit"),
                         (socket.AF_NETLINK, 0, "netlink route"), (socket.AF_INET6, 0, "inet6"), (40, 0, "vsock")):
    try:
        socket.socket(fam, socket.SOCK_RAW if fam != socket.AF_INET6 else socket.SOCK_STREAM, proto).close()
        out["socket " + name] = "ok"
    except OSError as exc:
        out["socket " + name] = errno.errorcode.get(exc.errno, str(exc.errno))
try:
    socket.socketpair(socket.AF_INET, socket.SOCK_STREAM)
    out["socketpair inet"] = "ok"
except OSError as exc:
    out["socketpair inet"] = errno.errorcode.get(exc.errno, str(exc.errno))
out["processes"] = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
out["run"] = sorted(os.listdir("/run"))
out["hostname"] = socket.gethostname()
out["caps"] = open("/proc/self/status").read().split("CapEff:")[1].split()[0]
out["/tmp"] = os.listdir("/tmp")
wrote = 0
try:
    for k in range(40):
        with open(f"/tmp/fill{{k}}", "wb") as f:
            f.write(b"x" * (1 << 20))
            f.flush()
            os.fsync(f.fileno())
        wrote += 1
    out["tmp full"] = "never"
except OSError as exc:
    out["tmp full"] = errno.errorcode.get(exc.errno, str(exc.errno)) + f" after {{wrote}} MiB"
import json
print(json.dumps(out))
"""


@needs_root
def test_the_sandbox_refuses_what_its_allowlist_does_not_allow(sandbox_isolation, data_dir):
    """The escapes the seccomp allowlist, bubblewrap's namespaces and its tmpfs stop; what a program needs works."""
    nr = syscall_numbers("clone", "clone3", "unshare", "setns", "mount", "umount2", "ptrace", "keyctl", "bpf",
                         "perf_event_open", "userfaultfd", "io_uring_setup", "init_module", "kexec_load",
                         "open_by_handle_at", "process_vm_readv", "chroot", "sethostname", "settimeofday", "reboot",
                         "swapon", "acct", "getpid", "personality")
    r = launch(job(ESCAPES.format(nr=nr), data_dir=data_dir))
    assert r["exit_code"] == 0, r
    out = json.loads(r["stdout"])
    denied = ["clone newuser", "clone newnet", "unshare", "setns", "mount", "umount2", "ptrace", "keyctl", "bpf",
              "perf_event_open", "userfaultfd", "io_uring_setup", "init_module", "kexec_load", "open_by_handle_at",
              "process_vm_readv", "chroot", "sethostname", "settimeofday", "reboot", "swapon", "acct"]
    assert {k: out[k] for k in denied} == {k: "EPERM" for k in denied}
    not_there = ["clone3", "a call unknown to the filter", "x32 getpid", "personality no-aslr", "socket packet",
                 "socket netlink audit", "socket vsock", "socketpair inet"]
    assert {k: out[k] for k in not_there} == {k: "ENOSYS" for k in not_there}
    assert out["personality query"] == "ok" and out["socket netlink route"] == "ok" and out["socket inet6"] == "ok"
    assert out["processes"] == [1, 2] and out["run"] == [] and out["hostname"] == "twb-sandbox"
    assert out["caps"] == "0000000000000000" and out["/tmp"] == ["twb-program"]
    assert out["tmp full"] in (f"ENOSPC after {k} MiB" for k in (14, 15))  # a 16 MiB tmpfs holds the program too
    assert r["isolation"]["seccomp"] is True


@needs_root
def test_without_bubblewrap_auto_falls_back_and_required_refuses(data_dir):
    """bwrap missing: the program runs without namespaces (its own uid, the seccomp filter loaded by the
    launcher), or, with namespaces required, not at all."""
    program = """
import ctypes
libc = ctypes.CDLL(None, use_errno=True)
print("unshare", libc.unshare(0x10000000), ctypes.get_errno())
"""
    spec = {**job(program, data_dir=data_dir, uid=3_950_005), "bwrap": "/nonexistent/bwrap"}
    r = launch(spec)
    iso = r["isolation"]
    assert iso["namespaces"] == [] and iso["uid"] == 3_950_005 and iso["sandbox"] is None
    assert iso["reason"] == "no namespaces available (bubblewrap (bwrap) is not installed)"
    assert iso["seccomp"] is True and r["stdout"] == "unshare -1 1\n"
    r = launch({**spec, "namespaces": "required"})
    assert explain(r, LIMITS) == ("program could not start: the sandbox needs Linux namespaces and cannot create "
                                  "them: bubblewrap (bwrap) is not installed")


@needs_root
def test_a_sandbox_bwrap_cannot_make_is_reported_in_its_words(data_dir):
    """A machine that refuses user namespaces (bwrap says so and exits): auto falls back, required refuses."""
    where = Path(tempfile.mkdtemp(prefix="twb-fake-bwrap-"))
    try:
        where.chmod(0o755)  # the program's uid runs it
        fake = where / "bwrap"
        fake.write_text("#!/bin/sh\necho 'bwrap: No permissions to creating new namespace, likely because the "
                        "kernel does not allow non-privileged user namespaces.' >&2\nexit 1\n")
        fake.chmod(0o755)
        spec = {**job("print('ran')", data_dir=data_dir), "bwrap": str(fake)}
        r = launch(spec)
        assert r["isolation"]["namespaces"] == [] and r["stdout"] == "ran\n"
        assert r["isolation"]["reason"].startswith("no namespaces available (No permissions to creating new namespace")
        r = launch({**spec, "namespaces": "required"})
        assert r["launch_error"].startswith("the sandbox needs Linux namespaces and cannot create them: No permissions")
    finally:
        shutil.rmtree(where)


@needs_root
def test_exit_codes_signals_and_files_that_cannot_run(sandbox_isolation, data_dir):
    """bwrap passes the program's exit code, and a signal as 128 + its number; a file the kernel cannot execute
    is the program's failure to start, not the sandbox's."""
    r = launch(job("import sys\nsys.exit(3)", data_dir=data_dir))
    assert (r["exit_code"], r["signal"], r["launch_error"]) == (3, None, None)
    r = launch(job("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)", data_dir=data_dir))
    assert (r["exit_code"], r["signal"]) == (None, signal.SIGSEGV)
    assert explain(r, LIMITS).startswith("program crashed: killed by signal SIGSEGV")
    spec = job("", data_dir=data_dir)
    spec["argv"] = ["{workdir}/program"]
    for content, error in ((b"\x7fELF not really", "Exec format error"), (b"echo no #! line", "Exec format error"),
                           (b"#!/nonexistent/interpreter\n", "No such file or directory")):
        spec["files"]["program"] = {"base64": base64.b64encode(content).decode(), "mode": 0o555}
        r = launch(spec)
        assert r["stdout"] == r["stderr"] == "", r
        assert explain(r, LIMITS).startswith("program could not start: ") and error in r["launch_error"], r


@needs_root
def test_root_without_namespaces_still_protects_files_by_uid_and_kills_escapees(data_dir):
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]
    program = read_attempt(data_dir) + f"""
import os, socket, subprocess
socket.create_connection(("127.0.0.1", {port}), timeout=2).close()
print("host network reachable")
subprocess.Popen(["sleep", "300"], start_new_session=True)
print("uid", os.getuid(), "groups", os.getgroups())
"""
    try:
        r = launch(job(program, data_dir=data_dir, namespaces="off", uid=3_950_001))
    finally:
        listener.close()
    assert r["isolation"]["namespaces"] == [] and r["exit_code"] == 0, r
    out = r["stdout"]
    assert "refused Permission denied" in out and "READ" not in out  # other uid, data dir 0700
    assert "host network reachable" in out  # documented: no network isolation without namespaces
    assert "uid 3950001 groups []" in out
    assert processes_of(3_950_001) == []  # the session-escaped sleeper was killed by uid


@needs_root
@pytest.mark.skipif(shutil.which("setpriv") is None, reason="needs setpriv")
def test_without_namespaces_required_refuses_and_auto_falls_back(data_dir):
    """Root without capabilities (a container without CAP_SYS_ADMIN): it cannot switch to a uid of its own, and
    bwrap, running as root, may not map root into a user namespace (that needs CAP_SETFCAP): no namespaces."""
    no_caps = ["setpriv", "--inh-caps=-all", "--bounding-set=-all"]
    r = launch(job("print('ran')", data_dir=data_dir, namespaces="required"), no_caps)
    assert r["launch_error"].startswith("the sandbox needs Linux namespaces and cannot create them")
    assert explain(r, LIMITS).startswith("program could not start: the sandbox needs Linux namespaces")
    r = launch(job("print('ran')", data_dir=data_dir), no_caps)
    assert r["isolation"]["namespaces"] == [] and r["isolation"]["uid"] is None and r["stdout"] == "ran\n"
    assert r["isolation"]["reason"] == "no namespaces available (setting up uid map: Operation not permitted)"


# --------------------------------------------------------------------------- the memory limit is per program

SEND_GOOD_PATH = """
import os, socket
with socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"]))) as s:
    f = s.makefile("rwb")
    f.readline()
    f.write(b"T,T,P,300,300,0;1500,300,90\\n")
    f.flush()
    print(f.readline().decode().strip())
"""


def children_touching(mib: int, n: int = 4) -> str:
    """A program whose ``n`` children each fill ``mib`` MiB and hold it until all have; a path if they all could."""
    child = f"import sys; x = b'x' * ({mib} << 20); print('ready', flush=True); sys.stdin.read()"
    return f"""
import subprocess, sys
kids = [subprocess.Popen([sys.executable, "-c", {child!r}], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        for _ in range({n})]
ready = [k.stdout.readline() == b"ready\\n" for k in kids]
for k in kids:
    k.stdin.close()
codes = [k.wait() for k in kids]
print("ready", ready, "codes", codes, flush=True)
if not all(ready) or any(codes):
    sys.exit(1)
""" + SEND_GOOD_PATH


def program_cgroup_parents() -> list[str]:
    """Where launchers started by this process make program cgroups (in each hierarchy)."""
    try:
        dirs = cgroups.own_dirs()
    except cgroups.Unavailable:
        return []
    return [os.path.dirname(d) if os.path.basename(d) == cgroups.LEAF else d for d in dirs.values()]


def cgroups_left(name: str) -> list[str]:
    """Directories of the program cgroup ``name`` still there."""
    return [os.path.join(d, name) for d in program_cgroup_parents() if os.path.exists(os.path.join(d, name))]


MEMORY_LIMITS = {**LIMITS, "memory_bytes": 512 << 20, "wall_s": 30, "cpu_s": 10}


@pytest.fixture(scope="module")
def program_cgroups():
    """Skip unless programs get a cgroup here (as root on this machine they do: cgroup v1 memory and pids)."""
    if not is_root or PYTHON is None:
        pytest.skip("needs root and a system python3")
    probe = launch({"probe": True, "namespaces": "auto"})
    if probe["memory_limit"] != "cgroup":
        pytest.skip(f"no cgroup for programs on this machine: {probe['memory_note']}")
    return probe


@pytest.mark.parametrize("namespaces", ["auto", "off"])
def test_the_memory_limit_holds_for_all_processes_of_a_program_together(program_cgroups, data_dir, namespaces):
    """4 children x 200 MiB under 512 MiB: each is under the limit, the program is not; the kernel kills it."""
    r = launch(job(children_touching(200), data_dir=data_dir, namespaces=namespaces, limits=MEMORY_LIMITS))
    iso = r["isolation"]
    assert iso["memory_limit"] == "cgroup" and iso["cgroup"] == program_cgroups["cgroup"]
    assert r["path"] is None and r["memory_oom_kills"] >= 1, r
    assert explain(r, MEMORY_LIMITS) == ("program memory limit: it used all of its 512 MiB of memory "
                                         "(all its processes together) and was killed")
    assert r["memory_peak_kib"] <= 512 << 10
    assert cgroups_left(iso["cgroup_name"]) == []
    assert processes_of(3_950_000) == []


def test_a_program_under_the_memory_limit_completes(program_cgroups, data_dir):
    r = launch(job(children_touching(60), data_dir=data_dir, limits=MEMORY_LIMITS))
    assert r["isolation"]["memory_limit"] == "cgroup" and r["memory_oom_kills"] == 0, r
    assert "codes [0, 0, 0, 0]" in r["stdout"] and r["path"] == [[0.3, 0.3, 0.0], [1.5, 0.3, 1.570796]]
    assert 4 * 60 << 10 <= r["memory_peak_kib"] < 512 << 10
    assert explain(r, MEMORY_LIMITS) is None and cgroups_left(r["isolation"]["cgroup_name"]) == []


def test_cgroups_left_by_killed_launchers_are_removed(program_cgroups, data_dir):
    gone = subprocess.Popen(["true"])
    gone.wait()
    name = f"{cgroups.PREFIX}{gone.pid}-left"
    dirs = cgroups.own_dirs()
    keys = ["memory", "pids"] if program_cgroups["cgroup"] == "v1" else [""]
    for d in {os.path.dirname(dirs[k]) if os.path.basename(dirs[k]) == cgroups.LEAF else dirs[k]
              for k in keys if k in dirs}:
        os.mkdir(os.path.join(d, name))
    assert cgroups_left(name)
    r = launch(job("print('ran')", data_dir=data_dir))
    assert r["stdout"] == "ran\n" and cgroups_left(name) == []


@needs_root
def test_without_cgroups_the_memory_limit_is_per_process(data_dir):
    """The documented fallback: RLIMIT_AS bounds each process, so 4 x 200 MiB pass a 512 MiB limit."""
    r = launch({**job(children_touching(200), data_dir=data_dir, limits=MEMORY_LIMITS), "cgroups": "off"})
    assert r["isolation"]["memory_limit"] == "per-process" and r["isolation"]["cgroup"] is None
    assert r["memory_oom_kills"] is None and r["path"] is not None, r
    r = launch({**job("x = b'x' * (600 << 20)", data_dir=data_dir, limits=MEMORY_LIMITS), "cgroups": "off"})
    assert explain(r, MEMORY_LIMITS) == "program memory limit: it ran out of its 512 MiB of memory"


# --------------------------------------------------------------------------- the launcher ends with its server

#: starts the launcher from a thread that ends at once, prints its pid, then prints its result or sleeps
INTERMEDIATE = """
import subprocess, sys, threading, time
job = sys.stdin.buffer.read()
started = []
def start():
    p = subprocess.Popen([sys.executable, "-m", "server.sandbox.launch"], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE)
    p.stdin.write(job)
    p.stdin.close()
    started.append(p)
thread = threading.Thread(target=start)
thread.start()
thread.join()  # the launcher's parent thread is gone, its parent process is not
print(started[0].pid, flush=True)
if sys.argv[1] == "result":
    print(started[0].stdout.read().decode().strip(), flush=True)
else:
    time.sleep(600)
"""


def intermediate(spec: dict, mode: str) -> tuple[subprocess.Popen, int]:
    """An intermediate process (the server's stand-in) running the launcher; (it, the launcher's pid)."""
    p = subprocess.Popen([sys.executable, "-c", INTERMEDIATE, mode], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         cwd=ROOT, env=launcher_env())
    p.stdin.write(json.dumps(spec).encode())
    p.stdin.close()
    return p, int(p.stdout.readline())


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in "ZX"
    except OSError:
        return False


def wait_until(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


@needs_root
@pytest.mark.parametrize("namespaces, uid", [("auto", 3_950_003), ("off", 3_950_004)])
def test_the_launcher_and_its_program_end_when_the_server_is_killed(data_dir, namespaces, uid):
    spec = job("import time\ntime.sleep(600)", data_dir=data_dir, namespaces=namespaces, uid=uid,
               limits={**LIMITS, "wall_s": 300, "cpu_s": 60})
    server, launcher = intermediate(spec, "sleep")
    try:
        wait_until(lambda: processes_of(uid), 30, "the program never started")
    finally:
        server.kill()
        server.wait()
    wait_until(lambda: not alive(launcher) and not processes_of(uid), 20,
               f"launcher alive: {alive(launcher)}; program: {processes_of(uid)}")
    wait_until(lambda: not any(e.startswith(f"{cgroups.PREFIX}{launcher}-") for d in program_cgroup_parents()
                               for e in os.listdir(d)), 10, "the program's cgroup was not removed")


@needs_root
def test_the_launcher_outlives_the_server_thread_that_started_it(data_dir):
    """The parent-death signal also comes when that thread ends; the launcher checks its parent and goes on."""
    program = "import time\ntime.sleep(1.5)\n" + SEND_GOOD_PATH
    server, _ = intermediate(job(program, data_dir=data_dir), "result")
    r = json.loads(server.stdout.read().decode().splitlines()[-1])
    assert server.wait() == 0
    assert r["launch_error"] is None and r["path"] == [[0.3, 0.3, 0.0], [1.5, 0.3, 1.570796]], r


# --------------------------------------------------------------------------- an unprivileged server (simulated)


def _as_user_prefix(uid: int) -> list[str] | None:
    """A command prefix running as ``uid`` with no capabilities, where this Python is still reachable."""
    if not is_root or not (shutil.which("unshare") and shutil.which("setpriv")):
        return None
    needed = {os.path.realpath(sys.executable), os.path.realpath(sys.prefix), os.path.realpath(sys.base_prefix),
              str(ROOT)}
    blocked: dict[str, set[str]] = {}  # directory others cannot enter -> its children we need
    for path in needed:
        parts = Path(path).parts
        for i in range(1, len(parts)):
            d = Path(*parts[:i])
            if not os.stat(d).st_mode & stat.S_IXOTH:
                blocked.setdefault(str(d), set()).add(parts[i])
                break
    script, stage = ["set -e"], tempfile.mkdtemp(prefix="twb-asuser-")
    for k, (d, children) in enumerate(blocked.items()):
        for j, child in enumerate(sorted(children)):
            script += [f"mkdir -p {stage}/{k}-{j}", f"mount --bind '{d}/{child}' {stage}/{k}-{j}"]
        script.append(f"mount -t tmpfs -o mode=755 tmpfs '{d}'")
        for j, child in enumerate(sorted(children)):
            script += [f"mkdir -p '{d}/{child}'", f"mount --bind {stage}/{k}-{j} '{d}/{child}'"]
    script.append(f'exec setpriv --reuid {uid} --regid {uid} --clear-groups --inh-caps=-all --bounding-set=-all "$@"')
    prefix = ["unshare", "--mount", "sh", "-c", "\n".join(script), "sh"]
    ok = subprocess.run([*prefix, sys.executable, "-c", "import numpy, server.sandbox.launch"], capture_output=True)
    return prefix if ok.returncode == 0 else None


@pytest.fixture(scope="module")
def as_nobody():
    prefix = _as_user_prefix(NOBODY)
    if prefix is None:
        pytest.skip("cannot run this Python as an unprivileged user here")
    probe = launch({"probe": True, "namespaces": "auto"}, prefix)
    if not probe["user_namespace"]:
        pytest.skip(f"no unprivileged user namespaces: {probe['reason']}")
    return prefix


@pytest.fixture
def own_data_dir(data_dir):
    """The data dir of a server running as nobody: its own files, readable by its own uid."""
    for p in (data_dir, data_dir / "twb.db"):
        os.chown(p, NOBODY, NOBODY)
    return data_dir


def test_unprivileged_server_isolates_with_a_user_namespace(as_nobody, own_data_dir):
    program = read_attempt(own_data_dir) + """
import ctypes, os, socket
print("caps", open("/proc/self/status").read().split("CapEff:")[1].split()[0])
libc = ctypes.CDLL(None, use_errno=True)
print("umount", libc.umount2(os.path.dirname(os.environ["TWB_ENV_FILE"]).encode(), 2), ctypes.get_errno())
for addr in [("1.1.1.1", 53), ("127.0.0.1", 22)]:
    try:
        socket.create_connection(addr, timeout=2)
        print("CONNECTED", addr)
    except OSError as exc:
        print("no network", exc.errno)
print("processes", sorted(int(p) for p in os.listdir("/proc") if p.isdigit()))
""" + SEND_PATH
    r = launch(job(program, data_dir=own_data_dir), as_nobody)
    iso = r["isolation"]
    assert iso["user_namespace"] is True and iso["uid"] is None and iso["hidden"] == [str(own_data_dir)]
    out = r["stdout"]
    assert "READ" not in out and "refused Permission denied" in out  # readable by the uid, but hidden
    assert "caps 0000000000000000" in out and "umount -1 1" in out  # cannot undo the mounts (EPERM)
    assert "CONNECTED" not in out and out.count("no network") == 2
    assert "processes [1, 2]" in out  # only the launcher (pid 1) and the program
    assert r["path"] == [[0.3, 0.3, 0.0], [1.5, 0.3, 1.570796]]


def test_unprivileged_server_bounds_a_fork_bomb(as_nobody, data_dir):
    bomb = job(":(){ :|:& };:\n:\nsleep 600", data_dir=data_dir, interpreter="/bin/bash",
               limits={**LIMITS, "wall_s": 3})
    r = launch(bomb, as_nobody)
    assert r["timed_out"] and 1 < r["procs_max"] <= LIMITS["processes"]
    assert explain(r, LIMITS).startswith("program process limit")
    assert processes_of(NOBODY) == []


def test_unprivileged_server_without_namespaces_cannot_protect_its_files(as_nobody, own_data_dir):
    """The documented weakness: the program runs as the server's uid and reads what it can read."""
    r = launch(job(read_attempt(own_data_dir), data_dir=own_data_dir, namespaces="off"), as_nobody)
    assert r["isolation"]["namespaces"] == [] and r["isolation"]["uid"] is None
    assert "READ SECRET DATABASE" in r["stdout"]
