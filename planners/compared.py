"""What is compared, named and flattened one way for every surface: configurations, problems, runs as rows.

The study tooling (``client_sdk/study``) and the server (a job's default ``label`` and ``problem``,
``GET /api/v1/comparisons``, and through it ``twb results``, the SDK's ``Client.compare`` and the
dashboard's compare page) name a configuration, name a problem, turn a run into a row and compare the
rows with these functions and defaults, so the surfaces cannot differ on the same runs.  Pure
computation; the statistics are :mod:`planners.comparisons`'.

- A **configuration** is what is compared: a planner with the parameters given (``fm2(saturation=0.1)``),
  the robots' controller when it is not the default (``fmm/pure_pursuit``) and the field robot's profile
  variant (``fmm · tracker_noise_xy_m=0.003``): :func:`configuration_name`, :func:`job_configuration`.
- A **problem** is an environment with a start/goal (``room A`` for a plan of the environment's,
  ``room (0.30,0.30)→(1.50,1.50)`` otherwise) or a fleet (``room 4 robots``): :func:`problem_label`.
- A run is a **row** of the comparisons: ``configuration``, ``mode``, ``repetition``, ``status``,
  ``outcome``, the problem's keys and the metrics flattened (:func:`flat_metrics`, a fleet's
  :func:`fleet_row`).
"""

from __future__ import annotations

import math
from operator import itemgetter
from typing import Any, Hashable, Iterable, Mapping, NamedTuple, Optional, Sequence

import numpy as np

from contract.overrides import overrides_label
from contract.vocabulary import JUDGED, NOT_COUNTED, SUCCESS, RunStatus

from .comparisons import DIRECTION as _BASE_DIRECTION
from .comparisons import Comparisons, compare, distinct_runs, problem_of
from .stats import MIN_PROBLEMS, proportion

__all__ = ["COMPARED_METRICS", "CONTROLLER_METRICS", "DEFAULT_CONTROLLER", "DIRECTION", "FLEET_COMPARED",
           "FLEET_KINDS", "FLEET_METHOD", "FLEET_METRICS", "LABEL_LENGTH", "METHOD", "PROBLEM_LENGTH", "FleetMetric",
           "compare_runs", "compared_over", "comparisons_job", "configuration_name", "default_metrics", "enters",
           "flat_metrics", "fleet_outcome", "fleet_row", "job_configuration", "measured", "outcome_summaries",
           "plain", "problem_label", "shorten"]

#: metrics compared by default (the paper's Fig. 6), after the success rate
COMPARED_METRICS = ("length_m", "execution_time_s", "average_speed_m_s", "deviation_mean_m", "smoothness_rad",
                    "clearance_min_m")
#: compared too when controllers are compared (docs/metrics.md, "Controller metrics")
CONTROLLER_METRICS = ("cross_track_error_mean_m", "heading_error_rms_rad", "time_to_goal_s", "jerk_linear_rms_m_s3")
#: the robots' controller when a job names none
DEFAULT_CONTROLLER = "schema"
#: the longest configuration label and problem name a job may carry (characters)
LABEL_LENGTH = 64
PROBLEM_LENGTH = 100


class FleetMetric(NamedTuple):
    """How a fleet metric is named (``words``, ``unit``, ``decimals``), over which runs it is summarised and
    compared (``"completed"`` or ``"measured"``) and which way is better (+1 higher, -1 lower, 0 neither)."""

    words: str
    unit: str
    decimals: int
    over: str
    direction: int


#: the fleet metrics of a study's tables and of the comparisons, in the order they are shown
FLEET_METRICS: dict[str, FleetMetric] = {
    "makespan_s": FleetMetric("makespan", "s", 2, "completed", -1),
    "time_sum_s": FleetMetric("flowtime (sum of arrival times)", "s", 2, "completed", -1),
    "path_length_sum_m": FleetMetric("sum of path lengths", "m", 3, "completed", -1),
    "robot_success_rate": FleetMetric("share of robots arrived", "", 3, "measured", 1),
    "robot_distance_min_m": FleetMetric("closest approach of two robots", "m", 3, "measured", 1),
    "safety_time_s": FleetMetric("time within the safety radius", "s", 2, "completed", -1),
    "collisions_robot": FleetMetric("robots in robot-robot collisions", "", 2, "measured", -1),
    "collisions_moving": FleetMetric("robots hitting a moving obstacle", "", 2, "measured", -1),
    "collisions_static": FleetMetric("robots hitting a block or the wall", "", 2, "measured", -1),
    "planning_time_s": FleetMetric("planning time", "s", 3, "measured", -1),
}
#: compared between configurations by default on fleets (after the success rate)
FLEET_COMPARED = ("makespan_s", "time_sum_s", "path_length_sum_m", "robot_distance_min_m", "safety_time_s",
                  "planning_time_s")
