"""Study files: which environments, plans, planners, repetitions and modes to cross.

A study file is JSON (YAML too when PyYAML happens to be installed; it is not a
dependency)::

    {"name": "my-study",
     "environments": ["room", "blocks"],          # names, environment objects to create, or their files
     "plans": ["A", "B"],                          # plan names of each environment; omit for all of them
     "planners": ["fmm", "fm2", {"name": "prm", "params": {"samples": 800}}],
     "repetitions": 2, "modes": ["sim", "twb"], "seed": 0, "field": "sub",
     "jitter": {"xy_m": 0.005, "theta_rad": 0.02},  # optional: start-pose noise, so repetitions differ
     "controllers": ["schema", {"name": "pure_pursuit", "params": {"lookahead_m": 0.1}}],  # optional
     "profiles": [{"label": "noiseless", "tracker_noise_xy_m": 0},     # optional: field-robot variants
                  {"tracker_noise_xy_m": 0.003}]}

``plans`` may also hold explicit start/goal pairs, ``{"name": "C", "start":
[x, y, theta], "goal": [x, y, theta]}`` (m, rad), used in every environment,
or fleets of 2 to 16 robots (64 with ``"field": "full"``; :mod:`._fleet`; docs/study.md, "Fleets"):
``{"name": "swap4", "robots": [{"start": [...], "goal": [...]}, ...]}`` or
``{"name": "circle-8", "circle": {"robots": 8, "radius_m": 0.6}}`` (robots on a
circle around the environment's centre, each bound for the antipodal point).  A
study's plans are all single robots or all fleets; planners ``prioritized`` and
``lacam`` plan a fleet together, any other planner each robot alone.
A planner entry may carry a ``"label"`` (the configuration's name in tables;
default: the name, with the parameters if any) or, instead of a planner,
``"waypoints"``: ``{"name": "corner", "waypoints": [[x, y], ...]}`` sends the
explicit path start -> waypoints -> goal of each problem.  ``controllers`` (optional;
docs/controllers.md) are the robots' path-tracking controllers, a dimension beside the planners: a
name or ``{"name", "params", "label"}``; with them the configuration is the planner's and the
controller's, ``fmm/pure_pursuit``; without, the planner's alone (and every robot runs the default
controller).  ``profiles`` lists variants of the field robot: field parameters of the robot profile
(:data:`contract.overrides.OVERRIDE_LIMITS`, SI units) with an optional
``"label"`` (default: the overrides, ``tracker_noise_xy_m=0.003``; ``shipped``
for none); each configuration is then compared per variant, as
``fmm · noiseless``.  Every combination environment x plan x planner (x controller x profile
variant) is one experiment with ``repetitions`` runs per mode.

``worlds`` takes a generated world set (``twb worlds generate``; docs/gymnasium.md, "World sets"):
``"worlds": "worlds-cave-0/index.json"`` or ``{"index": "...", "split": "test"}`` (``train``, ``test``
or ``all``, the default), read relative to the study file: the split's worlds join ``environments``
(which may then be omitted) and the spec keeps each world's split and difficulty metrics, which the
report relates to success (:mod:`._worlds`).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional

from contract.overrides import OverrideError, check_overrides, overrides_label
from contract.vocabulary import Mode
from planners.compared import configuration_name

from ._fleet import MAX_ROBOTS, MAX_ROBOTS_SUB, Circle, is_pose, parse_circle, parse_robots
from ._fleet import finite as _finite

__all__ = ["ARENA", "CONTROLLERS", "DISCS", "FLEET", "FLEET_DISCS", "FLEET_PLANNER", "FLEET_PLANNERS", "JITTER_LIMITS", "NOISE", "PAPER", "PREDICTIVITY", "READY", "ControllerChoice",
           "PlannerSpec", "PlanSpec", "ProfileSpec", "StudySpec", "StudySpecError", "controllers_spec", "fleet_discs_spec", "fleet_spec",
           "load_spec", "noise_spec", "paper_spec", "predictivity_spec"]

_KEYS = {"name", "description", "environments", "plans", "planners", "repetitions", "modes", "seed", "field", "jitter",
         "worlds",
         "profiles", "controllers"}
_PLANNER_KEYS = {"name", "params", "label", "waypoints"}
_CONTROLLER_KEYS = {"name", "params", "label"}
#: the server's bounds of a job's start-pose jitter (standard deviations: m, rad)
JITTER_LIMITS = {"xy_m": 0.05, "theta_rad": 0.5}
_MAX_WAYPOINTS = 1000
#: the planner that plans a fleet's robots together (docs/server.md, "Multi-robot jobs")
FLEET_PLANNER = "prioritized"
#: every planner that plans a fleet's robots together, fleets only: prioritized planning and LaCAM* on a grid
FLEET_PLANNERS = (FLEET_PLANNER, "lacam")


class StudySpecError(ValueError):
    """A study file that cannot be used; the message names the file and the field."""


def _configuration(name: str, params: Mapping[str, Any], label: Optional[str]) -> str:
    """``label``, else ``name`` with its parameters (``fm2(saturation=0.1)``): as the server names a job's
    configuration (:func:`planners.compared.configuration_name`)."""
    return configuration_name(name, params, label)


@dataclass(frozen=True)
class PlannerSpec:
    """A configuration: a planner by name with its parameters (empty: the planner's defaults), or an explicit
    path through ``waypoints`` (m) from each problem's start to its goal; ``label`` names it in tables."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)
    label: Optional[str] = None
    waypoints: Optional[list[list[float]]] = None

    @property
    def configuration(self) -> str:
        """The configuration's name: ``label``, else the name with its parameters (``fm2(saturation=0.1)``)."""
        return _configuration(self.name, self.params, self.label)

    def to_json(self) -> Any:
        if not self.params and self.label is None and self.waypoints is None:
            return self.name
        out: dict[str, Any] = {"name": self.name}
        if self.params:
            out["params"] = dict(self.params)
        if self.label is not None:
            out["label"] = self.label
        if self.waypoints is not None:
            out["waypoints"] = [list(p) for p in self.waypoints]
        return out


@dataclass(frozen=True)
class ControllerChoice:
    """A controller of a study (docs/controllers.md): its name and parameters (SI units; empty: its defaults);
    ``label`` names it in configurations."""

    name: str
    params: dict[str, float] = field(default_factory=dict)
    label: Optional[str] = None

    @property
    def configuration(self) -> str:
        """``label``, else the name with its parameters (``pure_pursuit(lookahead_m=0.1)``)."""
        return _configuration(self.name, self.params, self.label)

    def to_json(self) -> Any:
        if not self.params and self.label is None:
            return self.name
        return {"name": self.name, **({"params": dict(self.params)} if self.params else {}),
                **({"label": self.label} if self.label is not None else {})}


@dataclass(frozen=True)
class PlanSpec:
    """A problem: a plan name of the environment, explicit start and goal poses (m, rad), or a fleet of robots
    (:mod:`._fleet`): explicit ``robots`` (``{"start", "goal"}`` each) or a generated ``circle``."""

    name: str
    start: Optional[list[float]] = None
    goal: Optional[list[float]] = None
    robots: Optional[list[dict[str, list[float]]]] = None
    circle: Optional[Circle] = None

    @property
    def fleet(self) -> bool:
        """Several robots (``robots`` or ``circle``)."""
        return self.robots is not None or self.circle is not None

    @property
    def robot_count(self) -> int:
        """How many robots the problem has (1 for a single robot)."""
        if self.circle is not None:
            return self.circle.robots
        return len(self.robots) if self.robots is not None else 1

    def to_json(self) -> Any:
        if self.robots is not None:
            return {"name": self.name, "robots": [dict(r) for r in self.robots]}
        if self.circle is not None:
            return {"name": self.name, "circle": self.circle.to_json()}
        if self.start is None:
            return self.name
        return {"name": self.name, "start": self.start, "goal": self.goal}


@dataclass(frozen=True)
class ProfileSpec:
    """A variant of the field robot: field parameters of its profile (SI units) and the variant's name."""

    label: str
    overrides: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"label": self.label, **self.overrides}


