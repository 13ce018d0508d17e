"""Is calibration's long motor lag the noise-free re-simulation's doing?  On the validation runs of
tests/test_calibration.py (white slip, true lag 0.2 s), the lag is profiled twice at the true latency, every
run's track gains fitted at each lag: against the noise-free re-simulation (what stage 1 does) and against the
mean of ``--replicates`` re-simulations with the true wheel noise on (a simulated likelihood; the same random
numbers at every lag).  Prints JSON: the lag of least cost of each, and the costs.

With ``--own-estimates`` the simulated likelihood is what calibration itself could compute: the lag profiled
around the fit's lag (0.6 to 1.1 times it) at the fit's latency, with the fit's wheel noise, every run's gains
fitted at each lag from the fit's; against the fit's own lag and wheel noise.

    python bench/calibration_lag_bias.py --seeds 1,3 --replicates 8
    python bench/calibration_lag_bias.py --seeds 1-5 --replicates 8 --own-estimates
    python bench/calibration_lag_bias.py --seeds 1-5 --own-estimates --variant all   # the coverage bench's runs
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

if __package__ in (None, ""):
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from bench._common import seed_list  # noqa: E402
from bench.calibration_coverage import TEST_TRUTH, VARIANTS, WHITE_SLIP, emulated_runs  # noqa: E402
from contract.overrides import apply_overrides  # noqa: E402
from contract.robot_profile import load_profile  # noqa: E402
from robot_agent.engine import calibration as cal  # noqa: E402

#: tests/test_calibration.py's validation profile, with white slip
TRUTH = {**TEST_TRUTH, **WHITE_SLIP}
LAGS = np.round(np.arange(0.1, 0.351, 0.025), 3)


def residual(run: cal.RecordedRun, profile: dict, gains: np.ndarray, seeds: list[int]) -> np.ndarray:
    """Tracked minus the mean of ``run`` re-simulated with each of ``seeds`` (positions, m, flattened)."""
    t = run.poses[:, 0]
    sims = [cal._simulate(run, profile, (float(gains[0]), float(gains[1])), s) for s in seeds]
    x = np.mean([np.interp(t, s[:, 0], s[:, 1]) for s in sims], axis=0)
    y = np.mean([np.interp(t, s[:, 0], s[:, 2]) for s in sims], axis=0)
    return np.column_stack([run.poses[:, 1] - x, run.poses[:, 2] - y]).ravel()


def lag_profile(runs: list[cal.RecordedRun], base: dict, replicates: int, lags: np.ndarray = LAGS,
                latency: float = TRUTH["tracker_latency_s"], noise: dict | None = None,
                gains0: list[np.ndarray] | None = None) -> list[float]:
    """Summed squared residual (m^2) at each of ``lags``, gains fitted per run (from ``gains0``); ``replicates`` 0:
    noise-free; the wheel ``noise`` of the re-simulations, by default the true one."""
    seeds = [1000 + k for k in range(replicates)] or [0]
    gains = [g.copy() for g in gains0] if gains0 is not None else [np.array([0.85, 0.85]) for _ in runs]
    noise = noise or {k: TRUTH[k] for k in ("wheel_noise_rel", "wheel_noise_abs_m_s")}
    costs = []
    for tau in lags:
        prof = cal._quiet_profile(base, float(tau), latency)
        if replicates:
            prof = apply_overrides(prof, noise)
        total = 0.0
        for i, run in enumerate(runs):
            r = least_squares(lambda g: residual(run, prof, g, seeds), gains[i], bounds=([0.3] * 2, [1.7] * 2),
                              diff_step=1e-2, x_scale=0.05, max_nfev=15)
            gains[i], total = r.x, total + 2.0 * float(r.cost)
        costs.append(round(total, 5))
    return costs


def own_estimates(runs: list[cal.RecordedRun], base: dict, seed: int, replicates: int, truth: dict) -> dict:
    """The fit (no bootstrap) of ``runs`` (emulated with the field values ``truth``), then the lag profiled against
    ``replicates`` noisy re-simulations with the fit's latency and wheel noise around the fit's lag: the lag of
    least cost (a parabola through it and its neighbours) and the costs (relative to the least)."""
    t0 = time.perf_counter()
    fit = cal._fit(runs, base, 0, bootstrap=False)
    v = fit.values
    t1 = time.perf_counter()
    lags = np.round(v["motor_time_constant_s"] * np.arange(0.6, 1.101, 0.05), 4)
    noise = {k: v[k] for k in ("wheel_noise_rel", "wheel_noise_abs_m_s")}
    costs = np.array(lag_profile(runs, base, replicates, lags, v["tracker_latency_s"], noise, list(fit.gains)))
    lag = cal._least_on_grid(lags, costs)
    return {"seed": seed, "true_lag_s": truth["motor_time_constant_s"], "true_wheel_noise_rel": truth["wheel_noise_rel"],
            "fit": {"lag_s": round(v["motor_time_constant_s"], 4), "wheel_noise_rel": round(v["wheel_noise_rel"], 4),
                    "tracker_latency_s": v["tracker_latency_s"], "seconds": round(t1 - t0, 1)},
            f"mean_of_{replicates}_noisy_own_estimates": {
                "least_cost_lag_s": round(lag, 4), "costs": dict(zip(lags.tolist(), np.round(costs / costs.min(), 4).tolist())),
                "seconds": round(time.perf_counter() - t1, 1)}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1,3", help="emulation seeds of the validation runs")
    ap.add_argument("--replicates", type=int, default=8, help="noisy re-simulations averaged per run")
    ap.add_argument("--own-estimates", action="store_true",
                    help="profile around the fit's lag with the fit's latency and wheel noise (what calibration knows)")
    ap.add_argument("--variant", choices=["all", *VARIANTS],
                    help="with --own-estimates: the coverage bench's runs of this variant (all: each) instead of the test's")
    a = ap.parse_args()
    if a.variant and not a.own_estimates:
        ap.error("--variant needs --own-estimates")
    # (label, the profile the runs are emulated with, the profile the fit starts from)
    if a.variant:
        sets = [(name, apply_overrides(load_profile("bebot"), VARIANTS[name]), load_profile("bebot"))
                for name in (VARIANTS if a.variant == "all" else [a.variant])]
    else:
        sets = [(None, apply_overrides(load_profile("bebot"), TRUTH), apply_overrides(load_profile("bebot"), WHITE_SLIP))]
    out = []
    for label, truth, base in sets:
        for seed in seed_list(a.seeds):
            runs = emulated_runs(truth, seed)
            if a.own_estimates:
                row = own_estimates(runs, base, seed, a.replicates, truth["field"])
            else:
                row = {"seed": seed, "true_lag_s": TRUTH["motor_time_constant_s"]}
                for name, k in (("noise_free", 0), (f"mean_of_{a.replicates}_noisy", a.replicates)):
                    t0 = time.perf_counter()
                    costs = lag_profile(runs, base, k)
                    row[name] = {"least_cost_lag_s": float(LAGS[int(np.argmin(costs))]),
                                 "costs": dict(zip(LAGS.tolist(), costs)), "seconds": round(time.perf_counter() - t0, 1)}
            out.append(row if label is None else {"variant": label, **row})
            print(f"{label + ', ' if label else ''}seed {seed}: done", file=sys.stderr, flush=True)
    print(json.dumps({"date": time.strftime("%Y-%m-%d", time.gmtime()), "command": " ".join(["python", *sys.argv]),
                      "cases": out}, indent=1))


if __name__ == "__main__":
    main()
