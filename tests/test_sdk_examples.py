"""The examples run: the SDK script against a testbed, the plug-in planner, C and bash planners over TCP."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from sdk_helpers import agent_process

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
TWB = Path(sys.executable).with_name("twb")


@pytest.fixture(scope="module")
def agent_port():
    with agent_process("ex") as port:
        yield port


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_c_planner_drives_a_real_agent(agent_port, tmp_path):
    exe = tmp_path / "ttp_planner"
    subprocess.run(["cc", "-O2", "-Wall", "-Werror", "-o", str(exe), str(EXAMPLES / "c_planner" / "ttp_planner.c"),
                    "-lm"], check=True, capture_output=True, text=True)
    r = subprocess.run([str(exe), "127.0.0.1", str(agent_port), "0.1", "0.1", "0.5", "0.1", "0.5", "0.6"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("HELLO,ex,") and "sent 10 points" in lines
    assert "OK,P,10" in lines and lines[-1].startswith("EV,DONE,")
    r = subprocess.run([str(exe), "127.0.0.1", str(agent_port), "0.1", "0.1", "9", "9"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 1 and r.stdout.splitlines()[-1].startswith("ERR,RANGE,")


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_bash_planner_sends_a_twb_plan_path(agent_port):
    ttp = subprocess.run([str(TWB), "plan", "--env", "room", "--plan", "A", "--planner", "fm2", "--format", "ttp"],
                         capture_output=True, text=True, check=True).stdout
    script = str(EXAMPLES / "shell_planner" / "send_path.sh")
    r = subprocess.run(["bash", script, "127.0.0.1", str(agent_port)], input=ttp, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("HELLO,ex,") and "\nOK,P," in r.stdout and "\nEV,DONE," in r.stdout
    r = subprocess.run(["bash", script, "127.0.0.1", str(agent_port), "T,T,P,1,2"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 1 and "ERR,SYNTAX," in r.stdout


@pytest.mark.slow
def test_plugin_planner_plans_and_declares_its_entry_point():
    meta = tomllib.loads((EXAMPLES / "planner_plugin" / "pyproject.toml").read_text())
    target = meta["project"]["entry-points"]["teleworkbench.planners"]["shortcut"]
    assert target == "twb_shortcut_planner:ShortcutPlanner"
    code = (
        "import sys; sys.path.insert(0, sys.argv[1])\n"
        "from planners import plan_path, register_planner\n"
        "from twb_shortcut_planner import ShortcutPlanner\n"
        "register_planner('shortcut', ShortcutPlanner)\n"
        "a = plan_path('room', (0.3, 0.3, 0), (1.5, 1.5, 1.57), 'shortcut')\n"
        "b = plan_path('room', (0.3, 0.3, 0), (1.5, 1.5, 1.57), 'astar')\n"
        "print(a.length_m < b.length_m, a.info['points_after'] < a.info['points_before'])\n"
    )
    r = subprocess.run([sys.executable, "-c", code, str(EXAMPLES / "planner_plugin")], capture_output=True, text=True)
    assert r.stdout.split() == ["True", "True"], r.stderr
