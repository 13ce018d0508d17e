"""The live field view after a restart, in a real browser: what is there now (the testbed's state), not what
the last session's runs left in the store (issue 32: robots drawn at the previous session's last poses,
moving obstacles "as tracked" on sub-fields that had nothing built)."""

from __future__ import annotations

import math
import re

import pytest
from servers import Process, wait_for
from test_dashboard import (
    CHROMIUM,
    CHROMIUM_ARGS,
    REQUIRE_BROWSER,
    _missing_browser,
    login,
)

JOB = {"environment": "crossing", "plan": None, "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.5708],
       "planner": "fmm", "modes": ["twb"], "repetitions": 1, "seed": 3}


def test_after_a_restart_the_field_view_shows_the_robots_at_their_start_up_poses(tmp_path):
    reason = _missing_browser()
    if reason:
        if REQUIRE_BROWSER:
            pytest.fail(f"browser tests are required here (CI / TWB_REQUIRE_BROWSER) but {reason}")
        pytest.skip(reason)
    from playwright.sync_api import expect, sync_playwright

    args = ["up", "--time-scale", "max", "--sim-robots", "1"]
    first = Process(args, tmp_path, timeout=240)
    try:
        with first.client() as c:
            job = {k: v for k, v in JOB.items() if v is not None}
            done = wait_for(c, c.post("/api/v1/experiments", json=job).json()["id"], timeout=240)
            run = done["runs"][0]  # completed, or stopped by a crossing disc: either way the robot drove
            assert run["t_start"] is not None, done
            moved = next(r for r in c.get("/api/v1/robots").json()["data"] if r["robot_id"] == run["robot_id"])
            (ox, oy), pose = moved["origin"], moved["last_pose"]
            assert pose is not None and math.dist(pose[1:3], (ox + 0.1, oy + 0.1)) > 0.3  # far from its start-up pose
    finally:
        assert first.stop() == 0, first.output()
    second = Process(args, tmp_path, timeout=240)
    try:
        with sync_playwright() as pw:
            b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            page = b.new_page()
            login(page, second.url)
            canvas = page.locator("#field-canvas")
            for k in range(1, 5):  # every field robot where it starts up, marked so
                expect(canvas).to_have_attribute("aria-label", re.compile(rf"field-{k} \(start-up\) at "))
            label = canvas.get_attribute("aria-label")
            assert "sub-field 1 idle;" in label and "with crossing" not in label, label
            expect(page.locator("#legend-obstacle")).to_be_hidden()
            b.close()
    finally:
        assert second.stop() == 0, second.output()
