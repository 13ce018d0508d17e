"""The worker processes that plan paths and compute metrics, off the event loop.

Spawned (not forked: the server has threads and an event loop), warmed up at
start so the first jobs do not wait for imports, deaf to Ctrl-C in a
terminal (the server decides when they stop), and ending by themselves when
the server process is gone, however it ended (:mod:`server.core.lifeline`).

A worker that dies (killed, or by the out-of-memory killer) breaks a
``ProcessPoolExecutor`` for good: every job after it would fail.  So the pool
replaces a broken executor with a fresh one, and the jobs that were in it end
with :class:`~server.errors.EngineFault` — their runs end ``error`` and are
retried once, no robot blamed — while later jobs plan as before.  If the fresh
workers cannot even warm up, the pool says so (:meth:`WorkerPool.status`,
``GET /health``).
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import signal
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Optional, Protocol

from robot_agent.engine import tasks

from ..core.lifeline import exit_with_parent
from ..errors import EngineFault

__all__ = ["ComputePool", "WorkerPool"]

log = logging.getLogger("server.pipeline.pool")


class ComputePool(Protocol):
    """Where the pipeline's pure functions run: these worker processes, or Ray tasks (:mod:`.ray_pool`)."""

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` off the event loop; its result, or its exception."""

    def kill(self) -> None:
        """End the workers now, whatever they are doing (a job stuck past every limit)."""


def _worker_init(server_pid: int, memory_mb: int, deadline_s: float) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    exit_with_parent(server_pid)
    tasks.CONFIGURE_WORKER(memory_mb, deadline_s)  # the planning limits (robot_agent.engine.limits)


class WorkerPool:
    """``workers`` processes running the engine's jobs (:mod:`robot_agent.engine.tasks`) and the like."""

    def __init__(self, workers: int, *, memory_mb: int = 0, deadline_s: float = 0.0) -> None:
        self.workers = workers
        self.memory_mb, self.deadline_s = memory_mb, deadline_s  #: each worker's planning limits (0: none)
        self._executor: Optional[ProcessPoolExecutor] = None
        self._lock = threading.Lock()  # replacing the executor (jobs fail on the loop, warm-ups in threads)
        self.restarts = 0  #: broken executors replaced since start
        self.ready = False  #: the current workers warmed up (their first job ran)
        self.last_failure = ""  #: why the last executor broke, or why the fresh one could not warm up

    def start(self) -> None:
        """Spawn the workers and start importing the numerical stack in each."""
        with self._lock:
            self._executor = self._spawn()

    def _spawn(self) -> ProcessPoolExecutor:
        executor = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                       initializer=_worker_init,
                                       initargs=(os.getpid(), self.memory_mb, self.deadline_s))
        self.ready = False
        for _ in range(self.workers):
            executor.submit(tasks.WARM_UP).add_done_callback(lambda f, ex=executor: self._warmed(ex, f))
        return executor

    def _warmed(self, executor: ProcessPoolExecutor, future: Future) -> None:
        if executor is not self._executor or future.cancelled():
            return
        exc = future.exception()
        if exc is None:
            self.ready = True
        elif isinstance(exc, BrokenProcessPool):
            self.last_failure = f"fresh workers died while warming up: {exc}"

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` in a worker process (``fn`` and the arguments must pickle); raises
        :class:`~server.errors.EngineFault` when a worker died under it (the pool is replaced)."""
        executor = self._executor
        if executor is None:
            raise RuntimeError("the worker pool is not started")
        try:
            return await asyncio.get_running_loop().run_in_executor(executor, fn, *args)
        except BrokenProcessPool as exc:
            why = str(exc) or "a worker process terminated abruptly"
            self._replace(executor, why)
            raise EngineFault(f"a worker process of the compute pool died ({why.rstrip('.')}; killed, or out of "
                              "memory); the pool was restarted") from None

    def _replace(self, broken: ProcessPoolExecutor, why: str) -> None:
        """Swap a broken executor for a fresh one, once however many jobs saw it break."""
        with self._lock:
            if self._executor is not broken:
                return  # replaced already (or stopped)
            self.restarts += 1
            self.last_failure = why
            log.warning("a worker process of the compute pool died (%s); starting fresh workers", why)
            broken.shutdown(wait=False, cancel_futures=True)
            self._executor = self._spawn()

    def status(self) -> dict[str, Any]:
        """``{"workers", "ready", "restarts", "last_failure"}`` for ``GET /health``: ``ready`` False means
        the current workers have not run a job yet (still starting, or unable to)."""
        return {"workers": self.workers, "ready": self.ready, "restarts": self.restarts,
                "last_failure": self.last_failure or None}

    def stop(self) -> None:
        """Stop the workers; work not yet started is dropped."""
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=False, cancel_futures=True)

    def kill(self) -> None:
        """End the workers now (SIGKILL), whatever they are doing: for a process that must exit at once."""
        executor = self._executor
        for proc in list(getattr(executor, "_processes", {}).values()) if executor is not None else ():
            try:
                proc.kill()
            except (OSError, ValueError):  # gone already, or its handle closed
                pass
