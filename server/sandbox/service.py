"""Running uploaded planner programs in the sandbox, from the server's event loop.

:class:`Sandbox` starts the launcher (``python -m server.sandbox.launch``,
as an asyncio subprocess: the event loop never blocks) with a JSON job,
reads its result and turns it into a :class:`~.outcome.ProgramOutcome`.
At most ``sandbox_workers`` programs run at once; as root each running
program has a uid/gid of its own (from ``sandbox_uid_base`` up, locked
machine-wide), so the process limit counts only its own processes and
programs cannot signal or read each other.

What is enforced where is in docs/uploads.md.
"""

from __future__ import annotations

import asyncio
import fcntl
import logging
import os
import signal
import sys
import tempfile
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional, Protocol

from .link import RUN_ENDED, LinkKind, encode, parse
from .outcome import ProgramOutcome, to_controller_outcome, to_outcome
from .program import ProgramSpec, program_argv, program_env, program_files

if TYPE_CHECKING:  # the launcher imports this package: keep it light
    from ..core.settings import Settings

__all__ = ["LAUNCHER", "Relay", "Sandbox", "launcher_env", "take_uid"]

log = logging.getLogger("twb.sandbox")

#: the launcher's module (``python -m``)
LAUNCHER = "server.sandbox.launch"
#: sandbox uids tried from the base up
UID_RANGE = 4096


def launcher_env() -> dict[str, str]:
    """The launcher's environment: a few of ours, and one thread for numpy's BLAS/OpenMP.

    One thread matters: the launcher imports the codec (numpy), then forks
    and runs Python between fork and exec, which must happen single-threaded.
    """
    env = {k: v for k, v in os.environ.items() if k in ("PATH", "PYTHONPATH", "LANG", "VIRTUAL_ENV")}
    env.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                "PYTHONDONTWRITEBYTECODE": "1"})
    return env


