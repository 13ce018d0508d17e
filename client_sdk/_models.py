"""Typed results: dataclasses mirroring the server's JSON responses (docs/design.md, "REST API").

They are defined here, not imported from the server, so the SDK runs without
the server's dependencies (``tests/test_sdk_models.py`` checks them against the
server's OpenAPI document).  Units are SI: metres, radians, seconds.  Unknown
keys in a response are ignored, so a newer server does not break an older SDK;
``from_json`` builds each type from a decoded response.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from dataclasses import field as _field
from datetime import datetime
from typing import Any, Callable, ClassVar, Generic, Iterator, Optional, TypeVar

import numpy as np

from contract.vocabulary import TERMINAL, run_outcome

__all__ = [
    "TERMINAL_STATES",
    "ComparedExperiment",
    "ComparisonReport",
    "ComparisonRow",
    "ConfigurationOutcome",
    "DirectComparison",
    "Environment",
    "Experiment",
    "ExperimentMetrics",
    "ExperimentSummary",
    "Message",
    "ModeAggregate",
    "ObstacleTracks",
    "Page",
    "Plan",
    "Program",
    "Robot",
    "Run",
    "RunMetrics",
    "Subfield",
    "Summary",
]

#: experiment and run states after which nothing changes any more
TERMINAL_STATES = TERMINAL  #: the statuses a run ends in (contract.vocabulary.TERMINAL)

T = TypeVar("T")


def _dt(v: Any) -> Optional[datetime]:
    if v is None or isinstance(v, datetime):
        return v
    return datetime.fromisoformat(str(v).replace("Z", "+00:00"))


def _pick(cls: type, data: dict[str, Any], **conv: Any) -> dict[str, Any]:
    """The keyword arguments of dataclass ``cls`` found in ``data``, converted by ``conv``."""
    out = {}
    for f in dataclasses.fields(cls):
        if f.name in data:
            v = data[f.name]
            out[f.name] = conv[f.name](v) if f.name in conv and v is not None else v
    return out


class _FromJson:
    """``from_json(data)``: the dataclass from a decoded response, fields converted by ``_conv``."""

    _conv: ClassVar[dict[str, Callable[[Any], Any]]] = {}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Any:
        return cls(**_pick(cls, data, **cls._conv))


@dataclass
class Page(Generic[T]):
    """One page of a list: ``data`` and the ``count`` of all matching items. Iterable."""

    data: list[T]
    count: int

    def __iter__(self) -> Iterator[T]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)


@dataclass
class CancelResult(_FromJson):
    """What a cancel of many experiments did: ``cancelled`` ids, and why the others were not
    (``not_cancelled``: id -> ``"not found"`` or ``"already <status>"``)."""

    cancelled: list[int]
    not_cancelled: dict[int, str]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "CancelResult":
        return cls(list(data["cancelled"]), {int(n["id"]): n["reason"] for n in data["not_cancelled"]})


@dataclass
class Plan(_FromJson):
    """A named start/goal pair of an environment: poses ``[x, y, theta]`` (m, m, rad)."""

    name: str
    start: list[float]
    goal: list[float]


@dataclass
class Environment(_FromJson):
    """An environment (docs/design.md, "Environment file"): ``size`` (m), rectangular ``blocks`` (centre, size,
    angle) and ``moving_obstacles`` (discs moving in time: radius m, waypoints or random_walk, speed m/s,
    repeat, delay_s s)."""

    name: str
    size: list[float]
    blocks: list[dict[str, float]]
    plans: list[Plan] = _field(default_factory=list)
    description: str = ""
    builtin: bool = False
    owner: Optional[str] = None
    moving_obstacles: list[dict[str, Any]] = _field(default_factory=list)
    #: derived by the testbed, for drawing (not part of the file, :meth:`to_json`): each moving obstacle as it
    #: moves, ``radius`` (m), ``speed`` (m/s), ``repeat``, ``delay_s`` (s) and its ``waypoints`` (m)
    moving_tracks: list[dict[str, Any]] = _field(default_factory=list)

    _conv = {"plans": lambda ps: [Plan.from_json(p) for p in ps]}

    def plan(self, name: str) -> Plan:
        """The plan called ``name``; ``KeyError`` listing the names otherwise."""
        for p in self.plans:
            if p.name == name:
                return p
        raise KeyError(f"environment {self.name!r} has no plan {name!r} (plans: {', '.join(p.name for p in self.plans) or 'none'})")

    def same_geometry(self, other: "Environment | dict[str, Any]") -> bool:
        """Whether ``other`` (an environment or its file as a dict) has the same name, size, blocks, plans and
        moving obstacles (the description may differ; a missing block angle is 0, a missing plan heading 0, a
        missing repeat ``once`` and delay 0, as on the testbed)."""
        data = other.to_json() if isinstance(other, Environment) else other
        try:
            return _geometry(self.to_json()) == _geometry(data)
        except (KeyError, TypeError, ValueError, IndexError):
            return False

    def to_json(self) -> dict[str, Any]:
        """The environment file (docs/design.md, "Environment file") of this environment."""
        d: dict[str, Any] = {"name": self.name, "size": list(self.size), "blocks": [dict(b) for b in self.blocks]}
        if self.plans:
            d["plans"] = [dataclasses.asdict(p) for p in self.plans]
        if self.description:
            d["description"] = self.description
        if self.moving_obstacles:
            d["moving_obstacles"] = [dict(o) for o in self.moving_obstacles]
        return d


def _mover(o: dict[str, Any]) -> tuple[Any, ...]:
    """A moving obstacle with the testbed's defaults filled, numbers as floats."""
    walk = o.get("random_walk")
    track = (tuple((float(x), float(y)) for x, y in o["waypoints"]) if walk is None else
             (int(walk["seed"]), tuple(float(v) for v in walk["start"]), int(walk["steps"]), float(walk["step_m"])))
    return (float(o["radius"]), float(o["speed"]), o.get("repeat", "once"), float(o.get("delay_s", 0.0)), track)


