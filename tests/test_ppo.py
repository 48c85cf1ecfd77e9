"""PPO: GAE against hand-computed numbers, determinism, checkpoints, resume,
callbacks, bad inputs, and learning the toy target task end to end."""
from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _toyenv import quiet_config, read_rows, PointMassTargetVecEnv  # noqa: E402

from mmrl.rl import ppo  # noqa: E402
from mmrl.rl.networks import OBSTACLE_DEFAULT_LAYOUT, ObstacleActorCritic, PlaneActorCritic  # noqa: E402
from mmrl.rl.ppo import (  # noqa: E402
    CheckpointError, NonFiniteError, PPOConfig, compute_gae, load_checkpoint, load_policy,
    save_checkpoint, successor_values, train,
)


def deterministic_columns(rows: list[dict]) -> list[dict]:
    # wall time, throughput and timings are the only columns allowed to vary between runs
    return [{k: v for k, v in row.items() if k not in ("wall_s", "sps", "env_us", "act_us", "update_us")} for row in rows]


# ----------------------------------------------------------------------------- GAE

def test_gae_matches_hand_computation_with_termination_and_truncation():
    gamma, lam = 0.9, 0.8
    # One env, four steps: step 1 terminates, step 3 is truncated with
    # V(final_obs) = 10; values[4] is the obs after the rollout (the reset obs
    # of the next episode) and must not be used.
    values = np.array([[0.5], [1.0], [1.5], [2.0], [99.0]])
    rewards = np.array([[1.0], [2.0], [3.0], [4.0]])
    terminated = np.array([[False], [True], [False], [False]])
    truncated = np.array([[False], [False], [False], [True]])
    next_values = successor_values(values, terminated, [(3, np.array([0]))], np.array([10.0]))
    np.testing.assert_allclose(next_values[:, 0], [1.0, 0.0, 2.0, 10.0])
    advantages, returns = compute_gae(rewards, values[:-1], next_values, terminated | truncated, gamma, lam)
    # deltas: 1 + .9*1 - .5 = 1.4 | 2 - 1 = 1 | 3 + .9*2 - 1.5 = 3.3 | 4 + .9*10 - 2 = 11
    # A3 = 11; A2 = 3.3 + .72*11 = 11.22; A1 = 1 (the episode ends); A0 = 1.4 + .72*1 = 2.12
    np.testing.assert_allclose(advantages[:, 0], [2.12, 1.0, 11.22, 11.0])
    np.testing.assert_allclose(returns[:, 0], [2.62, 2.0, 12.72, 13.0])


def test_gae_bootstraps_from_last_value_and_keeps_envs_apart():
    values = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 5.0]])
    rewards = np.array([[0.0, 1.0], [0.0, 1.0]])
    ends = np.zeros((2, 2), bool)
    next_values = successor_values(values, ends, [], np.zeros(0))
    advantages, _ = compute_gae(rewards, values[:-1], next_values, ends, 0.5, 1.0)
    # env 0: deltas 0 + .5*2 - 1 = 0 and 0 + .5*3 - 2 = -0.5 -> A = [-0.25, -0.5]
    # env 1: deltas 1 and 1 + .5*5 = 3.5 -> A = [1 + .5*3.5, 3.5]
    np.testing.assert_allclose(advantages, [[-0.25, 2.75], [-0.5, 3.5]])


class EchoNet(torch.nn.Module):
    """A 'policy' whose action is its (unnormalized) observation."""

    def __init__(self, obs_dim, act_dim):
        super().__init__()
        self.log_std = torch.nn.Parameter(torch.full((act_dim,), -30.0))
        self.bias = torch.nn.Parameter(torch.zeros(()))

    def actor_mean(self, obs):
        return obs + 0 * self.bias

    def value(self, obs):
        return obs.sum(-1) * 0 + self.bias


class EchoCheckEnv(PointMassTargetVecEnv):
    """Records whether every action equals the observation returned just before."""

    def __init__(self, num_envs):
        super().__init__(num_envs, max_steps=7)
        self.last_obs, self.mismatches, self.steps = None, 0, 0
        self.single_action_space = gym.spaces.Box(-np.inf, np.inf, (4,), np.float32)

    def reset(self, *, seed=None, options=None):
        obs, info = super().reset(seed=seed, options=options)
        self.last_obs = obs
        return obs, info

    def step(self, actions):
        self.mismatches += int(not np.allclose(actions, self.last_obs, atol=1e-5))
        self.steps += 1
        obs, *rest = super().step(actions[:, :2])
        self.last_obs = obs
        return (obs, *rest)


def test_policy_acts_on_the_observation_the_env_just_returned(tmp_path):
    env = EchoCheckEnv(3)
    train(env, quiet_config(total_steps=3 * 32 * 3, obs_norm=False, learning_rate=0.0), tmp_path,
          policy_factory=EchoNet)
    assert env.steps == 96 and env.mismatches == 0


# ----------------------------------------------------------------------------- determinism