def take_uid(base: int) -> tuple[int, int]:
    """A sandbox uid from ``base`` up that no other program on this machine uses now: (uid, fd of its lock).

    Close the fd to free the uid.  Locks (``flock``) live in a directory only
    this user may write, so several testbeds on one machine never share a uid
    (they would share a process limit, and the end of one sandbox would kill
    the other's).  Blocking file work: call it in a thread.
    """
    locks = Path(tempfile.gettempdir()) / f"twb-sandbox-uids-{os.geteuid()}"
    locks.mkdir(mode=0o700, exist_ok=True)
    st = locks.stat()
    if st.st_uid != os.geteuid() or st.st_mode & 0o077:
        raise RuntimeError(f"{locks} must be a directory of uid {os.geteuid()} with mode 0700")
    for uid in range(base, base + UID_RANGE):
        fd = os.open(locks / f"{uid}.lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return uid, fd
        except BlockingIOError:
            os.close(fd)
    raise RuntimeError(f"no free sandbox uid in {base}..{base + UID_RANGE - 1}")


async def _take_uid_off_loop(base: int) -> tuple[int, int]:
    """:func:`take_uid` in a thread; if the caller is cancelled meanwhile, the lock it takes is freed."""
    task = asyncio.ensure_future(asyncio.to_thread(take_uid, base))
    try:
        return await asyncio.shield(task)
    except asyncio.CancelledError:
        task.add_done_callback(lambda t: t.cancelled() or t.exception() is not None or os.close(t.result()[1]))
        raise


class Relay(Protocol):
    """The run's side of a controller program's robot port (:meth:`Sandbox.run_controller`)."""

    async def connected(self) -> None:
        """The program connected to its robot port."""

    async def to_robot(self, line: str) -> str:
        """A valid closed-loop line of the program for the run's robot; the reply line for the program."""

    async def from_robot(self) -> Optional[str]:
        """The next unsolicited line for the program (``PO``, ``EV``), or None: the run has ended."""

    def abort(self, reason: str) -> None:
        """The program broke the relay's rules (it flooded its robot port): the run fails with ``reason``,
        the program's fault; the sandbox ends it."""


class Sandbox:
    """Runs programs; one per testbed (``testbed.sandbox``)."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self._running: Optional[asyncio.Semaphore] = None
        self._probe: Optional[dict[str, Any]] = None

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
            sys.executable, "-m", LAUNCHER, stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=launcher_env(),
            start_new_session=True)
        try:
            out, err = await asyncio.wait_for(proc.communicate(encode(LinkKind.JSON, job)), timeout_s)
        except BaseException:
            # cancelled (the experiment, the server) or the launcher hangs: end the sandbox
            await _stop(proc)
            raise
        result = None
        for line in out.splitlines():
            msg = parse(line)
            if msg is not None and msg.kind is LinkKind.JSON:
                result = msg.data
        return result, err.decode("utf-8", "replace")

    async def probe(self) -> dict[str, Any]:
        """What isolation this machine gives programs (cached): bwrap's sandbox tried as a program's user."""
        if self._probe is None:
            uid, lock = await _take_uid_off_loop(self.settings.sandbox_uid_base)
            try:
                result, err = await self._launch({"probe": True, "namespaces": self.settings.sandbox_namespaces,
                                                  "uid": uid, "gid": uid}, 30)
            finally:
                os.close(lock)
            iso = result or {"namespaces": [], "user_namespace": False, "uid_switch": False,
                             "reason": f"the sandbox launcher failed: {err.strip()[-300:]}"}
            self._probe = {
                "namespaces": iso.get("namespaces", []),
                "user_namespace": iso.get("user_namespace", False),
                "sandbox": iso.get("sandbox") or "none",
                "network": "loopback only" if "net" in iso.get("namespaces", []) else "not isolated",
                "seccomp": iso.get("seccomp", False),
                "runs_as": ("a uid of its own" if iso.get("uid_switch")
                            else "the server's uid, in a user namespace" if iso.get("user_namespace")
                            else "the server's uid"),
                "memory_limit": iso.get("memory_limit", "per-process"),
                "cgroup": iso.get("cgroup"),
                "memory_note": iso.get("memory_note", ""),
                "note": iso.get("reason", ""),
            }
        return self._probe

    async def _namespaces(self) -> dict[str, Any]:
        """The job's ``namespaces``: ``auto`` is decided once, by the probe.

        Where bwrap makes its sandbox here, every program runs in it
        (``required``: a program whose sandbox cannot be set up does not run,
        it never runs unisolated because of a passing failure); where it does
        not, programs run without (``off``, with the probe's reason).
        """
        mode = self.settings.sandbox_namespaces
        if mode != "auto":
            return {"namespaces": mode}
        iso = await self.probe()
        if "net" in iso["namespaces"]:
            return {"namespaces": "required"}
        return {"namespaces": "off", "no_namespaces": iso["note"] or "the probe found none"}

    async def run(self, spec: ProgramSpec, *, env_data: dict[str, Any], start: list[float], goal: list[float],
                  field_size: tuple[float, float], seed: int, robot_radius: float, planning_margin: float,
                  robot_id: str, platform: str) -> ProgramOutcome:
        """Run ``spec`` once (lengths in m, angles in rad); never raises for the program's faults (the outcome says why)."""
        return await self._run(spec, env_data=env_data, start=start, goal=goal, field_size=field_size, seed=seed,
                               robot_radius=robot_radius, planning_margin=planning_margin, robot_id=robot_id,
                               platform=platform)

    async def run_fleet(self, spec: ProgramSpec, *, env_data: dict[str, Any], starts: list[list[float]],
                        goals: list[list[float]], field_size: tuple[float, float], seed: int, robot_radius: float,
                        planning_margin: float, robot_id: str, platform: str) -> ProgramOutcome:
        """Run ``spec`` once for a multi-robot job: one robot port per robot (``starts``/``goals``, m, rad, robot
        0 first; ``robot_id``/k greets on port k); the outcome's ``paths`` are the paths sent on each port, or its
        ``reason`` names the robots without one.  Never raises for the program's faults."""
        return await self._run(spec, env_data=env_data, start=starts[0], goal=goals[0], field_size=field_size,
                               seed=seed, robot_radius=robot_radius, planning_margin=planning_margin,
                               robot_id=robot_id, platform=platform, fleet=list(zip(starts, goals)))

    async def run_controller(self, spec: ProgramSpec, relay: Relay, *, env_data: dict[str, Any], start: list[float],
                             goal: list[float], path: list[list[float]], field_size: tuple[float, float], seed: int,
                             robot_radius: float, planning_margin: float, robot_id: str,
                             platform: str) -> ProgramOutcome:
        """Run ``spec`` as the run's controller: its robot port relays the closed-loop verbs to ``relay``
        (the run's robot) until the program ends or ``relay.from_robot()`` says the run has; ``path``
        (m, m, rad) is the planned path it follows.  The outcome's ``reason`` is set only when the
        program could not start, hit a limit or crashed (:func:`~.outcome.explain_controller`)."""
        return await self._run(spec, env_data=env_data, start=start, goal=goal, field_size=field_size, seed=seed,
                               robot_radius=robot_radius, planning_margin=planning_margin, robot_id=robot_id,
                               platform=platform, path=path, relay=relay)

    async def _run(self, spec: ProgramSpec, *, env_data: dict[str, Any], start: list[float], goal: list[float],
                   field_size: tuple[float, float], seed: int, robot_radius: float, planning_margin: float,
                   robot_id: str, platform: str, path: Optional[list[list[float]]] = None,
                   relay: Optional[Relay] = None,
                   fleet: Optional[list[tuple[list[float], list[float]]]] = None) -> ProgramOutcome:
        s = self.settings
        try:
            argv = program_argv(spec, s.sandbox_interpreters)
        except ValueError as exc:
            return ProgramOutcome(None, f"program could not start: {exc}")
        if self._running is None:
            self._running = asyncio.Semaphore(s.sandbox_workers)
        env = program_env(start=start, goal=goal, field_size=field_size, seed=seed, robot_radius=robot_radius,
                          planning_margin=planning_margin, robot_id=robot_id, wall_s=s.sandbox_wall_s,
                          path=path, fleet=fleet)
        job = {"files": program_files(spec, env_data, path), "argv": argv, "env": env,
               **await self._namespaces(), "hide": self.hidden_paths(), "limits": self._job_limits(),
               "field_size": list(field_size), "robot_id": robot_id, "platform": platform,
               "start_pose": list(start[:3]), "grace_s": 1.0, "relay": relay is not None}
        if fleet is not None:
            job["start_poses"] = [list(st[:3]) for st, _ in fleet]
        async with self._running:
            uid, lock = await _take_uid_off_loop(s.sandbox_uid_base)
            try:
                job = {**job, "uid": uid, "gid": uid}
                timeout = s.sandbox_wall_s + 30
                result, err = await (self._launch(job, timeout) if relay is None
                                     else self._launch_relay(job, timeout, relay))
            except asyncio.TimeoutError:
                raise RuntimeError("the sandbox launcher did not finish in time") from None
            finally:
                os.close(lock)
        if result is None:
            raise RuntimeError(f"the sandbox launcher failed: {err.strip()[-500:] or 'no result'}")
        if result.get("sandbox_error") and s.sandbox_namespaces == "auto":  # it works here, but not this time
            raise RuntimeError(f"the sandbox could not be set up: {result.get('launch_error')}")
        if relay is not None:
            return to_controller_outcome(spec, argv, result, self._job_limits())
        return to_outcome(spec, argv, result, self._job_limits())

    async def _launch_relay(self, job: dict[str, Any], timeout_s: float,
                            relay: Relay) -> tuple[Optional[dict[str, Any]], str]:
        """Run the launcher with a controller's ``job``, relaying its robot port to ``relay``; (result, stderr)."""
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", LAUNCHER, stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=launcher_env(),
            start_new_session=True, limit=1 << 20)
        assert proc.stdin is not None and proc.stdout is not None and proc.stderr is not None
        stdin = proc.stdin
        result: Optional[dict[str, Any]] = None
        pushing: Optional[asyncio.Task[None]] = None
        writing = asyncio.Lock()
        backlog = self.settings.controller_max_backlog
        waiting: deque[str] = deque()  # the program's lines for the robot, not sent yet
        arrived = asyncio.Event()
        in_flight = 0  # a line sent to the robot, its reply not back yet
        flooded: Optional[str] = None

        async def write(data: bytes) -> None:
            async with writing:
                try:
                    stdin.write(data)
                    await stdin.drain()
                except (OSError, RuntimeError):  # the launcher is gone: its result says why
                    pass

        async def push() -> None:
            """Unsolicited robot lines to the program; at the run's end, ``END``."""
            while (line := await relay.from_robot()) is not None:
                await write(encode(LinkKind.ROBOT, line))
            await write(encode(LinkKind.END, RUN_ENDED))

        async def forward() -> None:
            """The program's lines to the robot one at a time, in order, each reply back to the program."""
            nonlocal in_flight
            while True:
                while not waiting:
                    arrived.clear()
                    await arrived.wait()
                line, in_flight = waiting.popleft(), 1
                reply = await relay.to_robot(line)
                in_flight = 0
                await write(encode(LinkKind.ROBOT, reply))

        async def converse() -> None:
            """Read the launcher's lines as they come (the robot's pace is :func:`forward`'s): a program that
            has more than ``backlog`` lines waiting for its robot floods it, and its run ends (its fault)."""
            nonlocal result, pushing, flooded
            await write(encode(LinkKind.JSON, job))
            while raw := await proc.stdout.readline():  # type: ignore[union-attr]
                msg = parse(raw)
                if msg is None:
                    continue
                if msg.kind is LinkKind.CONNECTED and pushing is None:
                    await relay.connected()
                    pushing = asyncio.create_task(push(), name="twb-controller-push")
                elif msg.kind is LinkKind.ROBOT:
                    if flooded is not None:
                        continue  # the run is over: the rest is read and dropped until the launcher ends
                    waiting.append(msg.text)
                    arrived.set()
                    if len(waiting) + in_flight > backlog:
                        flooded = (f"program flooded its robot port: more than {backlog} of its lines were waiting "
                                   "for the robot's answers (a robot answers one line after the other; send one "
                                   "T,T,V per PO line)")
                        waiting.clear()
                        relay.abort(flooded)
                        await write(encode(LinkKind.END, flooded))
                elif msg.kind is LinkKind.JSON:
                    result = msg.data

        err_task = asyncio.create_task(proc.stderr.read())
        forwarding = asyncio.create_task(forward(), name="twb-controller-forward")
        conversation = asyncio.create_task(converse(), name="twb-controller-converse")
        try:
            done, _ = await asyncio.wait({conversation, forwarding}, timeout=timeout_s,
                                         return_when=asyncio.FIRST_COMPLETED)
            if not done:
                raise asyncio.TimeoutError
            if forwarding in done:  # it never returns: the robot's link failed (a testbed fault: it raises)
                forwarding.result()
            conversation.result()
            await asyncio.wait_for(proc.wait(), 5)
        except BaseException:
            await _stop(proc)
            raise
        finally:
            conversation.cancel()
            forwarding.cancel()
            if pushing is not None:
                pushing.cancel()
        err = await err_task
        return result, err.decode("utf-8", "replace")


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
