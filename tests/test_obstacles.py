"""mmrl/MovingObstacles-v0: sensor maps vs brute force, hits, collisions, spawning, bouncing,
the curriculum, the gymnasium contract, determinism and refused inputs."""
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mmrl
from mmrl import _core
from mmrl import default_database
from mmrl.tasks.obstacles import (OBSTACLE_LAYOUT, OBSTACLE_MAP_SHAPE, Curriculum, ObstaclesConfig, ObstaclesEnv,
                            ObstaclesVectorEnv)

MAP = 16
N_MAP = MAP * MAP


@pytest.fixture(scope="module")
def db():
    return default_database()


def make(db, n=4, **kw):
    return ObstaclesVectorEnv(n, db=db, num_threads=2, **kw)


def obstacle_frame(obst, x, z):
    """(u, v) of world points (..., ) in every obstacle's frame: (..., M) each (float64)."""
    c = obst["centres"].astype(np.float64)
    a = obst["angles"].astype(np.float64)
    dx = np.asarray(x, np.float64)[..., None] - c[:, 0]
    dz = np.asarray(z, np.float64)[..., None] - c[:, 1]
    cos, sin = np.cos(a), np.sin(a)
    return cos * dx - sin * dz, sin * dx + cos * dz


def reference_map(state, obst, size=6.0, forward=1.5):
    """Every sensor (documented layout) against every obstacle; also each sensor's distance to
    the nearest edge, to skip sensors that float rounding could flip."""
    pitch = size / MAP
    col, row = np.meshgrid(np.arange(MAP), np.arange(MAP))
    lx = (col + 0.5) * pitch - size / 2
    lz = (row + 0.5) * pitch - size / 2 + forward
    c, s = math.cos(state["yaw"]), math.sin(state["yaw"])
    wx = state["x"] + c * lx + s * lz
    wz = state["z"] - s * lx + c * lz
    u, v = obstacle_frame(obst, wx, wz)
    h = obst["half_sizes"].astype(np.float64)
    du, dv = np.abs(u) - h[:, 0], np.abs(v) - h[:, 1]
    inside = (du <= 0) & (dv <= 0)
    margin = np.min(np.minimum(np.abs(du), np.abs(dv)), axis=-1)
    return inside.any(axis=-1).astype(np.uint8), margin


def obb_distance(obst, x, z):
    u, v = obstacle_frame(obst, x, z)
    h = obst["half_sizes"].astype(np.float64)
    du = np.maximum(np.abs(u) - h[:, 0], 0)
    dv = np.maximum(np.abs(v) - h[:, 1], 0)
    return np.hypot(du, dv)


def set_scene(env, i, centres, half_sizes, angles=None, velocities=None):
    centres = np.asarray(centres, np.float32).reshape(-1, 2)
    n = len(centres)
    env._core.set_obstacles(i, centres, np.asarray(half_sizes, np.float32).reshape(n, 2),
                            np.zeros(n, np.float32) if angles is None else np.asarray(angles, np.float32),
                            np.zeros((n, 2), np.float32) if velocities is None
                            else np.asarray(velocities, np.float32).reshape(n, 2))


# -- sensors ---------------------------------------------------------------------------------

def test_layout_matches_the_network_default():
    from mmrl.tasks.obstacles import OBSTACLE_MAP_RANGE

    assert OBSTACLE_LAYOUT == (("maps", 512), ("pose", 15), ("goal", 2))
    assert OBSTACLE_MAP_RANGE == (0, 512)
    from mmrl.rl.networks import obstacle_policy_factory

    with pytest.raises(ValueError, match="obs_dim 17"):
        obstacle_policy_factory()(17, 12)
    assert OBSTACLE_MAP_SHAPE == (2, 16, 16)
    assert sum(size for _, size in _core.ObstacleVecEnv.layout) == 529
    env = mmrl.get_task("obstacles").make_vector_env(1, db=mmrl.default_database(), num_threads=1)
    assert env.obs_dim == 529 and env.layout == OBSTACLE_LAYOUT


