"""The simulation pool on Ray: the run pipeline's CPU work as Ray tasks (``--sim-engine ray``).

A drop-in for :class:`server.pipeline.pool.WorkerPool` (``run(fn, *args)``):
planning, metrics and whole simulation-mode runs
(:func:`robot_agent.engine.jobs.simulate_job`) run as Ray tasks, on a local
cluster started and stopped with the testbed (:mod:`server.pipeline.ray_head`)
or on an existing one (``--ray-address host:port``).  Ray retries nothing
itself (``max_retries=0``): a task lost with its worker or node is an
:class:`~server.errors.EngineFault`, and the dispatcher retries the run once,
as after a dead agent.  Exceptions raised by the functions themselves
(``PlanningError`` ...) reach the caller as they are.

Ray is an optional extra (``pip install 'teleworkbench[ray]'``); without it
:meth:`RayPool.start` says so in one line.
"""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

from robot_agent.engine import tasks

from ..errors import EngineFault

__all__ = ["EngineUnavailable", "RayPool", "INSTALL_HINT"]

log = logging.getLogger("twb.server")

INSTALL_HINT = "pip install 'teleworkbench[ray]' (in this checkout: uv pip install -e '.[ray]')"


class EngineUnavailable(Exception):
    """The compute engine cannot be used (not installed, unreachable, failed to start); one line why."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _split(address: str) -> tuple[str, int]:
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise EngineUnavailable(f"--ray-address {address!r}: expected host:port of the Ray head (its GCS, "
                                "e.g. 10.0.0.5:6379)")
    return host, int(port)


def _reachable(host: str, port: int, timeout_s: float) -> Optional[str]:
    """None if host:port accepts a TCP connection within ``timeout_s``, else why not."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return None
    except OSError as exc:
        return exc.strerror or type(exc).__name__


class _LocalHead:
    """A Ray head on this machine in its own process group, ending with the server (see ``ray_head``)."""

    def __init__(self, cpus: int, log_file: Path) -> None:
        self.cpus = cpus or (os.cpu_count() or 1)
        self.log_file = log_file
        self.proc: Optional[subprocess.Popen] = None
        self.address = ""

    def start(self, timeout_s: float = 90.0) -> str:
        port = _free_port()
        ports = {opt: _free_port() for opt in (
            "--node-manager-port", "--object-manager-port", "--dashboard-agent-listen-port",
            "--dashboard-agent-grpc-port", "--metrics-export-port", "--runtime-env-agent-port",
            "--dashboard-port")}
        args = ["--port", str(port), "--num-cpus", str(self.cpus), "--include-dashboard=false",
                "--disable-usage-stats", *[f"{k}={v}" for k, v in ports.items()]]
        self.log_file.parent.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
        with open(self.log_file, "ab") as out:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "server.pipeline.ray_head", "--server-pid", str(os.getpid()), "--", *args],
                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True, env=env)
        self.address = f"127.0.0.1:{port}"
        deadline = time.monotonic() + timeout_s
        while _reachable("127.0.0.1", port, 1.0) is not None:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                tail = self.log_file.read_text(errors="replace").strip().splitlines()[-3:]
                raise EngineUnavailable("the local Ray cluster did not start: " + (" | ".join(tail) or "no output")
                                        + f" (log: {self.log_file})")
            time.sleep(0.2)
        return self.address

    def stop(self) -> None:
        if self.proc is None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(timeout=10)
        self.proc = None


#: every task of the pool: one CPU; no retry by Ray (the dispatcher retries a run once); no task events (their
#: state transitions for Ray's dashboard and state API, which the testbed does not use: CPU in the server and
#: the workers at every task)
_TASK = {"num_cpus": 1, "max_retries": 0, "enable_task_events": False}


