"""The figures of docs/fidelity.md, one function each (``python bench/fidelity_figures.py --out docs/img``).

Every figure is drawn from runs made as :mod:`bench.fidelity` makes them (the
testbed's planning call, wire path, seeds and metrics); lengths in metres on
the axes unless labelled, ratios performed / computed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from bench.fidelity import (MAIN, PLANNERS, PLANNING_MARGIN, ROBOT_RADIUS, ablate, drive, profile_with, run_many,
                            summarize, varied)  # noqa: E402
from contract.params import robot_params  # noqa: E402
from contract.protocol import decode_path, encode_path  # noqa: E402
from planners import load_environment, plan_path  # noqa: E402
from planners.metrics import path_length, smoothness  # noqa: E402
from robot_agent.engine.backends import make_backend  # noqa: E402
from robot_agent.engine.noise import path_key  # noqa: E402
from server.store.experiments import run_seed  # noqa: E402

__all__ = ["ablation", "corners", "figures", "findings", "tracker", "varied_paths", "weave", "zigzag"]

EMPTY = {"name": "empty", "size": [1.8, 1.8], "blocks": []}
COLORS = {"fmm": "#2ca02c", "fm2": "#9467bd", "prm": "#ff7f0e"}


def _draw_env(ax: Axes, env_data: dict[str, Any]) -> None:
    for b in env_data["blocks"]:
        ax.add_patch(Rectangle((b["x"] - b["w"] / 2, b["y"] - b["h"] / 2), b["w"], b["h"],
                               angle=math.degrees(b.get("angle", 0.0)), rotation_point="center", color="0.82", lw=0))
    ax.set_aspect("equal")


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path


def weave(out: Path) -> Path:
    """A PRM path (room, plan B, seed 0) driven by the field robot before this work and now."""
    env = load_environment("room")
    p = env.plan("B")
    start, goal = list(p.start), list(p.goal)
    r = plan_path(env, start, goal, "prm", robot_radius=ROBOT_RADIUS + PLANNING_MARGIN, seed=0)
    wire = decode_path(encode_path(np.round(r.path, 6)))
    fig = Figure(figsize=(12, 6.2))
    axes = fig.subplots(1, 2)
    sim = drive(env.to_dict(), wire, start, "ideal", run_seed(0, "sim", 1), robot_params(), truth=True)[4]
    for ax, (title, ov) in zip(axes, [("before (e2c6fc3): acts on the 0.1 s old fix", MAIN),
                                      ("now: latency compensated, steers 0.12 s ahead", {})]):
        _draw_env(ax, env.to_dict())
        poses, t0, t1, _, true = drive(env.to_dict(), wire, start, "field", run_seed(0, "twb", 1),
                                       robot_params(profile_with(ov)), truth=True)
        ax.plot(wire[:, 0], wire[:, 1], "k.--", lw=0.8, ms=4, label="computed (PRM)")
        ax.plot(sim[:, 1], sim[:, 2], color="#1f77b4", lw=1.2, label="simulation (S)")
        ax.plot(true[:, 1], true[:, 2], color="#d62728", lw=1.2, label="field robot, driven")
        ax.plot(poses[:, 1], poses[:, 2], ".", color="#ff9896", ms=1.5, label="field robot, tracker log")
        inside = poses[(poses[:, 0] >= t0) & (poses[:, 0] <= t1)]
        ratio = path_length(inside[:, 1:3]) / path_length(wire)
        kappa = smoothness(inside[:, 1:3]) / smoothness(wire[:, :2])
        ax.set_title(f"{title}\nT length ratio {ratio:.3f}, κ' ratio {kappa:.2f}", fontsize=10)
        ax.set_xlim(0.2, 1.6)
        ax.set_ylim(0.2, 1.6)
        ax.legend(loc="lower left", fontsize=8)
    fig.suptitle("room, plan B, PRM (seed 0): the same path, the same noise, before and after", fontsize=11)
    return _save(fig, out / "fidelity-weave.png")


def ablation(out: Path, workers: int) -> Path:
    """Length and κ' ratios of the field runs per :data:`bench.fidelity.ABLATION` variant (paper study,
    seeds 0-9); the numbers also go to ``fidelity-ablation.json``."""
    rows = ablate(list(range(10)), workers)
    (out / "fidelity-ablation.json").write_text(json.dumps(rows, indent=1) + "\n")
    fig = Figure(figsize=(14, 7.5))
    axes = fig.subplots(2, 1, sharex=True)
    x = np.arange(len(rows))
    for i, pl in enumerate(PLANNERS):
        off = (i - 1) * 0.26
        axes[0].bar(x + off, [row[pl]["length_ratio"] for row in rows], 0.25, color=COLORS[pl], label=f"{pl} logged")
        axes[0].scatter(x + off, [row[pl]["true_length_ratio"] for row in rows], color="k", marker="_", s=120,
                        zorder=3, label="driven (true path)" if i == 0 else None)
        axes[1].bar(x + off, [row[pl]["smoothness_ratio"] for row in rows], 0.25, color=COLORS[pl], label=pl)
        axes[0].axhline(rows[0]["sim"][pl]["length_ratio"], color=COLORS[pl], lw=0.8, ls=":")
        axes[1].axhline(rows[0]["sim"][pl]["smoothness_ratio"], color=COLORS[pl], lw=0.8, ls=":")
    axes[0].set_ylim(0.95, 1.25)
    axes[0].set_ylabel("T length ratio")
    axes[1].set_ylabel("T κ' ratio (mean κ' / mean computed κ')")
    axes[0].legend(fontsize=8, ncol=4)
    axes[1].legend(fontsize=8)
    axes[1].set_xticks(x, [row["variant"] for row in rows], rotation=30, ha="right", fontsize=8)
    axes[0].set_title("paper study, seeds 0-9, field runs; dotted: the simulation's ratio (the shipped follower: "
                      "the last two variants change the simulated robot too)", fontsize=10)
    return _save(fig, out / "fidelity-ablation.png")


def zigzag(corner_deg: float = 60.0, leg_m: float = 0.2, legs: int = 7) -> np.ndarray:
    """A zig-zag path ``(N, 3)`` from (0.2, 0.9) m: ``legs`` legs of ``leg_m`` (two points each) turning
    by ``corner_deg`` at every corner; headings along the segments."""
    half = math.radians(corner_deg / 2)
    pts, sign = [(0.2, 0.9)], 1
    for _ in range(legs):
        for _ in range(2):
            pts.append((pts[-1][0] + leg_m / 2 * math.cos(sign * half), pts[-1][1] + leg_m / 2 * math.sin(sign * half)))
        sign = -sign
    xy = np.array(pts)
    return np.column_stack([xy, np.r_[np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0])), 0.0]])


def corners(out: Path) -> Path:
    """60° corners every 0.2 m driven by the ideal robot, the field robot without steering lead, and as shipped
    (true paths)."""
    zz = zigzag()
    fig = Figure(figsize=(12, 4.2))
    ax = fig.subplots()
    ax.plot(zz[:, 0], zz[:, 1], "k.--", lw=0.8, label=f"computed (κ' {smoothness(zz[:, :2]):.3f})")
    for label, backend, ov, color in [("ideal (S)", "ideal", {}, "#1f77b4"),
                                      ("field, steering lead 0", "field", {"field.control_lead_s": 0.0}, "#ff7f0e"),
                                      ("field as shipped", "field", {}, "#d62728")]:
        true = drive(EMPTY, zz, list(zz[0]), backend, 1, robot_params(profile_with(ov)), truth=True)[4]
        ax.plot(true[:, 1], true[:, 2], color=color, lw=1.3, label=f"{label} (κ' {smoothness(true[:, 1:3]):.3f})")
    ax.set_aspect("equal")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title("60° corners every 0.2 m (true paths): the field robot rounds them; without the lead it turns "
                 "late and overshoots", fontsize=10)
    return _save(fig, out / "fidelity-corners.png")


def _at_rest(overrides: dict[str, float], seconds: float = 6.0) -> np.ndarray:
    """Tracker errors (mm) ``(K, 2)`` of the frames a robot at rest at (0.9, 0.9) m gets in ``seconds``."""
    params = robot_params(profile_with(overrides))
    b = make_backend("field", 1, params)
    b.place(0, (0.9, 0.9, 0.0))
    b.begin_path(np.array([True]), np.array([path_key(4)], dtype=np.uint64), np.array([True]))
    m = []
    for k in range(1, int(round(seconds / params.dt)) + 1):
        seen, meas = b.sense(np.array([k]), np.array([True]))[1:]
        if seen[0]:
            m.append((meas[0, :2] - b.pose[0, :2]) * 1000)
        b.actuate(np.zeros((1, 2)))
    return np.array(m)


def _log_inflation(sigma_mm: float, seeds: int = 5) -> float:
    """Mean (over ``seeds`` runs) of logged / driven length − 1 (%) of a 1.3 m straight line with white
    tracker noise ``sigma_mm`` and no bias."""
    line = np.array([[0.2 + 0.1 * i, 0.9, 0.0] for i in range(14)])
    params = robot_params(profile_with({"field.tracker_noise_xy_m": sigma_mm / 1000, "field.tracker_bias_xy_m": 0.0}))
    infl = []
    for seed in range(seeds):
        poses, t0, t1, _, true = drive(EMPTY, line, list(line[0]), "field", seed, params, truth=True)
        inside = poses[(poses[:, 0] >= t0) & (poses[:, 0] <= t1)]
        drv = true[(true[:, 0] >= t0) & (true[:, 0] <= t1)]
        infl.append(100 * (path_length(inside[:, 1:3]) / path_length(drv[:, 1:3]) - 1))
    return float(np.mean(infl))


def tracker(out: Path) -> Path:
    """The tracker's error: a robot at rest before and now, and how white noise lengthens a logged line."""
    fig = Figure(figsize=(12, 4.6))
    axes = fig.subplots(1, 2)
    for label, ov, color in [("before: 1 mm white", MAIN, "#ff7f0e"),
                             ("now: 1 mm bias field + 0.3 mm jitter", {}, "#d62728")]:
        m = _at_rest(ov)
        axes[0].plot(m[:, 0], m[:, 1], ".-", color=color, lw=0.4, ms=3,
                     label=f"{label}: logged length {np.hypot(*np.diff(m, axis=0).T).sum():.0f} mm in 6 s")
    axes[0].set_aspect("equal")
    axes[0].set_xlabel("x error (mm)")
    axes[0].set_ylabel("y error (mm)")
    axes[0].set_title("a robot at rest, 6 s of tracker frames", fontsize=10)
    axes[0].legend(fontsize=8)
    sig = np.linspace(0, 1.5, 31)
    spacing = 0.17 / 30 * 1000  # mm between frames at the field robot's mean speed
    axes[1].plot(sig, 100 * (sig / spacing) ** 2, "k-", label="(σ / spacing)²: cruising, 5.7 mm per frame")
    for s_mm in (0.0, 0.3, 0.6, 1.0, 1.5):
        axes[1].plot(s_mm, _log_inflation(s_mm), "o", color="#d62728")
    axes[1].set_xlabel("white tracker noise σ per axis (mm)")
    axes[1].set_ylabel("logged length − driven length (%)")
    axes[1].set_title("a noisy log is longer than the path driven (1.3 m line; starting and stopping, frames\n"
                      "are closer together and the inflation larger)", fontsize=10)
    axes[1].legend(fontsize=8)
    return _save(fig, out / "fidelity-tracker.png")