def _geometry(env: dict[str, Any]) -> tuple[Any, ...]:
    """What makes two environment files the same field: name, size, blocks, plans (floats, defaults filled)."""
    def pose(p: Any) -> tuple[float, ...]:
        v = [float(x) for x in p]
        return tuple(v + [0.0]) if len(v) == 2 else tuple(v)

    blocks = tuple((float(b["x"]), float(b["y"]), float(b["w"]), float(b["h"]), float(b.get("angle", 0.0)))
                   for b in env.get("blocks", []))
    plans = tuple((p.get("name", str(i + 1)), pose(p["start"]), pose(p["goal"]))
                  for i, p in enumerate(env.get("plans", [])))
    movers = tuple(_mover(o) for o in env.get("moving_obstacles", []))
    return str(env["name"]).strip(), tuple(float(v) for v in env["size"]), blocks, plans, movers


@dataclass
class Run(_FromJson):
    """One run: an experiment's ``mode`` (``sim``/``twb``) and ``repetition``, with its metrics (docs/design.md, "Metrics")."""

    id: int
    experiment_id: int
    mode: str
    repetition: int
    status: str
    #: the seed of the run's noise, dropouts and start jitter (its own per mode)
    seed: int = 0
    attempt: int = 1
    #: how its robot's clock treated a closed-loop controller: ``lockstep`` or ``free`` (None: not recorded)
    clock: Optional[str] = None
    #: experiment seconds per wall second it ran at (None: as fast as possible, or not recorded)
    time_scale: Optional[float] = None
    subfield: Optional[int] = None
    robot_id: Optional[str] = None
    t_start: Optional[float] = None
    t_end: Optional[float] = None
    metrics: dict[str, Any] = _field(default_factory=dict)
    error: str = ""
    failure: Optional[str] = None
    stopped_at: Optional[list[float]] = None
    created_at: Optional[datetime] = None
    started_at: Optional[datetime] = None
    finished_at: Optional[datetime] = None
    #: the seed its repetition's planner planned with (the same for both modes of the repetition)
    planner_seed: Optional[int] = None
    #: the path it drove, ``(N, 3)`` (m, rad): its repetition's plan (None until planned)
    planned_path: Optional[np.ndarray] = None
    #: its repetition's planning: median wall and CPU seconds of ``planning_repeats`` planner calls in a warmed
    #: worker, and the machine's 1-minute load average per CPU then (docs/study.md, "Planning time")
    planning_time_s: Optional[float] = None
    planning_cpu_s: Optional[float] = None
    planning_repeats: Optional[int] = None
    planning_load: Optional[float] = None
    #: an anytime planner's best path length so far against its planning time, ``(K, 2)`` (s, m), of its
    #: repetition's planning (OMPL's planners); None: the planner reports none
    planning_progress: Optional[np.ndarray] = None

    _conv = {"created_at": _dt, "started_at": _dt, "finished_at": _dt,
             "planned_path": lambda p: np.asarray(p, dtype=float).reshape(-1, 3),
             "planning_progress": lambda p: np.asarray(p, dtype=float).reshape(-1, 2)}

    @property
    def finished(self) -> bool:
        """True once the run reached a terminal state."""
        return self.status in TERMINAL_STATES

    @property
    def outcome(self) -> str:
        """``success``, why it failed (``collision``, ``timeout``, ...), or its status (``error``,
        ``cancelled``, ``interrupted``; ``pending`` while it runs)."""
        return run_outcome(self.status, self.failure)


