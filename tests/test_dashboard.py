"""The web dashboard in a real browser: Debian's Chromium driven by Playwright against a real `twb up`.

Screenshots go to ``tests/output/dashboard/`` (``TWB_TEST_OUTPUT`` overrides the
``tests/output`` part).  Without ``/usr/bin/chromium`` (``TWB_CHROMIUM`` names another
binary) or the ``playwright`` package the browser tests skip, unless ``CI`` or
``TWB_REQUIRE_BROWSER`` is set, when they fail: CI must really run them.  The tests without a browser (files
served, path traversal, the planners list) always run.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import httpx
import numpy as np
import pytest

from servers import STANDARD, TOKEN, wait_for

CHROMIUM = Path(os.environ.get("TWB_CHROMIUM") or "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]
OUTPUT = Path(os.environ.get("TWB_TEST_OUTPUT") or Path(__file__).parent / "output") / "dashboard"
ROOT = Path(__file__).resolve().parents[1]
LAPTOP = {"width": 1366, "height": 900}
EXPECT_TIMEOUT_MS = 30_000
TABLET = {"width": 768, "height": 1024}

ROBOT_RGB = (0xFF, 0x6D, 0x00)
ROBOT_GHOST_RGB = (0xFF, 0xB2, 0x7A)
SIM_RGB = (0x7B, 0x3F, 0xBF)
TWB_RGB = (0x1F, 0x77, 0xB4)
SUBFIELD_ORIGINS = {1: (0.0, 0.0), 2: (1.8, 0.0), 3: (0.0, 1.8), 4: (1.8, 1.8)}


def _flag(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() not in ("", "0", "false", "no")


REQUIRE_BROWSER = _flag("CI") or _flag("TWB_REQUIRE_BROWSER")


def _missing_browser() -> str | None:
    if not CHROMIUM.exists():
        return f"{CHROMIUM} not found (install it: apt-get install -y --no-install-recommends chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the Python package playwright is not installed (pip install -e '.[dev]')"
    return None


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def testbed(testbeds):
    # its own: the field page's robots, traces and legend are those of this module's runs only
    yield from testbeds.own(*STANDARD)


@pytest.fixture(scope="module")
def browser(request):
    reason = _missing_browser()
    if reason:
        if REQUIRE_BROWSER:
            pytest.fail(f"browser tests are required here (CI / TWB_REQUIRE_BROWSER) but {reason}")
        pytest.skip(reason)
    # the server starts before the browser and stops after it (no open event stream to wait for)
    request.getfixturevalue("testbed")
    from playwright.sync_api import expect, sync_playwright

    # what a page shows after a request the server computes (a comparison's bootstrap, a study's figures) can
    # take seconds on a loaded 2-core machine: assertions wait up to 30 s, not Playwright's 5 s (a passing
    # assertion returns as soon as it holds)
    expect.set_options(timeout=EXPECT_TIMEOUT_MS)

    OUTPUT.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


class Console:
    """Console errors and uncaught exceptions of a page; `allow` lists expected resource failures."""

    def __init__(self, page) -> None:
        self.errors: list[str] = []
        page.on("console", lambda m: m.type == "error" and self.errors.append(f"{m.text} @ {m.location.get('url')}"))
        page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))

    def unexpected(self, *allowed: str) -> list[str]:
        return [e for e in self.errors if not any(a in e for a in allowed)]


@pytest.fixture
def page(browser, testbed):
    ctx = browser.new_context(viewport=LAPTOP, accept_downloads=True)
    pg = ctx.new_page()
    pg.set_default_timeout(15_000)
    pg.console = Console(pg)
    yield pg
    ctx.close()


def login(pg, url: str, token: str = TOKEN) -> None:
    from playwright.sync_api import expect

    pg.goto(url + "/")
    pg.fill("#login-token", token)
    pg.press("#login-token", "Enter")
    expect(pg.locator("#view-field")).to_be_visible()
    expect(pg.locator("#stream-state")).to_have_text("live")


def submit_and_wait(pg, testbed, status: str = "completed") -> dict:
    """Submit the form, land on the new experiment's page, see it reach `status`; the experiment as the API has it."""
    from playwright.sync_api import expect

    pg.click("#submit-button")
    expect(pg.locator("#view-experiment")).to_be_visible()
    expect(pg.locator("#view-experiment .exp-head .badge")).to_have_text(status, timeout=60_000)
    exp_id = int(pg.url.rsplit("/", 1)[1])
    with testbed.client() as c:
        return c.get(f"/api/v1/experiments/{exp_id}").json()


def canvas_geometry(pg, selector: str) -> dict:
    """The canvas's metres-to-pixels mapping (its data attributes) and its page position."""
    box = pg.locator(selector).bounding_box()
    ds = pg.eval_on_selector(selector, "c => ({...c.dataset})")
    return {"x": box["x"], "y": box["y"], "scale": float(ds["scale"]), "ox": float(ds["ox"]), "oy": float(ds["oy"])}


