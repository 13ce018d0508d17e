"""The worker processes that plan paths and compute metrics, off the event loop.

Spawned (not forked: the server has threads and an event loop), warmed up at
start so the first jobs do not wait for imports, deaf to Ctrl-C in a
terminal (the server decides when they stop), and ending by themselves when
the server process is gone, however it ended (:mod:`server.core.lifeline`).
"""

from __future__ import annotations

import asyncio
import multiprocessing
import os
import signal
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Callable, Optional, Protocol

from robot_agent.engine import tasks

from ..core.lifeline import exit_with_parent

__all__ = ["ComputePool", "WorkerPool"]


class ComputePool(Protocol):
    """Where the pipeline's pure functions run: these worker processes, or Ray tasks (:mod:`.ray_pool`)."""

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` off the event loop; its result, or its exception."""


def _worker_init(server_pid: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    exit_with_parent(server_pid)


class WorkerPool:
    """``workers`` processes running the pure functions of :mod:`robot_agent.engine.jobs` (and the like)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._executor: Optional[ProcessPoolExecutor] = None

    def start(self) -> None:
        """Spawn the workers and start importing the numerical stack in each."""
        self._executor = ProcessPoolExecutor(max_workers=self.workers,
                                             mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_worker_init, initargs=(os.getpid(),))
        for _ in range(self.workers):
            self._executor.submit(tasks.WARM_UP)

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` in a worker process (``fn`` and the arguments must pickle)."""
        if self._executor is None:
            raise RuntimeError("the worker pool is not started")
        return await asyncio.get_running_loop().run_in_executor(self._executor, fn, *args)

    def stop(self) -> None:
        """Stop the workers; work not yet started is dropped."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