def test_same_seed_gives_identical_metrics_and_other_seeds_differ(tmp_path):
    def run(seed: int, name: str) -> list[dict]:
        result = train(PointMassTargetVecEnv(8), quiet_config(seed=seed), tmp_path / name)
        return deterministic_columns(read_rows(result.metrics_csv))

    first, second, other = run(0, "a"), run(0, "b"), run(1, "c")
    assert len(first) == 8192 // (8 * 32)
    assert first == second
    assert first != other


# ----------------------------------------------------------------------------- checkpoints

def test_corrupt_or_foreign_checkpoint_raises_clear_error(tmp_path):
    out = tmp_path / "run"
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=256), out)
    latest = out / "latest.pt"
    assert load_checkpoint(latest)["global_step"] == 256

    data = latest.read_bytes()
    latest.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="latest.pt"):
        load_policy(latest)
    with pytest.raises(CheckpointError, match="latest.pt"):
        train(PointMassTargetVecEnv(4), quiet_config(total_steps=512), out, resume=True)

    foreign = tmp_path / "foreign.pt"
    torch.save({"state_dict": {"w": torch.zeros(2)}}, foreign)
    with pytest.raises(CheckpointError, match="foreign.pt.*not an mmrl PPO checkpoint"):
        load_policy(foreign)
    with pytest.raises(CheckpointError, match="missing.pt"):
        load_checkpoint(tmp_path / "missing.pt")


def test_failed_write_leaves_previous_checkpoint_intact(tmp_path, monkeypatch):
    path = tmp_path / "latest.pt"
    save_checkpoint({"global_step": 1}, path)
    before = path.read_bytes()

    def failing_save(obj, file, *args, **kwargs):
        file.write(b"half a checkpoint")
        raise OSError("disk full")

    monkeypatch.setattr(ppo.torch, "save", failing_save)
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint({"global_step": 2}, path)
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert load_checkpoint(path)["global_step"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest.pt"]  # no temp file left behind


def test_fresh_run_refuses_to_overwrite_an_existing_run(tmp_path):
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=128), tmp_path)
    with pytest.raises(FileExistsError, match="resume=True"):
        train(PointMassTargetVecEnv(4), quiet_config(total_steps=128), tmp_path)


class StageCounter:
    """A curriculum-like callback: adds a column and keeps state in checkpoints."""

    def __init__(self):
        self.stage = 1

    def on_iteration(self, stats):
        assert {"step", "success_rate", "episode_data"} <= stats.keys()
        self.stage += 1
        return {"curriculum_stage": self.stage}

    def state_dict(self):
        return {"stage": self.stage}

    def load_state_dict(self, state):
        self.stage = state["stage"]


def test_resume_continues_step_count_csv_and_callback_state(tmp_path):
    cfg = quiet_config(total_steps=1024, snapshot_steps=(512,))
    callback = StageCounter()
    first = train(PointMassTargetVecEnv(8), cfg, tmp_path, callbacks=[callback])
    assert first.global_step == 1024 and callback.stage == 5
    assert (tmp_path / "snapshot_512.pt").exists()
    assert load_checkpoint(tmp_path / "snapshot_512.pt")["global_step"] == 512

    resumed_callback = StageCounter()
    second = train(PointMassTargetVecEnv(8), quiet_config(total_steps=2048), tmp_path, resume=True,
                   callbacks=[resumed_callback])
    assert second.global_step == 2048
    rows = read_rows(tmp_path / "metrics.csv")
    assert [int(r["step"]) for r in rows] == list(range(256, 2049, 256))
    assert [int(r["curriculum_stage"]) for r in rows] == list(range(2, 10))
    assert (tmp_path / "metrics.csv").read_text().count("step,wall_s") == 1
    walls = [float(r["wall_s"]) for r in rows]
    assert walls == sorted(walls)
    state = load_checkpoint(tmp_path / "latest.pt")
    assert state["callbacks"][0] == {"stage": 9} and state["global_step"] == 2048


def test_resume_drops_metrics_rows_written_after_the_checkpoint(tmp_path):
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=512), tmp_path)
    with open(tmp_path / "metrics.csv", "a") as file:  # as if a crash came after logging step 768
        file.write("768" + ",0" * 14 + "\n")
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=1024), tmp_path, resume=True)
    assert [int(r["step"]) for r in read_rows(tmp_path / "metrics.csv")] == [256, 512, 768, 1024]


# ----------------------------------------------------------------------------- bad inputs

class NaNAfterEnv(PointMassTargetVecEnv):
    def __init__(self, num_envs, bad_step):
        super().__init__(num_envs)
        self.calls, self.bad_step = 0, bad_step

    def step(self, actions):
        obs, *rest = super().step(actions)
        self.calls += 1
        if self.calls == self.bad_step:
            obs[0, 1] = np.nan
        return (obs, *rest)