class RayPool:
    """Ray tasks for the pipeline: a local cluster of ``cpus`` CPUs, or the cluster at ``address``."""

    engine = "ray"

    def __init__(self, *, address: str = "", cpus: int = 0, slots: int = 0, log_dir: Path = Path(".")) -> None:
        self.address = address
        self.slots = slots
        self._head = None if address else _LocalHead(cpus, log_dir / "ray-head.log")
        self._runner: Any = None  # tasks.run_task as a Ray remote function, made once (_remote_run)
        self._runners: dict[str, Any] = {}  # ... with the name of each job it ran
        self._ray: Any = None
        self.description = ""

    def start(self, connect_timeout_s: float = 60.0) -> None:
        """Import Ray, start or reach the cluster and connect (blocking; seconds).  Raises :class:`EngineUnavailable`."""
        if self._head is not None:
            # our own cluster: token authentication with a secret of this start, inherited by the head, its
            # workers and this process's driver (Ray's nodes listen on the machine's address, not loopback);
            # set before Ray is imported, which reads them once
            os.environ["RAY_AUTH_MODE"] = "token"
            os.environ["RAY_AUTH_TOKEN"] = secrets.token_hex(32)
        try:
            import ray
        except ImportError:
            raise EngineUnavailable(f"--sim-engine ray needs Ray, which is not installed: {INSTALL_HINT}") from None
        self._ray = ray
        if self._head is not None:
            address = self._head.start()
        else:
            address = self.address
            host, port = _split(address)
            why = _reachable(host, port, 5.0)
            if why is not None:
                raise EngineUnavailable(f"cannot reach the Ray cluster at {address}: {why} (is `ray start --head` "
                                        "running there, and is its GCS port open to this machine?)")
        errors: list[BaseException] = []

        def connect() -> None:
            logging.getLogger("ray").setLevel(logging.ERROR)  # not: "SIGTERM handler is not set ..." (ours is)
            try:
                ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING, namespace="twb")
            except BaseException as exc:  # noqa: BLE001 - reported below
                errors.append(exc)

        t = threading.Thread(target=connect, name="twb-ray-connect", daemon=True)
        t.start()
        t.join(connect_timeout_s)
        if t.is_alive() or errors:
            why = f"{type(errors[0]).__name__}: {errors[0]}" if errors else f"no answer within {connect_timeout_s:.0f} s"
            self.stop()
            raise EngineUnavailable(f"cannot connect to the Ray cluster at {address}: {why}")
        cpus = int(ray.cluster_resources().get("CPU", 1))
        # three runs per CPU: a worker's next runs wait in Ray's queue while the server stores the one before
        # (faster than two in 5 of 6 alternated pairs of bench/scale.py, docs/scale-out.md)
        self.slots = self.slots or 3 * max(1, cpus)
        where = "a local Ray cluster" if self._head is not None else f"the Ray cluster at {address}"
        self.description = f"{where}, {cpus} CPUs, {self.slots} runs at once"
        self._warm_up(cpus, connect_timeout_s)

    def _warm_up(self, workers: int, timeout_s: float) -> None:
        """One :func:`~robot_agent.engine.jobs.warm_up` task per CPU, waited for (blocking, at most ``timeout_s``):
        each worker pays its imports and the compiled core's loading (about 1.4 s of CPU) before the first
        run rather than during it.  Workers not ready in time warm up with their first run; nothing fails."""
        ray = self._ray
        refs = [self._remote_run(tasks.WARM_UP).remote(tasks.WARM_UP) for _ in range(workers)]
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout_s)
        if len(ready) < len(refs):
            log.warning("%d of %d Ray workers were not warmed up within %.0f s", len(refs) - len(ready), len(refs),
                        timeout_s)

    def _remote_run(self, fn: Callable[..., Any]) -> Any:
        """:func:`robot_agent.engine.tasks.run_task` as a Ray remote function named for ``fn`` (made once per
        name): every task is ``run_task(fn, *args)``, so an engine task (a
        :class:`~robot_agent.engine.tasks.Task`, which Ray cannot wrap itself) and a plain function both run,
        and Ray's dashboard and the worker's process title name the job (``ray::simulate_job``)."""
        name = getattr(fn, "name", None) or getattr(fn, "__name__", "task")
        remote = self._runners.get(name)
        if remote is None:
            if self._runner is None:
                self._runner = self._ray.remote(**_TASK)(tasks.run_task)
            remote = self._runners[name] = self._runner.options(name=name)
        return remote

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` as a Ray task (one CPU); a task Ray lost raises :class:`EngineFault`."""
        ray = self._ray
        if ray is None:
            raise RuntimeError("the Ray pool is not started")
        ref = self._remote_run(fn).remote(fn, *args)
        try:
            return await ref
        except asyncio.CancelledError:
            ray.cancel(ref)
            raise
        except ray.exceptions.RayTaskError as exc:  # the function's own exception, without Ray's traceback text
            cause = getattr(exc, "cause", None)
            if isinstance(cause, Exception):
                raise cause from None
            raise
        except ray.exceptions.RayError as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise EngineFault(f"Ray lost the task ({type(exc).__name__}): {first}") from None

    def status(self) -> dict[str, Any]:
        """``{"workers", "ready", "restarts", "last_failure"}`` for ``GET /health``, as the local pool's (Ray
        replaces its own workers; a lost task is an :class:`EngineFault` of its run)."""
        return {"workers": self.slots, "ready": self._ray is not None, "restarts": 0, "last_failure": None,
                "engine": "ray"}

    def kill(self) -> None:
        """End now: as :meth:`stop` (the local head's own lifeline ends its workers)."""
        self.stop()

    def stop(self) -> None:
        """Disconnect and, for a local cluster, end it."""
        if self._ray is not None and self._ray.is_initialized():
            try:
                self._ray.shutdown()
            except Exception:  # noqa: BLE001 - stopping anyway
                log.exception("disconnecting from Ray failed")
        if self._head is not None:
            self._head.stop()
