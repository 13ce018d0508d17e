import json

import pytest

from planners import InvalidEnvironment, builtin_names, load_environment, parse_environment


def good(**over):
    data = {"name": "t", "size": [1.8, 1.8], "blocks": [{"x": 0.9, "y": 0.9, "w": 0.2, "h": 0.1, "angle": 0.5}]}
    data.update(over)
    return data


def test_builtins_are_the_papers_two_environments_with_two_plans_each():
    assert {"room", "blocks"} <= set(builtin_names())
    for name in ("room", "blocks"):
        env = load_environment(name)
        assert env.name == name
        assert env.size == (1.8, 1.8)
        assert len(env.blocks) >= 9
        assert [p.name for p in env.plans] == ["A", "B"]
    assert any(b.angle != 0 for b in load_environment("blocks").blocks)


def test_round_trip_through_dict_and_file(tmp_path):
    env = load_environment("room")
    path = tmp_path / "room.json"
    path.write_text(json.dumps(env.to_dict()))
    assert load_environment(path) == env
    assert load_environment(str(path)) == env
    assert parse_environment(env.to_dict()) == env


def test_plan_lookup_names_the_choices():
    env = load_environment("room")
    assert env.plan("A").start == (0.3, 0.3, 0.0)
    with pytest.raises(KeyError, match="plans: A, B"):
        env.plan("Z")


@pytest.mark.parametrize(
    "data, message",
    [
        ([1, 2], "must be a JSON object"),
        (good(name=""), "name must be a non-empty string"),
        (good(name=3), "name must be a non-empty string"),
        (good(size=[1.8]), r"size must be \[width, height\]"),
        (good(size=[1.8, -1]), r"size\[1\] must be in \(0, 100"),
        (good(size=[1.8, float("nan")]), r"size\[1\] must be finite"),
        (good(size=["a", 1]), r"size\[0\] must be a number"),
        (good(size=[True, 1]), r"size\[0\] must be a number"),
        (good(blocks={}), "blocks must be a list"),
        (good(blocks=[3]), r"blocks\[0\] must be an object"),
        (good(blocks=[{"x": 1, "y": 1, "w": 0.1}]), r"blocks\[0\]\.h is missing"),
        (good(blocks=[{"x": 1, "y": 1, "w": 0, "h": 1}]), r"blocks\[0\]\.w must be > 0"),
        (good(blocks=[{"x": 1, "y": 1, "w": 1, "h": 1, "angle": float("inf")}]), r"blocks\[0\]\.angle must be finite"),
        (good(blocks=[{"x": 5, "y": 1, "w": 1, "h": 1}]), r"blocks\[0\] centre \(5.0, 1.0\) must lie inside"),
        (good(blocks=[{"x": 1, "y": 1, "w": 1, "h": 1, "width": 2}]), r"blocks\[0\] has unknown key 'width'"),
        (good(blocks=[{"x": 1, "y": 1, "w": 1, "h": 1}] * 1001), "at most 1000 entries"),
        (good(blok=[]), "environment has unknown key 'blok'"),
        (good(plans=[{"name": "A", "start": [1, 1], "goal": [1]}]), r"plans\[0\]\.goal must be \[x, y\]"),
        (good(plans=[{"name": "A", "start": [1, "x"], "goal": [1, 1]}]), r"plans\[0\]\.start\[1\] must be a number"),
    ],
)
def test_invalid_environments_name_the_bad_field(data, message):
    with pytest.raises(InvalidEnvironment, match=message):
        parse_environment(data)


def test_file_errors_are_clear(tmp_path):
    with pytest.raises(InvalidEnvironment, match="not a built-in .* and no such file"):
        load_environment(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"name": "x", ')
    with pytest.raises(InvalidEnvironment, match=r"is not valid JSON: .* line 1"):
        load_environment(bad)
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps(good(size=[0, 1])))
    with pytest.raises(InvalidEnvironment, match=r"wrong.json: size\[0\] must be in"):
        load_environment(wrong)
    binary = tmp_path / "bin.json"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(InvalidEnvironment, match="cannot read environment file"):
        load_environment(binary)


def test_environment_files_and_robots_agree_on_which_blocks_fit():
    """A block the environment model accepts is one the robots build, and the other way round."""
    import random

    from contract.protocol import ProtocolError, encode_build, parse_command
    from planners import InvalidEnvironment, parse_environment

    rng = random.Random(5)
    agreed = {True: 0, False: 0}
    for _ in range(400):
        block = {"x": rng.uniform(0.0, 1.8), "y": rng.uniform(0.0, 1.8), "w": rng.uniform(0.01, 0.8),
                 "h": rng.uniform(0.01, 0.8), "angle": rng.uniform(-3.2, 3.2)}
        try:
            parse_environment({"name": "fit", "size": [1.8, 1.8], "blocks": [block]})
            file_ok = True
        except InvalidEnvironment:
            file_ok = False
        line = encode_build([(block["x"], block["y"], block["w"], block["h"], block["angle"])])
        try:
            parse_command(line, field_size=(1.8, 1.8))
            robot_ok = True
        except ProtocolError:
            robot_ok = False
        assert file_ok == robot_ok, block
        agreed[file_ok] += 1
    assert agreed[True] > 50 and agreed[False] > 50  # both kinds were tried


