"""Study files: which environments, plans, planners, repetitions and modes to cross.

A study file is JSON (YAML too when PyYAML happens to be installed; it is not a
dependency)::

    {"name": "my-study",
     "environments": ["room", "blocks"],          # names, or environment files (objects) to create
     "plans": ["A", "B"],                          # plan names of each environment; omit for all of them
     "planners": ["fmm", "fm2", {"name": "prm", "params": {"samples": 800}}],
     "repetitions": 2, "modes": ["sim", "twb"], "seed": 0, "field": "sub"}

``plans`` may also hold explicit start/goal pairs, ``{"name": "C", "start":
[x, y, theta], "goal": [x, y, theta]}`` (m, rad), used in every environment.
Every combination environment x plan x planner is one experiment with
``repetitions`` runs per mode.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional

__all__ = ["PAPER", "PlannerSpec", "PlanSpec", "StudySpec", "StudySpecError", "load_spec", "paper_spec"]

_KEYS = {"name", "description", "environments", "plans", "planners", "repetitions", "modes", "seed", "field"}


class StudySpecError(ValueError):
    """A study file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class PlannerSpec:
    """A planner by name with its parameters (empty: the planner's defaults)."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class PlanSpec:
    """A start/goal pair: a plan name of the environment, or explicit poses (m, rad)."""

    name: str
    start: Optional[list[float]] = None
    goal: Optional[list[float]] = None


@dataclass(frozen=True)
class StudySpec:
    """A cross-product study; see the module docstring for the file format."""

    name: str
    environments: list[Any]
    planners: list[PlannerSpec]
    plans: Optional[list[PlanSpec]] = None
    repetitions: int = 1
    modes: list[str] = field(default_factory=lambda: ["sim", "twb"])
    seed: int = 0
    field: str = "sub"
    description: str = ""

    def environment_names(self) -> list[str]:
        return [e if isinstance(e, str) else e["name"] for e in self.environments]

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["planners"] = [p if p["params"] else p["name"] for p in d["planners"]]
        if self.plans is not None:
            d["plans"] = [p["name"] if p["start"] is None else p for p in d["plans"]]
        return d

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
        envs = data.get("environments")
        if not isinstance(envs, list) or not envs:
            raise bad("`environments` must be a non-empty list of names or environment objects")
        for i, e in enumerate(envs):
            if not (isinstance(e, str) and e) and not (isinstance(e, Mapping) and isinstance(e.get("name"), str)):
                raise bad(f"environments[{i}] must be a name or an environment object with a `name`")
        planners = data.get("planners")
        if not isinstance(planners, list) or not planners:
            raise bad("`planners` must be a non-empty list of names or {\"name\", \"params\"} objects")
        pspecs = []
        for i, p in enumerate(planners):
            if isinstance(p, str) and p:
                pspecs.append(PlannerSpec(p))
            elif isinstance(p, Mapping) and isinstance(p.get("name"), str) and isinstance(p.get("params", {}), Mapping):
                pspecs.append(PlannerSpec(p["name"], dict(p.get("params", {}))))
            else:
                raise bad(f"planners[{i}] must be a name or {{\"name\": ..., \"params\": {{...}}}}")
        plans = data.get("plans")
        plan_specs = None
        if plans is not None:
            if not isinstance(plans, list) or not plans:
                raise bad("`plans` must be a non-empty list of plan names or {\"name\", \"start\", \"goal\"} objects")
            plan_specs = []
            for i, p in enumerate(plans):
                if isinstance(p, str) and p:
                    plan_specs.append(PlanSpec(p))
                elif isinstance(p, Mapping) and {"name", "start", "goal"} <= set(p):
                    for k in ("start", "goal"):
                        v = p[k]
                        if not (isinstance(v, list) and len(v) in (2, 3) and all(isinstance(x, (int, float)) for x in v)):
                            raise bad(f"plans[{i}].{k} must be [x, y] or [x, y, theta] (m, rad)")
                    plan_specs.append(PlanSpec(str(p["name"]), list(p["start"]), list(p["goal"])))
                else:
                    raise bad(f"plans[{i}] must be a plan name or {{\"name\", \"start\", \"goal\"}}")
        reps = data.get("repetitions", 1)
        if not isinstance(reps, int) or isinstance(reps, bool) or reps < 1:
            raise bad(f"`repetitions` must be an integer >= 1, got {reps!r}")
        modes = data.get("modes", ["sim", "twb"])
        if not isinstance(modes, list) or not modes or any(m not in ("sim", "twb") for m in modes) \
                or len(set(modes)) != len(modes):
            raise bad(f"`modes` must be a list of distinct \"sim\" and/or \"twb\", got {modes!r}")
        seed = data.get("seed", 0)
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise bad(f"`seed` must be an integer >= 0, got {seed!r}")
        fld = data.get("field", "sub")
        if fld not in ("sub", "full"):
            raise bad(f"`field` must be \"sub\" or \"full\", got {fld!r}")
        name = data.get("name", Path(source).stem if source != "study" else "study")
        if not isinstance(name, str) or not name:
            raise bad("`name` must be a non-empty string")
        return cls(name=name, environments=list(envs), planners=pspecs, plans=plan_specs, repetitions=reps,
                   modes=list(modes), seed=seed, field=fld, description=str(data.get("description", "")))

    @property
    def runs_per_experiment(self) -> int:
        return self.repetitions * len(self.modes)


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


def load_spec(source: str | Path) -> StudySpec:
    """``"paper"`` or a study file (``.json``; ``.yaml``/``.yml`` if PyYAML is installed)."""
    if str(source) == "paper":
        return paper_spec()
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
    return StudySpec.from_json(data, str(path))