@dataclass(frozen=True)
class StudySpec:
    """A cross-product study; see the module docstring for the file format."""

    name: str
    environments: list[Any]
    planners: list[PlannerSpec]
    plans: Optional[list[PlanSpec]] = None
    repetitions: int = 1
    modes: list[str] = field(default_factory=lambda: [Mode.SIM.value, Mode.TWB.value])
    seed: int = 0
    field: str = "sub"
    description: str = ""
    jitter: Optional[dict[str, float]] = None
    profiles: Optional[list[ProfileSpec]] = None
    controllers: Optional[list[ControllerChoice]] = None
    #: a world set's ``{"index": path, "split": train|test|all, "worlds": {name: {"split", "difficulty"}}}``
    worlds: Optional[dict[str, Any]] = None

    def environment_names(self) -> list[str]:
        return [e if isinstance(e, str) else e["name"] for e in self.environments]

    def configurations(self) -> list[tuple[PlannerSpec, Optional[ControllerChoice], str]]:
        """Every planner x controller with its configuration name, in study order."""
        if self.controllers is None:
            return [(p, None, p.configuration) for p in self.planners]
        return [(p, c, f"{p.configuration}/{c.configuration}") for p in self.planners for c in self.controllers]

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["planners"] = [p.to_json() for p in self.planners]
        if self.jitter is None:
            del d["jitter"]
        if self.profiles is None:
            del d["profiles"]
        else:
            d["profiles"] = [p.to_json() for p in self.profiles]
        if self.controllers is None:
            del d["controllers"]
        else:
            d["controllers"] = [c.to_json() for c in self.controllers]
        if self.worlds is None:
            del d["worlds"]
        if self.plans is not None:
            d["plans"] = [p.to_json() for p in self.plans]
        return d

    @property
    def fleet(self) -> bool:
        """The study's problems are fleets of robots (``robots`` or ``circle`` plans; docs/study.md)."""
        return self.plans is not None and any(p.fleet for p in self.plans)

    @classmethod
    def from_json(cls, data: Any, source: str = "study") -> "StudySpec":
        """Validate a decoded study file; :class:`StudySpecError` names ``source`` and the field."""
        def bad(msg: str) -> StudySpecError:
            return StudySpecError(f"{source}: {msg}")

        if not isinstance(data, Mapping):
            raise bad("must be a JSON object with environments, planners, ...")
        unknown = sorted(set(data) - _KEYS)
        if unknown:
            raise bad(f"unknown key(s) {', '.join(unknown)} (allowed: {', '.join(sorted(_KEYS))})")
        worlds = _worlds(data.get("worlds"), bad)
        envs = data.get("environments", [] if worlds is not None else None)
        if not isinstance(envs, list) or not (envs or worlds):
            raise bad("`environments` must be a non-empty list of names or environment objects")
        if worlds is not None and not envs:
            raise bad(f"`worlds`: split {worlds['split']!r} of {worlds['index']} has no worlds")
        for i, e in enumerate(envs):
            if not (isinstance(e, str) and e) and not (isinstance(e, Mapping) and isinstance(e.get("name"), str)):
                raise bad(f"environments[{i}] must be a name or an environment object with a `name`")
        planners = data.get("planners")
        if not isinstance(planners, list) or not planners:
            raise bad("`planners` must be a non-empty list of names or {\"name\", \"params\"} objects")
        pspecs = [_planner(p, f"planners[{i}]", bad) for i, p in enumerate(planners)]
        seen: dict[str, int] = {}
        for i, p in enumerate(pspecs):
            if p.configuration in seen:
                raise bad(f"planners[{i}] repeats planners[{seen[p.configuration]}] ({p.configuration}): give each "
                          "configuration once, or a distinct \"label\"")
            seen[p.configuration] = i
        plans = data.get("plans")
        plan_specs = None
        if plans is not None:
            if not isinstance(plans, list) or not plans:
                raise bad("`plans` must be a non-empty list of plan names or {\"name\", \"start\", \"goal\"} objects")
            plan_specs = [_plan(p, f"plans[{i}]", bad) for i, p in enumerate(plans)]
        reps = data.get("repetitions", 1)
        if not isinstance(reps, int) or isinstance(reps, bool) or reps < 1:
            raise bad(f"`repetitions` must be an integer >= 1, got {reps!r}")
        modes = data.get("modes", [Mode.SIM.value, Mode.TWB.value])
        if not isinstance(modes, list) or not modes or any(m not in tuple(Mode) for m in modes) \
                or len(set(modes)) != len(modes):
            raise bad(f"`modes` must be a list of distinct \"sim\" and/or \"twb\", got {modes!r}")
        seed = data.get("seed", 0)
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise bad(f"`seed` must be an integer >= 0, got {seed!r}")
        fld = data.get("field", "sub")
        if fld not in ("sub", "full"):
            raise bad(f"`field` must be \"sub\" or \"full\", got {fld!r}")
        jitter = _jitter(data.get("jitter"), bad)
        profiles = _profiles(data.get("profiles"), bad)
        if profiles is not None and "twb" not in modes:
            raise bad("`profiles` vary the field robot: `modes` must include \"twb\"")
        controllers = _controllers(data.get("controllers"), bad)
        _check_fleet(plan_specs, pspecs, jitter, fld, bad)
        name = data.get("name", Path(source).stem if source != "study" else "study")
        if not isinstance(name, str) or not name:
            raise bad("`name` must be a non-empty string")
        return cls(name=name, environments=list(envs), planners=pspecs, plans=plan_specs, repetitions=reps,
                   modes=list(modes), seed=seed, field=fld, description=str(data.get("description", "")),
                   jitter=jitter, profiles=profiles, controllers=controllers, worlds=worlds)

    @property
    def runs_per_experiment(self) -> int:
        return self.repetitions * len(self.modes)