#: +1: higher is better, -1: lower is better, 0: neither (reported, not judged); a fleet's metrics included
DIRECTION: dict[str, int] = {**_BASE_DIRECTION, **{m: spec.direction for m, spec in FLEET_METRICS.items()}}

#: how to read the comparisons (the study's summary, the API's ``method``)
METHOD = ("How to read this: the problem (an environment with a start/goal plan) is the unit of inference — its "
          "repetitions say how a configuration varies on that problem, not how it does on others. With 3 or more "
          "problems the verdict is over problems: each problem contributes the difference of its means, and the "
          "interval and test (one-sample t) are over those differences, with how many problems favour each side "
          "and how much they disagree (I²); with fewer, each problem has its own answer. On a problem, success "
          "rates are over the counted runs (completed or failed) with Wilson 95% intervals and Fisher's exact "
          "test; metrics are over completed runs only (a planner that fails often is judged on its successes "
          "there, so read them with its success rate), as the difference of means a − b with a studentized "
          "bootstrap 95% interval and the paired t by repetition when both ran the same repetitions with the "
          "same seed (common random numbers: a study gives every configuration the same noise per repetition), "
          "else Welch's t. p-values are Holm-adjusted per metric and level; effect sizes "
          "are Hedges' g, d_z paired, the risk difference, and d over problems. Identical repetitions (the "
          "deterministic simulation without jitter) count once. Details: docs/study.md.")
#: what fleets add to :data:`METHOD`
FLEET_METHOD = (" In a fleet study a run succeeds when every robot reached its goal; the closest approach of two "
                "robots is compared over every measured run, failed ones included (docs/study.md, \"Fleets\").")


# ----------------------------------------------------------------------------- names


def shorten(text: str, limit: int) -> str:
    """``text`` at most ``limit`` characters: cut, with ``…`` as the last one."""
    return text if len(text) <= limit else text[:limit - 1] + "…"


def configuration_name(name: str, params: Optional[Mapping[str, Any]] = None, label: Optional[str] = None) -> str:
    """``label``, else ``name`` with its parameters, sorted (``fm2(saturation=0.1)``); ``name`` alone without
    any."""
    if label:
        return label
    if not params:
        return name
    return f"{name}({','.join(f'{k}={v}' for k, v in sorted(params.items()))})"


def job_configuration(
    *,
    planner: Optional[str] = None,
    planner_params: Optional[Mapping[str, Any]] = None,
    program: Optional[int] = None,
    controller: Optional[str] = None,
    controller_params: Optional[Mapping[str, Any]] = None,
    controller_program: Optional[int] = None,
    profile_overrides: Optional[Mapping[str, float]] = None,
    profile_label: Optional[str] = None,
    always_controller: bool = False,
) -> str:
    """A job's configuration name, as a study names its configurations (``fm2(saturation=0.1)``,
    ``fmm/pure_pursuit``, ``fmm · tracker_noise_xy_m=0.003``), at most :data:`LABEL_LENGTH` characters.

    The path's source: ``planner`` with the parameters *given* (not the defaults filled in), an uploaded
    ``program`` (``program #7``), else an explicit path (``explicit path``); then ``/`` and the
    controller with its given parameters when it is not the default ``schema`` (``always_controller``: also
    then — a study that compares controllers names every one), or ``/controller program #8``; then ``·``
    and the profile variant's ``profile_label`` or, without one, the ``profile_overrides``
    (:func:`contract.overrides.overrides_label`) when there are any.
    """
    if planner:
        name = configuration_name(planner, planner_params)
    elif program is not None:
        name = f"program #{program}"
    else:
        name = "explicit path"
    if controller_program is not None:
        name += f"/controller program #{controller_program}"
    elif always_controller or (controller or DEFAULT_CONTROLLER) != DEFAULT_CONTROLLER or controller_params:
        name += "/" + configuration_name(controller or DEFAULT_CONTROLLER, controller_params)
    if profile_label:
        name += f" · {profile_label}"
    elif profile_overrides:
        name += f" · {overrides_label(profile_overrides)}"
    return shorten(name, LABEL_LENGTH)


def _heading(p: Sequence[float]) -> Optional[float]:
    t = p[2] if len(p) > 2 else None
    return None if t is None or not math.isfinite(float(t)) else float(t)


def _same_pose(a: Optional[Sequence[float]], b: Optional[Sequence[float]]) -> bool:
    """Two poses the same up to JSON rounding: x and y, and the heading (both without one, or the same)."""
    if a is None or b is None or len(a) < 2 or len(b) < 2:
        return False
    if any(abs(float(p) - float(q)) > 1e-6 for p, q in zip(a[:2], b[:2])):
        return False
    ta, tb = _heading(a), _heading(b)
    if ta is None or tb is None:
        return ta is None and tb is None
    return abs(math.remainder(ta - tb, 2 * math.pi)) <= 1e-6


