"""Helpers shared by the benchmarks: interleaved timing with medians, the JSON report, a PostgreSQL server."""

from __future__ import annotations

import json
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterable


def postgres(work: Path):  # type: ignore[no-untyped-def]
    """A throw-away PostgreSQL server in ``work/pg`` from the machine's binaries, started as the tests start
    one (tests/pg_support.py); None when they are not installed.  The caller stops it."""
    tests = str(Path(__file__).resolve().parents[1] / "tests")
    if tests not in sys.path:
        sys.path.append(tests)
    from pg_support import PostgresServer, postgres_bin

    if postgres_bin() is None:
        return None
    work.chmod(0o755)  # PostgreSQL runs as its own user when this runs as root
    return PostgresServer(work / "pg")


def _reference_workload() -> None:
    """A fixed piece of the work a robot host does per line: protocol lines formatted and parsed, small arrays."""
    import numpy as np

    acc = np.zeros(3)
    for i in range(60_000):
        line = f"PO,{i * 0.5:.1f},{i * 0.25:.1f},{i % 360:.1f},{i * 0.02:.3f}"
        _, x, y, a, t = line.split(",")
        acc += (float(x), float(y), float(a))
    np.linalg.norm(acc)


def machine_reference_s(repeat: int = 5) -> float:
    """This machine's speed now: the median CPU time (s, of this process) of a fixed workload, ``repeat`` times.

    A benchmark that measures CPU shares over days (a process's share of one core is the machine's speed as much
    as the code's) reports it beside them: a share divided by it is comparable between machines and days."""
    times = []
    for _ in range(repeat):
        c0 = time.process_time()
        _reference_workload()
        times.append(time.process_time() - c0)
    return statistics.median(times)


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


def seed_list(text: str) -> list[int]:
    """Seeds from a command line's ``"0-19"``, ``"1,4,7"`` or ``"0-3,10"``."""
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def key_values(items: Iterable[str]) -> dict[str, float]:
    """``{"key": value}`` from a command line's ``key=value`` items (``--set``)."""
    out = {}
    for item in items:
        k, _, v = item.partition("=")
        out[k] = float(v)
    return out
