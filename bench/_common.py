"""Helpers shared by the benchmarks: interleaved timing with medians, and the JSON report."""

from __future__ import annotations

import json
import platform
import statistics
import sys
import time
from typing import Any, Callable


def time_once(fn: Callable[[], Any]) -> float:
    """Wall time (s) of one call of ``fn``."""
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def interleaved(tasks: dict[str, Callable[[], Any]], baseline: str, runs: int = 5) -> dict[str, dict[str, float]]:
    """Time every task once per round, ``runs`` rounds, after one warm-up round.

    Interleaving makes each round's baseline see the same machine load as the
    tasks timed next to it.  Returns, per task, the median time (s) and the
    median over rounds of ``task / baseline`` (``ratio``).
    """
    for fn in tasks.values():
        fn()
    times: dict[str, list[float]] = {name: [] for name in tasks}
    for _ in range(runs):
        for name, fn in tasks.items():
            times[name].append(time_once(fn))
    base = times[baseline]
    return {
        name: {
            "median_s": statistics.median(ts),
            "ratio": statistics.median(t / b for t, b in zip(ts, base)),
        }
        for name, ts in times.items()
    }


def report(name: str, results: list[dict[str, Any]], **extra: Any) -> None:
    """Print the benchmark's JSON document on stdout."""
    doc = {
        "benchmark": name,
        "python": sys.version.split()[0],
        "machine": platform.machine(),
        **extra,
        "results": results,
    }
    json.dump(doc, sys.stdout, indent=1)
    sys.stdout.write("\n")