def varied_paths(out: Path, seed: int = 0) -> Path:
    """The varied environments with seed ``seed``'s start/goal pairs, computed paths and field logs."""
    data = varied(seed)
    fig = Figure(figsize=(14, 3.9))
    axes = fig.subplots(1, len(data.environments))
    for ax, (name, env_data) in zip(axes, data.environments.items()):
        _draw_env(ax, env_data)
        for e in data.experiments:
            if e["environment"] != name or not e.get("planned_path"):
                continue
            xy = np.asarray(e["planned_path"])
            ax.plot(xy[:, 0], xy[:, 1], "--", color=COLORS[e["planner"]], lw=0.9)
            for rid in e["runs"]:
                row = next(r for r in data.rows if r["run_id"] == rid)
                if row["mode"] == "twb" and row["repetition"] == 1 and row["status"] == "completed":
                    poses = data.poses(rid)
                    ax.plot(poses[:, 1], poses[:, 2], "-", color=COLORS[e["planner"]], lw=0.6, alpha=0.8)
            ax.plot(*e["start"][:2], "ko", ms=3)
        ax.set_xlim(0, 1.8)
        ax.set_ylim(0, 1.8)
        ax.set_title(name, fontsize=10)
    fig.legend([Line2D([], [], color=COLORS[pl]) for pl in PLANNERS], PLANNERS, loc="lower center", ncol=3,
               fontsize=8, bbox_to_anchor=(0.5, 0.02))
    fig.suptitle(f"the varied environments, seed {seed}: computed paths (dashed) and field runs (tracker log)",
                 fontsize=11)
    return _save(fig, out / "fidelity-varied.png")