def test_nan_observation_raises_and_keeps_last_good_checkpoint(tmp_path):
    cfg = quiet_config(total_steps=4096, checkpoint_interval_steps=1)
    with pytest.raises(NonFiniteError, match="NaN"):
        train(NaNAfterEnv(4, bad_step=100), cfg, tmp_path)
    assert load_checkpoint(tmp_path / "latest.pt")["global_step"] == 3 * 32 * 4


def test_env_without_same_step_autoreset_is_refused(tmp_path):
    env = PointMassTargetVecEnv(2)
    env.metadata = {"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}
    with pytest.raises(ValueError, match="SAME_STEP"):
        train(env, quiet_config(), tmp_path)


def test_gymnasium_sync_vector_env_with_object_final_obs(tmp_path):
    envs = gym.make_vec("Pendulum-v1", num_envs=2, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP})
    result = train(envs, quiet_config(total_steps=2 * 256, num_steps=256), tmp_path)
    row = result.last_stats
    assert row["episodes"] == 2 and row["episode_length"] == 200  # Pendulum truncates at 200
    assert math.isnan(row["success_rate"])  # no success info
    envs.close()


# ----------------------------------------------------------------------------- networks

def test_obstacle_network_splits_the_flat_observation_by_layout():
    net = ObstacleActorCritic(act_dim=12)
    assert ObstacleActorCritic.map_range() == (0, 512) and net.obs_dim == 529
    obs = torch.randn(3, 529)
    maps, vector = net._split(obs)
    assert torch.equal(maps[1, 1, 2, 5], obs[1, 256 + 2 * 16 + 5])  # channel 1 = previous map
    assert torch.equal(vector, obs[:, 512:])
    assert net.actor_mean(obs).shape == (3, 12) and net.value(obs).shape == (3,)

    reordered = ObstacleActorCritic(act_dim=12, layout=(("pose", 15), ("maps", 512), ("goal", 2)))
    maps, vector = reordered._split(obs)
    assert torch.equal(vector, torch.cat([obs[:, :15], obs[:, 527:]], dim=1))
    with pytest.raises(ValueError, match="map_shape"):
        ObstacleActorCritic(act_dim=12, layout=(("maps", 100), ("goal", 2)))
    with pytest.raises(ValueError, match="expected obs with 529"):
        net.value(torch.zeros(2, 17))


def test_obstacle_network_trains_with_unnormalized_maps(tmp_path):
    layout = (("goal", 2), ("pose", 2), ("maps", 512))
    env = PointMassTargetVecEnv(4, extra_obs_dims=512, extra_act_dims=10)
    cfg = quiet_config(total_steps=256, obs_norm_exclude=ObstacleActorCritic.map_range(layout))
    train(env, cfg, tmp_path, policy_factory=lambda obs_dim, act_dim: ObstacleActorCritic(act_dim, layout=layout))
    policy = load_policy(tmp_path / "latest.pt")
    assert policy.obs_normalizer.scale[4:].eq(1).all() and policy.obs_normalizer.shift[4:].eq(0).all()
    assert policy.act(np.zeros(516, np.float32)).shape == (12,)


def test_plane_network_shapes():
    net = PlaneActorCritic(17, 12)
    assert net.actor_mean(torch.zeros(5, 17)).shape == (5, 12) and net.value(torch.zeros(5, 17)).shape == (5,)
    assert sum(p.numel() for p in net.actor.parameters()) == 17 * 32 + 32 + 32 * 32 + 32 + 32 * 12 + 12


# ----------------------------------------------------------------------------- learning

def evaluate_success(policy, episodes: int, seed: int) -> float:
    env = PointMassTargetVecEnv(episodes)
    obs, _ = env.reset(seed=seed)
    finished = np.zeros(episodes, bool)
    succeeded = np.zeros(episodes, bool)
    while not finished.all():
        obs, _, terminated, truncated, infos = env.step(policy.act(obs, deterministic=True))
        newly = (terminated | truncated) & ~finished
        succeeded |= newly & terminated
        finished |= newly
    return float(succeeded.mean())


def test_learns_sparse_bonus_target_task_end_to_end(tmp_path):
    # Targets uniform in 10 x 10 m, +1000 on reaching 0.5 m, exp(-dist) shaping.
    # A random policy succeeds in about 15% of episodes.
    untrained = evaluate_success(load_policy_from_fresh_model(tmp_path / "untrained"), 200, seed=123)
    cfg = quiet_config(total_steps=60_000, tensorboard=True, progress=True)
    result = train(PointMassTargetVecEnv(32), cfg, tmp_path / "run")
    assert any((tmp_path / "run").glob("events.out.tfevents.*"))
    success = evaluate_success(load_policy(result.checkpoint), 200, seed=123)
    assert untrained < 0.5
    assert success >= 0.95, f"success {success} after {result.global_step} steps"
    assert result.last_stats["success_rate"] >= 0.9


def load_policy_from_fresh_model(out: Path):
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=4 * 32, learning_rate=0.0), out)
    return load_policy(out / "latest.pt")