def world_to_page(geo: dict, x: float, y: float) -> tuple[float, float]:
    return geo["x"] + geo["ox"] + x * geo["scale"], geo["y"] + geo["oy"] - y * geo["scale"]


COUNT_PIXELS = """([sel, rgb, tol, region]) => {
  const c = document.querySelector(sel);
  const k = c.width / c.clientWidth;
  const ds = c.dataset, s = +ds.scale, ox = +ds.ox, oy = +ds.oy;
  let [x0, y0, x1, y1] = region || [0, 0, c.clientWidth / s, c.clientHeight / s];
  if (region) { [x0, y0, x1, y1] = [ox + x0 * s, oy - y1 * s, ox + x1 * s, oy - y0 * s]; }
  else { [x0, y0, x1, y1] = [0, 0, c.clientWidth, c.clientHeight]; }
  const px = (v) => Math.max(0, Math.round(v * k));
  const w = Math.max(1, px(x1) - px(x0)), h = Math.max(1, px(y1) - px(y0));
  const d = c.getContext("2d").getImageData(px(x0), px(y0), w, h).data;
  let n = 0;
  for (let i = 0; i < d.length; i += 4) {
    if (Math.abs(d[i] - rgb[0]) <= tol && Math.abs(d[i + 1] - rgb[1]) <= tol && Math.abs(d[i + 2] - rgb[2]) <= tol) n++;
  }
  return n;
}"""


def count_pixels(pg, selector: str, rgb: tuple[int, int, int], tol: int = 12,
                 region: tuple[float, float, float, float] | None = None) -> int:
    """Pixels of the canvas within `tol` of `rgb`, optionally only in a world box (x0, y0, x1, y1) in metres."""
    return pg.evaluate(COUNT_PIXELS, [selector, list(rgb), tol, list(region) if region else None])


def no_horizontal_overflow(pg) -> bool:
    return pg.evaluate("() => document.documentElement.scrollWidth <= window.innerWidth + 1")


# --------------------------------------------------------------------------- without a browser


def test_the_page_and_its_files_are_served_safely(testbed):
    with httpx.Client(base_url=testbed.url, timeout=10) as c:
        r = c.get("/")
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        assert '<script type="module" src="/static/js/app.js">' in r.text
        assert "script-src 'self'" in r.headers["content-security-policy"]
        assert c.head("/").status_code == 200
        js = c.get("/static/js/app.js")
        assert js.status_code == 200 and "javascript" in js.headers["content-type"]
        for bad in ("/static/../app.py", "/static/%2e%2e/app.py", "/static/js/../../app.py", "/static/nope.js", "/static/js"):
            assert c.get(bad).status_code == 404, bad
        assert c.get("/api/v1/planners").status_code == 401
        planners = c.get("/api/v1/planners", headers={"Authorization": f"Bearer {TOKEN}"}).json()
        names = {p["name"]: p for p in planners["data"]}
        assert {"fmm", "fm2", "prm", "astar"} <= set(names) and names["fm2"]["defaults"]["saturation"] > 0


# --------------------------------------------------------------------------- in the browser


def test_a_bad_token_is_refused_clearly_and_the_right_one_logs_in(page, testbed):
    from playwright.sync_api import expect

    page.goto(testbed.url + "/")
    expect(page.locator("#view-login")).to_be_visible()
    page.fill("#login-token", "not-a-token")
    page.click("#login-form button[type=submit]")
    expect(page.locator("#login-error")).to_contain_text("refused this token")
    expect(page.locator("#login-token")).to_have_attribute("aria-invalid", "true")
    assert page.locator("#nav").is_hidden()
    page.fill("#login-token", TOKEN)
    page.press("#login-token", "Enter")
    expect(page.locator("#user-name")).to_have_text("admin (admin)")
    expect(page.locator("#stream-state")).to_have_text("live")
    assert page.evaluate("() => sessionStorage.getItem('twb.token')") == TOKEN
    page.reload()  # the token survives a reload of the tab
    expect(page.locator("#view-field")).to_be_visible()
    page.click("#logout")
    expect(page.locator("#view-login")).to_be_visible()
    assert page.evaluate("() => sessionStorage.getItem('twb.token')") is None
    # the one expected console error: the browser's note on the refused /users/me
    assert page.console.unexpected("status of 401") == []
    assert len(page.console.errors) == 1, page.console.errors