def test_previous_map_is_the_map_read_one_step_ago(db):
    lag = 1
    env = make(db, n=4, target_half_extent=5.0, obstacle_max_speed=0.5)
    obs, _ = env.reset(seed=11)
    rng = np.random.default_rng(1)
    low, high = env.single_action_space.low, env.single_action_space.high
    history = [[obs[i, :N_MAP].copy()] for i in range(env.num_envs)]  # current maps of each episode
    checked = 0
    for _ in range(30):
        obs, _, term, trunc, _ = env.step(rng.uniform(low, high, (env.num_envs, 12)).astype(np.float32))
        for i in range(env.num_envs):
            if term[i] or trunc[i]:
                history[i] = []  # the new episode's first map is its own previous map
            history[i].append(obs[i, :N_MAP].copy())
            h = history[i]
            expected = h[-1 - lag] if len(h) > lag else h[0]
            np.testing.assert_array_equal(obs[i, N_MAP:2 * N_MAP], expected)
            np.testing.assert_array_equal(env.sensor_map(i, previous=True).reshape(-1), expected)
            checked += len(h) > lag and not np.array_equal(h[-1 - lag], h[-1])
    assert checked > 10  # the maps did change over the lag


@pytest.mark.parametrize("speed", [0.0, 0.05, 0.5, 2.0])  # grid rebuilt never, every 16, 4, 1 steps
def test_sensor_maps_and_collisions_match_brute_force_on_random_moving_scenes(db, speed):
    env = make(db, n=6, target_half_extent=5.0, obstacle_max_speed=speed)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    checked = ones = 0
    prev_maps = obs[:, :N_MAP].copy()
    for step in range(40):
        for i in range(env.num_envs):
            st, ob = env.env_state(i), env.obstacles(i)
            ref, margin = reference_map(st, ob)
            got = env.sensor_map(i)
            sure = margin > 1e-4
            np.testing.assert_array_equal(got[sure], ref[sure])
            np.testing.assert_array_equal(obs[i, :N_MAP].reshape(MAP, MAP), got)
            np.testing.assert_array_equal(env._core.sensor_map_bruteforce(i), got)
            checked += int(sure.sum())
            ones += int(ref.sum())
            # Body-disc collisions near the character, exact through the (possibly older) grid.
            pts = np.array([st["x"], st["z"]]) + rng.uniform(-3, 3, (20, 2))
            d = obb_distance(ob, pts[:, 0], pts[:, 1]).min(axis=-1)
            got_c = np.array([env._core.collides(i, float(x), float(z)) for x, z in pts])
            sure_c = np.abs(d - 0.25) > 1e-4
            np.testing.assert_array_equal(got_c[sure_c], (d <= 0.25)[sure_c])
        actions = rng.uniform(low, high, (env.num_envs, 12)).astype(np.float32)
        obs, _, term, trunc, infos = env.step(actions)
        done = term | trunc
        # The previous map of a continuing episode is the last step's current map.
        np.testing.assert_array_equal(obs[~done, N_MAP:2 * N_MAP], prev_maps[~done])
        # A fresh episode starts with previous = current.
        np.testing.assert_array_equal(obs[done, N_MAP:2 * N_MAP], obs[done, :N_MAP])
        prev_maps = obs[:, :N_MAP].copy()
    assert checked > 0.99 * 40 * 6 * N_MAP
    assert 0.05 * checked < ones < 0.95 * checked  # scenes are neither empty nor full


def test_sensor_map_orientation_on_a_hand_built_scene(db):
    env = make(db, n=1)
    env.reset(seed=0)
    # Facing +X (yaw pi/2): forward = +X, left = -Z. One small square 2 m ahead, 1 m left.
    env._core.set_root(0, 0.0, 0.0, math.pi / 2)
    set_scene(env, 0, [[2.0, -1.0]], [[0.12, 0.12]])
    m = env.sensor_map(0)
    assert m.sum() == 1
    row, col = np.argwhere(m)[0]
    pitch = 6.0 / 16
    assert abs((col + 0.5) * pitch - 3.0 - 1.0) < pitch  # X (left) = 1 m
    assert abs((row + 0.5) * pitch - 3.0 + 1.5 - 2.0) < pitch  # Z (forward) = 2 m
    pos = env.sensor_positions(0)
    assert np.hypot(*(pos[row, col] - [2.0, -1.0])) < 0.12 * math.sqrt(2)
    # The observation shows it after the refresh.
    np.testing.assert_array_equal(env.observe(0)[:N_MAP].reshape(MAP, MAP), m)


# -- hits, reward, collision --------------------------------------------------------------

def _action_of_frame(db, frame):
    return db.normalized_features[frame, 15:27].astype(np.float32).copy()


