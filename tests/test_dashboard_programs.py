"""Uploaded planner programs in the dashboard: Chromium against a real `twb up --time-scale max --enable-uploads`.

Upload a small Python planner through the form, submit a job with it through the
submit form, watch it complete and read the program's log on the experiment page; a
failing program's reason, exit code and dropped output at tablet width.  The
browser, the console check and the screenshots (``tests/output/dashboard/``) are
those of ``test_dashboard.py``; uploads switched off are checked there, against its
default ``twb up``.
"""

from __future__ import annotations

import base64

import pytest

from servers import wait_for
from test_dashboard import OUTPUT, TABLET, Console, login, no_horizontal_overflow, submit_and_wait
from test_dashboard import browser, page  # noqa: F401  (the shared fixtures)

# a straight line from the start to the goal, sent as T,T,P; its arguments on stdout, a note on stderr
LINE_PLANNER = """\
import os, socket, sys
print("args:", " ".join(sys.argv[1:]))
print("a note on stderr", file=sys.stderr)
sx, sy = (float(v) for v in os.environ["TWB_START"].split(",")[:2])
gx, gy = (float(v) for v in os.environ["TWB_GOAL"].split(",")[:2])
line = f"T,T,P,{sx * 1000:.0f},{sy * 1000:.0f},45;{gx * 1000:.0f},{gy * 1000:.0f},45"
with socket.create_connection((os.environ["TWB_ROBOT_HOST"], int(os.environ["TWB_ROBOT_PORT"]))) as sock:
    robot = sock.makefile("rw", newline="\\n")
    print("robot:", robot.readline().strip())
    robot.write(line + "\\n")
    robot.flush()
    print("robot:", robot.readline().strip())
"""
# floods stdout past the 64 KiB the log keeps, then gives up
CRASH = """\
import sys
for i in range(100):
    print(f"{i:03d} " + "x" * 1000)
print("giving up", file=sys.stderr)
sys.exit(3)
"""
OPEN = {"name": "open", "size": [1.8, 1.8], "blocks": []}  # nothing in the way of a straight line


@pytest.fixture(scope="module")
def testbed(testbeds):  # its own: uploads enabled
    for p in testbeds.own("up", "--time-scale", "max", "--sim-robots", "2", "--enable-uploads"):
        with p.client() as c:
            assert c.post("/api/v1/environments", json=OPEN).status_code == 201
        yield p


def fact(pg, name: str):
    return pg.locator(f'#program-panel [data-fact="{name}"] dd')