def test_submit_through_the_form_watch_it_complete_and_read_the_metrics(page, testbed):
    from playwright.sync_api import expect

    login(page, testbed.url)
    # the field shows all four robots (where they start up, or where they last stopped)
    expect(page.locator("#subfield-table tbody tr")).to_have_count(4)
    page.wait_for_timeout(300)
    for k, (ox, oy) in SUBFIELD_ORIGINS.items():
        n = count_pixels(page, "#field-canvas", ROBOT_RGB, region=(ox, oy, ox + 1.8, oy + 1.8)) + \
            count_pixels(page, "#field-canvas", ROBOT_GHOST_RGB, region=(ox, oy, ox + 1.8, oy + 1.8))
        assert n > 20, f"no robot drawn on sub-field {k}"

    page.click("#nav a[data-view=submit]")
    page.select_option("#f-environment", "room")
    page.wait_for_timeout(200)
    geo = canvas_geometry(page, "#submit-canvas")
    page.check("input[name=pick][value=start]")
    page.mouse.click(*world_to_page(geo, 0.3, 0.3))  # a click: position, heading kept
    expect(page.locator("input[name=pick][value=goal]")).to_be_checked()  # moves on to the goal
    gx, gy = world_to_page(geo, 1.5, 1.5)
    page.mouse.move(gx, gy)
    page.mouse.down()
    page.mouse.move(gx, gy - 50, steps=5)  # drag upwards: heading +90°
    page.mouse.up()
    assert float(page.input_value("#f-start-x")) == pytest.approx(0.3, abs=0.01)
    assert float(page.input_value("#f-start-y")) == pytest.approx(0.3, abs=0.01)
    assert float(page.input_value("#f-goal-x")) == pytest.approx(1.5, abs=0.01)
    assert float(page.input_value("#f-goal-y")) == pytest.approx(1.5, abs=0.01)
    assert float(page.input_value("#f-goal-a")) == pytest.approx(math.pi / 2, abs=0.02)
    page.select_option("#f-planner", "fm2")
    expect(page.locator("#f-controller option")).to_have_count(4)  # the built-ins, schema first
    page.select_option("#f-controller", "pure_pursuit")
    # the controller's parameters: one input each, the default as placeholder; a bad value is refused next to it
    expect(page.locator("#f-cparam-lookahead_m")).to_have_attribute("placeholder", "0.06")
    page.fill("#f-cparam-lookahead_m", "-1")
    page.fill("#f-repetitions", "2")
    page.fill("#f-seed", "3")
    page.click("#submit-button")
    expect(page.locator("#err-controller_params")).to_contain_text("lookahead_m")
    expect(page.locator("#f-cparam-lookahead_m")).to_have_attribute("aria-invalid", "true")
    page.fill("#f-cparam-lookahead_m", "0.08")
    page.screenshot(path=OUTPUT / "submit.png")
    exp = submit_and_wait(page, testbed)
    exp_id = exp["id"]
    assert exp["controller"] == "pure_pursuit" and exp["controller_params"]["lookahead_m"] == 0.08
    expect(page.locator("dl.facts").first).to_contain_text("Controllerpure_pursuit")
    assert exp["start"][:2] == pytest.approx([0.3, 0.3], abs=0.01) and exp["planner"] == "fm2"
    assert exp["goal"][2] == pytest.approx(math.pi / 2, abs=0.02) and exp["repetitions"] == 2 and exp["seed"] == 3

    # metrics: every run's row filled, aggregates per mode, the direct comparison
    rows = page.locator("#runs-table tbody tr[data-run]")
    expect(rows).to_have_count(4)
    expect(page.locator('#runs-table tr[data-run] .badge')).to_have_text(["completed"] * 4)
    lengths = [float(t) for t in page.locator('#runs-table tr[data-run] td[data-metric="length_m"]').all_inner_texts()]
    by_api = sorted(r["metrics"]["length_m"] for r in exp["runs"])
    assert sorted(lengths) == pytest.approx(by_api, abs=1e-3)
    # each run's planning time under its status (its repetition's own timing), as the API has it
    shown = page.locator('#runs-table tr[data-run] .planning').all_inner_texts()
    assert sorted(shown) == sorted(f"plan {1000 * r['planning_time_s']:.1f} ms" for r in exp["runs"]), shown
    expect(page.locator('#aggregates-table tr[data-metric="length_m"] td')).to_have_count(6)
    expect(page.locator("#direct-table tbody tr")).to_have_count(2)
    expect(page.locator("#experiment-charts figure svg")).to_have_count(6)
    # planned and performed paths drawn: both modes' colours on the canvas
    assert count_pixels(page, "#experiment-canvas", TWB_RGB, tol=40) > 50
    assert count_pixels(page, "#experiment-canvas", SIM_RGB, tol=40) > 50
    page.screenshot(path=OUTPUT / "experiment.png", full_page=True)

    # a download goes through the token-carrying fetch
    twb_run = next(r for r in exp["runs"] if r["mode"] == "twb")
    with page.expect_download() as dl:
        page.click(f'#runs-table button[aria-label="Download poses of run {twb_run["id"]} as CSV"]')
    path = dl.value.path()
    assert dl.value.suggested_filename == f"run-{twb_run['id']}-poses.csv"
    assert Path(path).read_text().splitlines()[0] == "t,x,y,theta"
    # and the run for Foxglove: an MCAP file (docs/exports.md; its contents: tests/test_exports.py)
    with page.expect_download() as dl:
        page.click(f'#runs-table button[aria-label="Download run {twb_run["id"]} as MCAP (Foxglove)"]')
    assert dl.value.suggested_filename == f"run-{twb_run['id']}.mcap"
    assert Path(dl.value.path()).read_bytes()[:8] == b"\x89MCAP0\r\n"

    # back on the field: the robot that drove stands at the goal, its trace drawn
    page.click("#nav a[data-view=field]")
    ox, oy = SUBFIELD_ORIGINS[twb_run["subfield"]]
    goal = (1.5 + ox, 1.5 + oy)
    page.wait_for_timeout(500)
    near_goal = (goal[0] - 0.15, goal[1] - 0.15, goal[0] + 0.15, goal[1] + 0.15)
    assert count_pixels(page, "#field-canvas", ROBOT_RGB, region=near_goal) > 20
    assert count_pixels(page, "#field-canvas", TWB_RGB, tol=70, region=(ox, oy, ox + 1.8, oy + 1.8)) > 30
    label = page.get_attribute("#field-canvas", "aria-label")
    assert f"{twb_run['robot_id']} at" in label
    page.screenshot(path=OUTPUT / "field.png")
    page.click("#nav a[data-view=experiments]")
    expect(page.locator(f'#exp-finished tr[data-experiment="{exp_id}"]')).to_be_visible()
    # the only console error: the browser's note on the 422 answer to the bad controller parameter
    assert len(page.console.errors) == 1 and "422" in page.console.errors[0], page.console.errors