@dataclass
class ExperimentSummary(_FromJson):
    """An experiment as listed: status and job, without planned path and runs."""

    id: int
    status: str
    environment: str
    owner: str = ""
    planner: Optional[str] = None
    program: Optional[int] = None
    modes: list[str] = _field(default_factory=list)
    repetitions: int = 1
    field: str = "sub"
    controller: str = "schema"
    #: the uploaded program driving the robots instead of ``controller`` (docs/controllers.md), or None
    controller_program: Optional[int] = None
    #: the configuration's name in comparisons (the job's ``label``, or the server's default) and the problem's
    label: str = ""
    problem: str = ""
    error: str = ""
    created_at: Optional[datetime] = None
    finished_at: Optional[datetime] = None
    estimated_start_s: Optional[float] = None

    _conv = {"created_at": _dt, "finished_at": _dt}

    @property
    def finished(self) -> bool:
        """True once the experiment reached a terminal state."""
        return self.status in TERMINAL_STATES


@dataclass
class Experiment(ExperimentSummary):
    """An experiment with its job, planned path (``(N, 3)`` array, m/rad: repetition 1's; each run has its
    own) and runs."""

    start: list[float] = _field(default_factory=list)
    goal: list[float] = _field(default_factory=list)
    #: a multi-robot job's robots, ``{"start", "goal", "path"?}`` each (m, rad); None for one robot
    robots: Optional[list[dict[str, Any]]] = None
    planner_params: dict[str, Any] = _field(default_factory=dict)
    seed: int = 0
    #: the job's planner seed (None: ``seed`` is the base of every repetition's planner seed)
    planner_seed: Optional[int] = None
    #: its planner is randomised: planned once per repetition (each run's ``planned_path``), else one path for all
    planner_stochastic: bool = False
    robot_radius: Optional[float] = None
    planning_margin: Optional[float] = None
    planned_path: Optional[np.ndarray] = None
    planning_time_s: Optional[float] = None
    planning_info: dict[str, Any] = _field(default_factory=dict)
    jitter: Optional[dict[str, float]] = None
    profile_overrides: Optional[dict[str, float]] = None
    controller_params: dict[str, float] = _field(default_factory=dict)
    started_at: Optional[datetime] = None
    runs: list[Run] = _field(default_factory=list)

    _conv = {
        "created_at": _dt, "finished_at": _dt, "started_at": _dt,
        "planned_path": lambda p: np.asarray(p, dtype=float).reshape(-1, 3) if p else np.empty((0, 3)),
        "runs": lambda rs: [Run.from_json(r) for r in rs],
    }

    @property
    def runs_total(self) -> int:
        """Number of runs of the experiment (modes x repetitions)."""
        return len(self.runs) or len(self.modes) * self.repetitions

    @property
    def runs_done(self) -> int:
        """Number of runs in a terminal state."""
        return sum(r.finished for r in self.runs)


