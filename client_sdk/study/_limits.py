"""What a study asks of the testbed, checked before anything is submitted.

:func:`check_study` compares a study with what the server offers and allows:

- planners (``GET /api/v1/planners``: names and parameters);
- environments (given by name: they must exist; given as files: they are created);
- the server's limits, where it states them (``GET /api/v1/limits``:
  ``max_repetitions``, ``max_queued_per_user``; a server without that endpoint
  states them only when it refuses a job, and :func:`refusal` reads that answer).
  A study with more experiments than the queue quota is not refused: it is
  paced (submitted as its earlier experiments finish).

It returns every problem at once, so a study is fixed in one go.
"""

from __future__ import annotations

import re
from typing import Any, Optional

import numpy as np

from .._base import API_PREFIX, Call
from .._client import Client
from .._exceptions import ApiError, NotFound
from ._fleet import SEPARATION_M
from ._spec import StudySpec, StudySpecError

__all__ = ["StudyRefused", "check_study", "refusal", "server_limits"]


class StudyRefused(StudySpecError):
    """The testbed cannot run the study as it is; ``reasons`` lists why, one sentence each."""

    def __init__(self, reasons: list[str]) -> None:
        super().__init__("study refused: " + "; ".join(reasons))
        self.reasons = list(reasons)


def _json(response: Any) -> Any:
    return response.json()


def server_limits(client: Client) -> dict[str, int]:
    """The limits the server states (``GET /api/v1/limits``), or ``{}`` when it has no such endpoint."""
    try:
        data = client._send(Call("GET", f"{API_PREFIX}/limits", _json))
    except NotFound:
        return {}
    return {k: int(v) for k, v in (data or {}).items() if isinstance(v, int) and not isinstance(v, bool)}


def _planners(client: Client) -> dict[str, Optional[dict[str, Any]]]:
    """Planner name -> its parameter defaults (None: it takes any parameters)."""
    page = client._send(Call("GET", f"{API_PREFIX}/planners", _json))
    return {p["name"]: p.get("defaults") for p in page.get("data", [])}


def check_study(client: Client, spec: StudySpec, *, limits: Optional[dict[str, int]] = None) -> list[str]:
    """Every reason the testbed behind ``client`` would refuse ``spec`` (empty: none found).

    Checks planners and their parameter names, environments given by name,
    and, where the server states them (``limits``, default
    :func:`server_limits`), the repetitions and the queue quota (the study's
    experiments plus the user's queued ones).
    """
    reasons: list[str] = []
    offered = _planners(client)
    for p in spec.planners:
        if p.waypoints is not None:
            continue
        if p.name not in offered:
            reasons.append(f"planner {p.name!r} is not offered by this testbed (it offers {', '.join(sorted(offered))})")
            continue
        defaults = offered[p.name]
        unknown = sorted(set(p.params) - set(defaults)) if defaults is not None else []
        if unknown:
            reasons.append(f"planner {p.name!r} has no parameter(s) {', '.join(unknown)} "
                           f"(its parameters: {', '.join(sorted(defaults or {})) or 'none'})")
    reasons += _controller_reasons(client, spec)
    experiments = 0
    for e in spec.environments:
        plans = len(e.get("plans", [])) if isinstance(e, dict) else 0
        size = e.get("size") if isinstance(e, dict) else None
        if isinstance(e, str):
            try:
                known = client.get_environment(e)
                plans, size = len(known.plans), known.size
            except NotFound:
                reasons.append(f"unknown environment {e!r}: create it first or give its file in the study's "
                               "`environments`")
        experiments += len(spec.configurations()) * (len(spec.plans) if spec.plans is not None else plans)
        if size:
            reasons += _circle_reasons(spec, e if isinstance(e, str) else e["name"], size)
    lim = server_limits(client) if limits is None else limits
    max_reps = lim.get("max_repetitions")
    if max_reps is not None and spec.repetitions > max_reps:
        reasons.append(f"repetitions {spec.repetitions}: the testbed allows at most {max_reps} per experiment")
    quota = lim.get("max_queued_per_user")
    if quota is not None and experiments:
        # a study larger than the quota is paced (run_study submits more as its experiments finish), but it
        # needs room for one
        queued = client.list_experiments(status="queued", limit=1).count
        if queued >= quota:
            reasons.append(f"you already have {queued} queued experiments and the testbed allows {quota} per user: "
                           "wait for them to finish or cancel some")
    return reasons


def _circle_reasons(spec: StudySpec, env: str, size: list[float]) -> list[str]:
    """The study's circles of robots that do not fit in environment ``env`` of ``size`` (m): every start and goal
    at least a robot radius with the planning margin (:data:`~client_sdk.study._fleet.SEPARATION_M` / 2) inside
    the field."""
    out = []
    room = SEPARATION_M / 2
    for p in spec.plans or []:
        if p.circle is None:
            continue
        xy = np.array([r[k][:2] for r in p.circle.robots_in(size) for k in ("start", "goal")])
        if (xy < room - 1e-9).any() or (xy > np.asarray(size[:2]) - room + 1e-9).any():
            out.append(f"plan {p.name!r}: its circle of radius {p.circle.radius_m:g} m does not fit in environment "
                       f"{env!r} ({size[0]:g} x {size[1]:g} m): every robot needs {room:.3f} m to the field's edge")
    return out


def _controller_reasons(client: Any, spec: StudySpec) -> list[str]:
    """Controllers of ``spec`` the testbed does not offer, and parameters they do not have."""
    if spec.controllers is None:
        return []
    offered = {c["name"]: {p["name"] for p in c["parameters"]} for c in client.list_controllers()}
    out = []
    for c in spec.controllers:
        if c.name not in offered:
            out.append(f"controller {c.name!r} is not offered by this testbed (it offers {', '.join(offered)})")
        elif set(c.params) - offered[c.name]:
            out.append(f"controller {c.name!r} has no parameter(s) {', '.join(sorted(set(c.params) - offered[c.name]))} "
                       f"(its parameters: {', '.join(sorted(offered[c.name])) or 'none'})")
    return out


_REPS = re.compile(r"repetitions must be at most (\d+)")


def refusal(exc: ApiError, spec: StudySpec, submitted: int, total: int) -> Optional[str]:
    """The sentence for a refused submission that dooms the whole study, or None for one job's own problem.

    Study-wide: too many repetitions (422 ``repetitions must be at most N``)
    and the queue quota (429; :func:`run_study` asks only when none of the
    study's experiments is left to finish, else it waits).  Anything else (a start inside an obstacle,
    say) concerns one job, which is recorded as rejected while the others go on.
    """
    detail = exc.detail if isinstance(exc.detail, str) else str(exc)
    if exc.status == 422:
        m = _REPS.search(detail)
        if m:
            return (f"repetitions {spec.repetitions}: the testbed allows at most {m.group(1)} per experiment "
                    f"({detail})")
        return None
    if exc.status == 429:
        return (f"the testbed refused experiment {submitted + 1} of {total}: {detail}; wait for your queued "
                "experiments, or ask the operator to raise TWB_MAX_QUEUED_PER_USER")
    return None