def _points_in_empty_scene(env, action, yaw=0.0):
    """Root at the origin with ``yaw``, no obstacles: the action's three world positions (3, 2)."""
    env._core.set_root(0, 0.0, 0.0, yaw)
    set_scene(env, 0, np.zeros((0, 2)), np.zeros((0, 2)))
    return env._core.action_hits(0, action)[1]


def test_hit_points_are_the_action_positions_in_the_character_frame(db):
    env = make(db, n=1)
    env.reset(seed=1)
    frame = int(np.flatnonzero(db.valid_mask)[50])
    action = _action_of_frame(db, frame)
    raw = db.features[frame, 15:27].astype(np.float64)
    x0, z0, yaw = 1.5, -2.0, 0.7
    env._core.set_root(0, x0, z0, yaw)
    set_scene(env, 0, np.zeros((0, 2)), np.zeros((0, 2)))
    hits, pts, inside = env._core.action_hits(0, action)
    assert hits == 0 and inside == (False, False, False)
    c, s = math.cos(yaw), math.sin(yaw)
    for k in range(3):
        lx, lz = raw[4 * k], raw[4 * k + 1]
        np.testing.assert_allclose(pts[k], [x0 + c * lx + s * lz, z0 - s * lx + c * lz], atol=1e-4)


def test_hit_counts_on_hand_built_scenes(db):
    env = make(db, n=1)
    env.reset(seed=1)
    frame = int(np.flatnonzero(db.valid_mask)[120])
    action = _action_of_frame(db, frame)
    pts = _points_in_empty_scene(env, action, 0.3)
    # One 10 cm square on each chosen point (a rotated one on the last).
    for chosen, expected in [((0,), 1), ((2,), 1), ((0, 2), 2), ((0, 1, 2), 3), ((), 0)]:
        centres = [pts[k] for k in chosen]
        angles = [0.0, 0.0, 0.9][:len(chosen)]
        set_scene(env, 0, np.asarray(centres).reshape(-1, 2), np.full((len(chosen), 2), 0.05),
                  angles=np.asarray(angles[:len(chosen)]))
        hits, _, inside = env._core.action_hits(0, action)
        assert hits == expected
        assert tuple(k in chosen for k in range(3)) == inside
    # A square beside a point (just out of reach) is no hit; a tall thin one through all three
    # points' neighbourhood only counts the points inside it.
    set_scene(env, 0, [pts[1] + [0.2, 0.0]], [[0.1, 0.1]])
    assert env._core.action_hits(0, action)[0] == 0


def test_hit_radius_counts_points_whose_disc_touches_an_obstacle(db):
    frame = int(np.flatnonzero(db.valid_mask)[120])
    action = _action_of_frame(db, frame)
    counts = {}
    for radius in (0.0, 0.15, 0.3, 0.6):
        env = make(db, n=1, hit_radius=radius)
        env.reset(seed=1)
        pts = _points_in_empty_scene(env, action, 0.3)
        # A 10 cm square whose near edge is 0.2 m beside the +20 point (rotated 0.4 rad about
        # its centre, so the distance is measured through the obstacle frame).
        centre = pts[1] + np.array([0.25 + 0.05, 0.0])
        set_scene(env, 0, [centre], [[0.05, 0.05]], angles=[0.4])
        d = obb_distance(env.obstacles(0), pts[:, 0], pts[:, 1]).min(axis=-1)
        hits, _, inside = env._core.action_hits(0, action)
        assert inside == tuple(bool(x) for x in d <= radius)
        counts[radius] = hits
    assert counts[0.0] == 0 and counts[0.6] >= 1
    assert counts[0.0] <= counts[0.15] <= counts[0.3] <= counts[0.6]


def test_hit_lookahead_tests_each_point_against_the_obstacles_at_its_time(db):
    """A point the obstacle will reach after 20 frames (not at 10 or now) is a hit only for the
    +20 point with lookahead; the predicted positions are where stepping the field puts them."""
    frame = int(np.flatnonzero(db.valid_mask)[120])
    action = _action_of_frame(db, frame)
    speed = 1.5
    found = {}
    for lookahead in (False, True):
        env = make(db, n=1, hit_lookahead=lookahead, speed_cap=2.0, obstacle_max_speed=2.0)
        env.reset(seed=1)
        pts = _points_in_empty_scene(env, action, 0.3)
        # Starts 1 m (at 1.5 m/s: 20 frames) beside the +20 point, moving toward it.
        t20 = 20 / db.fps
        start = pts[1] - np.array([speed * t20, 0.0])
        set_scene(env, 0, [start], [[0.05, 0.05]], velocities=[[speed, 0.0]])
        found[lookahead] = env._core.action_hits(0, action)[2]
    assert found[False] == (False, False, False)
    assert found[True][1] and not found[True][0]


