"""The follower, kinematics, noise, world and simulation core as pure computation (no sockets)."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import robot_agent
from robot_agent.engine import follower as fl
from robot_agent.engine.backends import Backend, make_backend
from robot_agent.engine.cores import layout_core
from robot_agent.engine.kinematics import body_to_tracks, tracks_to_body, unicycle_step, wrap_angle
from robot_agent.engine.noise import normals, path_key, uniforms
from contract.params import robot_params
from contract.robot_profile import load_profile, profile_names
from robot_agent.engine.sim import SimCore, State
from contract.frames import SUBFIELD_ORIGINS, field_layout
from robot_agent.engine.world import World

P = robot_params("bebot")
C = P.controller
G = fl.gains(P)


def test_every_profile_value_has_a_note():
    for name in profile_names():
        prof = load_profile(name)
        robot_params(prof)  # complete and valid
        notes = prof["notes"]
        for key, value in prof.items():
            if key in ("name", "platform", "notes"):
                continue
            if isinstance(value, dict):
                for sub in value:
                    assert f"{key}.{sub}" in notes, f"{name}: {key}.{sub} has no note"
            else:
                assert key in notes, f"{name}: {key} has no note"


def test_bad_profile_names_the_key():
    prof = load_profile("bebot")
    prof["controller"] = {**prof["controller"], "heading_gain_1_s": float("nan")}
    with pytest.raises(ValueError, match="heading_gain_1_s"):
        robot_params(prof)


def test_move_to_waypoint_points_at_target_with_given_speed():
    assert fl.move_to_waypoint(0.0, 0.0, 3.0, 4.0, 0.5) == pytest.approx((0.3, 0.4))
    assert fl.move_to_waypoint(1.0, 1.0, 1.0, 0.0, 0.2) == pytest.approx((0.0, -0.2))
    assert fl.move_to_waypoint(2.0, 2.0, 2.0, 2.0, 0.3) == (0.0, 0.0)


def test_approach_speed_slows_only_for_the_last_point():
    assert fl.approach_speed(0.001, False, G) == P.max_speed_m_s
    assert fl.approach_speed(0.001, True, G) == C.min_speed_m_s
    assert fl.approach_speed(0.05, True, G) == pytest.approx(min(max(C.arrive_gain_1_s * 0.05, C.min_speed_m_s),
                                                                 P.max_speed_m_s))


def test_heading_control_turns_towards_and_slows_with_error():
    v, w = fl.heading_control(0.0, 0.2, 0.0, G)
    assert v == pytest.approx(0.2) and w == 0.0
    v, w = fl.heading_control(0.0, 0.0, 0.2, G)
    assert v == 0.0 and w == pytest.approx(min(C.heading_gain_1_s * math.pi / 2, P.max_angular_speed_rad_s))
    v, w = fl.heading_control(0.0, -0.2, 0.0, G)
    assert v == 0.0 and abs(w) == pytest.approx(P.max_angular_speed_rad_s)
    v, w = fl.heading_control(0.3, 0.2, 0.0, G._replace(max_turn=3.0))
    assert v == pytest.approx(0.2 * math.cos(0.3)) and w == pytest.approx(-C.heading_gain_1_s * 0.3)


def test_align_control_has_minimum_rate_and_stops_inside_tolerance():
    g = G._replace(max_turn=3.0)
    assert fl.align_control(0.0, 0.01, g) == (0.0, True)
    w, aligned = fl.align_control(0.0, 0.1, g)
    assert not aligned and w == pytest.approx(max(C.min_turn_rate_rad_s, C.heading_gain_1_s * 0.1))
    assert fl.align_control(0.0, -2.0, g) == (pytest.approx(-3.0), False)


def test_rate_limit():
    assert [fl.rate_limit(p, d, 0.05) for p, d in [(0.0, 1.0), (0.1, 0.12), (0.2, -1.0)]] == pytest.approx(
        [0.05, 0.12, 0.15])


def test_advance_waypoint_skips_several_close_points_and_detects_arrival():
    path = np.array([[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0], [1, 0, 0]], float)
    assert fl.advance_waypoint(0.0, 0.0, path, 0, G) == (3, False)
    assert fl.advance_waypoint(5.0, 5.0, np.array([[5, 5, 0], [5.001, 5, 0]], float), 0, G) == (1, True)
    assert fl.advance_waypoint(0.5, 0.5, path, 0, G) == (0, False)


def _fleet(n: int, path: np.ndarray) -> dict:
    return {"points": np.vstack([path] * n), "offset": np.arange(n) * len(path), "count": np.full(n, len(path)),
            "wp": np.zeros(n, dtype=np.int64), "aligning": np.zeros(n, dtype=bool), "cmd": np.zeros((n, 2)),
            "anchor": np.zeros((n, 3)), "anchor_k": np.zeros(n, dtype=np.int64), "k": np.zeros(n, dtype=np.int64),
            "timeout": np.full(n, 10**6), "cid": np.zeros(n, dtype=np.int64), "cpar": np.zeros((n, 8)),
            "cmem": np.zeros((n, 4)), "want": np.zeros((n, 2))}


def _control(f: dict, i: int, belief: tuple[float, float, float]) -> int:
    return fl.control(i, *belief, f["points"], f["offset"], f["count"], f["wp"], f["aligning"], f["cmd"],
                      f["anchor"], f["anchor_k"], f["k"], f["timeout"], G, f["cid"], f["cpar"], f["cmem"], f["want"],
                      np.inf)


def test_control_starts_accelerates_limited_and_flags_the_end():
    f = _fleet(1, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5]]))
    assert _control(f, 0, (0.0, 0.0, 0.0)) == fl.STARTED
    assert f["wp"][0] == 1 and f["cmd"][0].tolist() == [pytest.approx(G.dv_max), 0.0]  # acceleration limit
    f["k"][0] = 1
    flags = _control(f, 0, (0.995, 0.0, 0.5))  # within the goal tolerance, already at the final angle
    assert flags & fl.ARRIVED and flags & fl.DONE and f["cmd"][0].tolist() == [0.0, 0.0]


def test_stall_and_timeout():
    f = _fleet(2, np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
    steps = int(C.stall_time_s / P.dt) + 1
    f["k"][:] = steps
    f["anchor_k"][:] = 0
    assert _control(f, 0, (0.0, 0.0, 0.0)) == fl.STALLED  # no progress since step 0
    assert _control(f, 1, (0.5, 0.0, 0.0)) == 0 and f["anchor_k"][1] == steps  # progress: a new anchor
    f["timeout"][1] = steps
    assert _control(f, 1, (0.5, 0.0, 0.0)) == fl.TIMED_OUT
    n = fl.timeout_steps(np.array([[1.0, 0, 0], [1.0, 1.0, 0]]), np.zeros(2), P)
    assert n == math.ceil((C.timeout_base_s + C.timeout_factor * 2.0 / P.max_speed_m_s) / P.dt)


def test_kinematics():
    assert unicycle_step(0.0, 0.0, 0.0, 0.1, 0.0, 0.5) == pytest.approx((0.05, 0.0, 0.0))
    assert unicycle_step(1.0, 1.0, math.pi / 2, 0.0, 1.0, 0.5) == pytest.approx((1.0, 1.0, math.pi / 2 + 0.5))
    assert tracks_to_body(*body_to_tracks(0.2, 1.0, 0.07), 0.07) == pytest.approx((0.2, 1.0))
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)
    assert wrap_angle(math.pi) == pytest.approx(-math.pi) and wrap_angle(0.25) == 0.25


def test_noise_is_a_pure_function_of_key_and_counter():
    keys = np.array([path_key(1), path_key(1), path_key(2)], dtype=np.uint64)
    u = uniforms(keys, np.array([5, 5, 5]), 4)
    assert (u[0] == u[1]).all() and not (u[0] == u[2]).any()
    assert ((u > 0) & (u < 1)).all()
    z = normals(np.full(20000, path_key(3), dtype=np.uint64), np.arange(20000), 3)
    assert abs(z.mean()) < 0.03 and abs(z.std() - 1) < 0.03
    assert path_key(7, "robot-1", 0) != path_key(7, "robot-2", 0) != path_key(7, "robot-1", 1)


def test_field_layout():
    sizes, world_of, origin, area = field_layout(4)
    assert sizes.tolist() == [[3.6, 3.6]] and world_of.tolist() == [0, 0, 0, 0]
    assert [tuple(o) for o in origin.tolist()] == list(SUBFIELD_ORIGINS)
    _, _, origin, area = field_layout(1, area=(3.6, 3.6))
    assert origin.tolist() == [[0, 0]] and area.tolist() == [[3.6, 3.6]]
    sizes, world_of, _, _ = field_layout(10)
    assert len(sizes) == 10 and world_of.tolist() == list(range(10))
    _, _, origin, area = field_layout(4, "shared", area=[(3.6, 3.6)] + [(1.8, 1.8)] * 3)
    assert origin.tolist() == [[0, 0], [1.8, 0], [0, 1.8], [1.8, 1.8]] and area[0].tolist() == [3.6, 3.6]
    with pytest.raises(ValueError, match="once per robot"):
        field_layout(2, area=[(1.0, 1.0)] * 3)
    with pytest.raises(ValueError, match="4 sub-fields"):
        field_layout(5, "shared")
    with pytest.raises(ValueError, match="inside"):
        field_layout(1, area=(3.6, 3.7))
    # several whole-field robots (a simulation pool's agent): a world each, or they would drive through each other
    sizes, world_of, origin, area = field_layout(2, area=(3.6, 3.6))
    assert world_of.tolist() == [0, 1] and origin.tolist() == [[0, 0], [0, 0]] and sizes.tolist() == [[3.6, 3.6]] * 2


def test_world_collisions_blocks_walls_robots_and_frames():
    sizes, world_of, origin, area = field_layout(2)
    w = World(sizes, world_of, origin, area, 0.04)
    w.set_blocks(0, np.array([[0.9, 0.9, 0.2, 0.2, math.pi / 4]]))
    poses = np.array([[0.9, 0.9 + 0.14 + 0.035, 0], [0.5, 0.5, 0]])  # robot 1 is at (2.3, 0.5) in the world
    hit = w.collisions(poses, np.array([True, True]))
    assert hit.tolist() == [True, False]  # the rotated block's corner reaches y = 0.9 + 0.1414
    assert w.place_conflict(0, (0.02, 0.5, 0), poses) is not None  # the wall
    poses2 = np.array([[1.78, 0.5, 0], [0.0 + 0.03, 0.5, 0]])  # 5 cm apart across the sub-field border
    assert w.collisions(poses2, np.array([True, False])).tolist() == [True, False]
    np.testing.assert_allclose(w.blocks_local(0)[:, :2], [[0.9, 0.9]])


def _core(backend: str, n: int = 1) -> SimCore:
    return layout_core(P, backend, n)


def _drive(core: SimCore, steps: int = 20000) -> list:
    events = []
    for _ in range(steps):
        events += core.step()
        if not (core.state == State.MOVING).any():
            break
    return events


@pytest.mark.parametrize("backend", ["ideal", "field"])
def test_core_follows_a_path_to_the_goal(backend):
    core = _core(backend)
    core.place(0, (0.3, 0.3, 0.0))
    path = np.array([[0.3, 0.3, 0], [1.0, 0.3, 0], [1.0, 1.0, math.pi]])
    core.set_path(0, path, path_key(1))
    events = _drive(core)
    kinds = [(e.kind, e.index) for e in events]
    assert kinds[0] == ("START", None) and kinds[-1] == ("DONE", None)
    assert [i for k, i in kinds if k == "WP"] == [0, 1, 2]
    tol = C.goal_tolerance_m + (0.0 if backend == "ideal" else 0.02)
    assert math.hypot(*(core.backend.pose[0, :2] - path[-1, :2])) < tol
    # the field robot's lagging motors turn on after the align command stops: about the slowest align rate times
    # the motors' time constant (0.6 rad/s x 0.25 s = 0.15 rad on the BeBot)
    coast = 0.0 if backend == "ideal" else C.min_turn_rate_rad_s * P.field.motor_time_constant_s
    assert abs(wrap_angle(np.array([core.backend.pose[0, 2] - math.pi]))[0]) < C.angle_tolerance_rad + 0.1 + coast


class _Foreign(Backend):
    """A backend the compiled loop does not know (as a real robot's would be): it delegates to an
    emulated one, so the core has to step it through the Backend methods."""

    def __init__(self, inner: Backend) -> None:
        self.inner, self.n, self.params, self.dt = inner, inner.n, inner.params, inner.dt

    pose = property(lambda self: self.inner.pose)
    belief = property(lambda self: self.inner.belief)

    def begin_path(self, mask, keys, from_rest):
        self.inner.begin_path(mask, keys, from_rest)

    def sense(self, step, moving):
        return self.inner.sense(step, moving)

    def actuate(self, cmd):
        self.inner.actuate(cmd)

    def halt(self, mask):
        self.inner.halt(mask)

    def place(self, i, pose):
        self.inner.place(i, pose)

    def in_motion(self):
        return self.inner.in_motion()


def _busy_shared_core(backend, foreign: bool = False) -> SimCore:
    """Four robots on the shared field with blocks, random paths: waypoints, collisions with
    blocks and with each other."""
    sizes, world_of, origin, area = field_layout(4, "shared")
    inner = make_backend(backend, 4, P)
    core = SimCore(P, _Foreign(inner) if foreign else inner, World(sizes, world_of, origin, area,
                                                                   P.collision_radius_m))
    rng = np.random.default_rng(5)
    for i in range(4):
        core.world.set_blocks(i, np.array([[0.9, 0.9, 0.2, 0.3, 0.5], [0.4, 1.2, 0.1, 0.4, 0.0]]))
        path = np.hstack([rng.uniform(0.2, 1.6, size=(6, 2)), rng.uniform(-3, 3, size=(6, 1))])
        core.place(i, tuple(path[0]))
        core.set_path(i, path, path_key(i))
    return core


def _record(core: SimCore, events: list) -> tuple:
    return [(e.robot, e.kind, e.t, e.index, e.reason) for e in events], core.poses.drain(), core.backend.pose.copy()


@pytest.mark.parametrize("backend", ["ideal", "field"])
def test_compiled_loop_and_python_stepping_agree(backend):
    fused = _busy_shared_core(backend)
    python = _busy_shared_core(backend, foreign=True)
    assert fused.busy() and python.busy()
    a, b = _record(fused, fused.advance(6000)), _record(python, python.advance(6000))
    assert a[0] == b[0]
    kinds = {(k, r) for _, k, _, _, r in a[0]}
    assert {("START", None), ("WP", None), ("FAIL", "COLLISION")} <= kinds
    assert a[1].keys() == b[1].keys()
    for r in a[1]:
        np.testing.assert_allclose(a[1][r], b[1][r], rtol=0, atol=1e-9)
    np.testing.assert_allclose(a[2], b[2], rtol=0, atol=1e-9)


@pytest.mark.parametrize("backend", ["ideal", "field"])
def test_advance_equals_single_steps_and_stops_when_nothing_moves(backend):
    many, single = _busy_shared_core(backend), _busy_shared_core(backend)
    ev_many = many.advance(10**6)
    assert not many.busy() and many.step_count < 10**6  # it stopped once every robot was done
    ev_single = []
    while single.step_count < many.step_count:
        ev_single += single.step()
    a, b = _record(many, ev_many), _record(single, ev_single)
    assert a[0] == b[0]
    for r in a[1]:
        assert (a[1][r] == b[1][r]).all()  # bit for bit: the same compiled code in both
    assert (a[2] == b[2]).all()


@pytest.mark.slow
def test_kernel_cache_follows_every_kernel_source(tmp_path):
    """numba only notices changes to a cached function's own file; the cache directory is keyed by
    all kernel sources, so editing the follower cannot leave a stale compiled stepper behind."""
    pkg = tmp_path / "robot_agent"
    shutil.copytree(Path(robot_agent.__file__).parent, pkg, ignore=shutil.ignore_patterns("__pycache__"))

    def where() -> str:
        code = "from robot_agent.engine.compiled import cache_dir; print(cache_dir())"
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
        return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True,
                              text=True, check=True).stdout.strip()

    first = where()
    assert first.startswith(str(pkg / "engine" / "__pycache__" / "kernels")) and where() == first
    with open(pkg / "engine" / "follower.py", "a") as f:
        f.write("\n# changed\n")
    second = where()
    assert second != first and Path(second).parent == Path(first).parent