@dataclass
class Summary(_FromJson):
    """Mean, sample std and Student-t interval of one metric over ``n`` runs (None where undefined)."""

    n: int
    mean: Optional[float] = None
    std: Optional[float] = None
    ci_low: Optional[float] = None
    ci_high: Optional[float] = None
    confidence: float = 0.95


@dataclass
class ModeAggregate:
    """Aggregates of one mode: ``runs`` completed and a :class:`Summary` per metric."""

    runs: int
    metrics: dict[str, Summary]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "ModeAggregate":
        return cls(runs=data.get("runs", 0),
                   metrics={k: Summary.from_json(v) for k, v in data.get("metrics", {}).items()})


@dataclass
class RunMetrics(_FromJson):
    """Metrics of one run as listed by the experiment's metrics (a failed run's too, flagged by ``outcome``)."""

    run_id: int
    mode: str
    repetition: int
    status: str
    metrics: dict[str, Any]
    outcome: str = ""
    stopped_at: Optional[list[float]] = None


@dataclass
class Outcomes:
    """How the runs of one mode ended: ``counts`` per outcome (``success``, ``collision``, ``timeout``,
    ``error`` ...) and the success rate over the runs that ended in the job's own outcomes (``success``:
    ``n``, ``k``, ``rate``, ``ci_low``, ``ci_high`` — a Wilson 95% interval)."""

    runs: int
    counts: dict[str, int]
    success: dict[str, Any]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "Outcomes":
        return cls(runs=data.get("runs", 0), counts=dict(data.get("counts", {})), success=dict(data.get("success", {})))


@dataclass
class DirectComparison:
    """The paper's direct comparison "ST" of one repetition: the field path against the simulated one.

    ``metrics`` holds ``deviation_mean_m``, ``deviation_max_m``, ``hausdorff_m``
    and ``frechet_m``.
    """

    repetition: int
    sim_run_id: int
    twb_run_id: int
    metrics: dict[str, Any]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "DirectComparison":
        keys = ("repetition", "sim_run_id", "twb_run_id")
        return cls(*(data[k] for k in keys), metrics={k: v for k, v in data.items() if k not in keys})


@dataclass
class ExperimentMetrics:
    """``GET /experiments/{id}/metrics``: per run, aggregates per mode, direct sim-vs-twb, planned path's."""

    experiment_id: int
    status: str
    planned: Optional[dict[str, Any]]
    runs: list[RunMetrics]
    aggregates: dict[str, ModeAggregate]
    direct: list[DirectComparison]
    outcomes: dict[str, Outcomes] = _field(default_factory=dict)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "ExperimentMetrics":
        return cls(
            experiment_id=data["experiment_id"], status=data["status"], planned=data.get("planned"),
            runs=[RunMetrics.from_json(r) for r in data.get("runs", [])],
            aggregates={m: ModeAggregate.from_json(a) for m, a in data.get("aggregates", {}).items()},
            direct=[DirectComparison.from_json(d) for d in data.get("direct", [])],
            outcomes={m: Outcomes.from_json(o) for m, o in data.get("outcomes", {}).items()},
        )


@dataclass
class ComparedExperiment(_FromJson):
    """An experiment of a comparison: its ``label`` and ``problem``, and the ``configuration`` its runs are
    compared as (the label, or ``#<id> <label>`` where two of the selection share the label and the problem)."""

    id: int
    label: str
    problem: str
    configuration: str
    status: str = ""
    environment: str = ""
    planner: Optional[str] = None
    modes: list[str] = _field(default_factory=list)
    repetitions: int = 1
    seed: int = 0
    robots: int = 1


