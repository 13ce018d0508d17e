"""What a program's execution gave: the launcher's result turned into a path or a reason, and log lines."""

from __future__ import annotations

import signal
from dataclasses import dataclass, field
from typing import Any, Optional

from .program import ProgramSpec

__all__ = ["ProgramOutcome", "explain", "explain_controller", "explain_fleet", "memory_full", "robots_phrase",
           "to_controller_outcome", "to_outcome"]

_FORK_SIGNS = ("Resource temporarily unavailable", "BlockingIOError", "fork: retry", "Cannot fork",
               "can't fork", "fork failed")
_MEMORY_SIGNS = ("MemoryError", "Cannot allocate memory", "cannot allocate", "out of memory", "bad_alloc",
                 "Out of memory", "failed to map segment", "mmap failed")


@dataclass
class ProgramOutcome:
    """What one execution gave: a path (m, m, rad) or the reason there is none."""

    path: Optional[list[list[float]]]
    reason: Optional[str]
    #: (direction, line) for the run's log: ``o`` stdout, ``e`` stderr, ``s`` sandbox and robot port
    log: list[tuple[str, str]] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    planning_time_s: Optional[float] = None
    #: a multi-robot job's paths, robot by robot (m, m, rad; ``path`` is robot 0's), or None
    paths: Optional[list[list[list[float]]]] = None


def explain(r: dict[str, Any], limits: dict[str, Any]) -> Optional[str]:
    """Why a finished program gave no path (``None``: it did); ``limits`` as in the job (bytes, s).

    Limits first (they explain the crash or the silence that follows), then
    a refused line, a crash, and at last plain silence.  With a cgroup the
    kernel's counts say it (out-of-memory kills, refused forks); otherwise
    running out of processes or memory shows as failed forks / allocations in
    the program's stderr (or, for processes, as the count reaching the limit).
    """
    if r.get("launch_error"):
        return f"program could not start: {r['launch_error']}"
    if len(r.get("ports") or []) > 1:
        return explain_fleet(r, limits)
    if r.get("path") is not None:
        return None
    err = r.get("stderr") or ""
    sig = r.get("signal")
    refused = r.get("refused") or []
    after = f" (its last line was refused: {refused[-1]})" if refused else ""
    wall = limits["wall_s"]
    limit = _limit_reason(r, limits)
    if limit:
        return limit
    if r.get("timed_out"):
        return f"program time limit: no path within {wall:g} s" + after
    if refused:
        ended = (f"; it then exited with code {r['exit_code']}" if r.get("exit_code") not in (None, 0)
                 else f"; it was then killed by {_signame(sig)}" if sig is not None else "")
        return f"program sent an invalid path: {refused[-1]}{ended}"
    if r.get("exit_code") not in (None, 0):
        return f"program crashed: exit code {r['exit_code']}" + _last_line(err)
    if sig is not None:
        return f"program crashed: killed by signal {_signame(sig)}" + _last_line(err)
    if not r.get("connected"):
        return "program sent no path: it exited without connecting to the robot port"
    return "program sent no path: it exited without sending a T,T,P line"


def explain_fleet(r: dict[str, Any], limits: dict[str, Any]) -> Optional[str]:
    """Why a multi-robot job's program did not give every robot its path (``None``: it did), naming the
    robots without one and what their ports saw; ``r["ports"]`` is the launcher's per robot port."""
    if r.get("launch_error"):
        return f"program could not start: {r['launch_error']}"
    ports = r["ports"]
    missing = [k for k, p in enumerate(ports) if p.get("path") is None]
    if not missing:
        return None
    who = robots_phrase(missing)
    sig, err = r.get("signal"), r.get("stderr") or ""
    refused = [k for k in missing if ports[k].get("refused")]
    limit = _limit_reason(r, limits)
    if limit:
        head = f"{limit}; no path for {who}"
    elif r.get("timed_out"):
        head = f"program time limit: no path for {who} within {limits['wall_s']:g} s"
    elif r.get("exit_code") not in (None, 0):
        head = f"program crashed: exit code {r['exit_code']}{_last_line(err)}; no path for {who}"
    elif sig is not None:
        head = f"program crashed: killed by signal {_signame(sig)}{_last_line(err)}; no path for {who}"
    elif refused == missing:
        head = f"program sent an invalid path for {who}"
    else:
        head = f"program sent no path for {who}"
    unheard = [k for k in missing if not ports[k].get("connected")]
    silent = [k for k in missing if ports[k].get("connected") and not ports[k].get("refused")]
    details = [f"robot {k}'s port refused its last line: {ports[k]['refused'][-1]}" for k in refused]
    if unheard:
        details.append("it never connected to " + (f"robot {unheard[0]}'s port" if len(unheard) == 1
                                                     else f"the ports of {robots_phrase(unheard)}"))
    if silent:
        details.append("it sent no T,T,P line on " + (f"robot {silent[0]}'s port" if len(silent) == 1
                                                       else f"the ports of {robots_phrase(silent)}"))
    return f"{head} ({'; '.join(details)})"


