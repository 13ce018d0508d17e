"""Running uploaded planner programs in the sandbox, from the server's event loop.

:class:`Sandbox` starts :mod:`server.sandbox_launch` (as an asyncio
subprocess: the event loop never blocks) with a JSON job, reads its result
and turns it into a :class:`ProgramOutcome`: the planned path, or the reason
the program gave none (:func:`explain`), plus the lines for the run's log.
At most ``sandbox_workers`` programs run at once; as root each running
program has a uid/gid of its own (from ``sandbox_uid_base`` up, locked
machine-wide), so the process limit counts only its own processes and
programs cannot signal or read each other.

What is enforced where is in docs/uploads.md.
"""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import os
import signal
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

from .core.settings import Settings

__all__ = ["ProgramOutcome", "ProgramSpec", "Sandbox", "explain", "launcher_env", "program_argv"]

log = logging.getLogger("twb.sandbox")

#: file names of the program in its working directory
PROGRAM_FILE = {"python": "program.py", "executable": "program"}
ENV_FILE = "environment.json"


@dataclass(frozen=True)
class ProgramSpec:
    """An uploaded program, as stored."""

    id: int
    name: str
    kind: str  # "python" | "executable"
    interpreter: Optional[str]
    args: list[str]
    content: bytes


@dataclass
class ProgramOutcome:
    """What one execution gave: a path (m, m, rad) or the reason there is none."""

    path: Optional[list[list[float]]]
    reason: Optional[str]
    #: (direction, line) for the run's log: ``o`` stdout, ``e`` stderr, ``s`` sandbox and robot port
    log: list[tuple[str, str]] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    planning_time_s: Optional[float] = None


def launcher_env() -> dict[str, str]:
    """The launcher's environment: a few of ours, and one thread for numpy's BLAS/OpenMP.

    One thread matters: the launcher imports the codec (numpy) before it
    unshares namespaces and forks, which must happen single-threaded.
    """
    env = {k: v for k, v in os.environ.items() if k in ("PATH", "PYTHONPATH", "LANG", "VIRTUAL_ENV")}
    env.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                "PYTHONDONTWRITEBYTECODE": "1"})
    return env


def program_argv(spec: ProgramSpec, interpreters: dict[str, str]) -> list[str]:
    """The command line (the launcher replaces ``{workdir}``, ``{robot_port}``, ...); ValueError if it cannot run."""
    path = "{workdir}/" + PROGRAM_FILE[spec.kind]
    interp = "python3" if spec.kind == "python" else spec.interpreter
    if interp is None:
        return [path, *spec.args]
    if interp not in interpreters:
        raise ValueError(f"interpreter {interp!r} is not available on this testbed "
                         f"(available: {', '.join(sorted(interpreters)) or 'none'})")
    return [interpreters[interp], path, *spec.args]


def _num(v: float) -> str:
    return f"{v:.9g}"