def _plan(p: Any, where: str, bad: Any) -> PlanSpec:
    """One entry of ``plans``: a plan name, ``{"name", "start", "goal"}``, or a fleet: ``{"name", "robots"}`` or
    ``{"name", "circle"}`` (:mod:`._fleet`)."""
    if isinstance(p, str) and p:
        return PlanSpec(p)
    forms = "a plan name, {\"name\", \"start\", \"goal\"}, {\"name\", \"robots\"} or {\"name\", \"circle\"}"
    if not isinstance(p, Mapping) or "name" not in p:
        raise bad(f"{where} must be {forms}")
    kinds = [k for k in ("robots", "circle") if k in p] + (["start/goal"] if {"start", "goal"} & set(p) else [])
    if len(kinds) != 1:
        raise bad(f"{where} must be {forms}" + (f": give one of {', '.join(kinds)}, not both" if kinds else ""))
    if kinds[0] == "start/goal":
        if not {"start", "goal"} <= set(p):
            raise bad(f"{where} must be {forms}")
        for k in ("start", "goal"):
            if not is_pose(p[k]):
                raise bad(f"{where}.{k} must be [x, y] or [x, y, theta] (m, rad)")
        return PlanSpec(str(p["name"]), list(p["start"]), list(p["goal"]))
    if not (isinstance(p["name"], str) and p["name"]):
        raise bad(f"{where}.name must be a non-empty string")
    unknown = sorted(set(p) - {"name", kinds[0]})
    if unknown:
        raise bad(f"{where}: unknown key(s) {', '.join(unknown)} (allowed: name, {kinds[0]})")
    if kinds[0] == "robots":
        return PlanSpec(p["name"], robots=parse_robots(p["robots"], f"{where}.robots", bad))
    return PlanSpec(p["name"], circle=parse_circle(p["circle"], f"{where}.circle", bad))