MOVERS = {"name": "movers", "size": [1.8, 1.8], "blocks": [], "moving_obstacles": [
    {"radius": 0.05, "waypoints": [[0.2, 0.2], [1.6, 0.2], [1.6, 1.0]], "speed": 0.1, "repeat": "once", "delay_s": 2},
    {"radius": 0.04, "waypoints": [[0.3, 1.5], [1.5, 1.5], [0.9, 0.9]], "speed": 0.15, "repeat": "loop"},
    {"radius": 0.06, "waypoints": [[0.2, 0.9], [1.0, 0.9]], "speed": 0.12, "repeat": "pingpong", "delay_s": 1},
    {"radius": 0.03, "random_walk": {"seed": 7, "start": [0.9, 0.5], "steps": 12, "step_m": 0.2}, "speed": 0.1,
     "repeat": "pingpong"}]}


def test_moving_obstacles_are_drawn_where_the_simulation_has_them(page, testbed):
    """The dashboard's moving obstacles (static/js/moving.js) stand where planners.moving puts them, at every
    repeat mode, delay and a random walk; the submit map draws them where they stand when a path starts."""
    from planners import parse_environment
    from planners.moving import positions

    with testbed.client() as c:
        r = c.post("/api/v1/environments", json=MOVERS)
        assert r.status_code in (201, 409), r.text
        tracks = c.get("/api/v1/environments/movers").json()["moving_tracks"]
    assert len(tracks) == 4 and len(tracks[3]["waypoints"]) == 13  # the random walk, expanded
    login(page, testbed.url)
    times = [0.0, 0.5, 1.0, 3.3, 7.7, 12.0, 19.9, 31.4, 64.0, 150.0]
    got = page.evaluate("""async ([tracks, times]) => {
      const { obstacleAt } = await import("/static/js/moving.js");
      return tracks.map((tr) => times.map((t) => obstacleAt(tr, t)));
    }""", [tracks, times])
    want = positions(parse_environment(MOVERS).moving_obstacles, np.array(times))
    np.testing.assert_allclose(np.array(got), want, atol=1e-9)

    page.click("#nav a[data-view=submit]")
    page.select_option("#f-environment", "movers")
    page.wait_for_timeout(300)
    teal = (0x00, 0x89, 0x7B)
    for (x, y), ob in zip(want[:, 0], MOVERS["moving_obstacles"]):
        r = ob["radius"] * 0.7
        assert count_pixels(page, "#submit-canvas", teal, tol=30, region=(x - r, y - r, x + r, y + r)) > 10, (x, y)
    assert page.console.errors == []


def test_server_validation_errors_are_shown_next_to_the_field(page, testbed):
    from playwright.sync_api import expect

    login(page, testbed.url)
    page.click("#nav a[data-view=submit]")
    page.select_option("#f-environment", "room")
    # start on a wall of the room (the wall block centred at (0.9, 0.15)) - typed, not clicked
    page.fill("#f-start-x", "0.9")
    page.fill("#f-start-y", "0.15")
    page.fill("#f-goal-x", "1.5")
    page.fill("#f-goal-y", "1.5")
    page.click("#submit-button")
    expect(page.locator("#err-start")).to_contain_text("inside an obstacle")
    expect(page.locator("#f-start-x")).to_have_attribute("aria-invalid", "true")
    expect(page.locator("#err-goal")).to_be_empty()
    assert page.evaluate("() => document.activeElement.id") == "f-start-x"
    # a request-model error (pydantic) lands next to its field too
    page.fill("#f-start-y", "0.3")
    page.fill("#f-start-x", "0.3")
    page.fill("#f-repetitions", "0")
    page.click("#submit-button")
    expect(page.locator("#err-repetitions")).to_contain_text("greater than or equal to 1")
    expect(page.locator("#err-start")).to_be_empty()
    # a planner parameter out of range
    page.fill("#f-repetitions", "1")
    page.fill("#f-param-step", "7")
    page.click("#submit-button")
    expect(page.locator("#err-planner_params")).to_contain_text("step must be a number in [0.05, 1]")
    expect(page.locator("#f-param-step")).to_have_attribute("aria-invalid", "true")
    # nothing was queued; the only console errors are the browser's notes on the three 422 answers
    assert page.console.unexpected("status of 422") == []
    assert len(page.console.errors) == 3, page.console.errors