class Sandbox:
    """Runs programs; one per testbed (``testbed.sandbox``)."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self._running: Optional[asyncio.Semaphore] = None
        self._probe: Optional[dict[str, Any]] = None

    def _take_uid(self) -> tuple[int, int]:
        """A sandbox uid no other program on this machine uses now: (uid, fd of its lock; close to free).

        Locks (``flock``) live in a directory only this user may write, so
        several testbeds on one machine never share a uid (they would share a
        process limit, and the end of one sandbox would kill the other's).
        """
        import fcntl
        import tempfile

        locks = Path(tempfile.gettempdir()) / f"twb-sandbox-uids-{os.geteuid()}"
        locks.mkdir(mode=0o700, exist_ok=True)
        if locks.stat().st_uid != os.geteuid() or locks.stat().st_mode & 0o077:
            raise RuntimeError(f"{locks} must be a directory of uid {os.geteuid()} with mode 0700")
        base = self.settings.sandbox_uid_base
        for uid in range(base, base + 4096):
            fd = os.open(locks / f"{uid}.lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return uid, fd
            except BlockingIOError:
                os.close(fd)
        raise RuntimeError(f"no free sandbox uid in {base}..{base + 4095}")

    @property
    def limits(self) -> dict[str, Any]:
        """The limits in the units users read (docs, ``GET /api/v1/programs/sandbox``)."""
        s = self.settings
        return {"wall_s": s.sandbox_wall_s, "cpu_s": s.sandbox_cpu_s, "memory_mb": s.sandbox_memory_mb,
                "file_mb": s.sandbox_file_mb, "processes": s.sandbox_processes, "open_files": s.sandbox_open_files,
                "output_kib": s.sandbox_output_kib, "tmp_mb": s.sandbox_tmpfs_mb,
                "max_program_bytes": s.max_program_bytes, "concurrent_programs": s.sandbox_workers}

    def _job_limits(self) -> dict[str, Any]:
        s = self.settings
        return {"wall_s": s.sandbox_wall_s, "cpu_s": s.sandbox_cpu_s, "memory_bytes": s.sandbox_memory_mb << 20,
                "file_bytes": s.sandbox_file_mb << 20, "processes": s.sandbox_processes,
                "open_files": s.sandbox_open_files, "output_bytes": s.sandbox_output_kib << 10,
                "tmpfs_bytes": s.sandbox_tmpfs_mb << 20}

    def hidden_paths(self) -> list[str]:
        """Paths the program must not see: the data dir and the SQLite database's directory."""
        s = self.settings
        paths = [str(s.data_dir.resolve())]
        if s.database_url.startswith("sqlite:///"):
            db_dir = str(Path(s.database_url[len("sqlite:///"):]).resolve().parent)
            if db_dir not in paths:
                paths.append(db_dir)
        return paths

    async def _launch(self, job: dict[str, Any], timeout_s: float) -> tuple[Optional[dict[str, Any]], str]:
        """Run the launcher with ``job``; (result or None, its stderr)."""
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "server.sandbox_launch", stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=launcher_env(),
            start_new_session=True)
        try:
            out, err = await asyncio.wait_for(proc.communicate(json.dumps(job).encode()), timeout_s)
        except BaseException:
            # cancelled (the experiment, the server) or the launcher hangs: end the sandbox
            await _stop(proc)
            raise
        result = None
        for line in out.decode("utf-8", "replace").splitlines():
            try:
                result = json.loads(line)
            except ValueError:
                continue
        return result, err.decode("utf-8", "replace")

    async def probe(self) -> dict[str, Any]:
        """What isolation this machine gives programs (cached)."""
        if self._probe is None:
            result, err = await self._launch({"probe": True, "namespaces": self.settings.sandbox_namespaces}, 30)
            iso = result or {"namespaces": [], "user_namespace": False, "uid_switch": False,
                             "reason": f"the sandbox launcher failed: {err.strip()[-300:]}"}
            self._probe = {
                "namespaces": iso.get("namespaces", []),
                "user_namespace": iso.get("user_namespace", False),
                "network": "loopback only" if "net" in iso.get("namespaces", []) else "not isolated",
                "seccomp": iso.get("seccomp", False),
                "runs_as": ("a uid of its own" if iso.get("uid_switch")
                            else "root of a user namespace (the server's uid outside)" if iso.get("user_namespace")
                            else "the server's uid"),
                "note": iso.get("reason", ""),
            }
        return self._probe

    async def run(self, spec: ProgramSpec, *, env_data: dict[str, Any], start: list[float], goal: list[float],
                  field_size: tuple[float, float], seed: int, robot_radius: float, planning_margin: float,
                  robot_id: str, platform: str) -> ProgramOutcome:
        """Run ``spec`` once; never raises for the program's faults (the outcome says why)."""
        s = self.settings
        try:
            argv = program_argv(spec, s.sandbox_interpreters)
        except ValueError as exc:
            return ProgramOutcome(None, f"program could not start: {exc}")
        if self._running is None:
            self._running = asyncio.Semaphore(s.sandbox_workers)
        env = {
            "PATH": "/usr/local/bin:/usr/bin:/bin", "LANG": "C.UTF-8", "LC_ALL": "C.UTF-8",
            "PYTHONUNBUFFERED": "1", "PYTHONDONTWRITEBYTECODE": "1",
            "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
            "TWB_ENV_FILE": ENV_FILE,
            "TWB_START": ",".join(map(_num, start)), "TWB_GOAL": ",".join(map(_num, goal)),
            "TWB_SEED": str(seed), "TWB_ROBOT_RADIUS": _num(robot_radius),
            "TWB_PLANNING_MARGIN": _num(planning_margin), "TWB_FIELD_SIZE": ",".join(map(_num, field_size)),
            "TWB_ROBOT_ID": robot_id, "TWB_TIME_LIMIT_S": _num(s.sandbox_wall_s),
        }
        files = {
            PROGRAM_FILE[spec.kind]: {"base64": base64.b64encode(spec.content).decode(),
                                      "mode": 0o500 if spec.kind == "executable" and spec.interpreter is None
                                      else 0o400},
            ENV_FILE: {"base64": base64.b64encode(json.dumps(env_data).encode()).decode(), "mode": 0o400},
        }
        async with self._running:
            uid, lock = self._take_uid()
            try:
                result, err = await self._launch(self._job(files, argv, env, uid, start, field_size, robot_id,
                                                           platform), s.sandbox_wall_s + 30)
            except asyncio.TimeoutError:
                raise RuntimeError("the sandbox launcher did not finish in time") from None
            finally:
                os.close(lock)
        if result is None:
            raise RuntimeError(f"the sandbox launcher failed: {err.strip()[-500:] or 'no result'}")
        return self._outcome(spec, argv, result)

    def _job(self, files: dict[str, Any], argv: list[str], env: dict[str, str], uid: int, start: list[float],
             field_size: tuple[float, float], robot_id: str, platform: str) -> dict[str, Any]:
        s = self.settings
        return {"files": files, "argv": argv, "env": env, "uid": uid, "gid": uid, "namespaces": s.sandbox_namespaces,
                "hide": self.hidden_paths(), "limits": self._job_limits(), "field_size": list(field_size),
                "robot_id": robot_id, "platform": platform, "start_pose": list(start[:3]), "grace_s": 1.0}

    def _outcome(self, spec: ProgramSpec, argv: list[str], r: dict[str, Any]) -> ProgramOutcome:
        limits = self._job_limits()
        iso = r.get("isolation") or {}
        shown = " ".join(a.replace("{workdir}/", "") for a in argv)
        lines: list[tuple[str, str]] = [
            ("s", f"program {spec.name!r} (#{spec.id}) started: {shown}; isolation: "
                  f"{'+'.join(iso.get('namespaces') or []) or 'no namespaces'}"
                  f"{', own uid' if iso.get('uid') is not None else ''}")]
        for direction, text in r.get("port_log", []):
            lines.append(("s", f"robot port {'<' if direction == '<' else '>'} {text}"))
        for d, name in (("o", "stdout"), ("e", "stderr")):
            text = r.get(name) or ""
            for ln in text.splitlines():
                lines.append((d, ln[:10_000]))
            if r.get(f"{name}_dropped"):
                lines.append(("s", f"{name} truncated: {r[f'{name}_dropped']} more bytes were dropped "
                                   f"(the log keeps {limits['output_bytes'] >> 10} KiB)"))
        reason = explain(r, limits)
        status = ("exit code %s" % r["exit_code"] if r.get("exit_code") is not None
                  else f"signal {_signame(r['signal'])}" if r.get("signal") is not None
                  else "stopped by the sandbox")
        lines.append(("s", f"program ended ({status}) after {r.get('wall_s', 0):.2f} s, CPU {r.get('cpu_s', 0):.2f} s"
                           + (f"; {reason}" if reason else f"; path of {len(r['path'])} points received")))
        info = {
            "id": spec.id, "name": spec.name, "exit_code": r.get("exit_code"), "signal": r.get("signal"),
            "timed_out": r.get("timed_out", False), "wall_s": r.get("wall_s"), "cpu_s": r.get("cpu_s"),
            "max_rss_kib": r.get("max_rss_kib"), "processes_max": r.get("procs_max"),
            "stdout_dropped_bytes": r.get("stdout_dropped", 0), "stderr_dropped_bytes": r.get("stderr_dropped", 0),
            "isolation": {"namespaces": iso.get("namespaces", []), "user_namespace": iso.get("user_namespace", False),
                          "own_uid": iso.get("uid") is not None, "proc": iso.get("proc"),
                          "server_files_hidden": bool(iso.get("hidden")), "seccomp": iso.get("seccomp", False)},
        }
        return ProgramOutcome(r.get("path") if reason is None else None, reason, lines, info, r.get("path_at_s"))


