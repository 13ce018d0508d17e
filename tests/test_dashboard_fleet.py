"""Multi-robot jobs made in the dashboard's submit form (docs/dashboard.md, "Pages"), in Chromium against a real
`twb up --time-scale max`.

A two-robot job placed on the map and typed in is stored with `robots` as entered and its runs complete; with
"an explicit path" each robot gets its own waypoints, sent as its `path`; the "Swap scenario" shortcut fills the built-in environment's four corners with `prioritized`; the preview draws
every robot's start and goal in its colour; a start too close to another robot's is refused by the server and
the refusal is shown under that robot.  The browser, fixtures and console check are those of
``test_dashboard.py``; screenshots go to ``tests/output/dashboard/`` (``submit-fleet.png``,
``submit-swap.png``).
"""

from __future__ import annotations

import json
import math

import pytest

from servers import STANDARD
from test_dashboard import (FLEET_RGB, LAPTOP, OUTPUT, ROOT, TABLET, canvas_geometry, count_pixels, login,
                            no_horizontal_overflow, submit_and_wait, world_to_page)
from test_dashboard import browser, page  # noqa: F401  (the shared fixtures)

SWAP = json.loads((ROOT / "planners" / "data" / "swap.json").read_text())


@pytest.fixture(scope="module")
def testbed(testbeds):
    yield from testbeds.module(*STANDARD)


def open_fleet_form(pg, url: str) -> None:
    """Log in, open the submit form and switch it to several robots."""
    from playwright.sync_api import expect

    login(pg, url)
    pg.click("#nav a[data-view=submit]")
    expect(pg.locator("#f-environment option")).not_to_have_count(0)
    pg.check("input[name=robots][value=fleet]")
    expect(pg.locator("#f-robots fieldset.robot")).to_have_count(2)


def robot_pose(pg, k: int, which: str) -> list[float]:
    return [float(pg.input_value(f"#f-r{k}-{which}-{c}")) for c in "xya"]


def near(x: float, y: float, r: float = 0.05) -> tuple[float, float, float, float]:
    return (x - r, y - r, x + r, y + r)


def test_a_two_robot_job_from_the_form_is_stored_as_entered_and_completes(page, testbed):  # noqa: F811
    from playwright.sync_api import expect

    open_fleet_form(page, testbed.url)
    page.select_option("#f-environment", "swap")
    expect(page.locator("#f-planner")).to_have_value("prioritized")  # the coordinated planner for fleets
    expect(page.locator("#f-planner option").first).to_have_text("prioritized")
    page.check("input[name=robots][value=one]")  # it plans fleets only: one robot is not offered it
    expect(page.locator("#f-planner option[value=prioritized]")).to_have_count(0)
    page.check("input[name=robots][value=fleet]")
    expect(page.locator("#f-planner")).to_have_value("prioritized")
    page.wait_for_timeout(200)
    geo = canvas_geometry(page, "#submit-canvas")
    # robot 0 on the map: a click for its start, a drag for its goal's heading; then the form moves on to robot 1
    page.check('input[name=robot-pick][value="0"]')
    page.check("input[name=pick][value=start]")
    page.mouse.click(*world_to_page(geo, 0.3, 0.9))
    expect(page.locator("input[name=pick][value=goal]")).to_be_checked()
    gx, gy = world_to_page(geo, 1.5, 0.9)
    page.mouse.move(gx, gy)
    page.mouse.down()
    page.mouse.move(gx, gy - 50, steps=5)  # upwards: heading +90°
    page.mouse.up()
    expect(page.locator('input[name=robot-pick][value="1"]')).to_be_checked()
    expect(page.locator("input[name=pick][value=start]")).to_be_checked()
    # robot 1 typed
    for which, pose in (("start", (1.5, 0.3, math.pi)), ("goal", (0.3, 0.3, math.pi))):
        for c, v in zip("xya", pose):
            page.fill(f"#f-r1-{which}-{c}", str(v))
    start0, goal0 = robot_pose(page, 0, "start"), robot_pose(page, 0, "goal")
    assert start0[:2] == pytest.approx([0.3, 0.9], abs=0.01) and goal0[:2] == pytest.approx([1.5, 0.9], abs=0.01)
    assert goal0[2] == pytest.approx(math.pi / 2, abs=0.02)
    # the preview: each robot's start and goal in its colour
    page.wait_for_timeout(200)
    for k, (s, g) in enumerate(((start0, goal0), ((1.5, 0.3), (0.3, 0.3)))):
        for x, y in (s[:2], g[:2]):
            assert count_pixels(page, "#submit-canvas", FLEET_RGB[k], tol=40, region=near(x, y)) > 5, (k, x, y)
    page.uncheck("input[name=modes][value=twb]")
    page.check("input[name=modes][value=twb]")  # both modes
    page.fill("#f-seed", "5")
    page.screenshot(path=OUTPUT / "submit-fleet.png")

    exp = submit_and_wait(page, testbed)  # lands on the experiment's page, which reaches "completed"
    assert exp["planner"] == "prioritized" and exp["seed"] == 5 and exp["environment"] == "swap"
    assert len(exp["robots"]) == 2
    assert exp["robots"][0]["start"] == pytest.approx(start0, abs=1e-9)
    assert exp["robots"][0]["goal"] == pytest.approx(goal0, abs=1e-9)
    assert exp["robots"][1] == {"start": pytest.approx([1.5, 0.3, math.pi]), "goal": pytest.approx([0.3, 0.3, math.pi])}
    assert sorted(r["mode"] for r in exp["runs"]) == ["sim", "twb"]
    assert {r["status"] for r in exp["runs"]} == {"completed"}
    for r in exp["runs"]:
        assert [m["robot"] for m in r["metrics"]["robots"]] == [0, 1] and all(m["done"] for m in r["metrics"]["robots"])
    expect(page.locator("dl.facts").first).to_contain_text("Robots2")
    expect(page.locator("#robots-table tbody tr")).to_have_count(4)  # 2 runs x 2 robots
    assert page.console.errors == []