def test_keyboard_only_placement_and_submit(page, testbed):
    from playwright.sync_api import expect

    login(page, testbed.url)
    page.click("#nav a[data-view=submit]")
    page.select_option("#f-environment", "room")
    page.click("#env-plans button:has-text('Plan A')")
    page.focus("#submit-canvas")
    page.keyboard.press("s")
    for _ in range(3):
        page.keyboard.press("ArrowRight")  # 3 cm
    page.keyboard.press("Shift+ArrowUp")  # 10 cm
    page.keyboard.press("[")  # +15°
    assert float(page.input_value("#f-start-x")) == pytest.approx(0.33, abs=1e-6)
    assert float(page.input_value("#f-start-y")) == pytest.approx(0.40, abs=1e-6)
    assert float(page.input_value("#f-start-a")) == pytest.approx(math.radians(15), abs=1e-3)
    expect(page.locator("#map-readout")).to_contain_text("start at (0.33, 0.40) m, heading 15°")
    page.uncheck("input[name=modes][value=twb]")
    page.focus("#f-seed")
    page.keyboard.press("Enter")  # submits the form
    expect(page.locator("#view-experiment")).to_be_visible()
    expect(page.locator("#view-experiment .exp-head .badge")).to_have_text("completed", timeout=60_000)
    assert page.console.errors == []


def test_a_user_sees_the_field_but_only_their_own_experiments(page, testbed):
    from playwright.sync_api import expect

    with testbed.client() as c:
        user = c.post("/api/v1/users", json={"name": "dash-user"}).json()
        theirs = c.post("/api/v1/experiments", json={"environment": "room", "start": [0.3, 0.3], "goal": [0.6, 0.3],
                                                      "planner": "astar", "modes": ["sim"]}).json()
    login(page, testbed.url, user["token"])
    expect(page.locator("#user-name")).to_have_text("dash-user")
    expect(page.locator("#subfield-table tbody tr")).to_have_count(4)
    page.wait_for_timeout(300)
    assert count_pixels(page, "#field-canvas", ROBOT_RGB) + count_pixels(page, "#field-canvas", ROBOT_GHOST_RGB) > 40
    page.click("#nav a[data-view=experiments]")
    expect(page.locator("#exp-finished tbody tr.empty-row")).to_have_count(1)
    page.goto(f"{testbed.url}/#/experiments/{theirs['id']}")
    expect(page.locator("#view-experiment .error")).to_contain_text("Experiment not found")
    # the browser's note on the 404 for someone else's experiment is the only console error
    assert page.console.unexpected("status of 404") == []


def test_without_uploads_the_dashboard_says_so_plainly(page, testbed):
    """The default `twb up` runs without --enable-uploads: no upload form, a plain statement instead."""
    from playwright.sync_api import expect

    login(page, testbed.url)
    page.click("#nav a[data-view=programs]")
    expect(page.locator("#uploads-disabled")).to_be_visible()
    expect(page.locator("#uploads-disabled")).to_contain_text("Uploads are disabled on this testbed")
    expect(page.locator("#uploads-disabled")).to_contain_text("--enable-uploads")
    expect(page.locator("#upload-form")).to_be_hidden()
    expect(page.locator("#sandbox-panel")).to_be_hidden()
    expect(page.locator("#programs-table tbody tr.empty-row")).to_have_text("No programs yet.")
    page.screenshot(path=OUTPUT / "uploads-disabled.png")
    # the submit form offers the program, says why it cannot be used, and refuses it next to the field
    page.click("#nav a[data-view=submit]")
    page.select_option("#f-environment", "room")
    page.click("#env-plans button:has-text('Plan A')")
    page.check('input[name="source"][value="program"]')
    expect(page.locator("#program-desc")).to_contain_text("Uploads are disabled on this testbed")
    expect(page.locator("#f-program")).to_be_hidden()
    expect(page.locator("#f-planner")).to_be_hidden()
    page.click("#submit-button")
    expect(page.locator("#err-program")).to_have_text("uploads are disabled on this testbed")
    # an explicit path instead: waypoints by clicking the map, checked by the server
    page.check('input[name="source"][value="path"]')
    expect(page.locator("#err-program")).to_be_hidden()
    page.check('input[name="pick"][value="waypoint"]')
    geo = canvas_geometry(page, "#submit-canvas")
    page.mouse.click(*world_to_page(geo, 0.9, 0.15))  # on the room's wall
    expect(page.locator("#f-path")).to_have_value("0.900, 0.150")
    expect(page.locator("#map-readout")).to_contain_text("1 so far")
    page.click("#submit-button")
    expect(page.locator("#err-path")).to_contain_text("path point 1")
    expect(page.locator("#f-path")).to_have_attribute("aria-invalid", "true")
    page.focus("#submit-canvas")
    page.keyboard.press("Delete")  # removes the last waypoint
    expect(page.locator("#f-path")).to_have_value("")
    page.fill("#f-path", "0.45, 0.9\n0.6 1.35")  # through the doorways
    page.uncheck("input[name=modes][value=twb]")
    page.screenshot(path=OUTPUT / "submit-path.png")
    page.click("#submit-button")
    expect(page.locator("#view-experiment")).to_be_visible()
    expect(page.locator("#view-experiment .facts dd").nth(2)).to_have_text("explicit path")
    expect(page.locator("#program-panel")).to_be_hidden()
    assert page.console.unexpected("status of 422") == []
    assert len(page.console.errors) == 1, page.console.errors


