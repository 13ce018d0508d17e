"""Scheduler benchmark: queue estimation and scheduling steps with 100 to 20,000 queued runs.

The fleet of ``twb up``: field-1..4 on the four sub-fields (field-1 covers the
whole field), sim-1..4 in the simulation pool (3.6 m areas), all online.  The
queue (seeded): half ``sim``, half ``twb`` runs, 1% of them full-field jobs,
three environments, expected durations 20-120 s; one ``assign()`` has filled
the fleet, so 8 runs are running.  Tasks per queue size:

- ``estimate``: ``estimate_starts`` — what every submission and every
  scheduling step pays on the event loop;
- ``estimate_retry``: the same with one run in 500 excluding an online robot
  (a retried run whose robot answers again), which needs the exact replay;
- ``wake``: ``assign()`` with the fleet busy (nothing can start);
- ``step``: release the oldest running run, then ``assign()`` (one run starts);
- ``cancel``: ``drop`` 100 queued runs spread through the queue (fewer in
  small queues: ``cancelled``), then ``add`` them back.

Baseline, measured in the same run: the first implementation
(``ReferenceScheduler`` in tests/test_scheduler.py) doing the same task on an
identical scheduler; ``ratio`` is the median over interleaved rounds of
new / old, ``speedup`` its inverse.  The old estimate is O(n^2) (1.2 s at 1,000
runs, about 30 s at 5,000), so it is timed only up to ``--reference-max`` runs
(with at most 3 rounds from 5,000 runs up); above that, ``estimate`` and
``estimate_retry`` are compared with ``estimate`` itself (ratio 1) and their
agreement with the reference is checked on the new implementation's
step-by-step replay instead.  Prints JSON.

    python bench/scheduler.py [--runs 5] [--sizes 100,1000,5000,20000] [--reference-max 5000]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import random
import sys
from pathlib import Path
from typing import Any, Callable

if __package__ in (None, ""):  # run as a script: the repository root on the path
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from bench._common import interleaved, report  # noqa: E402
from server.scheduler import FULL, SUBFIELD_ORIGINS, SUBFIELD_SIZE, Pending, RobotSlot, Scheduler  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TARGET_ESTIMATE_S = 0.005  # at 5,000 queued runs: a few ms on the event loop
TARGET_SIZE = 5000


def reference_class() -> type:
    """The first implementation, kept as the reference in the scheduler's tests."""
    spec = importlib.util.spec_from_file_location("scheduler_reference", ROOT / "tests" / "test_scheduler.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module.ReferenceScheduler


def twb_up(cls: type) -> Any:
    """A scheduler of class ``cls`` with the fleet ``twb up`` registers."""
    s = cls()
    for k, origin in SUBFIELD_ORIGINS.items():
        s.robots[f"field-{k}"] = RobotSlot(f"field-{k}", "127.0.0.1", 9000 + k, "field", origin=origin,
                                           area=FULL if k == 1 else SUBFIELD_SIZE)
    for i in range(1, 5):
        s.robots[f"sim-{i}"] = RobotSlot(f"sim-{i}", "127.0.0.1", 9100 + i, "ideal", area=FULL)
    return s


def queue(n: int, *, retry_every: int = 0, seed: int = 0) -> list[Pending]:
    """``n`` runs as users queue them; with ``retry_every``, every such run excludes an online robot."""
    rng = random.Random(seed)
    out = []
    for i in range(1, n + 1):
        exclude = frozenset({"sim-2", "field-3"}) if retry_every and i % retry_every == 7 else frozenset()
        out.append(Pending(i, 1 + i // 4, rng.choice(["sim", "twb"]), "full" if rng.random() < 0.01 else "sub",
                           rng.choice(["room", "blocks", "detour"]), rng.uniform(20.0, 120.0), exclude))
    return out


def loaded(cls: type, runs: list[Pending]) -> Any:
    """The fleet busy with the first runs that fit, the rest queued."""
    s = twb_up(cls)
    for p in runs:
        s.add(p)
    s.assign()
    return s


def remaining(s: Any) -> dict[int, float]:
    """Expected remaining seconds of the running runs (as the testbed guesses: half the expected time)."""
    return {r.run_id: 30.0 for r in s.robots.values() if r.run_id is not None}


def step(s: Any) -> Callable[[], Any]:
    """Release the oldest running run and start what can start."""
    def run() -> Any:
        s.release(min(remaining(s)))
        return s.assign()
    return run


def cancel(s: Any, ids: list[int], runs: dict[int, Pending]) -> Callable[[], None]:
    """Drop ``ids`` one by one (as cancelling experiments does), then queue them again."""
    def run() -> None:
        for rid in ids:
            s.drop(rid)
        for rid in ids:
            s.add(runs[rid])
    return run


def measure(n: int, rounds: int, reference: type, reference_max: int) -> tuple[list[dict], dict[str, bool]]:
    """Every task at queue size ``n``; returns the result rows and the agreement checks."""
    runs = queue(n)
    by_id = {p.run_id: p for p in runs}
    new, old = loaded(Scheduler, runs), loaded(reference, runs)
    retry = loaded(Scheduler, queue(n, retry_every=500))
    rem, rem_retry = remaining(new), remaining(retry)
    with_reference = n <= reference_max
    expected = old.estimate_starts(rem) if with_reference else new._estimate_events(dict(rem))
    checks = {
        f"estimate same as the {'reference' if with_reference else 'step-by-step replay'}, {n} runs":
            new.estimate_starts(rem) == expected,
        f"estimate_retry same as the step-by-step replay, {n} runs":
            retry.estimate_starts(rem_retry) == retry._estimate_events(dict(rem_retry)),
    }
    estimates = {"estimate": lambda: new.estimate_starts(rem),
                 "estimate_retry": lambda: retry.estimate_starts(rem_retry)}
    if with_reference:
        estimates["old estimate"] = lambda: old.estimate_starts(rem)
    timed = interleaved(estimates, "old estimate" if with_reference else "estimate",
                        rounds if n < 5000 or not with_reference else min(rounds, 3))
    base = "old estimate" if with_reference else "estimate"
    rows = [_row(n, name, timed, base) for name in ("estimate", "estimate_retry")]
    tail = runs[n // 10:]  # never started by the steps
    cancelled = [p.run_id for p in tail[::max(len(tail) // 100, 1)][:100]]
    for task, make in (("wake", lambda s: s.assign), ("step", step),
                       ("cancel", lambda s: cancel(s, cancelled, by_id))):
        timed = interleaved({task: make(new), "old": make(old)}, "old", rounds)
        rows.append(_row(n, task, timed, "old"))
    rows[-1]["cancelled"] = len(cancelled)
    checks[f"same queue after the steps, {n} runs"] = [p.run_id for p in new.queue] == [p.run_id for p in old.queue]
    return rows, checks


def _row(n: int, task: str, timed: dict[str, dict[str, float]], baseline: str) -> dict[str, Any]:
    ratio = timed[task]["ratio"]
    return {"queued": n, "task": task, "median_s": timed[task]["median_s"], "baseline": baseline,
            "baseline_median_s": timed[baseline]["median_s"], "ratio": ratio,
            "speedup": 1.0 / ratio if ratio > 0 else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--sizes", default="100,1000,5000,20000")
    ap.add_argument("--reference-max", type=int, default=5000,
                    help="largest queue on which the old O(n^2) estimate is timed")
    args = ap.parse_args()
    reference = reference_class()
    results: list[dict[str, Any]] = []
    checks: dict[str, bool] = {}
    for n in (int(x) for x in args.sizes.split(",")):
        rows, agree = measure(n, args.runs, reference, args.reference_max)
        results += rows
        checks.update(agree)
    targets = {f"estimate with {TARGET_SIZE} queued runs <= {TARGET_ESTIMATE_S * 1e3:g} ms":
               r["median_s"] <= TARGET_ESTIMATE_S for r in results
               if r["queued"] == TARGET_SIZE and r["task"] == "estimate"}
    report("scheduler", results, runs=args.runs, reference_max=args.reference_max,
           fleet="twb up: field-1..4 (field-1 full field), sim-1..4",
           queue="50% sim / 50% twb, 1% full-field, expected 20-120 s; 8 running",
           baseline="ReferenceScheduler (tests/test_scheduler.py), the first implementation",
           checks=checks, targets_met=targets)


if __name__ == "__main__":
    main()
