"""Calls coalesced into batches (server.pipeline.batching), on a real event loop with a worker thread as the
remote side: how batches form, each call's own result or error, a lost batch, cancellation."""

from __future__ import annotations

import asyncio
import threading

import pytest

from server.pipeline.batching import Batcher, call_each


def square(x: int) -> int:
    if x < 0:
        raise ValueError(f"negative: {x}")
    return x * x


class Remote:
    """The remote side: each batch is ``call_each`` in a thread, released by the test (``release``)."""

    def __init__(self, *, hold: bool = False) -> None:
        self.batches: list[list[tuple]] = []
        self.cancelled: list[int] = []
        self.gate = threading.Event()
        if not hold:
            self.gate.set()

    def submit(self, calls):
        n = len(self.batches)
        self.batches.append(list(calls))

        def work():
            self.gate.wait(10)
            if calls and calls[0] == ("lost",):
                raise ConnectionError("the worker died")
            return call_each(square, calls)

        return asyncio.to_thread(work), lambda: self.cancelled.append(n)


async def test_each_call_gets_its_own_result_and_error():
    remote = Remote()
    b = Batcher(remote.submit, parallel=1, max_size=8)
    out = await asyncio.gather(*(b.call(x) for x in (1, 2, -3, 4)), return_exceptions=True)
    assert out[:2] == [1, 4] and out[3] == 16
    assert isinstance(out[2], ValueError) and str(out[2]) == "negative: -3"
    assert sum(len(x) for x in remote.batches) == 4


async def test_calls_wait_for_a_free_cpu_and_go_together_up_to_the_batch_size():
    remote = Remote(hold=True)
    b = Batcher(remote.submit, parallel=1, max_size=4)
    first = asyncio.ensure_future(b.call(1))
    await asyncio.sleep(0.05)  # the window passes: the first call goes alone, the CPU is busy now
    assert remote.batches == [[(1,)]]
    rest = [asyncio.ensure_future(b.call(x)) for x in range(2, 8)]  # 6 more wait
    await asyncio.sleep(0.05)
    assert len(remote.batches) == 2 and remote.batches[1] == [(2,), (3,), (4,), (5,)]  # a full batch goes anyway
    remote.gate.set()
    assert await first == 1 and [await r for r in rest] == [x * x for x in range(2, 8)]
    assert [len(x) for x in remote.batches] == [1, 4, 2] and b.sizes == [1, 4, 2]


async def test_with_cpus_free_calls_go_at_once():
    remote = Remote()
    b = Batcher(remote.submit, parallel=4, max_size=8, window_s=0.0)
    for x in range(3):
        assert await b.call(x) == x * x
    assert b.sizes == [1, 1, 1]


async def test_a_lost_batch_fails_every_call_in_it_and_nothing_else():
    remote = Remote(hold=True)
    b = Batcher(remote.submit, parallel=1, max_size=2)
    lost = [asyncio.ensure_future(b.call(v)) for v in ("lost", 1)]  # a full batch: goes at once
    later = asyncio.ensure_future(b.call(3))
    await asyncio.sleep(0.05)
    remote.gate.set()
    for f in lost:
        with pytest.raises(ConnectionError, match="the worker died"):
            await f
    assert await later == 9


async def test_a_cancelled_call_leaves_its_batch_and_a_batch_nobody_waits_for_is_cancelled():
    remote = Remote(hold=True)
    b = Batcher(remote.submit, parallel=1, max_size=8)
    busy = asyncio.ensure_future(b.call(1))
    await asyncio.sleep(0.05)
    waiting = [asyncio.ensure_future(b.call(x)) for x in (2, 3)]
    await asyncio.sleep(0.01)
    waiting[0].cancel()  # while it waits: never sent
    busy.cancel()  # its batch under way: nobody waits for it any more
    await asyncio.sleep(0.01)
    assert remote.cancelled == [0]
    remote.gate.set()
    assert await waiting[1] == 9
    assert remote.batches == [[(1,)], [(3,)]]
