"""SAME_STEP and NEXT_STEP autoreset play the same episodes.

RLlib expects gymnasium's NEXT_STEP autoreset; our trainer uses SAME_STEP. Both modes are
driven with the same per-episode action scripts (a function of env index, episode number
and step in the episode, never of wall-clock step count), and every episode must come out
identical: first observation, every (action, reward, observation), the last observation,
return, length, success and frames played.
"""
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import mmrl


def scripted_action(env, episode, t, low, high):
    """A reproducible action for step t of episode `episode` of env `env` (the box's span)."""
    rng = np.random.default_rng([env, episode, t])
    return (low + (high - low) * rng.uniform(0.2, 0.8, low.shape)).astype(np.float32)


def play(task_name, db, mode, steps, n=4, **overrides):
    """Episodes of each env as lists of dicts, in the order they finished."""
    env = mmrl.get_task(task_name).make_vector_env(n, db=db, num_threads=2, autoreset_mode=mode, **overrides)
    low, high = env.single_action_space.low, env.single_action_space.high
    obs, _ = env.reset(seed=7)
    finished = [[] for _ in range(n)]
    current = [{"first": obs[i].copy(), "steps": []} for i in range(n)]
    episode = [0] * n
    t = [0] * n
    resetting = np.zeros(n, bool)  # NEXT_STEP: the env's next step is its reset
    reset_steps = 0
    for _ in range(steps):
        actions = np.stack([scripted_action(i, episode[i], t[i], low, high) for i in range(n)])
        if mode == AutoresetMode.NEXT_STEP:
            actions[resetting] = 1e6  # ignored: anything finite
        obs, rewards, terminated, truncated, infos = env.step(actions)
        for i in range(n):
            if resetting[i]:
                assert rewards[i] == 0 and not terminated[i] and not truncated[i]
                current[i] = {"first": obs[i].copy(), "steps": []}
                resetting[i] = False
                reset_steps += 1
                continue
            current[i]["steps"].append((actions[i].copy(), float(rewards[i])))
            t[i] += 1
            if terminated[i] or truncated[i]:
                last = obs[i] if mode == AutoresetMode.NEXT_STEP else infos["final_obs"][i]
                current[i].update(last=last.copy(), terminated=bool(terminated[i]),
                                  ret=float(infos["episode_return"][i]), length=int(infos["episode_length"][i]),
                                  success=bool(infos["success"][i]), frames=int(infos["episode_frames"][i]))
                finished[i].append(current[i])
                episode[i] += 1
                t[i] = 0
                if mode == AutoresetMode.NEXT_STEP:
                    resetting[i] = True
                else:
                    current[i] = {"first": obs[i].copy(), "steps": []}
            else:
                current[i]["steps"].append(obs[i].copy())
    return finished, env.pop_match_stats()["decisions"] + reset_steps


def assert_same_episodes(a, b):
    total = 0
    for env_a, env_b in zip(a, b):
        common = min(len(env_a), len(env_b))
        assert common >= 2, "too few episodes to compare"
        assert abs(len(env_a) - len(env_b)) <= 1  # NEXT_STEP spends one step per episode resetting
        for ea, eb in zip(env_a[:common], env_b[:common]):
            np.testing.assert_array_equal(ea["first"], eb["first"])
            np.testing.assert_array_equal(ea["last"], eb["last"])
            assert len(ea["steps"]) == len(eb["steps"])
            for sa, sb in zip(ea["steps"], eb["steps"]):
                if isinstance(sa, tuple):
                    np.testing.assert_array_equal(sa[0], sb[0])
                    assert sa[1] == sb[1]
                else:
                    np.testing.assert_array_equal(sa, sb)
            for key in ("terminated", "ret", "length", "success", "frames"):
                assert ea[key] == eb[key], key
            total += 1
    return total


@pytest.mark.parametrize("task_name,overrides", [("plane", {"max_steps": 12, "target_half_extent": 2.0}),
                                                 ("obstacles", {"max_steps": 10})])
def test_same_step_and_next_step_play_identical_episodes(task_name, overrides):
    db = mmrl.default_database()
    same, same_stats = play(task_name, db, AutoresetMode.SAME_STEP, 60, **overrides)
    nxt, next_stats = play(task_name, db, AutoresetMode.NEXT_STEP, 66, **overrides)
    compared = assert_same_episodes(same, nxt)
    assert compared >= 4 * 4
    # Both terminations and truncations were compared (the scripts reach some targets).
    kinds = {e["terminated"] for env in same for e in env}
    if task_name == "plane":
        assert kinds == {True, False}
    # Every env step is a decision, but a NEXT_STEP reset step is not.
    assert same_stats == 60 * 4 and next_stats == 66 * 4


def test_next_step_on_another_skeleton(tmp_path):
    """Mixamo names and other channel orders: the modes agree there too."""
    from test_import_axes_fps import other_skeleton_database

    db = other_skeleton_database(tmp_path)
    overrides = {"max_steps": 8, "target_half_extent": 1.5}
    same, _ = play("plane", db, AutoresetMode.SAME_STEP, 40, **overrides)
    nxt, _ = play("plane", db, AutoresetMode.NEXT_STEP, 45, **overrides)
    assert assert_same_episodes(same, nxt) >= 8


def test_next_step_returns_the_last_observation_and_ignores_the_reset_action():
    db = mmrl.default_database()
    env = mmrl.get_task("plane").make_vector_env(2, db=db, autoreset_mode="next_step", max_steps=2)
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    env.reset(seed=3)
    a = np.zeros((2, env.act_dim), np.float32)
    env.step(a)
    obs, r, term, trunc, infos = env.step(a)
    assert trunc.all()
    np.testing.assert_array_equal(obs, infos["final_obs"])
    # The reset step: any finite action gives the same first observation.
    copy = mmrl.get_task("plane").make_vector_env(2, db=db, autoreset_mode="next_step", max_steps=2)
    copy.reset(seed=3)
    copy.step(a)
    copy.step(a)
    first_a, *_ = env.step(np.full_like(a, 0.5))
    first_b, *_ = copy.step(np.full_like(a, -0.5))
    np.testing.assert_array_equal(first_a, first_b)
    with pytest.raises(ValueError, match="autoreset_mode"):
        mmrl.get_task("plane").make_vector_env(2, db=db, autoreset_mode="disabled")
    with pytest.raises(ValueError, match="autoreset_mode"):
        mmrl.get_task("plane").make_vector_env(2, db=db, autoreset_mode="sideways")