def test_upload_a_program_submit_it_and_read_its_log(page, testbed):  # noqa: F811
    from playwright.sync_api import expect

    login(page, testbed.url)
    page.click("#nav a[data-view=programs]")
    expect(page.locator("#upload-form")).to_be_visible()
    expect(page.locator("#uploads-disabled")).to_be_hidden()
    expect(page.locator("#sandbox-facts")).to_contain_text("Wall / CPU time")
    expect(page.locator("#programs-table tbody tr.empty-row")).to_have_count(1)

    # choosing a .py file names the program after it and picks the kind
    page.set_input_files("#p-file", files=[{"name": "line planner.py", "mimeType": "text/x-python",
                                             "buffer": LINE_PLANNER.encode()}])
    expect(page.locator("#p-name")).to_have_value("line_planner.py")
    expect(page.locator('input[name="p-kind"][value="python"]')).to_be_checked()
    expect(page.locator("#p-interpreter-field")).to_be_hidden()
    # the server's refusal of a name lands next to the name
    page.fill("#p-name", "line planner!")
    page.click("#upload-button")
    expect(page.locator("#err-p-name")).to_contain_text("should match pattern")
    expect(page.locator("#p-name")).to_have_attribute("aria-invalid", "true")
    assert page.evaluate("() => document.activeElement.id") == "p-name"
    # the interpreter is asked for only for an executable
    page.check('input[name="p-kind"][value="executable"]')
    expect(page.locator("#p-interpreter option")).to_contain_text(["none: run the file itself"])
    page.check('input[name="p-kind"][value="python"]')
    page.fill("#p-name", "line-planner")
    page.fill("#p-args", "--greeting\nhello")
    page.click("#upload-button")
    expect(page.locator("#upload-done")).to_contain_text("Uploaded program #")
    row = page.locator("#programs-table tbody tr[data-program]")
    expect(row).to_have_count(1)
    expect(row).to_contain_text("line-planner")
    expect(row).to_contain_text("--greeting hello")
    prog_id = int(row.get_attribute("data-program"))
    with testbed.client() as c:
        prog = c.get(f"/api/v1/programs/{prog_id}").json()
        assert c.get(f"/api/v1/programs/{prog_id}/content").content == LINE_PLANNER.encode()
    assert prog["kind"] == "python" and prog["args"] == ["--greeting", "hello"] and prog["interpreter"] is None
    page.screenshot(path=OUTPUT / "programs.png", full_page=True)

    # "Use in a job": the submit form with the program chosen
    row.locator("a:has-text('Use in a job')").click()
    expect(page.locator("#view-submit")).to_be_visible()
    expect(page.locator('input[name="source"][value="program"]')).to_be_checked()
    expect(page.locator("#f-program")).to_have_value(str(prog_id))
    expect(page.locator("#f-planner")).to_be_hidden()
    expect(page.locator("#program-desc")).to_contain_text("arguments --greeting hello")
    page.select_option("#f-environment", "open")
    for k, v in {"start-x": "0.3", "start-y": "0.3", "start-a": "0.785", "goal-x": "1.5", "goal-y": "1.5", "goal-a": "0.785"}.items():
        page.fill(f"#f-{k}", v)
    # a program that is gone by the time the job arrives: the server's answer under Program
    page.eval_on_selector("#f-program", "s => { s.options[s.selectedIndex].value = '999'; }")
    page.click("#submit-button")
    expect(page.locator("#err-program")).to_have_text("unknown program 999")
    expect(page.locator("#f-program")).to_have_attribute("aria-invalid", "true")
    page.eval_on_selector("#f-program", f"s => {{ s.options[s.selectedIndex].value = '{prog_id}'; }}")
    page.screenshot(path=OUTPUT / "submit-program.png", full_page=True)
    exp = submit_and_wait(page, testbed)
    exp_id = exp["id"]
    info = exp["planning_info"]["program"]
    assert exp["program"] == prog_id and exp["planner"] is None and info["exit_code"] == 0
    panel = page.locator("#program-panel")
    expect(panel).to_be_visible()
    expect(fact(page, "Program")).to_have_text(f"line-planner (#{prog_id})")
    expect(fact(page, "Ended with")).to_have_text("exit code 0")
    expect(fact(page, "Timed out")).to_have_text("no")
    expect(fact(page, "Dropped output")).to_have_text("stdout none, stderr none")
    expect(fact(page, "Executed in")).to_contain_text(f"run {info['run_id']}")
    expect(fact(page, "Isolation")).to_contain_text("namespaces" if info["isolation"]["namespaces"] else "no namespaces")
    expect(page.locator("#view-experiment .facts dd").nth(2)).to_have_text(f"program line-planner (#{prog_id})")

    # the log: stdout, stderr, the robot-port conversation and the sandbox's notes, each styled apart
    log = page.locator("#program-log")
    expect(log.locator("li.log-stdout")).to_contain_text(["args: --greeting hello", "robot: HELLO,", "robot: OK,P,2"])
    expect(log.locator("li.log-stderr .text")).to_have_text(["a note on stderr"])
    expect(log.locator("li.log-port").first).to_contain_text("robot port > HELLO,")
    expect(log.locator("li.log-port")).to_contain_text(["robot port < T,T,P,300,300,45;1500,1500,45"])
    expect(log.locator("li.log-sandbox").last).to_contain_text("program ended (exit code 0)")
    styles = page.evaluate("""() => ["stdout", "stderr", "port", "sandbox"].map((k) => {
      const s = getComputedStyle(document.querySelector(`#program-log li.log-${k}`));
      return [s.color, s.borderLeftColor, s.fontStyle].join(" ");
    })""")
    assert len(set(styles)) == 4, styles

    # keyboard: Tab reaches the filters and the scrollable log; Space hides stdout
    page.focus('#program-panel input[data-kind="stdout"]')
    page.keyboard.press("Space")
    expect(log.locator("li.log-stdout")).to_have_count(0)
    expect(log.locator("li.log-stderr")).to_have_count(1)
    page.keyboard.press("Space")
    expect(log.locator("li.log-stdout")).to_have_count(3)
    for _ in range(6):
        page.keyboard.press("Tab")
        if page.evaluate("() => document.activeElement.id") == "program-log":
            break
    assert page.evaluate("() => document.activeElement.id") == "program-log"
    page.locator("#program-panel").screenshot(path=OUTPUT / "program-panel.png")
    page.screenshot(path=OUTPUT / "experiment-program.png", full_page=True)

    # the experiment list names the program
    page.click("#nav a[data-view=experiments]")
    expect(page.locator(f'#exp-finished tr[data-experiment="{exp_id}"]')).to_contain_text(f"program line-planner (#{prog_id})")
    # the browser's notes on the two refusals (the name, the unknown program) are the only console errors
    assert page.console.unexpected("status of 422") == []
    assert len(page.console.errors) == 2, page.console.errors