def test_hit_lookahead_bounces_like_the_field(db):
    """A prediction across the border mirrors the obstacle back, as the field's own motion does."""
    env = make(db, n=1, hit_lookahead=True, speed_cap=2.0, obstacle_max_speed=2.0, body_radius=0.0)
    env.reset(seed=3)
    frame = int(np.flatnonzero(db.valid_mask)[120])
    action = _action_of_frame(db, frame)
    pts = _points_in_empty_scene(env, action, 0.0)
    # An obstacle 0.3 m from the +x border moving out at 1.8 m/s: after 30 frames (1 s) it has
    # bounced back to x = 10 - 1.5. Put the +30 point there by moving the root.
    start, v = np.array([9.7, 5.0]), np.array([1.8, 0.0])
    end = np.array([10.0 - (1.8 - 0.3), 5.0])
    env._core.set_root(0, float(end[0] - pts[2][0]), float(end[1] - pts[2][1]), 0.0)
    set_scene(env, 0, [start], [[0.05, 0.05]], velocities=[v])
    assert env._core.action_hits(0, action)[2] == (False, False, True)
    set_scene(env, 0, [start], [[0.05, 0.05]], velocities=[-v])  # moving inward instead: elsewhere
    assert env._core.action_hits(0, action)[2] == (False, False, False)


@pytest.mark.parametrize("options, hit_term", [
    ({}, math.exp(-1)),                                            # the paper's exp(-hits)
    ({"hit_reward": False}, 0.0),                                  # the --no-hit-reward ablation
    ({"hit_weight": 4.0}, 4.0 * math.exp(-1)),
    ({"hit_weight": 4.0, "hit_penalty": True}, 4.0 * (math.exp(-1) - 1.0)),
])
def test_step_reward_hit_term(db, options, hit_term):
    frame = int(np.flatnonzero(db.valid_mask)[200])
    action = _action_of_frame(db, frame)
    env = make(db, n=1, obstacle_max_speed=0.0, success_bonus=10.0, **options)
    env.reset(seed=5)
    env._core.set_root(0, 0.0, 0.0, 0.0)
    env.set_target(0, 40.0, 40.0)  # far away: no success
    set_scene(env, 0, np.zeros((0, 2)), np.zeros((0, 2)))
    _, pts, _ = env._core.action_hits(0, action)
    # A small square on the +30 point, which the root cannot reach within one 0.2 s step.
    assert np.hypot(*pts[2]) > 0.8
    set_scene(env, 0, [pts[2]], [[0.05, 0.05]])
    _, r, term, trunc, _ = env.step(action[None])
    assert not term[0] and not trunc[0]
    assert env.last_hits[0] == 1
    st = env.env_state(0)
    dist = math.hypot(40.0 - st["x"], 40.0 - st["z"])
    assert r[0] == pytest.approx(math.exp(-dist) + hit_term, rel=1e-5, abs=1e-9)


def test_collision_terminates_without_success(db):
    env = make(db, n=2)
    env.reset(seed=2)
    for i in range(2):
        st = env.env_state(i)
        env.set_target(i, st["x"] + 0.3, st["z"])  # a target in reach, but the body collides first
        set_scene(env, i, [[st["x"], st["z"] + 0.4]], [[0.3, 0.3]])  # 0.1 m from the root: body radius 0.25
    assert env._core.collides(0, env.env_state(0)["x"], env.env_state(0)["z"])
    actions = np.stack([_action_of_frame(db, int(np.flatnonzero(db.valid_mask)[0]))] * 2)
    _, r, term, trunc, infos = env.step(actions)
    assert term.all() and not trunc.any()
    assert infos["collision"].all() and not infos["success"].any()
    assert infos["_collision"].all()


def test_collides_matches_point_to_rectangle_distance(db):
    env = make(db, n=1)
    env.reset(seed=4)
    ob = env.obstacles(0)
    rng = np.random.default_rng(1)
    pts = rng.uniform(-11, 11, (2000, 2))
    d = obb_distance(ob, pts[:, 0], pts[:, 1]).min(axis=-1)
    sure = np.abs(d - 0.25) > 1e-4
    got = np.array([env._core.collides(0, float(x), float(z)) for x, z in pts])
    np.testing.assert_array_equal(got[sure], (d <= 0.25)[sure])
    assert 0 < got.sum() < len(got)