def _check_fleet(plans: Optional[list[PlanSpec]], planners: list[PlannerSpec], jitter: Optional[dict[str, float]],
                 fld: str, bad: Any) -> None:
    """A study compares single robots or fleets, not both; ``prioritized`` plans fleets only; a fleet takes no
    explicit ``waypoints`` path and no start-pose ``jitter``, and a sub-field at most 16 robots (the server's
    rules for multi-robot jobs)."""
    problems = plans or []
    fleets = [i for i, p in enumerate(problems) if p.fleet]
    single = [i for i, p in enumerate(problems) if not p.fleet]
    if fleets and single:
        f, s = problems[fleets[0]], problems[single[0]]
        raise bad(f"plans[{fleets[0]}] ({f.name}) is a fleet of {f.robot_count} robots but plans[{single[0]}] "
                  f"({s.name}) is one robot: a study compares either single robots or fleets (their metrics "
                  "differ); make two studies")
    crowded = next((i for i in fleets if fld == "sub" and problems[i].robot_count > MAX_ROBOTS_SUB), None)
    if crowded is not None:
        raise bad(f"plans[{crowded}] ({problems[crowded].name}) has {problems[crowded].robot_count} robots: a "
                  f"sub-field holds at most {MAX_ROBOTS_SUB} (use \"field\": \"full\" for up to {MAX_ROBOTS})")
    names = [p.name for p in problems]
    twin = next((i for i, n in enumerate(names) if n in names[:i]), None)
    if twin is not None:
        raise bad(f"plans[{twin}] repeats the name of plans[{names.index(names[twin])}] ({names[twin]}): give "
                  "each problem its own name")
    for i, p in enumerate(planners):
        if p.name in FLEET_PLANNERS and not fleets:
            raise bad(f"planners[{i}]: `{p.name}` plans several robots together: it needs fleet problems "
                      "in `plans` ({\"name\", \"robots\"} or {\"name\", \"circle\"})")
        if p.waypoints is not None and fleets:
            raise bad(f"planners[{i}]: `waypoints` is an explicit path for one robot; a fleet study's "
                      "configurations are planners")
    if jitter is not None and fleets:
        raise bad("`jitter`: multi-robot jobs take no start-pose jitter (docs/server.md, \"Multi-robot jobs\")")


def _controllers(data: Any, bad: Any) -> Optional[list[ControllerChoice]]:
    """The study's ``controllers``: names or ``{"name", "params", "label"}`` objects, each configuration once."""
    if data is None:
        return None
    if not isinstance(data, list) or not data:
        raise bad("`controllers` must be a non-empty list of names or {\"name\", \"params\"} objects")
    out = []
    for i, c in enumerate(data):
        where = f"controllers[{i}]"
        name, params, label = _entry(c, where, _CONTROLLER_KEYS, "controller", bad)
        if not all(_finite(v) for v in params.values()):
            raise bad(f"{where}.params must be an object of numbers (SI units)")
        out.append(ControllerChoice(name, {k: float(v) for k, v in params.items()}, label))
    seen: dict[str, int] = {}
    for i, c in enumerate(out):
        if c.configuration in seen:
            raise bad(f"controllers[{i}] repeats controllers[{seen[c.configuration]}] ({c.configuration})")
        seen[c.configuration] = i
    return out