def test_a_failing_program_shows_why_at_tablet_width(browser, testbed):  # noqa: F811
    from playwright.sync_api import expect

    with testbed.client() as c:
        prog = c.post("/api/v1/programs", json={"name": "crash.py", "kind": "python",
                                                "content_base64": base64.b64encode(CRASH.encode()).decode()}).json()
        exp = c.post("/api/v1/experiments", json={"environment": "open", "start": [0.3, 0.3], "goal": [1.5, 0.3],
                                                  "program": prog["id"], "modes": ["sim"]}).json()
        done = wait_for(c, exp["id"], timeout=60)
        programs = c.get("/api/v1/programs").json()["count"]  # this one and those of the module's other tests
    info = done["planning_info"]["program"]
    assert done["status"] == "failed" and info["exit_code"] == 3 and info["stdout_dropped_bytes"] > 0

    ctx = browser.new_context(viewport=TABLET, device_scale_factor=2, has_touch=True)
    pg = ctx.new_page()
    pg.set_default_timeout(15_000)
    console = Console(pg)
    try:
        login(pg, testbed.url)
        pg.goto(f"{testbed.url}/#/experiments/{exp['id']}")
        expect(pg.locator("#view-experiment .exp-head .badge")).to_have_text("failed")
        expect(pg.locator("#program-panel .program-reason")).to_contain_text("Why it failed: program crashed: exit code 3 (giving up)")
        expect(fact(pg, "Ended with")).to_have_text("exit code 3")
        expect(fact(pg, "Dropped output")).to_contain_text(f"stdout {info['stdout_dropped_bytes'] / 1024:.1f} KiB, stderr none")
        expect(fact(pg, "Path")).to_have_text("none accepted")
        log = pg.locator("#program-log")
        expect(log.locator("li.log-stderr .text")).to_have_text(["giving up"])
        expect(log.locator("li.log-sandbox")).to_contain_text(["stdout truncated:"])
        assert log.locator("li.log-stdout").count() >= 60  # the 64 KiB kept: 1000-character lines, wrapped
        assert no_horizontal_overflow(pg)
        pg.screenshot(path=OUTPUT / "tablet-experiment-program.png", full_page=True)
        pg.click("#nav a[data-view=programs]")
        expect(pg.locator("#programs-table tbody tr[data-program]")).to_have_count(programs)
        assert no_horizontal_overflow(pg)
        form = pg.locator("#upload-form").bounding_box()
        table = pg.locator("#programs-table").bounding_box()
        assert table["y"] > form["y"] + form["height"] - 1  # one column: the list below the form
        pg.screenshot(path=OUTPUT / "tablet-programs.png", full_page=True)
        assert console.errors == []
    finally:
        ctx.close()
