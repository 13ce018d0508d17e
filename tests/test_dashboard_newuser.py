"""The dashboard polish for what a new user hit (docs/dashboard.md, "Tests") in Chromium against a real
`twb up --time-scale max`.

The runs and experiment tables fit 1440 and 1024 px (no column cut off, nothing to scroll sideways);
the aggregates table names metrics as the other tables do; a 95% interval that reaches below 0 (or
above 1 for a share) is shown clipped to what the metric can take, marked, the computed bound in its
tooltip; the submit toast follows the experiment and leaves no stale text; a failed experiment says
why under an "Error" header; the speed chart has a legend; a sub-field shows its run's status as the
queue does.  Screenshots at both widths go to ``tests/output/dashboard/`` (``w1440-*.png``,
``w1024-*.png``).  The browser, fixtures and console check are those of ``test_dashboard.py``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from servers import STANDARD, Process, wait_for
from test_dashboard import CORNER, OUTPUT, OVERSHOOT_ENV, Console, login, no_horizontal_overflow
from test_dashboard import browser, page  # noqa: F401  (the shared fixtures)

WIDTHS = (1440, 1024)
#: the built-in room as a user's environment (given a name of its own below)
ROOM_ENV_LONG = json.loads((Path(__file__).resolve().parents[1] / "planners" / "data" / "room.json").read_text())
ROOM_JOB = {"environment": "room", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 0.0], "planner": "fm2"}
TOAST_LOG = """() => {
  window.toastLog = [];
  const el = document.getElementById("toast");
  new MutationObserver(() => window.toastLog.push({ text: el.textContent, shown: el.classList.contains("show") }))
    .observe(el, { childList: true, characterData: true, subtree: true, attributes: true, attributeFilter: ["class"] });
}"""
STATE_LOG = """() => {
  window.stateLog = {};
  const body = document.querySelector("#subfield-table tbody");
  const note = () => {
    for (const row of body.querySelectorAll("tr[data-subfield]")) {
      const log = (window.stateLog[row.dataset.subfield] ||= []);
      if (log[log.length - 1] !== row.dataset.state) log.push(row.dataset.state);
    }
  };
  new MutationObserver(note).observe(body, { childList: true, subtree: true, attributes: true });
}"""
# what each metric can take (server/static/js/metrics.js): shares are in [0, 1], the rest >= 0
SHARES = {"goal_reached", "collided"}
#: metrics with an upper bound (the shares, SPL, the heading error, the BARN score: docs/metrics.md)
UPPER = {"goal_reached": 1.0, "collided": 1.0, "spl": 1.0, "heading_error_rms_rad": 3.141592653589793,
         "barn_score": 0.5}


#: test_dashboard.py's environment under a name of this module's (the two may share a testbed)
OVERSHOOT = {**OVERSHOOT_ENV, "name": "newuser-overshoot"}


@pytest.fixture(scope="module")
def testbed(testbeds):
    # its own: the pages' layout is checked on what this module ran (other modules' experiments, shown to the
    # admin's lists, have names of their own lengths: the finished list once overflowed 1024 px with them)
    for p in testbeds.own(*STANDARD):
        with p.client() as c:
            assert c.post("/api/v1/environments", json=OVERSHOOT).status_code == 201
        yield p


@pytest.fixture(scope="module")
def finished(testbed) -> dict:
    """A completed sim + twb experiment of 2 repetitions and a failed one (a collision), as the API has them."""
    with testbed.client() as c:
        ok = c.post("/api/v1/experiments", json={**ROOM_JOB, "modes": ["sim", "twb"], "repetitions": 2, "seed": 4})
        # the field robot overshoots the path's corner into a block: the experiment fails, and says why
        bad = c.post("/api/v1/experiments", json={"environment": OVERSHOOT["name"], "modes": ["twb"], **CORNER,
                                                  "path": [CORNER["start"], [0.9, 0.69], CORNER["goal"]]})
        # the longest names the API takes: the lists must wrap them, not scroll sideways
        long_env = {**ROOM_ENV_LONG, "name": "a-" + "long-environment-name-" * 2 + "x" * 18}
        assert len(long_env["name"]) == 64 and c.post("/api/v1/environments", json=long_env).status_code == 201
        long = c.post("/api/v1/experiments", json={**ROOM_JOB, "environment": long_env["name"], "modes": ["sim"],
                                                   "planner": "theta_star"})
        assert ok.status_code == 202 and bad.status_code == 202 and long.status_code == 202, (ok.text, bad.text, long.text)
        done = {"ok": wait_for(c, ok.json()["id"], timeout=120), "bad": wait_for(c, bad.json()["id"], timeout=120),
                "long": wait_for(c, long.json()["id"], timeout=120)}
        done["metrics"] = c.get(f"/api/v1/experiments/{done['ok']['id']}/metrics").json()
    assert done["ok"]["status"] == "completed" and done["bad"]["status"] == "failed", done
    return done


def table_fits(pg, selector: str) -> bool:
    """The table is no wider than its scroll box: no column is cut off or behind a sideways scroll."""
    return pg.eval_on_selector(selector, "t => t.parentElement.scrollWidth <= t.parentElement.clientWidth + 1")


@pytest.mark.parametrize("width", WIDTHS)
def test_the_experiment_page_and_list_fit_the_width(browser, testbed, finished, width):  # noqa: F811
    from playwright.sync_api import expect

    ctx = browser.new_context(viewport={"width": width, "height": 900})
    pg = ctx.new_page()
    console = Console(pg)
    try:
        login(pg, testbed.url)
        expect(pg.locator("#field-canvas")).to_have_attribute("aria-label", re.compile(r"Robots: field-1 .*field-4 "))
        assert no_horizontal_overflow(pg)
        pg.screenshot(path=OUTPUT / f"w{width}-field.png")
        exp = finished["ok"]
        pg.goto(f"{testbed.url}/#/experiments/{exp['id']}")
        expect(pg.locator("#runs-table tr[data-run]")).to_have_count(4)
        pg.wait_for_timeout(300)
        assert no_horizontal_overflow(pg)
        for table in ("#runs-table", "#aggregates-table", "#direct-table"):
            assert table_fits(pg, table), table
        # every run's download buttons are on screen, inside the runs panel, on one line
        panel = pg.locator("#runs-table").locator("xpath=..").bounding_box()
        for run in exp["runs"]:
            boxes = [pg.locator(f'#runs-table tr[data-run="{run["id"]}"] .downloads button').nth(i).bounding_box() for i in range(3)]
            assert all(b["x"] >= panel["x"] and b["x"] + b["width"] <= panel["x"] + panel["width"] for b in boxes), boxes
            assert len({round(b["y"]) for b in boxes}) == 1, boxes
        expect(pg.locator(f'#runs-table tr[data-run="{exp["runs"][0]["id"]}"] td').nth(1)).to_have_text(
            f'{exp["runs"][0]["mode"]} #{exp["runs"][0]["repetition"]}')
        pg.screenshot(path=OUTPUT / f"w{width}-experiment.png", full_page=True)
        pg.click("#nav a[data-view=experiments]")
        expect(pg.locator(f'#exp-finished tr[data-experiment="{finished["bad"]["id"]}"]')).to_be_visible()
        assert table_fits(pg, "#exp-finished") and no_horizontal_overflow(pg)
        pg.screenshot(path=OUTPUT / f"w{width}-experiments.png", full_page=True)
        assert console.errors == []
    finally:
        ctx.close()


def test_aggregates_name_metrics_and_clip_intervals_to_what_a_metric_can_take(page, testbed, finished):  # noqa: F811
    """max curvature [-29.1, 170.0] was shown as computed; a share above 1 likewise."""
    from playwright.sync_api import expect

    exp, metrics = finished["ok"], finished["metrics"]
    twb = metrics["aggregates"]["twb"]["metrics"]
    # the server's Student-t interval of two runs as a new user saw it, and a share's above 1
    twb["max_curvature_rad_per_m"].update(mean=70.45, std=11.1, ci_low=-29.1, ci_high=170.0)
    twb["goal_reached"].update(mean=0.5, std=0.7, ci_low=-5.85, ci_high=6.85)
    twb["length_m"].update(ci_low=-0.5)  # the bar chart's whisker too
    page.route(f"**/api/v1/experiments/{exp['id']}/metrics", lambda route: route.fulfill(json=metrics))
    login(page, testbed.url)
    page.goto(f"{testbed.url}/#/experiments/{exp['id']}")
    rows = page.locator("#aggregates-table tbody tr")
    expect(rows.first).to_be_visible()
    labels = rows.locator("th").all_inner_texts()
    assert "Path length (m)" in labels and "Max. curvature (rad/m)" in labels and "Goal reached (share)" in labels
    assert not [t for t in labels if "_" in t], labels  # no raw keys such as length_m
    expect(page.locator('#aggregates-table tr[data-metric="length_m"] th')).to_have_attribute("title", "length_m")
    expect(page.locator("#direct-table thead th").nth(3)).to_have_text("Mean deviation (m)")

    curvature = page.locator('#aggregates-table tr[data-metric="max_curvature_rad_per_m"] td').nth(4)
    expect(curvature).to_have_text("[0.000, 170.000]*")
    expect(curvature.locator(".clipped")).to_have_attribute("title", "The Student-t interval is [-29.100, 170.000]; "
                                                            "Max. curvature cannot be below 0.000, so it is shown clipped.")
    expect(page.locator('#aggregates-table tr[data-metric="goal_reached"] td').nth(4)).to_have_text("[0.000, 1.000]*")
    # every interval: clipped exactly where the computed one leaves the metric's range, else as computed
    for mode_index, mode in enumerate(metrics["aggregates"]):
        for key, a in metrics["aggregates"][mode]["metrics"].items():
            cell = page.locator(f'#aggregates-table tr[data-metric="{key}"] td').nth(3 * mode_index + 1)
            if a["ci_low"] is None or a["std"] <= 1e-9 * max(1.0, abs(a["mean"])):
                continue  # no interval, or identical repetitions (said in words)
            outside = a["ci_low"] < 0 or a["ci_high"] > UPPER.get(key, float("inf"))
            expect(cell.locator(".clipped")).to_have_count(1 if outside else 0)
            low = float(cell.inner_text().strip("[]*").split(",")[0])
            assert low == pytest.approx(max(a["ci_low"], 0.0), abs=1e-3), (mode, key, a)
    expect(page.locator("#aggregates-note")).to_be_visible()
    expect(page.locator("#aggregates-note")).to_contain_text("shown clipped")
    # the chart's whisker stops at the axis and says why
    whisker = page.locator('#experiment-charts figure[data-metric="length_m"] path title', has_text="twb 95% interval")
    expect(whisker).to_contain_text("[0.000, ")
    expect(whisker).to_contain_text("it reaches -0.500; shown clipped at 0")

    # the compare page's means the same way
    page.goto(f"{testbed.url}/#/compare?ids={finished['bad']['id']},{exp['id']}")
    expect(page.locator("#compare-means")).to_be_visible()
    heads = page.locator("#compare-means thead th").all_inner_texts()[1:]  # each experiment's modes, in columns
    column = next(i for i, t in enumerate(heads) if t.startswith(f"#{exp['id']} ") and t.endswith("· twb"))
    cell = page.locator('#compare-means tr[data-metric="length_m"] td').nth(column)
    expect(cell.locator(".clipped")).to_have_count(1)
    expect(cell).to_contain_text("[0.000, ")
    expect(page.locator("#compare-means-note")).to_be_visible()
    assert page.console.errors == []


def test_a_failed_experiment_says_why_under_an_error_header(page, testbed, finished):  # noqa: F811
    from playwright.sync_api import expect

    bad = finished["bad"]
    assert bad["error"]
    login(page, testbed.url)
    page.click("#nav a[data-view=experiments]")
    heads = page.locator("#exp-finished thead th").all_inner_texts()
    assert heads[-1] == "Error" and all(heads), heads
    assert page.locator("#exp-queued thead th").all_inner_texts()[-1] == "Action"
    row = page.locator(f'#exp-finished tr[data-experiment="{bad["id"]}"]')
    expect(row.locator("td").last).to_have_text(bad["error"])  # whole, not cut at 60 characters
    assert row.locator("td").count() == len(heads)
    expect(page.locator(f'#exp-finished tr[data-experiment="{finished["ok"]["id"]}"] td').last).to_have_text("")
    assert page.console.errors == []


def test_the_speed_chart_has_a_legend(page, testbed, finished):  # noqa: F811
    from playwright.sync_api import expect

    login(page, testbed.url)
    page.goto(f"{testbed.url}/#/experiments/{finished['ok']['id']}")
    legend = page.locator(".wide-chart svg .chart-legend")
    expect(legend.locator("text")).to_have_text(["sim (simulation)", "twb (field)"])
    colours = legend.locator("line").evaluate_all("ls => ls.map((l) => l.getAttribute('stroke'))")
    series = page.locator(".wide-chart svg path[stroke-opacity]").evaluate_all(
        "ps => [...new Set(ps.map((p) => p.getAttribute('stroke')))]")
    assert sorted(colours) == sorted(series) and len(colours) == 2
    # the legend sits inside the chart
    chart, box = page.locator(".wide-chart svg").bounding_box(), legend.bounding_box()
    assert chart["x"] <= box["x"] and box["x"] + box["width"] <= chart["x"] + chart["width"]
    assert page.console.errors == []


def test_the_submit_toast_follows_the_experiment_and_leaves_nothing_stale(page, testbed):  # noqa: F811
    """"Experiment #10 queued" stayed on screen after the experiment had completed."""
    from playwright.sync_api import expect

    login(page, testbed.url)
    page.evaluate(TOAST_LOG)
    page.click("#nav a[data-view=submit]")
    page.select_option("#f-environment", "room")
    page.click("#env-plans button:has-text('Plan A')")
    page.uncheck("input[name=modes][value=twb]")  # the simulation: done within the toast's 3 s
    page.click("#submit-button")
    expect(page.locator("#view-experiment .exp-head .badge")).to_have_text("completed", timeout=60_000)
    exp_id = int(page.url.rsplit("/", 1)[1])
    # once gone, the toast has no text left for anyone to see or a screen reader to find
    expect(page.locator("#toast")).not_to_have_class(re.compile(r"\bshow\b"), timeout=10_000)
    expect(page.locator("#toast")).to_have_text("")
    shown = [e["text"] for e in page.evaluate("() => window.toastLog") if e["shown"] and e["text"]]
    assert shown[0].startswith(f"Experiment #{exp_id} "), shown
    assert shown[-1] == f"Experiment #{exp_id} completed", shown  # it followed the experiment to its end
    assert page.console.errors == []


@pytest.fixture
def slow_testbed(tmp_path_factory):  # the only module at ten times live speed: nothing to share it with
    """At ten times live speed the gripper, placing and planning take long enough to be seen (at 'max' a run's
    steps can all arrive within one frame of the browser)."""
    p = Process(["up", "--time-scale", "10", "--sim-robots", "1"], tmp_path_factory.mktemp("dashslow"))
    yield p
    assert p.stop() == 0, p.output()


@pytest.mark.slow
def test_a_sub_field_shows_its_runs_status_as_the_queue_does(browser, slow_testbed):  # noqa: F811
    """The sub-field said "building" while the queue said "placing": the field page now shows the run's status."""
    from playwright.sync_api import expect

    ctx = browser.new_context(viewport={"width": 1440, "height": 900})
    pg = ctx.new_page()
    console = Console(pg)
    try:
        login(pg, slow_testbed.url)
        pg.evaluate(STATE_LOG)
        # a new environment: the gripper builds it, then the robot is placed, plans, drives
        with slow_testbed.client() as c:
            env = {"name": "built-now", "size": [1.8, 1.8], "blocks": [{"x": 0.3, "y": 1.2, "w": 0.3, "h": 0.3}]}
            assert c.post("/api/v1/environments", json=env).status_code == 201
            exp = c.post("/api/v1/experiments", json={**ROOM_JOB, "environment": "built-now", "modes": ["twb"]}).json()
            done = wait_for(c, exp["id"], timeout=120)
        run = done["runs"][0]
        assert done["status"] == "completed" and run["subfield"] is not None
        k = str(run["subfield"])
        expect(pg.locator(f'#subfield-table tr[data-subfield="{k}"]')).to_have_attribute("data-state", "idle")
        log = pg.evaluate("() => window.stateLog")[k]
        while log and log[0] == "idle":
            log.pop(0)
        steps = log[:log.index("idle")] if "idle" in log else log  # until the sub-field is released
        order = ["reserved", "building", "placing", "planning", "running", "analyzing"]
        assert steps and all(s in order for s in steps), log
        assert steps == sorted(steps, key=order.index), log  # in the run's order, never back
        assert {"placing", "planning"} & set(steps), log  # the run's own steps, as the queue shows them
        assert console.errors == []
    finally:
        ctx.close()
