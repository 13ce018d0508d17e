"""``twb calibrate``: fit a robot profile's field parameters to the field runs a study recorded."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from contract.vocabulary import Mode

from .errors import fail

__all__ = ["calibrate", "calibration_figure", "recorded_runs", "variant_key"]


def variant_key(label: str) -> str:
    """How a variant's label is matched: case, spacing and the multiplication sign aside (the docs' "wheel slip
    ×4" is the study's "wheel slip x4")."""
    return " ".join(label.replace("×", "x").replace("✕", "x").casefold().split())


def recorded_runs(data: Any, variant: Optional[str] = None) -> list[Any]:
    """The completed field runs of a study (:class:`client_sdk.study.StudyData`) as
    :class:`robot_agent.engine.calibration.RecordedRun`: the experiment's planned path, the start where the gripper
    put the robot (facing the goal without a heading; moved by the study's seeded jitter), the tracked poses
    from the path's start to its end, the environment's blocks, grouped by seed (runs with one seed drew the
    same random numbers); only the profile ``variant`` if given."""
    import numpy as np

    from contract.frames import FIELD_SIZE, SUBFIELD_SIZE
    from robot_agent.engine.calibration import RecordedRun
    from robot_agent.engine.run_data import block_tuples, jittered

    variants = sorted({r.get("profile") or "" for r in data.rows if r.get("mode") == Mode.TWB})
    if variant is None and len(variants) > 1:
        fail(f"the study's field runs have {len(variants)} robot variants ({', '.join(variants)}): "
             "choose one with --variant")
    if variant is not None:
        match = [v for v in variants if variant_key(v) == variant_key(variant)]
        if not match:
            fail(f"no field runs of variant {variant!r}; the study's variants: "
                 + (", ".join(repr(v) for v in variants) if variants else "none (no field runs)"))
        variant = match[0]
    experiments = {e["experiment_id"]: e for e in data.experiments if e.get("experiment_id") is not None}
    area = FIELD_SIZE if data.spec.field == "full" else SUBFIELD_SIZE
    runs = []
    for row in data.rows:
        if row.get("mode") != Mode.TWB or row.get("status") != "completed" or row.get("t_start") is None:
            continue
        if variant is not None and (row.get("profile") or "") != variant:
            continue
        exp = experiments.get(row["experiment_id"])
        if exp is None or not exp.get("planned_path"):
            continue
        start = list(exp["start"])
        if len(start) < 3:
            start = [*start[:2], math.atan2(exp["goal"][1] - start[1], exp["goal"][0] - start[0])]
        start = jittered(start, data.spec.jitter, int(row["seed"]))
        poses = np.asarray(data.poses(row["run_id"]), dtype=float).copy()
        t0, t1 = float(row["t_start"]), float(row["t_end"])
        poses = poses[(poses[:, 0] >= t0 - 1e-9) & (poses[:, 0] <= t1 + 1e-9)]
        poses[:, 0] -= t0
        runs.append(RecordedRun(np.asarray(exp["planned_path"], dtype=float), tuple(start), poses,
                                block_tuples(data.environments[exp["environment"]]), area,
                                f"run {row['run_id']} ({exp['environment']} {exp['plan']} {row['configuration']})",
                                str(row["seed"])))
    return runs


def calibration_figure(runs: list[Any], cal: Any, columns: int = 4):  # type: ignore[no-untyped-def]
    """Measured (tracked) against re-simulated paths, one panel a run (at most 12): the planned path dashed,
    the tracked one red, the noise-free re-simulation with the fitted values blue; below, every run's distance
    between the two over time (mm)."""
    import numpy as np
    from matplotlib.figure import Figure

    shown = runs[:12]
    cols = min(columns, len(shown))
    rows = math.ceil(len(shown) / cols)
    fig = Figure(figsize=(3.0 * cols, 3.0 * rows + 2.6), layout="constrained")
    grid = fig.add_gridspec(rows + 1, cols, height_ratios=[3.0] * rows + [1.9])
    axes = np.array([[fig.add_subplot(grid[r, c]) for c in range(cols)] for r in range(rows)])
    for ax in axes.ravel()[len(shown):]:
        ax.set_visible(False)
    dist = fig.add_subplot(grid[rows, :])
    for run, sim in zip(runs, cal.resimulated):
        t = run.poses[:, 0]
        gap = np.hypot(run.poses[:, 1] - np.interp(t, sim[:, 0], sim[:, 1]),
                       run.poses[:, 2] - np.interp(t, sim[:, 0], sim[:, 2]))
        dist.plot(t, gap * 1000, lw=0.7, alpha=0.7)
    dist.set_xlabel("time from the path's start (s)", fontsize=8)
    dist.set_ylabel("tracked − re-simulated (mm)", fontsize=8)
    dist.tick_params(labelsize=7)
    dist.grid(alpha=0.3)
    for ax, run, sim in zip(axes.ravel(), shown, cal.resimulated):
        ax.plot(run.path[:, 0], run.path[:, 1], "--", color="0.55", lw=1, label="planned")
        ax.plot(run.poses[:, 1], run.poses[:, 2], color="tab:red", lw=1.2, label="tracked")
        ax.plot(sim[:, 1], sim[:, 2], color="tab:blue", lw=1, label="re-simulated (fitted)")
        ax.set_aspect("equal")
        ax.set_title(run.name, fontsize=7)
        ax.tick_params(labelsize=6)
    v = cal.values
    fig.suptitle(f"Calibration: {len(runs)} runs, replay error {cal.rms_m * 100:.2f} cm RMS; "
                 f"motor lag {v['motor_time_constant_s']:.3f} s, gains {v['wheel_gain_mean']:.3f} "
                 f"± {v['wheel_bias_sigma']:.3f}, latency {v['tracker_latency_s']:.2f} s", fontsize=9)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8)
    return fig