def test_success_terminates_with_bonus(db):
    env = make(db, n=1, success_bonus=10.0)
    env.reset(seed=6)
    set_scene(env, 0, np.zeros((0, 2)), np.zeros((0, 2)))
    st = env.env_state(0)
    obs = env.set_target(0, st["x"], st["z"])
    np.testing.assert_array_equal(obs[-2:], [0.0, 0.0])  # g_t: the target is on the root
    _, r, term, _, infos = env.step(_action_of_frame(db, int(np.flatnonzero(db.valid_mask)[0]))[None])
    assert term[0] and infos["success"][0] and not infos["collision"][0]
    assert r[0] > 10.0
    assert infos["episode_return"][0] == pytest.approx(r[0])
    assert infos["episode_length"][0] == 1


# -- spawning, motion, stages ---------------------------------------------------------------

def test_no_obstacle_starts_on_the_character_or_the_target(db):
    cfg = ObstaclesConfig()
    env = make(db, n=8)
    for seed in range(10):
        env.reset(seed=seed)
        for i in range(env.num_envs):
            st, ob = env.env_state(i), env.obstacles(i)
            assert len(ob["centres"]) == 100
            assert obb_distance(ob, st["x"], st["z"]).min() > cfg.body_radius + cfg.start_clearance - 1e-5
            assert obb_distance(ob, *st["target"]).min() > cfg.target_clearance - 1e-5
            sides = 2 * ob["half_sizes"]
            assert (sides <= 3.0 + 1e-6).all() and (sides >= 0.25 - 1e-6).all()
            assert (np.abs(ob["centres"]) <= 10.0).all()
            assert (np.hypot(*ob["velocities"].T) <= 0.5 + 1e-5).all()
            assert np.abs(np.asarray(st["target"])).max() <= 5.0


def test_obstacles_move_at_constant_velocity_and_bounce_inside_the_square(db):
    env = make(db, n=2, speed_cap=2.0, obstacle_max_speed=2.0, body_radius=0.0, start_clearance=0.0)
    env.reset(seed=8)
    rng = np.random.default_rng(2)
    before = env.obstacles(0)
    flips = 0
    for _ in range(60):
        _, _, term, trunc, _ = env.step(rng.uniform(env.single_action_space.low, env.single_action_space.high,
                                                    (2, 12)).astype(np.float32))
        after = env.obstacles(0)
        for i in range(2):
            assert (np.abs(env.obstacles(i)["centres"]) <= 10.0 + 1e-5).all()
        if not (term[0] or trunc[0]):
            # Speed is kept; a component flips only at the border.
            np.testing.assert_allclose(np.abs(after["velocities"]), np.abs(before["velocities"]), atol=1e-6)
            flipped = np.sign(after["velocities"]) != np.sign(before["velocities"])
            flips += int(flipped.sum())
            moved = np.hypot(*(after["centres"] - before["centres"]).T)
            assert (moved <= np.hypot(*before["velocities"].T) * 0.2 + 1e-4).all()
        before = after
    assert flips > 0


def test_stage_applies_at_the_next_reset(db):
    env = make(db, n=3)
    env.reset(seed=0)
    env.set_stage(0.0, 2.5, label=1)
    assert env.stage == (0.0, 2.5)
    assert env.env_state(0)["max_speed"] == pytest.approx(0.5)  # episodes in flight keep theirs
    env.reset(seed=1)
    for i in range(3):
        st = env.env_state(i)
        assert st["max_speed"] == 0.0 and st["target_half_extent"] == 2.5
        assert (env.obstacles(i)["velocities"] == 0).all()
        assert np.abs(np.asarray(st["target"])).max() <= 2.5
    with pytest.raises(ValueError, match="max_speed"):
        env.set_stage(3.0, 5.0)
    with pytest.raises(ValueError, match="target_half_extent"):
        env.set_stage(0.1, 0.5)
    with pytest.raises(ValueError, match="max_speed"):
        env.set_stage(float("nan"), 5.0)


# -- curriculum -------------------------------------------------------------------------------