def _xy(p: Sequence[float]) -> str:
    return f"({float(p[0]):.2f},{float(p[1]):.2f})"


def problem_label(environment: str, *, plans: Iterable[Mapping[str, Any]] = (),
                  start: Optional[Sequence[float]] = None, goal: Optional[Sequence[float]] = None,
                  robots: Optional[Sequence[Any]] = None) -> str:
    """A job's problem, at most :data:`PROBLEM_LENGTH` characters: ``room A`` when ``start`` and ``goal`` are
    those of one of the environment's ``plans`` (``{"name", "start", "goal"}``; the headings too when both
    give one), else ``room (0.30,0.30)→(1.50,1.50)`` (m, rounded to cm); a fleet of ``robots``:
    ``room 4 robots``."""
    if robots is not None:
        return shorten(f"{environment} {len(robots)} robots", PROBLEM_LENGTH)
    for p in plans:
        if _same_pose(start, p.get("start")) and _same_pose(goal, p.get("goal")):
            return shorten(f"{environment} {p.get('name')}", PROBLEM_LENGTH)
    if start is None or goal is None:
        return shorten(environment, PROBLEM_LENGTH)
    return shorten(f"{environment} {_xy(start)}→{_xy(goal)}", PROBLEM_LENGTH)


# ----------------------------------------------------------------------------- a run as a row