def _entry(p: Any, where: str, keys: set[str], what: str, bad: Any) -> tuple[str, Mapping[str, Any], Optional[str]]:
    """A ``planners`` or ``controllers`` entry's name, params and label: a name, or an object of ``keys``."""
    if isinstance(p, str) and p:
        return p, {}, None
    if not (isinstance(p, Mapping) and isinstance(p.get("name"), str) and p["name"]):
        raise bad(f"{where} must be a name or {{\"name\": ..., \"params\": {{...}}}}")
    unknown = sorted(set(p) - keys)
    if unknown:
        raise bad(f"{where}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(sorted(keys))})")
    params = p.get("params", {})
    if not isinstance(params, Mapping):
        raise bad(f"{where}.params must be an object of {what} parameters")
    label = p.get("label")
    if label is not None and not (isinstance(label, str) and label.strip()):
        raise bad(f"{where}.label must be a non-empty string")
    return p["name"], params, label


def _planner(p: Any, where: str, bad: Any) -> PlannerSpec:
    """One entry of ``planners``: a name, or an object with name and params, label or waypoints."""
    name, params, label = _entry(p, where, _PLANNER_KEYS, "planner", bad)
    waypoints = p.get("waypoints") if isinstance(p, Mapping) else None
    if waypoints is not None:
        if params:
            raise bad(f"{where}: give either `params` (a planner) or `waypoints` (an explicit path), not both")
        if not isinstance(waypoints, list) or len(waypoints) > _MAX_WAYPOINTS or not all(
                isinstance(w, list) and len(w) == 2 and all(_finite(x) for x in w) for w in waypoints):
            raise bad(f"{where}.waypoints must be a list of at most {_MAX_WAYPOINTS} [x, y] points (m)")
        waypoints = [[float(x) for x in w] for w in waypoints]
    return PlannerSpec(name, dict(params), label, waypoints)


def _jitter(j: Any, bad: Any) -> Optional[dict[str, float]]:
    """``{"xy_m", "theta_rad"}``: standard deviations of the start pose (m, rad), within the server's bounds."""
    if j is None:
        return None
    if not isinstance(j, Mapping) or not j:
        raise bad("`jitter` must be an object such as {\"xy_m\": 0.005, \"theta_rad\": 0.02}")
    unknown = sorted(set(j) - set(JITTER_LIMITS))
    if unknown:
        raise bad(f"jitter: unknown key(s) {', '.join(unknown)} (allowed: xy_m, theta_rad)")
    out = {}
    for k, hi in JITTER_LIMITS.items():
        v = j.get(k, 0.0)
        if not _finite(v) or not 0 <= v <= hi:
            unit = "m" if k == "xy_m" else "rad"
            raise bad(f"jitter.{k} must be a number in [0, {hi:g}] ({unit}, a standard deviation), got {v!r}")
        out[k] = float(v)
    return out


def _profiles(p: Any, bad: Any) -> Optional[list[ProfileSpec]]:
    """``profiles``: a non-empty list of ``{"label"?, <field parameter>: value, ...}``, each checked against the
    parameter's physical range, with distinct labels."""
    if p is None:
        return None
    if not isinstance(p, list) or not p:
        raise bad("`profiles` must be a non-empty list of objects of field parameters, e.g. "
                  "[{\"label\": \"noiseless\", \"tracker_noise_xy_m\": 0}]")
    out: list[ProfileSpec] = []
    for i, entry in enumerate(p):
        if not isinstance(entry, Mapping):
            raise bad(f"profiles[{i}] must be an object of field parameters with an optional \"label\"")
        label = entry.get("label")
        if label is not None and not (isinstance(label, str) and label.strip()):
            raise bad(f"profiles[{i}].label must be a non-empty string")
        try:
            overrides = check_overrides({k: v for k, v in entry.items() if k != "label"}, f"profiles[{i}]")
        except OverrideError as exc:
            raise bad(str(exc)) from None
        spec = ProfileSpec(label or overrides_label(overrides), overrides)
        twin = next((j for j, o in enumerate(out) if o.label == spec.label), None)
        if twin is not None:
            raise bad(f"profiles[{i}] has the label of profiles[{twin}] ({spec.label}): give each variant a "
                      "distinct \"label\"")
        out.append(spec)
    return out


#: The paper's study: both environments x plans A and B x FMM, FM², PRM x 2 repetitions x {sim, twb}.
PAPER: dict[str, Any] = {
    "name": "paper",
    "description": "Tanoto et al., Teletesting: both environments x plans A, B x FMM, FM2, PRM x 2 repetitions "
                   "x simulation and Teleworkbench (48 runs)",
    "environments": ["room", "blocks"],
    "plans": ["A", "B"],
    "planners": ["fmm", "fm2", "prm"],
    "repetitions": 2,
    "modes": ["sim", "twb"],
    "seed": 0,
}


def paper_spec() -> StudySpec:
    """The paper's study (48 runs)."""
    return StudySpec.from_json(PAPER, "paper")


