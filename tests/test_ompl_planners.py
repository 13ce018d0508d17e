"""OMPL's planners as built-ins (issue 31, item 1): valid paths by the project's own exact check, per-run
seeds, the listing, and one clear line when the ompl package is missing."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from planners import (
    DEFAULT_PLANNING_MARGIN,
    DEFAULT_ROBOT_RADIUS,
    PlanningError,
    available_planners,
    plan_path,
)
from planners.ompl_planners import INSTALL_HINT, OMPL_PLANNERS
from planners.problems import PROBLEM_CLEARANCE, problems

KW = {"robot_radius": DEFAULT_ROBOT_RADIUS, "planning_margin": DEFAULT_PLANNING_MARGIN}
PAPER = problems(("room-A", "room-B", "blocks-A", "blocks-B"))


def test_they_are_listed_without_ompl():
    names = available_planners()
    assert set(OMPL_PLANNERS) <= set(names)
    assert all("needs the ompl extra" in names[n] for n in OMPL_PLANNERS)


def test_missing_ompl_is_one_line_with_the_install_command(monkeypatch):
    for mod in [m for m in sys.modules if m == "ompl" or m.startswith("ompl.")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, "ompl", None)  # import ompl raises ImportError
    with pytest.raises(PlanningError) as err:
        plan_path("room", (0.3, 0.3), (1.5, 1.5), "ompl_rrtconnect", **KW)
    msg = str(err.value)
    assert "\n" not in msg and INSTALL_HINT in msg and "ompl_rrtconnect" in msg


@pytest.mark.parametrize("name", list(OMPL_PLANNERS))
def test_every_ompl_planner_returns_a_valid_path_on_the_paper_environments(name):
    pytest.importorskip("ompl.geometric", reason="the ompl package is not installed (pip install -e '.[ompl]')")
    from planners import config_space

    for p in PAPER:
        r = plan_path(p.env, p.start, p.goal, name, seed=1, params={"time_budget_s": 0.3}, **KW)
        space = config_space(p.env, PROBLEM_CLEARANCE)
        assert space.path_free(r.raw_path) and space.path_free(r.path)
        assert np.allclose(r.raw_path[0], p.start[:2]) and np.allclose(r.raw_path[-1], p.goal[:2])
        assert r.length_m >= p.optimum_m * 0.97
        assert r.info["ompl_planner"] == OMPL_PLANNERS[name][0] and r.info["progress"]
        lengths = [c for _, c in r.info["progress"]]
        assert lengths == sorted(lengths, reverse=True)  # the best length only improves


@pytest.mark.parametrize("name", ["ompl_rrtconnect", "ompl_kpiece1", "ompl_fmt"])
def test_a_run_seed_decides_a_first_solution_planners_path(name):
    pytest.importorskip("ompl.geometric", reason="the ompl package is not installed (pip install -e '.[ompl]')")
    p = problems(("clutter",))[0]
    a, b, c = (plan_path(p.env, p.start, p.goal, name, seed=s, params={"time_budget_s": 30}, **KW)
               for s in (5, 5, 6))
    assert np.array_equal(a.raw_path, b.raw_path)
    assert not np.array_equal(a.raw_path, c.raw_path)


def test_simplification_is_stated_and_shortens():
    pytest.importorskip("ompl.geometric", reason="the ompl package is not installed (pip install -e '.[ompl]')")
    p = PAPER[2]
    raw = plan_path(p.env, p.start, p.goal, "ompl_kpiece1", seed=2, params={"time_budget_s": 30}, **KW)
    simple = plan_path(p.env, p.start, p.goal, "ompl_kpiece1", seed=2,
                       params={"time_budget_s": 30, "simplify": True}, **KW)
    assert not raw.info["simplified"] and simple.info["simplified"]
    assert simple.length_m < raw.length_m
