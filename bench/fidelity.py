"""Field fidelity: the paper's sim-vs-field findings over many seeds and environments, offline.

A study's runs are reproduced in this process, exactly as the testbed runs them
(the same planning call with the robot radius plus the planning margin, the
same path on the wire, the same per-run noise seeds, the same metrics), but
without a server: the simulation core (:class:`robot_agent.sim.SimCore`) drives
one robot per run.  The result is a :class:`client_sdk.study.StudyData`, so the
findings (:func:`client_sdk.study.paper_findings`) apply to it as they do to a
study the testbed ran.

    python bench/fidelity.py paper --seeds 0-19             # held-counts of the nine findings
    python bench/fidelity.py varied --seeds 0-9             # the varied environments (corridors, clutter, open)
    python bench/fidelity.py ablate --seeds 0-9             # one profile change at a time
    python bench/fidelity.py figures --out docs/img         # the figures of docs/fidelity.md

Profile overrides are ``section.key=value`` (``field.tracker_latency_s=0``).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Iterable, Optional

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from client_sdk.study import StudyData, StudySpec, paper_findings, paper_spec  # noqa: E402
from client_sdk.study._collect import flat_metrics  # noqa: E402
from planners import load_environment, parse_environment, plan_path  # noqa: E402
from robot_agent.backends import make_backend  # noqa: E402
from robot_agent.frames import field_layout  # noqa: E402
from robot_agent.noise import path_key  # noqa: E402
from robot_agent.params import robot_params  # noqa: E402
from robot_agent.protocol import decode_path, encode_path  # noqa: E402
from robot_agent.robot_profile import load_profile  # noqa: E402
from robot_agent.sim import SimCore, State  # noqa: E402
from robot_agent.world import World  # noqa: E402
from server.pipeline.compute import compare_runs, measure_run  # noqa: E402
from server.store.experiments import run_seed  # noqa: E402

ROBOT_RADIUS, PLANNING_MARGIN = 0.045, 0.02  # the testbed's defaults (server/core/settings.py)
BACKEND = {"sim": "ideal", "twb": "field"}


# ---------------------------------------------------------------- environments of our own


def _block(x: float, y: float, w: float, h: float, a: float = 0.0) -> dict[str, float]:
    return {"x": x, "y": y, "w": w, "h": h, "angle": a}


def varied_environments() -> list[dict[str, Any]]:
    """Environments unlike the paper's two: corridors, clutter, an open field, a zig-zag."""
    corridors = {"name": "corridors", "size": [1.8, 1.8], "blocks": [
        _block(0.55, 0.6, 0.1, 1.2), _block(1.25, 1.2, 0.1, 1.2), _block(0.9, 0.05, 0.1, 0.1)]}
    rng = np.random.default_rng(11)
    clutter_blocks = []
    for _ in range(14):
        x, y = rng.uniform(0.3, 1.5, 2)
        clutter_blocks.append(_block(float(x), float(y), float(rng.uniform(0.06, 0.16)),
                                     float(rng.uniform(0.06, 0.16)), float(rng.uniform(0, math.pi))))
    clutter = {"name": "clutter", "size": [1.8, 1.8], "blocks": clutter_blocks}
    open_field = {"name": "open", "size": [1.8, 1.8], "blocks": [_block(0.9, 0.9, 0.2, 0.2, 0.3)]}
    zigzag = {"name": "zigzag", "size": [1.8, 1.8], "blocks": [
        _block(0.45, 0.55, 0.9, 0.08), _block(1.35, 0.95, 0.9, 0.08), _block(0.45, 1.35, 0.9, 0.08)]}
    return [corridors, clutter, open_field, zigzag]


def random_plans(env_data: dict[str, Any], n: int, seed: int, min_dist: float = 0.9) -> list[dict[str, Any]]:
    """``n`` start/goal pairs drawn uniformly in free space at least ``min_dist`` apart."""
    from planners import distance_to_obstacles

    env = parse_environment(env_data)
    rng = np.random.default_rng(seed)
    clear = ROBOT_RADIUS + PLANNING_MARGIN + 0.02
    out: list[dict[str, Any]] = []
    while len(out) < n:
        p = rng.uniform(0.1, 1.7, (2, 2))
        if math.dist(p[0], p[1]) < min_dist or (distance_to_obstacles(env, p) < clear).any():
            continue
        a = math.atan2(p[1, 1] - p[0, 1], p[1, 0] - p[0, 0])
        out.append({"name": f"r{len(out)}", "start": [*map(float, p[0]), a],
                    "goal": [*map(float, p[1]), float(rng.uniform(-math.pi, math.pi))]})
    return out


# ---------------------------------------------------------------- one run, as the testbed runs it