CRASH_RGB = (0xD8, 0x1B, 0x60)  # experiments.js CRASH_COLOR: the cross where a failed run stopped
OVERSHOOT_ENV = {"name": "dash-overshoot", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.3, "h": 0.3}]}
#: the first robots' colours of a multi-robot experiment (static/js/fleet.js ROBOT_COLORS)
FLEET_RGB = [(0xE6, 0x19, 0x4B), (0x3C, 0xB4, 0x4B), (0x43, 0x63, 0xD8), (0xF5, 0x82, 0x31)]


def test_a_multi_robot_experiment_shows_every_robot(page, testbed):
    """Four robots swapping corners (prioritized, sim and field): the experiment page draws each robot's planned
    and performed paths in its colour and tabulates each robot; the field page shows them where they ended."""
    from playwright.sync_api import expect

    job = json.loads((ROOT / "examples" / "fleet" / "swap-prioritized.json").read_text())
    with testbed.client() as c:
        r = c.post("/api/v1/experiments", json={**job, "modes": ["sim", "twb"]})
        assert r.status_code == 202, r.text
        exp_id = r.json()["id"]
    login(page, testbed.url)
    page.goto(f"{testbed.url}/#/experiments/{exp_id}")
    expect(page.locator("#view-experiment .exp-head .badge")).to_have_text("completed", timeout=60_000)
    expect(page.locator("#robots-table tbody tr")).to_have_count(8)  # 2 runs x 4 robots
    expect(page.locator("#robots-table tbody tr td:nth-child(4)")).to_have_text(["arrived"] * 8)
    with testbed.client() as c:
        m = c.get(f"/api/v1/experiments/{exp_id}/metrics").json()
    twb = next(x for x in m["runs"] if x["mode"] == "twb")
    shown = page.locator(f'#runs-table tr[data-run="{twb["run_id"]}"] td[data-metric="makespan_s"]').inner_text()
    assert float(shown) == pytest.approx(twb["metrics"]["makespan_s"], abs=1e-3)
    expect(page.locator("dl.facts").first).to_contain_text("Robots4")
    page.wait_for_timeout(300)
    for k, rgb in enumerate(FLEET_RGB):
        start = job["robots"][k]["start"]
        assert count_pixels(page, "#experiment-canvas", rgb, tol=40) > 100, f"robot {k}'s paths not drawn"
        assert count_pixels(page, "#experiment-canvas", rgb, tol=40,
                            region=(start[0] - 0.06, start[1] - 0.06, start[0] + 0.06, start[1] + 0.06)) > 5
    page.screenshot(path=OUTPUT / "fleet-experiment.png", full_page=True)

    page.click("#nav a[data-view=field]")
    expect(page.locator("#view-field")).to_be_visible()
    page.wait_for_timeout(600)
    seen = [count_pixels(page, "#field-canvas", rgb, tol=40) for rgb in FLEET_RGB]
    assert sum(n > 30 for n in seen) >= 2, seen  # at least two of the fleet's robots (and traces) on the field
    assert "/3 at (" in page.get_attribute("#field-canvas", "aria-label")
    page.screenshot(path=OUTPUT / "fleet-field.png")
    assert page.console.errors == []


CORNER = {"start": [0.9, 0.3, 1.5708], "goal": [1.5, 0.69, 0.0]}  # the path turns 6 cm below the block