def robots_phrase(ks: list[int]) -> str:
    """``robot 1``, ``robots 1 and 3``, ``robots 0, 1 and 3``."""
    if len(ks) == 1:
        return f"robot {ks[0]}"
    return "robots " + ", ".join(map(str, ks[:-1])) + f" and {ks[-1]}"


def _limit_reason(r: dict[str, Any], limits: dict[str, Any]) -> Optional[str]:
    """The limit a finished program hit (memory, processes, CPU, file size), or None."""
    err = r.get("stderr") or ""
    sig = r.get("signal")
    mib = limits["memory_bytes"] >> 20
    if r.get("memory_oom_kills"):
        return f"program memory limit: it used all of its {mib} MiB of memory (all its processes together) and was killed"
    if ((r.get("procs_max") or 0) >= limits["processes"] or r.get("fork_refusals")
            or any(x in err for x in _FORK_SIGNS)):
        return f"program process limit: it reached its limit of {limits['processes']} processes"
    if any(x in err for x in _MEMORY_SIGNS):
        return f"program memory limit: it ran out of its {mib} MiB of memory"
    if sig == signal.SIGXCPU or (sig == signal.SIGKILL and (r.get("cpu_s") or 0) >= limits["cpu_s"] - 0.5):
        if memory_full(r, limits):  # both: the memory limit first (see memory_full)
            return (f"program memory limit: it used all of its {mib} MiB of memory (all its processes together) "
                    f"and was ended by its CPU limit ({limits['cpu_s']} s) at that limit")
        return f"program CPU limit: it used more than {limits['cpu_s']} s of CPU time"
    if sig == signal.SIGXFSZ:
        return f"program file size limit: it wrote a file larger than {limits['file_bytes'] >> 20} MiB"
    return None


#: how far below its memory limit a program's peak still counts as at the limit (bytes): the kernel charges
#: memory to a cgroup in batches of up to 64 pages
AT_LIMIT_BYTES = 256 << 10


def memory_full(r: dict[str, Any], limits: dict[str, Any]) -> bool:
    """Whether the program's own memory filled its limit, though the kernel did not kill it (with a cgroup).

    At the limit the kernel first reclaims what it can (page cache of files),
    in the program's own time, and kills only when that fails; a program
    whose memory is its own up to the limit may run out of CPU time there
    first (``RLIMIT_CPU`` counts that system time too), and then the memory
    limit is the cause.  So: its charges met the limit, or its peak got
    there; and page cache (what of it is still charged when the program has
    ended, ``memory_cache_kib``) was less than an eighth of the limit: a
    program that merely read files larger than its limit fills it with cache
    the kernel drops at little cost, and its CPU limit is the cause.
    """
    limit, peak = int(limits["memory_bytes"]), r.get("memory_peak_kib")
    if not r.get("memory_limit_hits") and (peak is None or (peak << 10) < limit - AT_LIMIT_BYTES):
        return False
    cache = r.get("memory_cache_kib")
    own = (limit if peak is None else peak << 10) - (0 if cache is None else cache << 10)
    return own > limit - limit // 8


def explain_controller(r: dict[str, Any], limits: dict[str, Any]) -> Optional[str]:
    """Why a controller program's run failed through the program itself (``None``: the run decides:
    the program exited cleanly or the run ended it); ``limits`` as in the job (bytes, s)."""
    if r.get("launch_error"):
        return f"program could not start: {r['launch_error']}"
    if r.get("run_ended"):
        return None
    limit = _limit_reason(r, limits)
    if limit:
        return limit
    if r.get("timed_out"):
        return f"program time limit: the robot did not reach the goal within {limits['wall_s']:g} s"
    err, sig = r.get("stderr") or "", r.get("signal")
    if r.get("exit_code") not in (None, 0):
        return f"program crashed: exit code {r['exit_code']}" + _last_line(err)
    if sig is not None:
        return f"program crashed: killed by signal {_signame(sig)}" + _last_line(err)
    return None


def to_outcome(spec: ProgramSpec, argv: list[str], r: dict[str, Any], limits: dict[str, Any]) -> ProgramOutcome:
    """The outcome of the launcher's result ``r`` for ``spec`` run as ``argv`` under ``limits`` (the job's)."""
    reason = explain(r, limits)
    info = _info(spec, r)
    log = _log(spec, argv, r, limits, reason)
    ports = r.get("ports") or []
    if len(ports) > 1:
        info["robot_ports"] = [{"robot": k, "port": p["robot_port"], "connected": p["connected"],
                                "path_points": None if p["path"] is None else len(p["path"])}
                               for k, p in enumerate(ports)]
        if reason is not None:
            return ProgramOutcome(None, reason, log, info)
        return ProgramOutcome(ports[0]["path"], None, log, info, max(p["path_at_s"] for p in ports),
                              [p["path"] for p in ports])
    return ProgramOutcome(r.get("path") if reason is None else None, reason, log, info, r.get("path_at_s"))


