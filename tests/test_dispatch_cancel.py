"""A cancel that meets a run's end: the run is not queued again (test_security's bulk cancel saw an experiment
go back to `queued` when its run's robot failed while the cancel came in)."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from server import dispatch
from server.dispatch import CANCELLED, Dispatcher
from server.pipeline.runner import RunEnd
from server.status import RunStatus

RUN, EXPERIMENT = 7, 3


class Recorder:
    """The store's side of a run's end; `requeue` waits for `gate`, as the real one waits for the database."""

    def __init__(self) -> None:
        self.gate = asyncio.Event()
        self.calls: list[tuple] = []

    async def finish(self, run_id: int, status, error, *, retry=False, resume=False, **_):  # type: ignore[no-untyped-def]
        if resume:
            self.calls.append(("resume", run_id))
            return SimpleNamespace(id=run_id), SimpleNamespace(id=EXPERIMENT)
        if retry:
            self.calls.append(("requeue", run_id))
            await self.gate.wait()
            return SimpleNamespace(id=run_id), SimpleNamespace(id=EXPERIMENT)
        self.calls.append(("update", run_id, status))
        return None

    async def end(self, run_ids, status, error, *, failure=None) -> None:  # type: ignore[no-untyped-def]
        if list(run_ids):
            self.calls.append(("end", list(run_ids), status, error))


def dispatcher(monkeypatch) -> tuple[Dispatcher, Recorder]:  # type: ignore[no-untyped-def]
    rec = Recorder()
    monkeypatch.setattr(dispatch, "pending_of", lambda run, exp, exclude=frozenset(): dispatch.Pending(
        run.id, exp.id, "sim", "sub", "room", 1.0, exclude))
    services = SimpleNamespace(field=SimpleNamespace(robots={}, subfields={}), recorder=rec,
                               settings=SimpleNamespace(time_scale=1.0))
    return Dispatcher(services), rec


def test_a_run_queued_again_while_its_experiment_is_cancelled_ends_cancelled(monkeypatch):
    async def main() -> None:
        d, rec = dispatcher(monkeypatch)
        end = asyncio.create_task(d._store_end(RUN, EXPERIMENT, RunEnd(RunStatus.ERROR, "robot x: refused", robot_fault="x")))
        await asyncio.sleep(0)  # the store is queueing it again ...
        await d.cancel([EXPERIMENT])  # ... when its owner cancels
        rec.gate.set()
        await end
        assert [p.run_id for p in d.scheduler.queue] == []
        assert rec.calls[-1] == ("end", [RUN], RunStatus.CANCELLED, CANCELLED)

    asyncio.run(main())


def test_a_run_of_a_cancelled_experiment_is_not_retried(monkeypatch):
    async def main() -> None:
        d, rec = dispatcher(monkeypatch)
        rec.gate.set()
        await d.cancel([EXPERIMENT])
        await d._store_end(RUN, EXPERIMENT, RunEnd(RunStatus.ERROR, "robot x: refused", robot_fault="x"))
        await d._store_end(RUN + 1, EXPERIMENT, RunEnd(RunStatus.INTERRUPTED, "database away", resume=True))
        assert [c[0] for c in rec.calls] == ["update", "update"]  # neither queued again
        assert [c[2] for c in rec.calls] == [RunStatus.CANCELLED, RunStatus.CANCELLED]
        assert list(d.scheduler.queue) == []

    asyncio.run(main())


def test_other_experiments_are_still_retried(monkeypatch):
    async def main() -> None:
        d, rec = dispatcher(monkeypatch)
        await d.cancel([EXPERIMENT + 1])
        rec.gate.set()
        await d._store_end(RUN, EXPERIMENT, RunEnd(RunStatus.ERROR, "robot x: refused", robot_fault="x"))
        assert [p.run_id for p in d.scheduler.queue] == [RUN] and rec.calls == [("requeue", RUN)]

    asyncio.run(main())