def profile_with(overrides: Optional[dict[str, float]] = None, name: str = "bebot") -> dict[str, Any]:
    """The profile ``name`` with ``{"section.key": value}`` overrides."""
    prof = copy.deepcopy(load_profile(name))
    for k, v in (overrides or {}).items():
        section, _, key = k.rpartition(".")
        (prof[section] if section else prof)[key] = v
    return prof


def drive(env_data: dict[str, Any], path: np.ndarray, start: list[float], backend: str, seed: int,
          params: Any) -> tuple[np.ndarray, Optional[float], Optional[float], str]:
    """Drive ``path`` from ``start`` at rest; returns (poses (N, 4), t START, t end, DONE/FAIL reason)."""
    sizes, world_of, origin, area = field_layout(1, "separate")
    world = World(sizes, world_of, origin, area, params.collision_radius_m)
    blocks = np.array([[b["x"], b["y"], b["w"], b["h"], b.get("angle", 0.0)] for b in env_data["blocks"]])
    world.set_blocks(0, blocks.reshape(-1, 5))
    core = SimCore(params, make_backend(backend, 1, params), world)
    core.place(0, tuple(start))
    core.set_path(0, path, path_key(seed))
    t0 = t1 = None
    end = "?"
    while core.state[0] == State.MOVING:
        for ev in core.advance(100_000):
            if ev.kind == "START":
                t0 = ev.t
            elif ev.kind in ("DONE", "FAIL"):
                t1, end = ev.t, ev.kind if ev.kind == "DONE" else ev.reason
    poses = core.poses.drain().get(0, np.zeros((0, 4)))
    return poses, t0, t1, end


def study_data(spec: StudySpec, overrides: Optional[dict[str, float]] = None,
               environments: Optional[dict[str, dict[str, Any]]] = None) -> StudyData:
    """``spec`` run offline (see the module docstring); ``environments`` adds environment files by name."""
    params = robot_params(profile_with(overrides))
    envs: dict[str, dict[str, Any]] = {}
    for e in spec.environments:
        if isinstance(e, str):
            envs[e] = (environments or {}).get(e) or load_environment(e).to_dict()
        else:
            envs[e["name"]] = dict(e)
    data = StudyData(spec, envs, [], [], [])
    experiments, rows, direct = data.experiments, data.rows, data.direct
    eid = rid = 0
    for name, env_data in envs.items():
        env = parse_environment(env_data)
        plans = spec.plans if spec.plans is not None else [type("P", (), {"name": p.name, "start": None})()
                                                           for p in env.plans]
        for plan in plans:
            if plan.start is None:
                p = env.plan(plan.name)
                start, goal = list(p.start), list(p.goal)
            else:
                start, goal = list(plan.start), list(plan.goal)
            if len(start) < 3:
                start.append(math.atan2(goal[1] - start[1], goal[0] - start[0]))
            for planner in spec.planners:
                eid += 1
                r = plan_path(env, start, goal, planner.name, robot_radius=ROBOT_RADIUS + PLANNING_MARGIN,
                              params=planner.params, seed=spec.seed)
                planned = np.round(r.path, 6)
                wire = decode_path(encode_path(planned))
                ident = {"study": spec.name, "experiment_id": eid, "environment": name, "plan": plan.name,
                         "planner": planner.name}
                run_ids = []
                poses_of: dict[tuple[str, int], np.ndarray] = {}
                data_rows = []
                for rep in range(1, spec.repetitions + 1):
                    for mode in spec.modes:
                        rid += 1
                        run_ids.append(rid)
                        seed = run_seed(spec.seed, mode, rep)
                        poses, t0, t1, end = drive(env_data, wire, start, BACKEND[mode], seed, params)
                        row = {**ident, "run_id": rid, "mode": mode, "repetition": rep, "seed": seed,
                               "status": "completed" if end == "DONE" else "failed",
                               "error": "" if end == "DONE" else end.lower(), "t_start": t0, "t_end": t1}
                        if t0 is not None and t1 is not None:
                            inside = (poses[:, 0] >= t0 - 1e-9) & (poses[:, 0] <= t1 + 1e-9)
                            row.update(flat_metrics(measure_run(env_data, planned.tolist(), poses.tolist(), t0, t1,
                                                                goal, ROBOT_RADIUS, r.planning_time_s)))
                            poses_of[(mode, rep)] = poses[inside]
                        data_rows.append((rid, row))
                for rep in range(1, spec.repetitions + 1):
                    if ("sim", rep) in poses_of and ("twb", rep) in poses_of:
                        st = compare_runs(poses_of[("sim", rep)].tolist(), poses_of[("twb", rep)].tolist())
                        direct.append({**ident, "repetition": rep, **st})
                        for _, row in data_rows:
                            if row["repetition"] == rep:
                                row.update({f"st_{k}": v for k, v in st.items()})
                rows += [row for _, row in data_rows]
                experiments.append({**ident, "planner_params": planner.params, "start": start, "goal": goal,
                                    "status": "completed", "error": "", "planned_path": planned.tolist(),
                                    "planning_time_s": r.planning_time_s, "runs": run_ids})
                for rid_, row in data_rows:
                    if (row["mode"], row["repetition"]) in poses_of:
                        data.add_poses(rid_, poses_of[(row["mode"], row["repetition"])])
    return data