#: The noise study: FMM on the paper's problems, on the field robot as shipped and with more tracker noise,
#: slower motors, more wheel slip; 5 repetitions per variant and problem (80 field runs).
NOISE: dict[str, Any] = {
    "name": "noise",
    "description": "Sensor noise and control inaccuracies: FMM on both paper environments x plans A, B on the field "
                   "robot as shipped, with 3 mm tracker jitter, with 0.4 s motor lag and with 4x wheel slip, "
                   "5 repetitions each (80 field runs)",
    "environments": ["room", "blocks"],
    "plans": ["A", "B"],
    "planners": ["fmm"],
    "repetitions": 5,
    "modes": ["twb"],
    "seed": 0,
    "profiles": [
        {"label": "shipped"},
        {"label": "tracker 3 mm", "tracker_noise_xy_m": 0.003},
        {"label": "motor lag 0.4 s", "motor_time_constant_s": 0.4},
        {"label": "wheel slip x4", "wheel_noise_rel": 0.32, "wheel_noise_abs_m_s": 0.016},
    ],
}


def noise_spec() -> StudySpec:
    """The noise study (80 field runs; docs/fidelity.md, "Noise studies")."""
    return StudySpec.from_json(NOISE, "noise")


#: The ready controller study: one planner x every built-in controller x both paper environments x plans A, B
#: x 2 repetitions with start-pose jitter x sim and field (64 runs; about a minute on 2 cores under
#: `twb study controllers --embedded`).
CONTROLLERS: dict[str, Any] = {
    "name": "controllers",
    "description": "Controllers as a benchmark dimension: FMM paths tracked by the motor schema, pure pursuit, "
                   "regulated pure pursuit and Kanayama's controller, both paper environments, plans A and B, "
                   "2 repetitions with start-pose jitter, simulation and emulated field (64 runs)",
    "environments": ["room", "blocks"],
    "plans": ["A", "B"],
    "planners": ["fmm"],
    "controllers": ["schema", "pure_pursuit", "regulated_pure_pursuit", "kanayama"],
    "repetitions": 2,
    "modes": ["sim", "twb"],
    "seed": 0,
    "jitter": {"xy_m": 0.005, "theta_rad": 0.05},
}


def controllers_spec() -> StudySpec:
    """The ready controller study (64 runs)."""
    return StudySpec.from_json(CONTROLLERS, "controllers")


#: The ready predictivity study: FMM, FM² and PRM x every built-in controller (12 configurations) x both paper
#: environments x plans A, B x 2 repetitions x sim and field (192 runs; docs/fidelity.md, "Predictivity":
#: `twb study predictivity --embedded` writes predictivity.md, .json and .png).
PREDICTIVITY: dict[str, Any] = {
    "name": "predictivity",
    "description": "Does the simulation predict the field? FMM, FM² and PRM, each tracked by the motor schema, pure "
                   "pursuit, regulated pure pursuit and Kanayama's controller (12 configurations), both paper "
                   "environments, plans A and B, 2 repetitions, simulation and emulated field (192 runs)",
    "environments": ["room", "blocks"],
    "plans": ["A", "B"],
    "planners": ["fmm", "fm2", "prm"],
    "controllers": ["schema", "pure_pursuit", "regulated_pure_pursuit", "kanayama"],
    "repetitions": 2,
    "modes": ["sim", "twb"],
    "seed": 0,
}


def predictivity_spec() -> StudySpec:
    """The ready predictivity study (192 runs)."""
    return StudySpec.from_json(PREDICTIVITY, "predictivity")


#: An empty sub-field with two discs crossing its middle (inside a circle of radius 0.6 m around the centre, so
#: every robot of the fleet study starts and ends clear of them): the fleet study's obstacle scenario.
DISCS: dict[str, Any] = {
    "name": "discs",
    "size": [1.8, 1.8],
    "description": "An empty sub-field with two discs crossing its middle, one left and right (y = 1.05 m), one up "
                   "and down (x = 0.75 m): the fleet study's moving obstacles",
    "blocks": [],
    "moving_obstacles": [
        {"radius": 0.04, "waypoints": [[0.55, 1.05], [1.25, 1.05]], "speed": 0.1, "repeat": "pingpong"},
        {"radius": 0.04, "waypoints": [[0.75, 0.55], [0.75, 1.25]], "speed": 0.08, "repeat": "pingpong"},
    ],
}

