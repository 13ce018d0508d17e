"""Is calibration's long motor lag the noise-free re-simulation's doing?  On the validation runs of
tests/test_calibration.py (white slip, true lag 0.2 s), the lag is profiled twice at the true latency, every
run's track gains fitted at each lag: against the noise-free re-simulation (what stage 1 does) and against the
mean of ``--replicates`` re-simulations with the true wheel noise on (a simulated likelihood; the same random
numbers at every lag).  Prints JSON: the lag of least cost of each, and the costs.

    python bench/calibration_lag_bias.py --seeds 1,3 --replicates 8
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
from bench.calibration_coverage import TEST_TRUTH, WHITE_SLIP, emulated_runs  # noqa: E402
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


def lag_profile(runs: list[cal.RecordedRun], base: dict, replicates: int) -> list[float]:
    """Summed squared residual (m^2) at each of :data:`LAGS`, gains fitted per run; ``replicates`` 0: noise-free."""
    seeds = [1000 + k for k in range(replicates)] or [0]
    gains = [np.array([0.85, 0.85]) for _ in runs]
    costs = []
    for tau in LAGS:
        prof = cal._quiet_profile(base, float(tau), TRUTH["tracker_latency_s"])
        if replicates:
            prof = apply_overrides(prof, {k: TRUTH[k] for k in ("wheel_noise_rel", "wheel_noise_abs_m_s")})
        total = 0.0
        for i, run in enumerate(runs):
            r = least_squares(lambda g: residual(run, prof, g, seeds), gains[i], bounds=([0.3] * 2, [1.7] * 2),
                              diff_step=1e-2, x_scale=0.05, max_nfev=15)
            gains[i], total = r.x, total + 2.0 * float(r.cost)
        costs.append(round(total, 5))
    return costs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1,3", help="emulation seeds of the validation runs")
    ap.add_argument("--replicates", type=int, default=8, help="noisy re-simulations averaged per run")
    a = ap.parse_args()
    truth = apply_overrides(load_profile("bebot"), TRUTH)
    base = apply_overrides(load_profile("bebot"), WHITE_SLIP)
    out = []
    for seed in seed_list(a.seeds):
        runs = emulated_runs(truth, seed)
        row: dict = {"seed": seed, "true_lag_s": TRUTH["motor_time_constant_s"]}
        for name, k in (("noise_free", 0), (f"mean_of_{a.replicates}_noisy", a.replicates)):
            t0 = time.perf_counter()
            costs = lag_profile(runs, base, k)
            row[name] = {"least_cost_lag_s": float(LAGS[int(np.argmin(costs))]), "costs": dict(zip(LAGS.tolist(), costs)),
                         "seconds": round(time.perf_counter() - t0, 1)}
        out.append(row)
        print(f"seed {seed}: done", file=sys.stderr, flush=True)
    print(json.dumps({"date": time.strftime("%Y-%m-%d", time.gmtime()), "command": " ".join(["python", *sys.argv]),
                      "cases": out}, indent=1))


if __name__ == "__main__":
    main()