def to_controller_outcome(spec: ProgramSpec, argv: list[str], r: dict[str, Any],
                          limits: dict[str, Any]) -> ProgramOutcome:
    """The outcome of a controller program's result ``r`` (no path; ``reason``: :func:`explain_controller`)."""
    reason = explain_controller(r, limits)
    return ProgramOutcome(None, reason, _log(spec, argv, r, limits, reason), _info(spec, r))


def _info(spec: ProgramSpec, r: dict[str, Any]) -> dict[str, Any]:
    iso = r.get("isolation") or {}
    return {
        "id": spec.id, "name": spec.name, "exit_code": r.get("exit_code"), "signal": r.get("signal"),
        "timed_out": r.get("timed_out", False), "wall_s": r.get("wall_s"), "cpu_s": r.get("cpu_s"),
        "max_rss_kib": r.get("max_rss_kib"), "memory_peak_kib": r.get("memory_peak_kib"),
        "memory_limit_hits": r.get("memory_limit_hits"), "memory_cache_kib": r.get("memory_cache_kib"),
        "processes_max": r.get("procs_max"),
        "stdout_dropped_bytes": r.get("stdout_dropped", 0), "stderr_dropped_bytes": r.get("stderr_dropped", 0),
        "isolation": {"namespaces": iso.get("namespaces", []), "user_namespace": iso.get("user_namespace", False),
                      "own_uid": iso.get("uid") is not None, "proc": iso.get("proc"),
                      "server_files_hidden": bool(iso.get("hidden")), "seccomp": iso.get("seccomp", False),
                      "memory_limit": iso.get("memory_limit", "per-process")},
    }


def _log(spec: ProgramSpec, argv: list[str], r: dict[str, Any], limits: dict[str, Any],
         reason: Optional[str]) -> list[tuple[str, str]]:
    iso = r.get("isolation") or {}
    shown = " ".join(a.replace("{workdir}/", "") for a in argv)
    memory = (f"memory limit per program (cgroup {iso['cgroup']})" if iso.get("memory_limit") == "cgroup"
              else "memory limit per process")
    lines: list[tuple[str, str]] = [
        ("s", f"program {spec.name!r} (#{spec.id}) started: {shown}; isolation: "
              f"{'+'.join(iso.get('namespaces') or []) or 'no namespaces'}"
              f"{', own uid' if iso.get('uid') is not None else ''}, {memory}")]
    ports = r.get("ports") or []
    fleet = len(ports) > 1
    for k, port in enumerate(ports if fleet else [r]):
        name = f"robot {k} port" if fleet else "robot port"
        if fleet:
            lines.append(("s", f"{name} is 127.0.0.1:{port['robot_port']}"))
        for direction, text in port.get("port_log", []):
            lines.append(("s", f"{name} {'<' if direction == '<' else '>'} {text}"))
        if port.get("port_unlogged"):
            lines.append(("s", f"{name}: {port['port_unlogged']} more lines not logged"))
    for d, name in (("o", "stdout"), ("e", "stderr")):
        for ln in (r.get(name) or "").splitlines():
            lines.append((d, ln[:10_000]))
        if r.get(f"{name}_dropped"):
            lines.append(("s", f"{name} truncated: {r[f'{name}_dropped']} more bytes were dropped "
                               f"(the log keeps {limits['output_bytes'] >> 10} KiB)"))
    status = ("exit code %s" % r["exit_code"] if r.get("exit_code") is not None
              else f"signal {_signame(r['signal'])}" if r.get("signal") is not None
              else "stopped by the sandbox")
    peak = f", memory {r['memory_peak_kib'] / 1024:.1f} MiB" if r.get("memory_peak_kib") is not None else ""
    if fleet:
        got = [k for k, p in enumerate(ports) if p["path"] is not None]
        lines.append(("s", f"program ended ({status}) after {r.get('wall_s', 0):.2f} s, CPU {r.get('cpu_s', 0):.2f} s"
                           + peak + f"; paths received for {robots_phrase(got) if got else 'no robot'} of "
                           f"{len(ports)}" + (f"; {reason}" if reason else "")))
        return lines
    lines.append(("s", f"program ended ({status}) after {r.get('wall_s', 0):.2f} s, CPU {r.get('cpu_s', 0):.2f} s"
                       + peak + (f"; {reason}" if reason else f"; path of {len(r['path'])} points received"
                                 if r.get("path") is not None else f"; {r['run_ended']}" if r.get("run_ended")
                                 else "")))
    return lines


def _signame(sig: int) -> str:
    try:
        return signal.Signals(sig).name
    except ValueError:
        return str(sig)


def _last_line(err: str) -> str:
    lines = [ln.strip() for ln in err.strip().splitlines() if ln.strip()]
    return f" ({lines[-1][:300]})" if lines else ""