#: The fleet study among moving discs (docs/study.md, "Moving discs: prioritized against FMM"; until the
#: scale study took its name, `twb study fleet`): prioritized planning against FMM per robot (uncoordinated) on the
#: circle benchmark with 2, 4 and 8 robots, in the empty sub-field and with two moving discs, 3 repetitions x sim and
#: field (72 runs; `twb study fleet-discs --embedded`).
FLEET_DISCS: dict[str, Any] = {
    "name": "fleet-discs",
    "description": "Robot counts x obstacle scenarios: prioritized (space-time, coordinated) against FMM per robot "
                   "(uncoordinated) on the circle benchmark with 2, 4 and 8 robots (radius 0.6 m, each bound for "
                   "the antipodal point), in the empty sub-field `swap` and in `discs` (two moving discs), "
                   "3 repetitions, simulation and emulated field (72 runs)",
    "environments": ["swap", DISCS],
    "plans": [{"name": f"circle-{n}", "circle": {"robots": n, "radius_m": 0.6}} for n in (2, 4, 8)],
    "planners": ["prioritized", "fmm"],
    "repetitions": 3,
    "modes": ["sim", "twb"],
    "seed": 0,
}

#: The whole field, empty: the fleet study's arena (3.6 m x 3.6 m, no blocks)
ARENA: dict[str, Any] = {
    "name": "arena",
    "size": [3.6, 3.6],
    "description": "The whole field, empty: the fleet study's arena for up to 64 robots",
    "blocks": [],
}

#: The ready fleet study (docs/study.md, "The fleet study"): LaCAM against prioritized planning and FMM per robot
#: (uncoordinated) on the circle benchmark with 4 to 64 robots on the whole field, 2 repetitions x sim and field
#: (60 runs; `twb study fleet --embedded`).
FLEET: dict[str, Any] = {
    "name": "fleet",
    "description": "Robot counts up to 64 on the whole field: LaCAM (complete, on a grid of robot-sized cells) "
                   "against prioritized planning (space-time, robot by robot) and FMM per robot (uncoordinated) on "
                   "the circle benchmark with 4, 8, 16, 32 and 64 robots (radius 1.5 m round the field's centre, "
                   "each bound for the antipodal point) in the empty arena, 2 repetitions, simulation and emulated "
                   "field (60 runs)",
    "environments": [ARENA],
    "plans": [{"name": f"circle-{n}", "circle": {"robots": n, "radius_m": 1.5}} for n in (4, 8, 16, 32, 64)],
    "planners": ["lacam", "prioritized", "fmm"],
    "repetitions": 2,
    "modes": ["sim", "twb"],
    "seed": 0,
    "field": "full",
}


def fleet_spec() -> StudySpec:
    """The ready fleet study (60 runs; docs/study.md, "The fleet study")."""
    return StudySpec.from_json(FLEET, "fleet")


def fleet_discs_spec() -> StudySpec:
    """The fleet study among moving discs (72 runs; docs/study.md, "Moving discs")."""
    return StudySpec.from_json(FLEET_DISCS, "fleet-discs")


#: our built-in single-robot planners in the planner study (``twb study planners``); OMPL's join them when the
#: ``ompl`` package is installed
OUR_PLANNERS = ("fmm", "fm2", "prm", "astar", "theta_star")


def planners_spec() -> StudySpec:
    """The ready planner study (docs/planners.md, "The planner study"): every built-in planner (OMPL's when the
    ``ompl`` package is installed) on the paper's environments and the three hard ones of
    :mod:`planners.problems` (narrow passage, clutter, zigzag), plans A and B, 3 repetitions (each with its own
    planner seed), simulation."""
    import importlib.util

    from planners.ompl_planners import OMPL_PLANNERS
    from planners.problems import HARD, _load

    planners = list(OUR_PLANNERS)
    if importlib.util.find_spec("ompl") is not None:
        planners += list(OMPL_PLANNERS)
    data = {"name": "planners",
            "description": "Every built-in planner (ours; OMPL's when installed) on room, blocks and the hard "
                           "problems narrow (a 0.15 m gap), clutter (30 random blocks) and zigzag (a serpentine), "
                           "plans A and B, 3 repetitions with their own planner seeds, simulation",
            "environments": ["room", "blocks", *(_load(name) for name in HARD)],
            "plans": ["A", "B"], "planners": planners, "repetitions": 3, "modes": ["sim"], "seed": 0}
    return StudySpec.from_json(data, "planners")


#: the ready studies by name (``twb study NAME``)
READY = {"paper": paper_spec, "noise": noise_spec, "controllers": controllers_spec, "predictivity": predictivity_spec,
         "fleet": fleet_spec, "fleet-discs": fleet_discs_spec, "planners": planners_spec}