# ---------------------------------------------------------------- moving obstacles
# (docs/planners.md, "Moving obstacles")

def crossing(**over):
    ob = {"radius": 0.04, "waypoints": [[0.2, 1.2], [0.8, 1.2]], "speed": 0.05, "repeat": "once", "delay_s": 2}
    ob.update(over)
    return good(moving_obstacles=[ob])


def test_moving_obstacles_round_trip_and_move_exactly_in_time(tmp_path):
    import numpy as np

    walk = {"radius": 0.03, "speed": 0.1, "repeat": "loop",
            "random_walk": {"seed": 3, "start": [0.5, 0.5], "steps": 6, "step_m": 0.2}}
    data = crossing()
    data["moving_obstacles"].append(walk)
    env = parse_environment(data)
    path = tmp_path / "env.json"
    path.write_text(json.dumps(env.to_dict()))
    assert load_environment(path) == env and parse_environment(env.to_dict()) == env
    assert env.to_dict()["moving_obstacles"][1]["random_walk"]["seed"] == 3  # the walk is kept, not its expansion
    once = env.moving_obstacles[0]
    # at rest until delay_s, then 0.05 m/s along x, then stays at the last waypoint
    p = once.position(np.array([0.0, 2.0, 4.0, 14.0, 100.0]))
    np.testing.assert_allclose(p, [[0.2, 1.2], [0.2, 1.2], [0.3, 1.2], [0.8, 1.2], [0.8, 1.2]], atol=1e-12)
    pp = parse_environment(crossing(repeat="pingpong", delay_s=0)).moving_obstacles[0]
    np.testing.assert_allclose(pp.position(np.array([12.0, 18.0, 24.0, 30.0])),
                               [[0.8, 1.2], [0.5, 1.2], [0.2, 1.2], [0.5, 1.2]], atol=1e-12)
    loop = parse_environment(crossing(repeat="loop", delay_s=0, waypoints=[[0.2, 0.2], [0.6, 0.2], [0.6, 0.6]]))
    lp = loop.moving_obstacles[0]
    perimeter = 0.4 + 0.4 + float(np.hypot(0.4, 0.4))
    t = np.linspace(0, 60, 7)
    np.testing.assert_allclose(lp.position(t), lp.position(t + perimeter / 0.05), atol=1e-9)  # periodic
    # the walk stays inside the field by its radius, and the same seed gives the same walk
    w = env.moving_obstacles[1]
    assert w.waypoints == parse_environment(data).moving_obstacles[1].waypoints and len(w.waypoints) == 7
    assert all(0.03 <= c <= 1.77 for pt in w.waypoints for c in pt)
    other = dict(walk, random_walk={**walk["random_walk"], "seed": 4})
    assert parse_environment(good(moving_obstacles=[other])).moving_obstacles[0].waypoints != w.waypoints


@pytest.mark.parametrize(
    "data, message",
    [
        (good(moving_obstacles={}), "moving_obstacles must be a list"),
        (crossing(radius=0), r"moving_obstacles\[0\]\.radius must be in \(0, 0.25\]"),
        (crossing(radius=-0.1), r"moving_obstacles\[0\]\.radius must be in"),
        (crossing(speed=0), r"moving_obstacles\[0\]\.speed must be in \(0, 0.3\] m/s"),
        (crossing(speed=2.0), r"moving_obstacles\[0\]\.speed must be in \(0, 0.3\] m/s"),
        (crossing(speed=float("nan")), r"moving_obstacles\[0\]\.speed must be finite"),
        (crossing(waypoints=[[0.2, 1.2], [2.5, 1.2]]), r"moving_obstacles\[0\]\.waypoints\[1\] \(2.5, 1.2\) must lie inside"),
        (crossing(waypoints=[[0.2, float("nan")]]), r"moving_obstacles\[0\]\.waypoints\[0\]\[1\] must be finite"),
        (crossing(waypoints=[]), r"moving_obstacles\[0\]\.waypoints must be a list of 1"),
        (crossing(repeat="bounce"), r"moving_obstacles\[0\]\.repeat must be one of once, loop, pingpong"),
        (crossing(delay_s=-1), r"moving_obstacles\[0\]\.delay_s must be in \[0"),
        (crossing(colour="red"), r"moving_obstacles\[0\] has unknown key 'colour'"),
        (crossing(random_walk={"seed": 1, "start": [1, 1], "steps": 3, "step_m": 0.1}), "exactly one of waypoints"),
        (good(moving_obstacles=[{"radius": 0.04, "speed": 0.1, "random_walk": {"seed": 1, "start": [1, 1],
                                                                               "steps": 3}}]),
         r"moving_obstacles\[0\]\.random_walk\.step_m is missing"),
        (good(moving_obstacles=[{"radius": 0.04, "speed": 0.1}]), "exactly one of waypoints or random_walk"),
        (good(moving_obstacles=[{"radius": 0.04, "waypoints": [[1, 1]]}]), r"moving_obstacles\[0\]\.speed is missing"),
        (good(moving_obstacles=[crossing()["moving_obstacles"][0]] * 17), "at most 16 entries"),
    ],
)
def test_invalid_moving_obstacles_name_the_bad_field(data, message):
    with pytest.raises(InvalidEnvironment, match=message):
        parse_environment(data)
