"""Calls of one function coalesced into batches, each call handed its own result (group commit).

The run recorder writes the run ends that wait at the same time in one
transaction (:meth:`server.pipeline.recorder.RunRecorder.finish`); the
submit function computes a batch as :func:`call_each` describes.

How batches form (no timer holds work back while a writer is free): a call
goes out at once, after a ``window_s`` pause for others arriving with it,
while fewer than ``parallel`` batches are under way; otherwise calls wait
until a batch comes back, or until ``max_size`` of them wait.  Each call
gets its own result or its own exception; a batch that fails as a whole
fails every call in it.  A call cancelled while it waits
leaves the batch; when every call of a batch under way is cancelled, the
batch's cancel is called.
"""

from __future__ import annotations

import asyncio
from typing import Any, Awaitable, Callable, Sequence

__all__ = ["Batcher", "call_each"]


def call_each(fn: Callable[..., Any], calls: Sequence[tuple[Any, ...]]) -> list[tuple[bool, Any]]:
    """``fn(*args)`` for each ``args`` of ``calls``, in order (on the worker): ``(True, result)`` or
    ``(False, exception)`` each, so one call's error is not the others'."""
    out: list[tuple[bool, Any]] = []
    for args in calls:
        try:
            out.append((True, fn(*args)))
        except Exception as exc:  # noqa: BLE001 - handed to that call's caller
            out.append((False, exc))
    return out


#: submit(calls) -> (awaitable of call_each's list, cancel())
Submit = Callable[[list[tuple[Any, ...]]], tuple[Awaitable[list[tuple[bool, Any]]], Callable[[], None]]]


class Batcher:
    """Coalesces calls into batches given to ``submit`` (see the module's text)."""

    def __init__(self, submit: Submit, *, parallel: int, max_size: int, window_s: float = 0.002) -> None:
        self._submit = submit
        self.parallel = max(1, parallel)
        self.max_size = max(1, max_size)
        self.window_s = window_s
        self._waiting: list[tuple[tuple[Any, ...], asyncio.Future]] = []
        self._under_way = 0
        self._timer: asyncio.TimerHandle | None = None
        #: sizes of the batches sent (for the benchmark and the tests)
        self.sizes: list[int] = []

    async def call(self, *args: Any) -> Any:
        """The result of this call's ``fn(*args)``, computed in some batch."""
        fut: asyncio.Future = asyncio.get_running_loop().create_future()
        item = (args, fut)
        self._waiting.append(item)
        self._consider()
        try:
            return await fut
        except asyncio.CancelledError:
            if item in self._waiting:
                self._waiting.remove(item)
            raise

    def _consider(self) -> None:
        if len(self._waiting) >= self.max_size:
            self._flush()
        elif self._waiting and self._under_way < self.parallel and self._timer is None:
            self._timer = asyncio.get_running_loop().call_later(self.window_s, self._flush)

    def _flush(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        while self._waiting and (self._under_way < self.parallel or len(self._waiting) >= self.max_size):
            batch, self._waiting = self._waiting[:self.max_size], self._waiting[self.max_size:]
            batch = [(a, f) for a, f in batch if not f.done()]
            if batch:
                self._send(batch)
        self._consider()

    def _send(self, batch: list[tuple[tuple[Any, ...], asyncio.Future]]) -> None:
        self._under_way += 1
        self.sizes.append(len(batch))
        try:
            awaitable, cancel = self._submit([a for a, _ in batch])
        except BaseException as exc:  # the submission itself failed: every call hears it
            self._under_way -= 1
            for _, f in batch:
                if not f.done():
                    f.set_exception(exc)
            return
        task = asyncio.ensure_future(awaitable)
        futures = [f for _, f in batch]

        def abandoned(_: asyncio.Future) -> None:
            if all(f.cancelled() for f in futures) and not task.done():
                cancel()

        for f in futures:
            f.add_done_callback(abandoned)
        task.add_done_callback(lambda t: self._done(t, futures))

    def _done(self, task: asyncio.Future, futures: list[asyncio.Future]) -> None:
        self._under_way -= 1
        if task.cancelled():
            for f in futures:
                f.cancel()
        elif task.exception() is not None:
            for f in futures:
                if not f.done():
                    f.set_exception(task.exception())
        else:
            for f, (ok, value) in zip(futures, task.result()):
                if f.done():
                    continue
                if ok:
                    f.set_result(value)
                else:
                    f.set_exception(value)
        self._flush()