class FakeEnvs:
    def __init__(self):
        self.calls = []
        self.records = (np.zeros(0, np.int32), np.zeros(0, bool))

    def set_stage(self, speed, half, label=0):
        self.calls.append((speed, half, label))

    def pop_finished_episodes(self):
        out, self.records = self.records, (np.zeros(0, np.int32), np.zeros(0, bool))
        return out


def test_curriculum_stage_parameters():
    cur = Curriculum()
    assert cur.stage == 1
    assert cur.stage_params(1) == (0.0, 2.5)
    assert cur.stage_params(10) == pytest.approx((0.5, 5.0))
    assert cur.stage_params(4) == pytest.approx((0.5 * 3 / 9, 2.5 + 2.5 * 3 / 9))
    with pytest.raises(ValueError):
        cur.stage_params(11)
    assert Curriculum(enabled=False).stage == 10


def test_curriculum_advances_on_success_stats_and_resets_its_window():
    cur = Curriculum(window=10)
    step = iter(range(1000, 10**6, 1000))
    def it(s):  # one trainer iteration that finished episodes with these successes
        out = cur.on_iteration({"step": next(step), "episode_data": {"success": np.asarray(s, bool)}})
        return out["curriculum_stage"], out["curriculum_complete"]
    assert it([1] * 9) == (1, 0)  # window not full
    assert it([0]) == (2, 0)  # 9/10 > 40%
    assert it([0] * 6 + [1] * 4) == (2, 0)  # exactly 40%
    assert it([1]) == (3, 0)  # last 10: 5/10
    for _ in range(7):
        assert it([1] * 10)[1] == 0  # stages 4..10: one per iteration, not complete on arrival
    assert cur.stage == 10 and not cur.complete
    assert it([0] * 10) == (10, 0)  # the last stage's window must itself exceed 40%
    assert it([1] * 5) == (10, 1)  # 5/10: every stage passed, training stays at 10
    assert cur.complete_step == 13000  # the 13th iteration
    assert it([0] * 10) == (10, 1)  # completion is kept
    assert cur.complete_step == 13000
    off = Curriculum(window=1, enabled=False)
    assert off.on_iteration({"episode_data": {"success": np.ones(5, bool)}}) == {
        "curriculum_stage": 10, "curriculum_complete": 1}


def test_curriculum_drives_the_envs_and_ignores_episodes_of_old_stages():
    envs = FakeEnvs()
    cur = Curriculum(envs, window=4)
    assert envs.calls == [(0.0, 2.5, 1)]
    envs.records = (np.array([1, 1, 1, 1]), np.array([1, 1, 0, 1], bool))
    assert cur.on_iteration({})["curriculum_stage"] == 2
    assert envs.calls[-1] == (pytest.approx(0.5 / 9), pytest.approx(2.5 + 2.5 / 9), 2)
    envs.records = (np.array([1, 1, 1, 1, 2]), np.ones(5, bool))  # stage-1 episodes still finishing
    assert cur.on_iteration({})["curriculum_stage"] == 2
    assert list(cur._recent) == [True]


def test_curriculum_state_round_trip():
    envs = FakeEnvs()
    cur = Curriculum(envs, window=3)
    for _ in range(3):
        cur.record([True, True, True])
        cur.advance_if_ready()
    cur.record([True, False])
    state = cur.state_dict()
    assert state["stage"] == 4
    envs2 = FakeEnvs()
    other = Curriculum(envs2, window=3)
    other.load_state_dict(state)
    assert other.stage == 4 and list(other._recent) == [True, False] and not other.complete
    assert envs2.calls[-1][2] == 4
    with pytest.raises(ValueError, match="stage"):
        other.load_state_dict({"stage": 0})


def test_curriculum_with_the_real_env_labels_episodes(db):
    env = make(db, n=8)
    cur = Curriculum(env, window=5)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    stages_seen = []
    for _ in range(30):
        _, _, _, _, infos = env.step(rng.uniform(env.single_action_space.low, env.single_action_space.high,
                                                 (8, 12)).astype(np.float32))
        if "episode_stage" in infos:
            stages_seen += infos["episode_stage"][infos["_episode_stage"]].tolist()
    assert stages_seen and set(stages_seen) == {1}
    assert all(env.env_state(i)["target_half_extent"] == 2.5 for i in range(8))
    cur.on_iteration({})
    assert env.pop_finished_episodes()[0].size == 0  # drained by the curriculum


# -- gymnasium contract -----------------------------------------------------------------------