def flat_metrics(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """A run's metrics as one flat row: the planned path's become ``planned_<name>``; settings, poses and other
    nested values are left out."""
    out: dict[str, Any] = {}
    for k, v in metrics.items():
        if k == "planned" and isinstance(v, dict):
            out.update({f"planned_{pk}": pv for pk, pv in v.items() if not isinstance(pv, (dict, list))})
        elif not isinstance(v, (dict, list)):
            out[k] = v
    return out


#: how a fleet's run ended, in the order of the tables (every other failure is "other")
FLEET_KINDS = ("success", "robot-robot collision", "moving-obstacle collision", "block/wall collision", "deadlock",
               "timeout")
_COLLISIONS = (("collisions_robot", FLEET_KINDS[1]), ("collisions_moving", FLEET_KINDS[2]),
               ("collisions_static", FLEET_KINDS[3]))
_STUCK = ("timeout", "controller_timeout", "stalled")


def fleet_outcome(outcome: Optional[str], metrics: Mapping[str, Any]) -> str:
    """How a fleet's run ended: ``success``; a collision by the gravest kind present (robot-robot, a moving
    obstacle, a block or the wall); ``deadlock`` for a timeout, stall or controller time-out while the fleet
    was deadlocked; else the run's outcome (``timeout``, ``planning``, ``error``, ...)."""
    if outcome == "collision":
        return next((kind for key, kind in _COLLISIONS if (metrics.get(key) or 0) > 0), "collision")
    if outcome in _STUCK and metrics.get("deadlock"):
        return "deadlock"
    return outcome or "pending"


def _robot_end(r: Mapping[str, Any]) -> str:
    """One robot's end: ``arrived``, ``hit-robot``, ``hit-moving``, ``hit-static``, or its outcome."""
    if r.get("done"):
        return "arrived"
    if r.get("collision"):
        return f"hit-{r['collision']}"
    return str(r.get("outcome") or "unknown").lower()


def fleet_row(robots: int, outcome: Optional[str], metrics: Mapping[str, Any]) -> dict[str, Any]:
    """A fleet's run as a row: ``robots`` (how many), its scalar fleet metrics (the share of robots that arrived
    as ``robot_success_rate``: ``success_rate`` is the run-level rate), ``robots_arrived``, ``robot_ends`` (each
    robot's end, space-separated, robot 0 first) and ``fleet_outcome``."""
    row: dict[str, Any] = {"robots": robots, "fleet_outcome": fleet_outcome(outcome, metrics)}
    for k, v in metrics.items():
        if not isinstance(v, (dict, list)):
            row["robot_success_rate" if k == "success_rate" else k] = v
    per_robot = metrics.get("robots") or []
    row["robots_arrived"] = sum(bool(r.get("done")) for r in per_robot) if per_robot else None
    row["robot_ends"] = " ".join(_robot_end(r) for r in per_robot) or None
    return row


def measured(row: Mapping[str, Any]) -> bool:
    """A fleet's run that was driven and measured (completed, or failed after its robots set off)."""
    return row.get("status") in JUDGED and row.get("robots_arrived") is not None


def compared_over(metric: str) -> str:
    """The runs a metric is compared over: ``completed`` (a single robot's metrics, a fleet's times and lengths)
    or ``measured`` (a fleet's safety metrics: failed runs included; :data:`FLEET_METRICS`)."""
    spec = FLEET_METRICS.get(metric)
    return spec.over if spec is not None else "completed"


def enters(row: Mapping[str, Any], metric: str) -> bool:
    """Whether a run enters ``metric``'s comparison (:func:`compared_over`)."""
    return row.get("status") == RunStatus.COMPLETED if compared_over(metric) == "completed" else measured(row)


# ----------------------------------------------------------------------------- the comparisons


def default_metrics(*, single: bool = True, fleet: bool = False, controllers: bool = False) -> tuple[str, ...]:
    """The metrics compared after the success rate when none are named: a single robot's
    (:data:`COMPARED_METRICS`, with :data:`CONTROLLER_METRICS` when ``controllers`` are compared), a
    fleet's (:data:`FLEET_COMPARED`), or both when the runs have both."""
    out: tuple[str, ...] = ()
    if single:
        out += COMPARED_METRICS + (CONTROLLER_METRICS if controllers else ())
    if fleet:
        out += FLEET_COMPARED
    return out


def compare_runs(
    rows: Sequence[Mapping[str, Any]],
    metrics: Optional[Iterable[str]] = None,
    *,
    fleet: bool = False,
    controllers: bool = False,
    modes: Optional[Iterable[str]] = None,
    pairs: Optional[Iterable[tuple[str, str]]] = None,
    problem: Any = problem_of,
    problems: Optional[Iterable[Hashable]] = None,
    confidence: float = 0.95,
    family: str = "metric",
    test: str = "t",
    n_resamples: int = 9999,
    seed: int = 0,
) -> Comparisons:
    """:func:`planners.comparisons.compare` as every surface calls it: ``metrics`` by default
    :func:`default_metrics` (``fleet``: the rows are fleets' runs; ``controllers``: controllers are
    compared), each compared over the runs :func:`enters` says, judged by :data:`DIRECTION`; the other
    arguments as there."""
    if metrics is None:
        metrics = default_metrics(single=not fleet, fleet=fleet, controllers=controllers)
    return compare(rows, metrics, modes=modes, pairs=pairs, problem=problem, problems=problems, enters=enters,
                   direction=DIRECTION, confidence=confidence, family=family, test=test, n_resamples=n_resamples,
                   seed=seed, min_problems=MIN_PROBLEMS)


def outcome_summaries(rows: Sequence[Mapping[str, Any]], *, problem: Any = problem_of,
                      confidence: float = 0.95) -> list[dict[str, Any]]:
    """How the runs of each configuration x mode ended (configurations and modes in the rows' order):
    ``runs``, ``counts`` per outcome, ``counted`` (the job's own endings: success or a failure), and
    ``success``: :func:`planners.stats.proportion` of successes over the *distinct* counted runs (identical
    repetitions of a problem count once, :func:`~planners.comparisons.distinct_runs`; ``identical`` says
    whether any were), with its Wilson interval."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["configuration"], r["mode"]), []).append(r)
    out = []
    for (config, mode), mine in groups.items():
        counts: dict[str, int] = {}
        for r in mine:
            counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
        distinct, merged = distinct_runs(mine, problem)
        k = sum(r.get("outcome") == SUCCESS for r in distinct)
        out.append({"configuration": config, "mode": mode, "runs": len(mine), "counts": counts,
                    "counted": sum(n for o, n in counts.items() if o not in NOT_COUNTED),
                    "success": proportion(k, len(distinct), confidence), "identical": merged})
    return out


def plain(value: Any) -> Any:
    """A JSON-ready copy: NumPy scalars as Python's, NaN and infinities as None, tuples as lists."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def comparisons_job(rows: Sequence[Mapping[str, Any]], metrics: Optional[Sequence[str]], options: Mapping[str, Any]
                    ) -> dict[str, Any]:
    """The comparisons of runs whose problem is their ``problem`` key, as plain data for a worker process:
    ``{"rows": [...], "outcomes": [...], "problems": [...]}`` (rows' keys :data:`~planners.comparisons.COLUMNS`,
    NaN as None; outcomes :func:`outcome_summaries`; problems in the order first seen).  ``options``:
    ``fleet``, ``controllers``, ``confidence``, ``family``, ``test``, ``n_resamples``, ``seed`` of
    :func:`compare_runs`."""
    key = itemgetter("problem")
    opts = dict(options)
    comps = compare_runs(rows, metrics, problem=key, **opts)
    return {"rows": plain(comps.rows()),
            "outcomes": plain(outcome_summaries(rows, problem=key, confidence=opts.get("confidence", 0.95))),
            "problems": list(dict.fromkeys(key(r) for r in rows))}