@dataclass
class ConfigurationOutcome(_FromJson):
    """How the runs of one configuration in one mode ended, over its ``experiments``: ``counts`` per outcome,
    ``counted`` (success or a failure) and ``success`` (``n``, ``k``, ``rate``, ``ci_low``, ``ci_high``: the
    Wilson interval over the distinct counted runs; ``identical``: identical repetitions counted once)."""

    configuration: str
    mode: str
    experiments: list[int]
    runs: int
    counts: dict[str, int]
    counted: int
    success: dict[str, Any]
    identical: bool = False


@dataclass
class ComparisonRow(_FromJson):
    """One comparison of configurations ``a`` and ``b`` on ``metric`` in ``mode``: on ``problem``, or pooled
    over ``n_problems`` problems (``problem`` empty, :attr:`pooled`).  The columns of a study's
    ``comparisons.csv`` (:data:`planners.comparisons.COLUMNS`, :attr:`COLUMNS`), in the metric's unit (a rate
    as a fraction); ``diff`` is a − b; None where there is no value (no test, no interval)."""

    #: the columns, in order (a study's comparisons.csv)
    COLUMNS: ClassVar[tuple[str, ...]] = (
        "metric", "mode", "a", "b", "n_a", "n_b", "mean_a", "mean_b", "diff", "ci_low", "ci_high", "test", "p",
        "p_holm", "effect", "effect_size", "paired", "runs_a", "runs_b", "family_size", "problem", "n_problems",
        "favour_a", "favour_b", "heterogeneity_i2", "heterogeneity_p", "n_needed", "needed_unit", "note")

    metric: str
    mode: str
    a: str
    b: str
    n_a: int
    n_b: int
    mean_a: Optional[float]
    mean_b: Optional[float]
    diff: Optional[float]
    ci_low: Optional[float]
    ci_high: Optional[float]
    test: str
    p: Optional[float]
    p_holm: Optional[float]
    effect: str
    effect_size: Optional[float]
    paired: bool
    runs_a: int
    runs_b: int
    family_size: int
    problem: str
    n_problems: int
    favour_a: Optional[int]
    favour_b: Optional[int]
    heterogeneity_i2: Optional[float]
    heterogeneity_p: Optional[float]
    n_needed: Optional[int]
    needed_unit: str
    note: str

    @property
    def pooled(self) -> bool:
        """Over problems (True), or on one problem."""
        return not self.problem

    def significant(self, alpha: float = 0.05) -> bool:
        """Holm-adjusted p-value at most ``alpha``."""
        return self.p_holm is not None and self.p_holm <= alpha

    def row(self) -> dict[str, Any]:
        """The row as a dict in :attr:`COLUMNS` order (a study's comparisons.csv row, None for an empty cell)."""
        return {c: getattr(self, c) for c in self.COLUMNS}


@dataclass
class ComparisonReport:
    """``GET /api/v1/comparisons`` (:meth:`Client.compare`): the experiments, how each configuration's runs
    ended (``outcomes``) and the comparisons (``rows``: per metric, mode and pair, the pooled one first when
    there are at least ``min_problems`` problems, then each problem's), with ``method``: how to read them."""

    experiments: list[ComparedExperiment]
    configurations: list[str]
    problems: list[str]
    metrics: list[str]
    outcomes: list[ConfigurationOutcome]
    rows: list[ComparisonRow]
    method: str = ""
    test: str = "t"
    family: str = "metric"
    confidence: float = 0.95
    n_resamples: int = 9999
    seed: int = 0
    min_problems: int = 3

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "ComparisonReport":
        plain = {k: data[k] for k in ("method", "test", "family", "confidence", "n_resamples", "seed",
                                      "min_problems") if k in data}
        return cls(experiments=[ComparedExperiment.from_json(e) for e in data.get("experiments", [])],
                   configurations=list(data.get("configurations", [])), problems=list(data.get("problems", [])),
                   metrics=list(data.get("metrics", [])),
                   outcomes=[ConfigurationOutcome.from_json(o) for o in data.get("outcomes", [])],
                   rows=[ComparisonRow.from_json(r) for r in data.get("rows", [])], **plain)

    def pooled(self) -> list[ComparisonRow]:
        """The comparisons over problems (none with fewer than ``min_problems`` problems)."""
        return [r for r in self.rows if r.pooled]

    def per_problem(self, problem: Optional[str] = None) -> list[ComparisonRow]:
        """The comparisons on one problem each (every problem's, or ``problem``'s)."""
        return [r for r in self.rows if not r.pooled and (problem is None or r.problem == problem)]

    def get(self, metric: str, mode: str, a: str, b: str, problem: Optional[str] = None) -> Optional[ComparisonRow]:
        """The row of ``a`` against ``b`` (either order: the signs are as stored) on ``problem``, or without one
        the pooled row; None where there is none."""
        return next((r for r in self.rows if (r.metric, r.mode) == (metric, mode) and {r.a, r.b} == {a, b}
                     and r.problem == (problem or "")), None)

    def table(self) -> list[dict[str, Any]]:
        """Every row as a dict in :attr:`ComparisonRow.COLUMNS` order (write it as CSV: a study's
        comparisons.csv)."""
        return [r.row() for r in self.rows]