def test_each_robot_gets_its_own_explicit_path(page, testbed):  # noqa: F811
    """With "an explicit path" the waypoints box is the chosen robot's: waypoints clicked for robot 0 and typed for
    robot 1 are sent as each robot's `path` (start, waypoints, goal) and driven as given."""
    from playwright.sync_api import expect

    open_fleet_form(page, testbed.url)
    page.select_option("#f-environment", "swap")
    page.check("input[name=source][value=path]")
    poses = [((0.3, 0.3, 0.0), (1.5, 0.3, 0.0)), ((0.3, 1.5, 0.0), (1.5, 1.5, 0.0))]
    for k, pair in enumerate(poses):
        for which, pose in zip(("start", "goal"), pair):
            for c, v in zip("xya", pose):
                page.fill(f"#f-r{k}-{which}-{c}", str(v))
    page.check('input[name=robot-pick][value="0"]')
    page.check("input[name=pick][value=waypoint]")
    page.wait_for_timeout(200)
    page.mouse.click(*world_to_page(canvas_geometry(page, "#submit-canvas"), 0.9, 0.6))
    expect(page.locator("#f-path")).to_have_value("0.900, 0.600")
    page.check('input[name=robot-pick][value="1"]')
    expect(page.locator("#path-whose")).to_have_text("robot 1's start and goal")
    expect(page.locator("#f-path")).to_have_value("")
    page.fill("#f-path", "0.9, 1.3")
    page.check('input[name=robot-pick][value="0"]')
    expect(page.locator("#f-path")).to_have_value("0.900, 0.600")
    page.wait_for_timeout(200)
    assert count_pixels(page, "#submit-canvas", FLEET_RGB[1], tol=40, region=near(0.9, 1.3, 0.03)) > 3  # its path
    page.uncheck("input[name=modes][value=twb]")

    exp = submit_and_wait(page, testbed)
    assert exp["planner"] is None
    assert exp["robots"][0]["path"] == [[0.3, 0.3, 0.0], [0.9, 0.6], [1.5, 0.3, 0.0]]
    assert exp["robots"][1]["path"] == [[0.3, 1.5, 0.0], [0.9, 1.3], [1.5, 1.5, 0.0]]
    assert [r["status"] for r in exp["runs"]] == ["completed"]
    assert page.console.errors == []