def findings(out: Path, workers: int) -> Path:
    """Held-counts of the nine findings over seeds 0-19, paper study and varied environments, before and now;
    the counts also go to ``fidelity-findings.json``."""
    counts = {}
    for kind in ("paper", "varied"):
        for label, ov in (("before", MAIN), ("now", {})):
            counts[f"{kind} {label}"] = summarize(run_many(kind, list(range(20)), ov, workers))["held"]
    (out / "fidelity-findings.json").write_text(json.dumps(counts, indent=1) + "\n")
    keys = list(counts["paper now"])
    fig = Figure(figsize=(12, 4.5))
    ax = fig.subplots()
    x = np.arange(len(keys))
    for i, (label, color) in enumerate(zip(counts, ("#ffbb78", "#d62728", "#aec7e8", "#1f77b4"))):
        ax.bar(x + (i - 1.5) * 0.2, [counts[label][k] for k in keys], 0.19, color=color, label=label)
    ax.axhline(18, color="k", lw=0.8, ls=":")
    ax.set_ylim(0, 24)
    ax.set_xticks(x, [f"{i + 1}. {k}" for i, k in enumerate(keys)], rotation=25, ha="right", fontsize=8)
    ax.set_ylabel("seeds (of 20) where it held")
    ax.legend(fontsize=8, ncol=4, loc="upper center")
    ax.set_title("the nine findings over seeds 0-19: paper study and the varied environments, before and now",
                 fontsize=10)
    return _save(fig, out / "fidelity-findings.png")


def figures(out: Path, workers: int) -> list[Path]:
    """Every figure of docs/fidelity.md, as PNG files in ``out`` (a few minutes)."""
    out.mkdir(parents=True, exist_ok=True)
    return [weave(out), ablation(out, workers), corners(out), tracker(out), varied_paths(out), findings(out, workers)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("docs/img"))
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    for p in figures(a.out, a.workers):
        print(p)


if __name__ == "__main__":
    main()
