"""The `_core` env additions for the Python layer: frames played per step, obstacles after k
played frames, current frames. The C++ tests (cpp/tests/test_envs.cpp, test_obstacles_env.cpp)
check them against brute force; here: the bindings forward, agree with stepping, and refuse
bad arguments by name."""
import numpy as np
import pytest

from mmrl import _core
from mmrl import default_database


def core_env(cls, config, n, seed):
    db = default_database()
    env = cls(db._db, db.matcher, n, config, 1)
    obs = np.zeros((n, env.obs_dim), np.float32)
    env.reset(seed, obs)
    return db, env, obs


def buffers(env, n, obstacles):
    b = dict(obs=np.zeros((n, env.obs_dim), np.float32), rewards=np.zeros(n, np.float32),
             terminated=np.zeros(n, np.uint8), truncated=np.zeros(n, np.uint8), success=np.zeros(n, np.uint8))
    if obstacles:
        b.update(collision=np.zeros(n, np.uint8), hits=np.zeros(n, np.int32))
    b.update(final_obs=np.zeros((n, env.obs_dim), np.float32), episode_return=np.zeros(n, np.float32),
             episode_length=np.zeros(n, np.int32))
    return b


def policy_actions(db, rng, n):
    rows = np.flatnonzero(db.valid_mask)
    t = db.normalized_features[rng.choice(rows, n), 15:]
    return np.ascontiguousarray(t + rng.normal(0, 0.5, t.shape), np.float32)


def test_obstacles_after_and_step_frames_agree_with_stepping():
    cfg = _core.ObstacleTaskConfig()
    cfg.num_obstacles, cfg.obstacle_max_speed, cfg.target_half_extent = 60, 2.0, 1.5
    n = 12
    db, env, _ = core_env(_core.ObstacleVecEnv, cfg, n, 4)
    played = np.full(n, -1, np.int32)
    env.step_frames(played)
    assert (played == 0).all()
    rng = np.random.default_rng(0)
    b = buffers(env, n, True)
    ended_early = continued = 0
    for _ in range(40):
        now = [env.obstacles(i) for i in range(n)]
        after = [env.obstacles_after(i, cfg.frames_per_step) for i in range(n)]
        for i in range(n):
            same = env.obstacles_after(i, 0)
            assert all(np.array_equal(same[k], now[i][k]) for k in now[i])
        env.step(policy_actions(db, rng, n), *b.values())
        env.step_frames(played)
        frames = np.zeros(n, np.int64)
        env.current_frames(frames)
        for i in range(n):
            st = env.state(i)
            assert frames[i] == st["frame"] and played[i] == st["step_frames"]
            if b["terminated"][i] or b["truncated"][i]:
                assert 1 <= played[i] <= cfg.frames_per_step
                ended_early += played[i] < cfg.frames_per_step
            else:
                assert played[i] == cfg.frames_per_step
                o = env.obstacles(i)  # the prediction from the step's start, bit for bit
                assert np.array_equal(o["centres"], after[i]["centres"])
                assert np.array_equal(o["velocities"], after[i]["velocities"])
                assert np.array_equal(o["half_sizes"], after[i]["half_sizes"])
                continued += 1
    assert ended_early >= 5 and continued >= 100


def test_plane_step_frames_counts_to_the_first_frame_inside_the_disc():
    cfg = _core.TargetTaskConfig()
    n = 4
    db, env, _ = core_env(_core.PlaneVecEnv, cfg, n, 2)
    for i in range(n):  # the target at the root: the first played frame is inside the disc
        s = env.state(i)
        env.set_target(i, s["x"], s["z"])
    b = buffers(env, n, False)
    env.step(policy_actions(db, np.random.default_rng(1), n), *b.values())
    played = np.zeros(n, np.int32)
    env.step_frames(played)
    assert b["success"].all() and (played == 1).all()
    for i in range(n):
        env.set_target(i, 30.0, 30.0)  # out of reach
    env.step(policy_actions(db, np.random.default_rng(2), n), *b.values())
    env.step_frames(played)
    assert (played == cfg.frames_per_step).all()


def test_bad_arguments_are_refused_by_name():
    _, env, _ = core_env(_core.ObstacleVecEnv, _core.ObstacleTaskConfig(), 2, 0)
    with pytest.raises(TypeError, match="out: expected dtype int32"):
        env.step_frames(np.zeros(2, np.int64))
    with pytest.raises(ValueError, match="out: expected size 2"):
        env.current_frames(np.zeros(3, np.int64))
    with pytest.raises(ValueError, match="frames: must be >= 0"):
        env.obstacles_after(0, -1)
    with pytest.raises(IndexError):
        env.obstacles_after(2, 1)
    with pytest.raises(ValueError, match="velocities: obstacle speed exceeds speed_cap"):
        z = np.zeros((1, 2), np.float32)
        env.set_obstacles(0, z, z, np.zeros(1, np.float32), np.full((1, 2), 5.0, np.float32))
    _, plane, _ = core_env(_core.PlaneVecEnv, _core.TargetTaskConfig(), 2, 0)
    with pytest.raises(TypeError, match="out: expected dtype int32"):
        plane.step_frames(np.zeros(2, np.float32))
    with pytest.raises(ValueError, match="target must be finite"):
        plane.set_target(0, float("nan"), 0.0)
