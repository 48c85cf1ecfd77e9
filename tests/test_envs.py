"""The plane task: gymnasium contract, and the C++ batched step against a numpy reference."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import mmrl
from mmrl.tasks.plane import PlaneVectorEnv


@pytest.fixture(scope="module")
def db():
    return mmrl.default_database()


def ref_match(db, frame, traj):
    """Brute-force motion matching with the continuation rule (float64)."""
    feats = db.normalized_features.astype(np.float64)
    q = np.concatenate([feats[frame, :15], traj])
    cost = ((feats - q) ** 2).sum(1)
    cost[~db.valid_mask] = np.inf
    a, b = db.clip_ranges[db.frame_clip[frame]]
    masked = cost.copy()
    masked[max(a, frame - 20):min(b, frame + 21)] = np.inf  # the exclusion window
    j = int(np.argmin(masked))
    if db.valid_mask[frame] and cost[frame] <= masked[j]:
        j = frame
    return j, cost


def ref_step(db, st, action, low, high, frames=6):
    """One step of the plane task in numpy. Returns the per-frame root positions."""
    traj = np.clip(action.astype(np.float64), low, high)
    j, cost = ref_match(db, st["frame"], traj)
    x, z, yaw = st["x"], st["z"], st["yaw"]
    path = []
    for k in range(frames):
        dx, dz, dyaw = db.root_deltas[j + k].astype(np.float64)
        c, s = np.cos(yaw), np.sin(yaw)
        x, z = x + c * dx + s * dz, z - s * dx + c * dz
        yaw = np.angle(np.exp(1j * (yaw + dyaw)))
        path.append((x, z))
    return dict(frame=j + frames, x=x, z=z, yaw=yaw, path=np.array(path), match=j, cost=cost)


def local_target(st):
    tx, tz = st["target"]
    dx, dz = tx - st["x"], tz - st["z"]
    c, s = np.cos(st["yaw"]), np.sin(st["yaw"])
    return np.array([c * dx - s * dz, s * dx + c * dz])


def policy_like_actions(db, rng, n, noise=0.5):
    rows = rng.choice(np.flatnonzero(db.valid_mask), n)
    t = db.normalized_features[rows, 15:]
    return (t + rng.normal(0, noise, t.shape) * t.std(0)).astype(np.float32)


def test_gymnasium_contract(db):
    env = gym.make_vec("mmrl/Plane-v0", num_envs=8)
    assert isinstance(env, PlaneVectorEnv)
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.observation_space.shape == (8, 17) and env.action_space.shape == (8, 12)
    assert env.single_observation_space.shape == (17,) and env.single_action_space.shape == (12,)
    obs, info = env.reset(seed=3)
    assert obs.shape == (8, 17) and obs.dtype == np.float32
    env.close()


def test_check_env(db):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        # Our action box is the data's (normalized feature units), and observations are unbounded.
        warnings.filterwarnings("ignore", message=".*symmetric and normalized space.*")
        warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum).*")
        check_env(gym.make("mmrl/Plane-v0").unwrapped, skip_render_check=True)


def test_step_matches_numpy_reference(db):
    n = 6
    env = PlaneVectorEnv(n, db=db, num_threads=2)
    obs, _ = env.reset(seed=11)
    low, high = env.single_action_space.low, env.single_action_space.high
    rng = np.random.default_rng(0)
    for step in range(12):
        states = [env.env_state(i) for i in range(n)]
        for i, st in enumerate(states):
            np.testing.assert_allclose(obs[i, :15], db.normalized_features[st["frame"], :15])
            np.testing.assert_allclose(obs[i, 15:], local_target(st), atol=1e-4)
        actions = policy_like_actions(db, rng, n) if step % 3 else rng.uniform(low, high, (n, 12)).astype(np.float32)
        obs, rew, term, trunc, info = env.step(actions)
        for i, st in enumerate(states):
            ref = ref_step(db, st, actions[i], low, high)
            if term[i] or trunc[i]:
                continue  # reset already; covered by other tests
            new = env.env_state(i)
            assert new["last_match"] == ref["match"] or abs(ref["cost"][new["last_match"]] - ref["cost"][ref["match"]]) < 1e-4
            if new["last_match"] == ref["match"]:
                assert new["frame"] == ref["frame"]
                np.testing.assert_allclose([new["x"], new["z"]], [ref["x"], ref["z"]], atol=1e-4)
                d = np.hypot(*(np.array(st["target"]) - [ref["x"], ref["z"]]))
                assert rew[i] == pytest.approx(np.exp(-d), rel=1e-4)


def test_success_is_tested_on_every_played_frame(db):
    env = PlaneVectorEnv(16, db=db, num_threads=1)
    env.reset(seed=5)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = np.tile(db.normalized_features[env.env_state(0)["frame"], 15:], (16, 1)).astype(np.float32)
    checked = 0
    for i in range(16):
        st = env.env_state(i)
        ref = ref_step(db, st, actions[i], low, high)
        p1, p6 = ref["path"][0], ref["path"][-1]
        if np.linalg.norm(p6 - p1) < 0.1:
            continue
        u = (p6 - p1) / np.linalg.norm(p6 - p1)
        target = p1 - 0.45 * u  # within 0.5 m of frame 1 only
        assert np.linalg.norm(target - p6) > 0.5
        env.set_target(i, *target)
        checked += 1
    assert checked >= 4
    _, rew, term, trunc, info = env.step(actions)
    assert term.sum() >= checked
    assert info["success"][term].all()
    assert (rew[term] > 1000).all()


def test_truncation_final_obs_and_autoreset(db):
    env = PlaneVectorEnv(3, db=db, max_steps=3)
    env.reset(seed=1)
    for i in range(3):
        env.set_target(i, 1000.0, 1000.0)
    acts = np.zeros((3, 12), np.float32)
    for _ in range(2):
        _, _, term, trunc, info = env.step(acts)
        assert not trunc.any() and "final_obs" not in info
    before = [env.env_state(i) for i in range(3)]
    obs, rew, term, trunc, info = env.step(acts)
    assert trunc.all() and not term.any()
    assert info["_final_obs"].all() and not info["success"].any()
    np.testing.assert_array_equal(info["episode_length"], [3, 3, 3])
    # The final observation still sees the far target; the new episode's target is nearby.
    assert (np.linalg.norm(info["final_obs"][:, 15:], axis=1) > 1000).all()
    assert (np.linalg.norm(obs[:, 15:], axis=1) < 8).all()
    assert [env.env_state(i)["steps"] for i in range(3)] == [0, 0, 0]
    assert before[0]["target"] != env.env_state(0)["target"]


def test_seeding_is_per_env_and_reproducible(db):
    def rollout(n, seed):
        env = PlaneVectorEnv(n, db=db)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(1)
        out = [obs[:2].copy()]
        for _ in range(20):
            a = policy_like_actions(db, rng, 2)
            a = np.concatenate([a, np.zeros((n - 2, 12), np.float32)])
            obs, *_ = env.step(a)
            out.append(obs[:2].copy())
        return np.array(out)

    a = rollout(4, 7)
    np.testing.assert_array_equal(a, rollout(4, 7))
    np.testing.assert_array_equal(a, rollout(2, 7))  # env i's stream does not depend on N
    assert not np.array_equal(a, rollout(4, 8))


def test_bad_actions(db):
    env = PlaneVectorEnv(2, db=db)
    env.reset(seed=0)
    good = np.zeros((2, 12), np.float32)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full((2, 12), np.nan, np.float32))
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.where(np.arange(12) == 3, np.inf, good))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros((3, 12), np.float32))
    with pytest.raises(TypeError, match="float"):
        env.step(np.zeros((2, 12), np.int64))
    env.step(good.astype(np.float64))  # floats of any width are accepted
    with pytest.raises(TypeError, match="unknown plane-task option"):
        PlaneVectorEnv(2, db=db, max_stepz=3)
    with pytest.raises(ValueError):
        PlaneVectorEnv(0, db=db)
    single = gym.make("mmrl/Plane-v0")
    single.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        single.step(np.full(12, np.nan, np.float32))


def test_actions_are_clipped_to_the_box(db):
    env = PlaneVectorEnv(1, db=db)
    env.reset(seed=4)
    st = env.env_state(0)
    high = env.single_action_space.high
    huge = np.full((1, 12), 1e6, np.float32)
    env.step(huge)
    ref = ref_step(db, st, high, env.single_action_space.low, high)
    assert env.env_state(0)["last_match"] == ref["match"]


def test_database_match_with_controller_windows_equals_reference(db):
    rng = np.random.default_rng(3)
    frames = rng.choice(np.flatnonzero(db.valid_mask), 40)
    traj = policy_like_actions(db, rng, 40)
    queries = np.concatenate([db.normalized_features[frames, :15], traj], 1).astype(np.float32)
    idx, cost = db.match(queries, normalized=True, bound_indices=frames.astype(np.int64),
                         exclude=db.controller_windows(frames))
    for k, f in enumerate(frames):
        j, ref_cost = ref_match(db, int(f), traj[k].astype(np.float64))
        assert idx[k] == j or abs(ref_cost[idx[k]] - ref_cost[j]) < 1e-4
    with pytest.raises(ValueError, match="exclude"):
        db.match(queries, normalized=True, exclude=np.zeros((3, 2), np.int64))
