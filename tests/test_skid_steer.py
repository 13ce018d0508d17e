"""Skid steering (``field.track_width_factor``): a tracked field robot turns slower than its track speeds say.

The factor is a field parameter like the others: optional in a profile (absent: 1, no skid, the numbers of before;
the shipped BeBot has 1.15),
checked at >= 1 and overridable within [1, 3]; the field robot's tracks then turn it over the wider
effective track width, while its software still commands and dead-reckons with the nominal one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.fidelity import drive, one_robot_core, profile_with
from contract.overrides import OverrideError, check_overrides
from contract.params import robot_params
from contract.robot_profile import load_profile
from planners.metrics import path_length, smoothness
from robot_agent.engine.noise import path_key

OPEN_FIELD = {"name": "open", "blocks": []}


def _turned(factor: float, seconds: float = 2.0) -> tuple[float, float]:
    """Heading turned (rad, unwrapped) and distance driven (m) by a field robot commanded 0.1 m/s and
    1 rad/s in velocity mode for ``seconds``, with the shipped BeBot's noise and ``track_width_factor``."""
    core = one_robot_core(OPEN_FIELD, "field", robot_params(profile_with({"field.track_width_factor": factor})))
    core.place(0, (0.9, 0.9, 0.0))
    turned, last, xy = 0.0, 0.0, []
    for _ in range(round(seconds / core.dt)):
        core.drive(0, 0.1, 1.0, path_key(7), 10.0)
        assert not [ev for ev in core.advance(1) if ev.kind == "FAIL"]
        a = float(core.backend.pose[0, 2])
        turned += math.remainder(a - last, math.tau)
        last = a
        xy.append(core.backend.pose[0, :2].copy())
    return turned, path_length(np.array(xy))


def test_the_factor_divides_the_turn_rate_of_the_same_track_speeds():
    """Open loop, the same seed: the tracks run the same speeds (slip and lag included), the robot drives
    as far, and turns exactly 1 / factor as much."""
    base, dist = _turned(1.0)
    skid, dist_skid = _turned(1.5)
    assert base > 1.0  # it did turn (lag and slip make it less than the 2 rad commanded)
    assert skid == pytest.approx(base / 1.5, rel=1e-9)
    assert dist_skid == pytest.approx(dist, rel=0.05)  # the same speeds along a tighter or wider arc


def test_skid_rounds_a_sharp_corner_and_lengthens_the_path():
    """A 50-degree corner driven by the field robot's path follower: with skid it turns later and wider
    (the paper's "the controller cannot follow its sharp curves"): the driven path is smoother and longer."""
    path = np.array([[0.3, 0.6, 0.0], [1.0, 0.6, 0.0], [1.0 + 0.6 * math.cos(0.87), 0.6 + 0.6 * math.sin(0.87), 0.0]])
    driven = {}
    for factor in (1.0, 1.3):
        params = robot_params(profile_with({"field.track_width_factor": factor}))
        poses, t0, t1, end, _ = drive(OPEN_FIELD, path, [0.3, 0.6, 0.0], "field", 11, params)
        assert end == "DONE"
        driven[factor] = poses[(poses[:, 0] >= t0) & (poses[:, 0] <= t1), 1:3]
    assert smoothness(driven[1.3]) < smoothness(driven[1.0])
    assert path_length(driven[1.3]) > path_length(driven[1.0])


def test_a_profile_without_the_factor_has_none_and_one_below_1_is_refused():
    prof = load_profile("bebot")
    assert robot_params(prof).field.track_width_factor == 1.15  # the shipped BeBot skids a little
    del prof["field"]["track_width_factor"]  # profiles written before the parameter
    assert robot_params(prof).field.track_width_factor == 1.0
    prof["field"]["track_width_factor"] = 0.9
    with pytest.raises(ValueError, match=r"`field.track_width_factor` must be >= 1 \(1: no skid\), got 0.9"):
        robot_params(prof)


def test_an_override_outside_its_range_is_refused():
    assert check_overrides({"track_width_factor": 1.3}) == {"track_width_factor": 1.3}
    with pytest.raises(OverrideError, match=r"profile_overrides.track_width_factor must be a number in \[1, 3\]"):
        check_overrides({"track_width_factor": 0.5})


def test_the_benches_refuse_a_misspelt_profile_change():
    """``bench/fidelity.py --set`` with a key the profile lacks would change nothing: it is refused, naming the
    closest key."""
    with pytest.raises(ValueError, match=r"profile bebot has no parameter 'field.track_widht_factor' \(did you mean "
                                         r"field.track_width_factor\?\)"):
        profile_with({"field.track_widht_factor": 1.3})
    with pytest.raises(ValueError, match="no parameter 'gripper2.seconds_per_block'"):
        profile_with({"gripper2.seconds_per_block": 1.0})
    assert profile_with({"max_accel_m_s2": 0.4})["max_accel_m_s2"] == 0.4