def test_the_swap_shortcut_and_a_refused_robot_shown_under_it(page, testbed):  # noqa: F811
    from playwright.sync_api import expect

    with testbed.client() as c:
        before = c.get("/api/v1/experiments").json()["count"]
    open_fleet_form(page, testbed.url)
    page.click("#fill-swap")
    expect(page.locator("#f-robots fieldset.robot")).to_have_count(4)
    expect(page.locator("#f-environment")).to_have_value("swap")
    expect(page.locator("#f-planner")).to_have_value("prioritized")
    for k, plan in enumerate(SWAP["plans"]):
        assert robot_pose(page, k, "start") == pytest.approx(plan["start"], abs=1e-3)
        assert robot_pose(page, k, "goal") == pytest.approx(plan["goal"], abs=1e-3)
    # prioritized offers the parameters the server lists for it: the space-time planner's with the fleet's defaults
    expect(page.locator("#f-param-time_margin_s")).to_have_attribute("placeholder", "0.5")
    expect(page.locator("#f-param-execution")).to_have_attribute("placeholder", "dependencies")
    expect(page.locator("#f-param-wait option").first).to_have_text("default (true)")
    page.wait_for_timeout(200)
    for k, plan in enumerate(SWAP["plans"]):  # every robot's start in its colour (each corner is another's goal)
        assert count_pixels(page, "#submit-canvas", FLEET_RGB[k], tol=40, region=near(*plan["start"][:2])) > 5, k
    page.screenshot(path=OUTPUT / "submit-swap.png")
    page.set_viewport_size(TABLET)  # the four robots' rows fit a tablet too: nothing scrolls sideways
    page.wait_for_timeout(100)
    assert no_horizontal_overflow(page)
    page.set_viewport_size(LAPTOP)
    # the keyboard: r chooses the next robot, s its start, the arrows move it
    page.focus("#submit-canvas")
    page.keyboard.press("r")
    expect(page.locator('input[name=robot-pick][value="1"]')).to_be_checked()
    page.keyboard.press("s")
    page.keyboard.press("Shift+ArrowUp")  # 10 cm
    assert robot_pose(page, 1, "start") == pytest.approx([1.5, 0.4, SWAP["plans"][1]["start"][2]], abs=1e-3)
    expect(page.locator("#map-readout")).to_contain_text("Placing robot 1's start at (1.50, 0.40) m")

    # where the server's messages go: the robot a message or a request-model location names, the list, a field
    keys = page.evaluate('''async () => {
      const { errorKey } = await import("/static/js/submit.js");
      return [errorKey("robots: a multi-robot job has 2 to 16 robots, got 17; a sub-field holds at most 16"),
              errorKey("Input should be a valid number", ["body", "robots", 1, "start", 0]),
              errorKey("List should have at least 2 items after validation, not 1", ["body", "robots"]),
              errorKey("robots[0].path: `prioritized` plans every robot together", ["body"]),
              errorKey("robots[2].goal: goal (0.9, 0.45) is inside an obstacle"),
              errorKey("planner_params: `cell` must be > 0, got -1.0")];
    }''')
    assert keys == ["robots", {"robot": 1, "part": "start"}, "robots", {"robot": 0, "part": "path"},
                    {"robot": 2, "part": "goal"}, "planner_params"]

    # the client's own checks: an emptied coordinate, then a single robot, are refused without asking the server
    page.fill("#f-r2-goal-y", "")
    page.click("#submit-button")
    expect(page.locator("#err-robots-2")).to_contain_text("robot 2: place its goal")
    expect(page.locator("#f-r2-goal-x")).to_have_attribute("aria-invalid", "true")
    page.fill("#f-r2-goal-y", "0.3")
    for k in (3, 2, 1):
        page.click(f'button[aria-label="Remove robot {k}"]')
    page.click("#submit-button")
    expect(page.locator("#err-robots")).to_contain_text("at least 2 robots")
    assert page.console.errors == []

    # the server's refusal: robot 1 starts 5 cm from robot 0; it is shown under robot 1, its start marked
    page.click("#add-robot")
    for which, pose in (("start", (0.35, 0.3)), ("goal", (1.5, 0.3))):
        for c, v in zip("xy", pose):
            page.fill(f"#f-r1-{which}-{c}", str(v))
    page.click("#submit-button")
    expect(page.locator("#err-robots-1")).to_contain_text(
        "robots[1].start is 0.050 m from robots[0].start: two robots need 0.130 m between their centres")
    expect(page.locator("#f-r1-start-x")).to_have_attribute("aria-invalid", "true")
    expect(page.locator("#f-r1-goal-x")).not_to_have_attribute("aria-invalid", "true")
    expect(page.locator("#f-r0-start-x")).not_to_have_attribute("aria-invalid", "true")
    assert page.evaluate("() => document.activeElement.id") == "f-r1-start-x"
    expect(page.locator("#submit-error")).to_be_empty()
    expect(page.locator("#view-submit")).to_be_visible()
    with testbed.client() as c:
        assert c.get("/api/v1/experiments").json()["count"] == before  # nothing was queued
    # the only console error: the browser's note on the 422
    assert len(page.console.errors) == 1 and "422" in page.console.errors[0], page.console.errors