_FORK_SIGNS = ("Resource temporarily unavailable", "BlockingIOError", "fork: retry", "Cannot fork",
               "can't fork", "fork failed")
_MEMORY_SIGNS = ("MemoryError", "Cannot allocate memory", "cannot allocate", "out of memory", "bad_alloc",
                 "Out of memory", "failed to map segment", "mmap failed")


def _signame(sig: int) -> str:
    try:
        return signal.Signals(sig).name
    except ValueError:
        return str(sig)


def explain(r: dict[str, Any], limits: dict[str, Any]) -> Optional[str]:
    """Why a finished program gave no path (``None``: it did).

    Limits first (they explain the crash or the silence that follows), then
    a refused line, a crash, and at last plain silence.  Heuristics: running
    out of processes or memory shows as failed forks / allocations in the
    program's stderr (or, for processes, as the count reaching the limit).
    """
    if r.get("launch_error"):
        return f"program could not start: {r['launch_error']}"
    if r.get("path") is not None:
        return None
    err = r.get("stderr") or ""
    sig = r.get("signal")
    refused = r.get("refused") or []
    after = f" (its last line was refused: {refused[-1]})" if refused else ""
    wall = limits["wall_s"]
    if (r.get("procs_max") or 0) >= limits["processes"] or any(x in err for x in _FORK_SIGNS):
        return f"program process limit: it reached its limit of {limits['processes']} processes"
    if any(x in err for x in _MEMORY_SIGNS):
        return f"program memory limit: it ran out of its {limits['memory_bytes'] >> 20} MiB of memory"
    if sig == signal.SIGXCPU or (sig == signal.SIGKILL and (r.get("cpu_s") or 0) >= limits["cpu_s"] - 0.5):
        return f"program CPU limit: it used more than {limits['cpu_s']} s of CPU time"
    if sig == signal.SIGXFSZ:
        return f"program file size limit: it wrote a file larger than {limits['file_bytes'] >> 20} MiB"
    if r.get("timed_out"):
        return f"program time limit: no path within {wall:g} s" + after
    if refused:
        ended = (f"; it then exited with code {r['exit_code']}" if r.get("exit_code") not in (None, 0)
                 else f"; it was then killed by {_signame(sig)}" if sig is not None else "")
        return f"program sent an invalid path: {refused[-1]}{ended}"
    if r.get("exit_code") not in (None, 0):
        return f"program crashed: exit code {r['exit_code']}" + _last_line(err)
    if sig is not None:
        return f"program crashed: killed by signal {_signame(sig)}" + _last_line(err)
    if not r.get("connected"):
        return "program sent no path: it exited without connecting to the robot port"
    return "program sent no path: it exited without sending a T,T,P line"


def _last_line(err: str) -> str:
    lines = [ln.strip() for ln in err.strip().splitlines() if ln.strip()]
    return f" ({lines[-1][:300]})" if lines else ""


async def _stop(proc: asyncio.subprocess.Process) -> None:
    """End a launcher early: SIGTERM (it kills its sandbox), then SIGKILL."""
    if proc.returncode is not None:
        return
    try:
        proc.send_signal(signal.SIGTERM)
        await asyncio.wait_for(asyncio.shield(proc.wait()), 3)
    except (asyncio.TimeoutError, ProcessLookupError, asyncio.CancelledError):
        pass
    if proc.returncode is None:
        try:
            proc.kill()
        except ProcessLookupError:
            pass
        try:
            await asyncio.wait_for(asyncio.shield(proc.wait()), 5)
        except (asyncio.TimeoutError, asyncio.CancelledError):
            log.warning("sandbox launcher %s did not stop", proc.pid)