def load_spec(source: str | Path) -> StudySpec:
    """A ready study by name (:data:`READY`: ``"paper"``, ``"noise"``, ``"controllers"``, ``"predictivity"``,
    ``"fleet"``, ``"fleet-discs"``, ``"planners"``) or a study
    file (``.json``; ``.yaml``/``.yml`` if PyYAML is installed)."""
    if str(source) in READY:
        return READY[str(source)]()
    path = Path(source)
    try:
        text = path.read_text()
    except OSError as exc:
        raise StudySpecError(f"cannot read study file {path}: {exc.strerror or exc}") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml  # type: ignore[import-untyped]
        except ImportError:
            raise StudySpecError(f"{path}: YAML study files need PyYAML (not a dependency); "
                                 "write the study as JSON instead") from None
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise StudySpecError(f"{path}: invalid YAML: {' '.join(str(exc).split())}") from None
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise StudySpecError(f"{path}: invalid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    return StudySpec.from_json(_environment_files(_world_set(data, path), path), str(path))


#: the splits a world set's index marks, and ``all``
WORLD_SPLITS = ("train", "test", "all")


def _world_set(data: Any, path: Path) -> Any:
    """A study file's ``worlds`` (an index.json path, or ``{"index", "split"}``) read relative to the study file:
    the split's worlds appended to ``environments`` as environment objects, and ``worlds`` replaced by what the
    spec keeps of them (:func:`_worlds`)."""
    ws = data.get("worlds") if isinstance(data, Mapping) else None
    if ws is None:
        return data
    where = f"{path}: `worlds`"
    given = ws if isinstance(ws, Mapping) else {"index": ws}
    index, split = given.get("index"), given.get("split", "all")
    if not isinstance(index, str) or not index or set(given) - {"index", "split"}:
        raise StudySpecError(f"{where} must be a world set's index.json path or {{\"index\": PATH, \"split\": "
                             f"\"train\"|\"test\"|\"all\"}}, got {ws!r}")
    if split not in WORLD_SPLITS:
        raise StudySpecError(f"{where}: split must be one of {', '.join(WORLD_SPLITS)}, got {split!r}")
    f = path.parent / index
    try:
        doc = json.loads(f.read_text())
        listed = doc["worlds"]
    except OSError as exc:
        raise StudySpecError(f"{where}: cannot read {f} (paths are relative to the study file; `twb worlds "
                             f"generate` writes one): {exc.strerror or exc}") from None
    except (json.JSONDecodeError, KeyError, TypeError):
        raise StudySpecError(f"{where}: {f} is not a world set's index.json (`twb worlds generate` writes one)") \
            from None
    envs, kept = [], {}
    for w in listed:
        if split != "all" and w.get("split") != split:
            continue
        try:
            envs.append(json.loads((f.parent / w["file"]).read_text()))
        except (OSError, json.JSONDecodeError, KeyError, TypeError) as exc:
            raise StudySpecError(f"{where}: world {w.get('name')!r} of {f}: cannot read its environment file: "
                                 f"{getattr(exc, 'strerror', None) or exc}") from None
        kept[w["name"]] = {"split": w.get("split"), "difficulty": w.get("difficulty") or {}}
    return {**data, "environments": [*data.get("environments", []), *envs],
            "worlds": {"index": index, "split": split, "worlds": kept}}


def _worlds(ws: Any, bad: Any) -> Optional[dict[str, Any]]:
    """The spec's record of a world set (what :func:`_world_set` made of a study file's ``worlds``)."""
    if ws is None:
        return None
    if not (isinstance(ws, Mapping) and isinstance(ws.get("index"), str) and ws.get("split") in WORLD_SPLITS
            and isinstance(ws.get("worlds"), Mapping)):
        raise bad("`worlds` names a world set's index.json, which only a study file can (load_spec reads it "
                  "relative to the file); in memory, give the worlds as `environments`")
    for name, w in ws["worlds"].items():
        diff = w.get("difficulty") if isinstance(w, Mapping) else None
        if not isinstance(diff, Mapping) or not all(isinstance(v, (int, float)) for v in diff.values()):
            raise bad(f"`worlds`: world {name!r} has no difficulty metrics")
    return {"index": ws["index"], "split": ws["split"],
            "worlds": {str(k): {"split": v.get("split"), "difficulty": dict(v["difficulty"])}
                       for k, v in ws["worlds"].items()}}


def _environment_files(data: Any, path: Path) -> Any:
    """The study file's ``environments`` with each entry that names a file (``*.json``, or a path with a ``/``)
    replaced by the environment object in it, read relative to the study file's directory, as ``twb submit
    --env FILE`` reads one."""
    envs = data.get("environments") if isinstance(data, Mapping) else None
    if not isinstance(envs, list):
        return data
    out = []
    for i, e in enumerate(envs):
        if isinstance(e, str) and (e.lower().endswith(".json") or "/" in e):
            f = path.parent / e
            try:
                e = json.loads(f.read_text())
            except OSError as exc:
                raise StudySpecError(f"{path}: environments[{i}]: cannot read environment file {f} (paths are "
                                     f"relative to the study file): {exc.strerror or exc}") from None
            except json.JSONDecodeError as exc:
                raise StudySpecError(f"{path}: environments[{i}]: {f}: invalid JSON: {exc.msg} at line "
                                     f"{exc.lineno} column {exc.colno}") from None
        out.append(e)
    return {**data, "environments": out}