# gymnasium's advice on Box bounds, not errors: the action box is the database's feature
# range (not [-1, 1]) and c_t, g_t are unbounded (as in mmrl/Plane-v0).
@pytest.mark.filterwarnings("ignore:.*we recommend using a symmetric and normalized space:UserWarning")
@pytest.mark.filterwarnings("ignore:.*A Box observation space minimum value is -infinity:UserWarning")
@pytest.mark.filterwarnings("ignore:.*A Box observation space maximum value is infinity:UserWarning")
def test_check_env_passes(db):
    check_env(ObstaclesEnv(db=db), skip_render_check=True)


def test_registered_single_and_vector(db):
    assert "mmrl/MovingObstacles-v0" in gym.registry
    env = gym.make("mmrl/MovingObstacles-v0", db=db)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (529,) and obs.dtype == np.float32
    env.close()
    venv = gym.make_vec("mmrl/MovingObstacles-v0", num_envs=3, db=db)
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (3, 529)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    assert venv.observation_space.shape == (3, 529)
    venv.close()


def test_same_step_autoreset_infos(db):
    env = make(db, n=16)
    env.reset(seed=11)
    rng = np.random.default_rng(3)
    ended = 0
    for _ in range(60):
        obs, r, term, trunc, infos = env.step(rng.uniform(env.single_action_space.low, env.single_action_space.high,
                                                          (16, 12)).astype(np.float32))
        assert obs.dtype == np.float32 and r.dtype == np.float32 and term.dtype == bool
        done = term | trunc
        if done.any():
            for key in ("final_obs", "success", "collision", "episode_return", "episode_length", "episode_stage"):
                np.testing.assert_array_equal(infos["_" + key], done)
            assert (infos["episode_length"][done] >= 1).all()
            assert not (infos["success"] & infos["collision"]).any()
            assert (infos["success"][done] | infos["collision"][done] | trunc[done]).all()
            ended += int(done.sum())
            # The new episode's observation is in obs; final_obs differs from it.
            assert not np.array_equal(infos["final_obs"][done], obs[done])
        else:
            assert infos == {}
    assert ended > 0


def test_seeded_runs_are_deterministic(db):
    runs = []
    for _ in range(2):
        env = make(db, n=5)
        obs, _ = env.reset(seed=42)
        rng = np.random.default_rng(7)
        trace = [obs]
        for _ in range(25):
            obs, r, term, trunc, _ = env.step(rng.uniform(env.single_action_space.low, env.single_action_space.high,
                                                          (5, 12)).astype(np.float32))
            trace += [obs, r, term, trunc]
        runs.append(trace)
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
    other = make(db, n=5)
    obs, _ = other.reset(seed=43)
    assert not np.array_equal(obs, runs[0][0])


# -- refused inputs ---------------------------------------------------------------------------