def test_a_crash_is_marked_and_experiments_compare_side_by_side(page, testbed):
    """The field robot overshoots a corner into a block, the ideal one does not: the experiment page marks where
    each failed run stopped; the compare view shows both experiments' outcomes, means and the server's
    comparisons on their one problem (and says that one problem gives no verdict over problems)."""
    from playwright.sync_api import expect

    with testbed.client() as c:
        assert c.post("/api/v1/environments", json=OVERSHOOT_ENV).status_code == 201
        job = {"environment": "dash-overshoot", "modes": ["sim", "twb"], "repetitions": 2, "seed": 0, **CORNER}
        safe = c.post("/api/v1/experiments", json={**job, "planner": "fm2"})  # the lower id: "a" in the comparison
        corner = c.post("/api/v1/experiments", json={**job, "path": [CORNER["start"], [0.9, 0.69], CORNER["goal"]]})
        corner, safe = (wait_for(c, r.json()["id"], timeout=120) for r in (corner, safe))
    crashed = [r for r in corner["runs"] if r["mode"] == "twb"]
    assert [r["failure"] for r in crashed] == ["collision", "collision"] and safe["status"] == "completed"

    login(page, testbed.url)
    page.goto(f"{testbed.url}/#/experiments/{corner['id']}")
    expect(page.locator("#view-experiment .exp-head .badge")).to_have_text("failed")
    # (at --time-scale max the server occasionally has no stopped_at for a collision; the map then marks the
    # last logged pose)
    located = [r for r in crashed if r["stopped_at"]]
    expect(page.locator("#runs-table .stopped")).to_have_count(len(located))
    if located:
        expect(page.locator("#runs-table .stopped").first).to_contain_text("✕ stopped at (0.9")
    expect(page.locator(".legend label", has_text="✕ collision")).to_have_count(2)
    expect(page.locator("#experiment-charts figure").first).to_contain_text("none completed")  # under "twb"
    page.wait_for_timeout(400)
    for r in located:
        x, y = r["stopped_at"]
        assert count_pixels(page, "#experiment-canvas", CRASH_RGB, tol=20, region=(x - 0.06, y - 0.06, x + 0.06, y + 0.06)) > 20
    assert count_pixels(page, "#experiment-canvas", CRASH_RGB, tol=20, region=(1.2, 1.2, 1.8, 1.8)) == 0
    page.screenshot(path=OUTPUT / "experiment-crash.png", full_page=True)

    # tick both in the list, compare
    page.click("#nav a[data-view=experiments]")
    expect(page.locator("#compare-button")).to_be_disabled()
    page.check(f'#exp-finished tr[data-experiment="{safe["id"]}"] input.compare-pick')
    expect(page.locator("#compare-button")).to_be_disabled()  # two or more
    page.check(f'#exp-finished tr[data-experiment="{corner["id"]}"] input.compare-pick')
    expect(page.locator("#compare-button")).to_have_text("Compare selected (2)")
    page.click("#compare-button")
    expect(page.locator("#view-compare")).to_be_visible()
    assert page.url.endswith(f"#/compare?ids={safe['id']},{corner['id']}")
    expect(page.locator("#compare-title")).to_have_text(f"Compare experiments #{safe['id']}, #{corner['id']}")
    expect(page.locator("#compare-facts tbody tr")).to_have_count(2)
    assert (safe["label"], corner["label"]) == ("fm2", "explicit path")  # the server's names for these jobs
    assert safe["problem"] == corner["problem"] == "dash-overshoot (0.90,0.30)→(1.50,0.69)"
    expect(page.locator("#compare-facts tbody tr").first).to_contain_text("dash-overshoot (0.90,0.30)→(1.50,0.69)")
    # outcomes per configuration (each one experiment here), with the server's Wilson interval
    crash_row = page.locator('#compare-outcomes tr[data-configuration="explicit path"][data-mode="twb"]')
    expect(crash_row.locator('td[data-outcome="collision"]')).to_have_text("2")
    expect(crash_row.locator('td[data-outcome="success"]')).to_have_text("0")
    expect(crash_row).to_contain_text("0/2 (0 %–66 %)")
    safe_row = page.locator('#compare-outcomes tr[data-configuration="fm2"][data-mode="twb"]')
    expect(safe_row).to_contain_text("2/2 (34 %–100 %)")
    expect(safe_row).to_have_attribute("data-experiments", str(safe["id"]))
    # the simulation repeats itself without jitter: its two runs are one observation, said so
    sim_row = page.locator('#compare-outcomes tr[data-configuration="fm2"][data-mode="sim"]')
    expect(sim_row).to_contain_text("2/2 runs; identical repetitions (deterministic simulation) counted once: 1/1")
    # means: the field column of the crashing path has no completed run, and says so
    expect(page.locator('#compare-means tr[data-metric="length_m"] td').nth(2)).to_have_text("no completed run (0 of 2)")
    # sim repetitions without jitter are identical: said, not given an interval
    expect(page.locator('#compare-means tr[data-metric="length_m"] td').nth(1)).to_contain_text(
        "identical repetitions (deterministic simulation)")
    # one problem: no verdict over problems, in words; its own comparisons below
    expect(page.locator("#compare-no-verdict")).to_contain_text("No verdict over problems: these experiments are on 1 "
                                                                 "problem")
    expect(page.locator("#compare-pooled")).to_have_count(0)
    # the problem's comparisons: the success rate on the field, Fisher's exact p of 2/2 against 0/2 (1/3)
    rate = page.locator('#compare-differences tr[data-a="fm2"][data-mode="twb"][data-metric="success_rate"]')
    expect(rate.locator('td[data-k="diff"]')).to_have_text("+100 points")
    expect(rate.locator('td[data-k="p"]')).to_have_text("0.33")
    twb_length = page.locator('#compare-differences tr[data-mode="twb"][data-metric="length_m"]')
    expect(twb_length.locator('td[data-k="note"]')).to_have_text("no completed run of explicit path")
    sim_length = page.locator('#compare-differences tr[data-mode="sim"][data-metric="length_m"]')
    expect(sim_length.locator('td[data-k="ci"]')).to_have_text("–")
    expect(sim_length.locator('td[data-k="note"]')).to_contain_text("identical repetitions (deterministic simulation)")
    fm2 = [r["metrics"]["length_m"] for r in safe["runs"] if r["mode"] == "sim"]
    cor = [r["metrics"]["length_m"] for r in corner["runs"] if r["mode"] == "sim"]
    shown = float(sim_length.locator('td[data-k="diff"]').inner_text().split()[0])
    assert shown == pytest.approx(fm2[0] - cor[0], abs=1e-3)
    expect(page.locator("#compare-method")).to_contain_text("the problem (an environment with a start/goal plan) is "
                                                            "the unit of inference")
    page.screenshot(path=OUTPUT / "compare.png", full_page=True)
    assert no_horizontal_overflow(page)
    assert page.console.errors == []


