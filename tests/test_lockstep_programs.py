"""Lockstep through the whole testbed: the example P-controller program (uploaded, sandboxed, relayed) drives
the same seed's job at time scale 1, 5 and max on real `twb up` processes, all three at once (each one's host
is loaded by the others); the robot's clock waits for its answer to every pose, so the runs' poses are the
same, and each run says how its clock ran."""

from __future__ import annotations

import base64
import random
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from servers import serve, wait_for

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = (ROOT / "examples" / "controllers" / "p_controller.py").read_bytes()
ENV = {"name": "open", "size": [1.8, 1.8], "blocks": []}
JOB = {"environment": "open", "start": [0.3, 0.3, 0.0], "goal": [0.8, 0.45, 0.0], "modes": ["sim", "twb"],
       "seed": 11, "planner": "astar"}
#: the sandbox without namespaces (a uid of its own): lockstep does not depend on them, and this test then runs
#: wherever uploads do (test_controller_programs.py covers the program in bubblewrap)
LIMITS = {"TWB_SANDBOX_WALL_S": "120", "TWB_SANDBOX_CPU_S": "30", "TWB_SANDBOX_NAMESPACES": "off",
          "TWB_SANDBOX_UID_BASE": str(3_100_000 + random.randrange(800, 1600) * 1000)}


def drive(tmp_path: Path, scale: str) -> tuple[dict, dict[str, np.ndarray]]:
    """One testbed at ``scale``: the job's experiment and each mode's poses, times from the run's first pose."""
    gen = serve(["up", "--time-scale", scale, "--sim-robots", "1", "--enable-uploads"], tmp_path / scale,
                env=LIMITS, timeout=240)
    testbed = next(gen)
    try:
        with testbed.client() as c:
            assert c.post("/api/v1/environments", json=ENV).status_code == 201
            r = c.post("/api/v1/programs", json={"name": "p_controller.py", "kind": "python",
                                                 "content_base64": base64.b64encode(PROGRAM).decode()})
            assert r.status_code == 201, r.text
            r = c.post("/api/v1/experiments", json={**JOB, "controller_program": r.json()["id"]})
            assert r.status_code == 202, r.text
            exp = wait_for(c, r.json()["id"], timeout=300)
            poses = {}
            for run in exp["runs"]:
                p = np.array(c.get(f"/api/v1/runs/{run['id']}/poses").json()["poses"], dtype=float)
                p[:, 0] -= p[0, 0]
                poses[run["mode"]] = p
    finally:
        next(gen, None)
    return exp, poses


@pytest.mark.slow  # three real testbeds at once
def test_a_controller_program_gives_the_same_poses_at_time_scale_1_5_and_max(tmp_path):
    scales = ("1", "5", "max")
    with ThreadPoolExecutor(len(scales)) as pool:
        runs = dict(zip(scales, pool.map(lambda scale: drive(tmp_path, scale), scales)))
    for scale, (exp, _) in runs.items():
        assert exp["status"] == "completed", (scale, exp.get("error"), [r["error"] for r in exp["runs"]])
        assert {(r["clock"], r["time_scale"]) for r in exp["runs"]} == {("lockstep", None if scale == "max"
                                                                         else float(scale))}
    ref = runs["1"][1]
    assert set(ref) == {"sim", "twb"} and all(len(p) > 50 for p in ref.values())
    for scale in ("5", "max"):
        for mode in ("sim", "twb"):
            got = runs[scale][1][mode]
            n = min(len(got), len(ref[mode]))
            differ = np.flatnonzero(np.any(np.abs(got[:n] - ref[mode][:n]) > 1e-9, axis=1))
            assert got.shape == ref[mode].shape, (scale, mode, got.shape, ref[mode].shape, differ[:5], got[-3:],
                                                  ref[mode][-3:])
            np.testing.assert_allclose(got, ref[mode], atol=1e-9, err_msg=f"{mode} at time scale {scale}")
    assert pytest.approx(runs["max"][0]["runs"][0]["metrics"]["length_m"]) == runs["1"][0]["runs"][0]["metrics"]["length_m"]