def calibrate(
    runs: Annotated[Path, typer.Option("--runs", help="A study directory (twb study --out DIR) with field runs.")],
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="Profile JSON to write (default: RUNS/calibrated-profile.json).")] = None,
    figure: Annotated[Optional[Path], typer.Option("--figure", help="Figure of tracked vs re-simulated paths (default: RUNS/calibration.png).")] = None,
    profile: Annotated[str, typer.Option("--profile", help="The robot profile fitted (its other values are kept).")] = "bebot",
    variant: Annotated[Optional[str], typer.Option("--variant", help="Only the field runs of this profile variant (a noise study's label).")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the fit's simulations, bootstraps and emulated runs.", min=0)] = 0,
    refits: Annotated[Optional[int], typer.Option("--refits", help="Refits of the parametric bootstrap (default 4; 0: no intervals).", min=0)] = None,
) -> None:
    """Fit the field parameters of a robot profile (motor time constant, track gains and bias, wheel noise,
    tracker latency and noise) to the completed field runs of a study; writes the fitted profile with each
    value's bias-corrected estimate and 95 % interval (a parametric bootstrap: runs emulated with the fitted profile,
    fitted again; no interval where that does not cover the truth on the validation cases) and a figure of tracked
    against re-simulated paths (docs/fidelity.md, "Calibration")."""
    from client_sdk.study import load_study
    from contract.robot_profile import profile_names
    from robot_agent.engine.calibration import FITTED, INVERSION_OFFSETS, METHOD, REFITS
    from robot_agent.engine.calibration import calibrate as fit

    if profile not in profile_names():
        fail(f"unknown robot profile {profile!r} (profiles: {', '.join(profile_names())})")
    try:
        data = load_study(runs)
    except ValueError as exc:
        fail(str(exc))
    recorded = recorded_runs(data, variant)
    if len(recorded) < 2:
        fail(f"{runs}: {len(recorded)} completed field run(s){f' of variant {variant!r}' if variant else ''}; "
             "calibration needs at least 2")
    refits = REFITS if refits is None else refits
    started = time.monotonic()
    checks = (f", then {len(INVERSION_OFFSETS)} latency checks (more while the latency's interval is still open), each "
              "about half as long")
    typer.echo(f"calibrating {len(recorded)} runs: the fit, then {refits} refit(s) of runs emulated with it, each about "
               "as long" + (checks if refits >= 2 else ""), err=True)

    def progress(step: str) -> None:
        typer.echo(f"  {step} done after {time.monotonic() - started:.0f} s", err=True)

    cal = fit(recorded, profile, seed=seed, refits=refits, progress=progress)
    result = dict(cal.profile)
    result["calibration"] = {
        "runs": len(recorded), "study": data.spec.name, "variant": variant, "seed": seed,
        "rms_residual_m": round(cal.rms_m, 6),
        "replay_error_cm_rms": round(cal.rms_m * 100, 4),
        "refits": refits,
        "values": {k: round(cal.values[k], 6) for k in FITTED},
        "fitted": {k: round(cal.fitted[k], 6) for k in FITTED},
        "bias": {k: round(cal.bias[k], 6) for k in FITTED if math.isfinite(cal.bias.get(k, math.nan))},
        "std_error": {k: round(cal.std[k], 6) for k in cal.interval if math.isfinite(cal.std[k])},
        "interval_95": {k: [round(lo, 6), round(hi, 6)] for k, (lo, hi) in cal.interval.items()},
        "no_interval": dict(cal.no_interval),
        "interval_notes": dict(cal.interval_notes),
        "method": METHOD + "; robot_agent/engine/calibration.py; docs/fidelity.md#calibration",
    }
    out = out or runs / "calibrated-profile.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    figure = figure or runs / "calibration.png"
    calibration_figure(recorded, cal).savefig(figure, dpi=110)
    width = max(len(k) for k in FITTED)
    for k in FITTED:
        lo_hi = cal.interval.get(k)
        where = f"  [{lo_hi[0]:.4g}, {lo_hi[1]:.4g}]" if lo_hi else f"  ({cal.no_interval.get(k, 'no interval')})"
        where += f"  ({cal.interval_notes[k]})" if k in cal.interval_notes else ""
        typer.echo(f"{k:<{width}}  {cal.values[k]:.4g}{where}")
    typer.echo(f"[{METHOD} (docs/fidelity.md#calibration)]")
    typer.echo(f"{len(recorded)} runs, replay error (fitted profile re-simulated against the runs) "
               f"{cal.rms_m * 100:.2f} cm RMS; profile {out}, figure {figure}")