def test_bad_inputs_are_refused(db):
    env = make(db, n=2)
    env.reset(seed=0)
    good = np.zeros((2, 12), np.float32)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((3, 12), np.float32))
    with pytest.raises(TypeError, match="float"):
        env.step(np.zeros((2, 12), np.int64))
    bad = good.copy()
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        env.step(bad)
    buffers = dict(obs=env._obs, rewards=env._rewards, terminated=env._terminated, truncated=env._truncated,
                   success=env._success, collision=env._collision, hits=env._hits, final_obs=env._final_obs,
                   episode_return=env._ep_return, episode_length=env._ep_length)
    core = env._core
    with pytest.raises(TypeError, match="actions: expected dtype float32"):
        core.step(good.astype(np.float64), *buffers.values())
    with pytest.raises(ValueError, match="actions: contains NaN"):
        core.step(bad, *buffers.values())
    with pytest.raises(TypeError, match="hits: expected dtype int32"):
        core.step(good, *{**buffers, "hits": np.zeros(2, np.int64)}.values())
    with pytest.raises(ValueError, match="obs: expected size 529"):
        core.step(good, *{**buffers, "obs": np.zeros((2, 17), np.float32)}.values())
    ro = np.zeros(2, np.float32)
    ro.flags.writeable = False
    with pytest.raises(ValueError, match="rewards: array is read-only"):
        core.step(good, *{**buffers, "rewards": ro}.values())
    with pytest.raises(IndexError):
        core.obstacles(2)
    with pytest.raises(IndexError):
        core.sensor_map(-1)
    z2 = np.zeros((1, 2), np.float32)
    with pytest.raises(ValueError, match="half_sizes: must be >= 0"):
        core.set_obstacles(0, z2, -np.ones((1, 2), np.float32), np.zeros(1, np.float32), z2)
    with pytest.raises(ValueError, match="centres: contains NaN"):
        core.set_obstacles(0, np.full((1, 2), np.nan, np.float32), z2, np.zeros(1, np.float32), z2)
    with pytest.raises(ValueError, match="angles: expected size 1"):
        core.set_obstacles(0, z2, z2, np.zeros(2, np.float32), z2)
    with pytest.raises(ValueError, match="at most num_obstacles"):
        core.set_obstacles(0, np.zeros((101, 2), np.float32), np.zeros((101, 2), np.float32),
                           np.zeros(101, np.float32), np.zeros((101, 2), np.float32))
    with pytest.raises(ValueError, match="half sizes must be in"):
        core.set_obstacles(0, z2, np.full((1, 2), 1.6, np.float32), np.zeros(1, np.float32), z2)
    with pytest.raises(ValueError, match="centres must lie in the square"):
        core.set_obstacles(0, np.full((1, 2), 10.5, np.float32), z2, np.zeros(1, np.float32), z2)
    with pytest.raises(ValueError, match="speed_cap"):
        core.set_obstacles(0, z2, z2, np.zeros(1, np.float32), np.full((1, 2), 5.0, np.float32))
    with pytest.raises(ValueError, match="action"):
        core.action_hits(0, np.zeros(11, np.float32))
    with pytest.raises(ValueError, match="finite"):
        core.set_root(0, np.nan, 0.0, 0.0)
    with pytest.raises(TypeError, match="seed"):
        env.reset(seed=[1, 2])


@pytest.mark.parametrize("option, value, match", [
    ("num_obstacles", -1, "num_obstacles"),
    ("obstacle_max_side", 0.1, "max_side"),
    ("obstacle_max_speed", 3.0, "obstacle_max_speed"),
    ("target_half_extent", 0.5, "target_half_extent"),
    ("frames_per_step", 0, "frames_per_step"),
    ("body_radius", -0.1, "body_radius"),
    ("hit_radius", -0.1, "hit_radius"),
    ("hit_weight", -1.0, "hit_weight"),
    ("sensor_size", 0.0, "sensor_size"),
    ("grid_cell_size", 0.0, "cell_size"),
])
def test_bad_configs_are_refused(db, option, value, match):
    with pytest.raises(ValueError, match=match):
        make(db, n=1, **{option: value})
    with pytest.raises(TypeError, match="unknown moving-obstacles option"):
        make(db, n=1, speed=1.0)


def test_fast_evaluation_counts_each_first_episode(db):
    from mmrl import get_task
    from mmrl.rollout import evaluate_fast
    from mmrl.tasks.curriculum import stage_params
    from mmrl.tasks.obstacles import ObstaclesConfig

    def evaluate_obstacles_fast(policy, db, **kwargs):
        return evaluate_fast(get_task("obstacles"), db, policy, **kwargs)
    from mmrl.rl.policies import JoystickPolicy

    joy = JoystickPolicy.preset(db, "joystick")
    empty = evaluate_obstacles_fast(joy, db, episodes=64, seed=3, config=ObstaclesConfig(num_obstacles=0), stage=1)
    assert empty["collision_rate"] == 0.0 and empty["success_rate"] > 0.95  # nothing in the way
    a = evaluate_obstacles_fast(joy, db, episodes=64, seed=3, stage=10)
    b = evaluate_obstacles_fast(joy, db, episodes=64, seed=3, stage=10)
    assert a == b  # the same episodes for the same seed
    assert a["collision_rate"] > 0.1 and a["success_rate"] < empty["success_rate"]
    assert a["success_rate"] + a["collision_rate"] + a["truncation_rate"] == pytest.approx(1.0)
    # The first episode of env i is the one the vector env runs from the same seed.
    env = make(db, n=64)
    env.set_stage(*stage_params(10), 10)
    obs, _ = env.reset(seed=3)
    joy.bind_layout(env.observation_layout)
    first = np.full(64, -1)
    while (first < 0).any():
        obs, _, term, trunc, info = env.step(joy.act(obs))
        for i in np.flatnonzero((term | trunc) & (first < 0)):
            first[i] = info["success"][i]
    assert a["success_rate"] == pytest.approx(first.mean())