def paper(seed: int, overrides: Optional[dict[str, float]] = None) -> StudyData:
    """The paper's 48 runs with study seed ``seed``, offline."""
    return study_data(StudySpec.from_json({**paper_spec().to_json(), "seed": seed}, "paper"), overrides)


def varied(seed: int, overrides: Optional[dict[str, float]] = None, plans_per_env: int = 3) -> StudyData:
    """The varied environments, ``plans_per_env`` random start/goal pairs each (drawn with ``seed``)."""
    datas = []
    for env in varied_environments():
        spec = StudySpec.from_json({"name": "varied", "environments": [env], "planners": ["fmm", "fm2", "prm"],
                                    "plans": random_plans(env, plans_per_env, seed * 1000 + len(datas)),
                                    "repetitions": 2, "seed": seed}, "varied")
        datas.append(study_data(spec, overrides))
    return merge(datas)


def merge(datas: list[StudyData]) -> StudyData:
    """One StudyData of several (experiment and run ids renumbered)."""
    first = datas[0]
    out = StudyData(first.spec, {}, [], [], [])
    eid = rid = 0
    for d in datas:
        out.environments.update(d.environments)
        emap, rmap = {}, {}
        for e in d.experiments:
            eid += 1
            emap[e["experiment_id"]] = eid
            e = {**e, "experiment_id": eid, "runs": []}
            out.experiments.append(e)
        for r in d.rows:
            rid += 1
            rmap[r["run_id"]] = rid
            out.rows.append({**r, "experiment_id": emap[r["experiment_id"]], "run_id": rid})
        for x in d.direct:
            out.direct.append({**x, "experiment_id": emap[x["experiment_id"]]})
    return out


# ---------------------------------------------------------------- command line


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def _overrides(items: Iterable[str]) -> dict[str, float]:
    out = {}
    for item in items:
        k, _, v = item.partition("=")
        out[k] = float(v)
    return out


def _one(args: tuple[str, int, dict[str, float]]) -> dict[str, Any]:
    kind, seed, ov = args
    data = paper(seed, ov) if kind == "paper" else varied(seed, ov)
    found = paper_findings(data)
    return {"seed": seed, "held": {f.key: f.held for f in found}, "numbers": {f.key: f.numbers for f in found},
            "means": _means(data)}


def _means(data: StudyData) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for p in data.planners:
        for m in ("sim", "twb"):
            rows = [r for r in data.rows if r["planner"] == p and r["mode"] == m and r["status"] == "completed"]
            out[f"{p}/{m}"] = {k: float(np.mean([r[k] for r in rows if r.get(k) is not None]))
                               for k in ("length_ratio", "smoothness_ratio", "smoothness_rad", "deviation_mean_m",
                                         "execution_time_s", "clearance_min_m")}
            out[f"{p}/{m}"]["failed"] = sum(r["status"] != "completed" for r in data.rows
                                            if r["planner"] == p and r["mode"] == m)
    return out


def run_many(kind: str, seeds: list[int], overrides: dict[str, float], workers: int) -> list[dict[str, Any]]:
    jobs = [(kind, s, overrides) for s in seeds]
    if workers <= 1:
        return [_one(j) for j in jobs]
    with ProcessPoolExecutor(workers) as ex:
        return list(ex.map(_one, jobs))


def summarize(results: list[dict[str, Any]]) -> dict[str, Any]:
    keys = list(results[0]["held"])
    held = {k: sum(r["held"][k] for r in results) for k in keys}
    means: dict[str, dict[str, float]] = {}
    for g in results[0]["means"]:
        means[g] = {k: round(float(np.mean([r["means"][g][k] for r in results])), 4) for k in results[0]["means"][g]}
    return {"seeds": len(results), "held": held, "means": means}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=["paper", "varied"])
    ap.add_argument("--seeds", default="0-19")
    ap.add_argument("--set", action="append", default=[], help="profile override section.key=value")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--per-seed", action="store_true")
    a = ap.parse_args()
    results = run_many(a.what, _seeds(a.seeds), _overrides(a.set), a.workers)
    out = summarize(results)
    if a.per_seed:
        out["per_seed"] = [{"seed": r["seed"], "failed": [k for k, v in r["held"].items() if not v]} for r in results]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