@dataclass
class Message(_FromJson):
    """A protocol line sent to (``>``) or received from (``<``) a robot, at experiment time ``t`` (s)."""

    t: Optional[float]
    direction: str
    line: str
    t_estimated: bool = False


@dataclass
class ObstacleTracks:
    """Where a run's moving obstacles were (``GET /api/v1/runs/{id}/obstacles``).

    ``tracks[k]``: ``(T, 4)`` t, x, y, theta (s on the run's clock, m, m, rad) of the environment's
    ``moving_obstacles[k]``, ``radii[k]`` its radius (m).  ``exact`` False: a field run's obstacle robots as
    the tracker saw them (robots of the run's radius); True: the exact tracks, sampled over the run (a
    simulation's, or a field run's without stored ones).
    """

    run_id: int
    exact: bool
    tracks: list[np.ndarray]
    radii: list[float]

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "ObstacleTracks":
        obstacles = data.get("obstacles") or []
        return cls(int(data["run_id"]), bool(data["exact"]),
                   [np.asarray(o["poses"], dtype=float).reshape(-1, 4) for o in obstacles],
                   [float(o["radius"]) for o in obstacles])


@dataclass
class Subfield(_FromJson):
    """One of the four 1.8 m sub-fields: state, environment built on it, robot, current run and the last run
    since the testbed started (yours only)."""

    id: int
    state: str
    environment: Optional[str] = None
    robot_id: Optional[str] = None
    run_id: Optional[int] = None
    last_run_id: Optional[int] = None
    origin: list[float] = _field(default_factory=list)
    size: list[float] = _field(default_factory=list)


@dataclass
class Robot(_FromJson):
    """A registered robot: a field robot on a sub-field or one of the simulation pool."""

    robot_id: str
    host: str
    port: int
    backend: str
    pool: str
    status: str
    platform: str = ""
    profile: str = ""
    origin: list[float] = _field(default_factory=list)
    area: list[float] = _field(default_factory=list)
    subfield: Optional[int] = None
    last_seen: Optional[datetime] = None
    #: why an offline robot is offline
    status_reason: Optional[str] = None
    #: the last tracked pose ``[t, x, y, theta]`` in field coordinates (s, m, m, rad), if any (not shown while it
    #: runs someone else's run)
    last_pose: Optional[list[float]] = None

    _conv = {"last_seen": _dt}


@dataclass
class Program(_FromJson):
    """An uploaded planner program (docs/uploads.md): how it runs, not its content."""

    id: int
    name: str
    kind: str
    owner: str = ""
    interpreter: Optional[str] = None
    args: list[str] = _field(default_factory=list)
    size: int = 0
    sha256: str = ""
    #: declared at upload: runs once per repetition with its planner seed (else once per experiment)
    stochastic: bool = False
    created_at: Optional[datetime] = None

    _conv = {"created_at": _dt}


@dataclass
class User(_FromJson):
    """A testbed user; ``token`` only when it was just created (shown once)."""

    id: int
    name: str
    is_admin: bool
    created_at: Optional[datetime] = None
    token: Optional[str] = None

    _conv = {"created_at": _dt}