def test_tablet_width_layout(browser, testbed):
    ctx = browser.new_context(viewport=TABLET, device_scale_factor=2, has_touch=True)
    pg = ctx.new_page()
    console = Console(pg)
    try:
        login(pg, testbed.url)
        canvas = pg.locator("#field-canvas").bounding_box()
        side = pg.locator("aside.side").bounding_box()
        assert canvas["width"] > 500 and canvas["x"] >= 0 and canvas["x"] + canvas["width"] <= TABLET["width"]
        assert side["y"] >= canvas["y"] + canvas["height"]  # one column: the tables below the field
        assert no_horizontal_overflow(pg)
        pg.wait_for_timeout(300)
        assert count_pixels(pg, "#field-canvas", ROBOT_RGB) + count_pixels(pg, "#field-canvas", ROBOT_GHOST_RGB) > 40
        pg.screenshot(path=OUTPUT / "tablet-field.png")
        pg.click("#nav a[data-view=submit]")
        pg.locator("#f-environment option").first.wait_for(state="attached")
        m = pg.locator("#submit-canvas").bounding_box()
        assert m["width"] > 300 and m["x"] + m["width"] <= TABLET["width"]
        assert no_horizontal_overflow(pg)
        pg.screenshot(path=OUTPUT / "tablet-submit.png", full_page=True)
        with testbed.client() as c:
            exp = c.post("/api/v1/experiments", json={"environment": "blocks", "start": [0.15, 0.15, 0], "goal": [1.65, 1.65, 1.57],
                                                       "planner": "fmm", "modes": ["sim", "twb"], "repetitions": 1}).json()
            wait_for(c, exp["id"], timeout=60)
        pg.goto(f"{testbed.url}/#/experiments/{exp['id']}")
        pg.locator("#runs-table tbody tr[data-run]").first.wait_for()
        assert no_horizontal_overflow(pg)  # wide tables scroll inside their panel
        pg.screenshot(path=OUTPUT / "tablet-experiment.png", full_page=True)
        assert console.errors == []
    finally:
        ctx.close()


def test_without_the_event_stream_the_dashboard_polls(browser, testbed):
    """A proxy that buffers or blocks the stream: the dashboard says so and keeps itself current."""
    from playwright.sync_api import expect

    ctx = browser.new_context(viewport=LAPTOP)
    ctx.route("**/api/v1/events", lambda route: route.fulfill(status=503, body="no streams here"))
    pg = ctx.new_page()
    console = Console(pg)
    try:
        pg.goto(testbed.url + "/")
        pg.fill("#login-token", TOKEN)
        pg.press("#login-token", "Enter")
        expect(pg.locator("#stream-state")).to_have_text("polling")
        with testbed.client() as c:
            exp = c.post("/api/v1/experiments", json={"environment": "room", "start": [0.3, 0.3], "goal": [1.5, 0.3],
                                                       "planner": "astar", "modes": ["twb"]}).json()
            done = wait_for(c, exp["id"], timeout=60)
        run = done["runs"][0]
        ox, oy = SUBFIELD_ORIGINS[run["subfield"]]
        # the finished experiment shows up and the robot is drawn where it stopped, all by polling
        pg.click("#nav a[data-view=experiments]")
        expect(pg.locator(f'#exp-finished tr[data-experiment="{exp["id"]}"]')).to_be_visible(timeout=10_000)
        pg.click("#nav a[data-view=field]")
        expect(pg.locator(f'#subfield-table tr[data-subfield="{run["subfield"]}"] td').nth(2)).to_have_text("room")
        pg.wait_for_timeout(300)
        assert count_pixels(pg, "#field-canvas", ROBOT_RGB, region=(ox + 1.3, oy + 0.1, ox + 1.7, oy + 0.5)) > 20
        assert console.unexpected("status of 503") == []
    finally:
        ctx.close()
