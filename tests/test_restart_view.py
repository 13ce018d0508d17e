"""After a restart the field shows what is there now, not the last session's runs (issue 32).

A field run drives a robot away from where it starts up and leaves its path and moving obstacles on the
field page; the testbed stops and starts again on the same data: its robots are back where they start up,
and the API and the dashboard say so (robots where their trackers see them, no earlier run's path, no
obstacle robots, no "last run" on any sub-field).
"""

from __future__ import annotations

import math
import re
import time
from types import SimpleNamespace

import pytest

from servers import STANDARD, Process, wait_for
from test_dashboard import ROBOT_RGB, SUBFIELD_ORIGINS, TWB_RGB, browser, count_pixels, login  # noqa: F401

pytestmark = pytest.mark.slow

#: where a field robot stands after start-up, in its own frame (docs/protocol.md)
HOME = (0.1, 0.1)
ENV = {"name": "restart-movers", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.45, "w": 0.2, "h": 0.2}],
       "moving_obstacles": [{"radius": 0.04, "waypoints": [[1.6, 0.3], [1.6, 1.5]], "speed": 0.05,
                             "repeat": "pingpong"}]}
JOB = {"environment": ENV["name"], "start": [0.3, 0.3, 0.0], "goal": [1.3, 1.3, 1.5708], "planner": "fmm",
       "modes": ["twb"], "repetitions": 1, "seed": 3}


@pytest.fixture(scope="module")
def testbed(tmp_path_factory):
    """One data directory; ``start()`` starts the testbed on it (again)."""
    data = tmp_path_factory.mktemp("restart")
    bed = SimpleNamespace(proc=None)

    def start() -> Process:
        bed.proc = Process(list(STANDARD), data)
        bed.url = bed.proc.url
        return bed.proc

    bed.start = start
    yield bed
    if bed.proc is not None:
        assert bed.proc.stop() == 0, bed.proc.output()


def field_poses(c, want_all: bool = True, timeout_s: float = 120.0) -> dict[str, list[float]]:
    """The field robots' last poses as ``GET /robots`` gives them, once every one has one."""
    deadline = time.monotonic() + timeout_s
    while True:
        robots = [r for r in c.get("/api/v1/robots").json()["data"] if r["pool"] == "field"]
        if len(robots) == 4 and all(r["last_pose"] for r in robots) or time.monotonic() > deadline:
            return {r["robot_id"]: r["last_pose"] for r in robots}
        time.sleep(0.1)


#: an ended run's performed path is drawn at 55 % opacity over the white field
FADED_RGB = tuple(round(0.55 * c + 0.45 * 255) for c in TWB_RGB)


def path_pixels(pg, points: list[tuple[float, float]]) -> int:
    """Pixels of the performed path's colour (drawn fully or faded) within 2 cm of ``points`` (field frame, m)."""
    return sum(count_pixels(pg, "#field-canvas", rgb, tol=30, region=(x - 0.02, y - 0.02, x + 0.02, y + 0.02))
               for x, y in points for rgb in (TWB_RGB, FADED_RGB))


def at_home(pose: list[float], origin: tuple[float, float]) -> bool:
    return math.dist(pose[1:3], (origin[0] + HOME[0], origin[1] + HOME[1])) < 0.03  # tracker noise: mm


def test_after_a_restart_the_field_shows_where_robots_are_and_no_earlier_run(browser, testbed):  # noqa: F811
    from playwright.sync_api import expect

    proc = testbed.start()
    with proc.client() as c:
        homes = field_poses(c)
        origins = {r["robot_id"]: tuple(r["origin"]) for r in c.get("/api/v1/robots").json()["data"]}
        # a robot that has not moved yet: where its tracker sees it, at start-up
        assert all(at_home(p, origins[rid]) for rid, p in homes.items()), homes
        assert c.post("/api/v1/environments", json=ENV).status_code == 201
        exp = wait_for(c, c.post("/api/v1/experiments", json=JOB).json()["id"], timeout=120)
        run = next(r for r in exp["runs"] if r["mode"] == "twb")
        assert run["t_start"] is not None, exp
        rid, k = run["robot_id"], run["subfield"]
        moved = field_poses(c)[rid]
        assert not at_home(moved, origins[rid]), moved  # it drove away
        assert next(s for s in c.get("/api/v1/subfields").json()["data"] if s["id"] == k)["last_run_id"] == run["id"]
        poses = c.get(f"/api/v1/runs/{run['id']}/poses").json()["poses"]
    ox, oy = SUBFIELD_ORIGINS[k]
    path = [(p[1] + ox, p[2] + oy) for p in poses[len(poses) // 4: 3 * len(poses) // 4: max(1, len(poses) // 12)]]
    here = (moved[1] - 0.06, moved[2] - 0.06, moved[1] + 0.06, moved[2] + 0.06)
    ctx = browser.new_context(viewport={"width": 1366, "height": 900})
    pg = ctx.new_page()
    login(pg, proc.url)
    # this session: the run's path, the robot where it stopped, its obstacle robot named in the legend
    expect(pg.locator("#legend-obstacle")).to_contain_text(f"as tracked (solid; run {run['id']})")
    pg.wait_for_timeout(400)
    assert path_pixels(pg, path) > 30, path
    assert count_pixels(pg, "#field-canvas", ROBOT_RGB, region=here) > 20
    ctx.close()

    assert proc.stop() == 0, proc.output()
    proc = testbed.start()
    with proc.client() as c:
        again = field_poses(c)
        assert all(at_home(p, origins[r]) for r, p in again.items()), again
        subfields = c.get("/api/v1/subfields").json()["data"]
        assert all(s["last_run_id"] is None and s["run_id"] is None and s["environment"] is None
                   for s in subfields), subfields
    ctx = browser.new_context(viewport={"width": 1366, "height": 900})
    pg = ctx.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    login(pg, proc.url)
    _, x, y, _ = again[rid]
    expect(pg.locator("#field-canvas")).to_have_attribute("aria-label", re.compile(rf"{rid} at \({x:.2f}, {y:.2f}\) m"))
    pg.wait_for_timeout(600)  # a chance for anything stale to be drawn
    assert pg.locator("#legend-obstacle").is_hidden()
    assert path_pixels(pg, path) == 0  # no earlier path
    assert count_pixels(pg, "#field-canvas", ROBOT_RGB, region=here) == 0  # nor the robot where it stopped
    home = (x - 0.06, y - 0.06, x + 0.06, y + 0.06)
    assert count_pixels(pg, "#field-canvas", ROBOT_RGB, region=home) > 20  # but where it is
    assert errors == []
    ctx.close()
