"""The cheap fast-path quality log of training (issue 14): the envs' per-step transition flag and
matched cost against the full-path Character in lockstep, and the training CSV's columns
against a brute-force recomputation of every decision of a toy run."""
import csv

import numpy as np
import pytest

import mmrl
from mmrl.rl import ppo
from mmrl.rl.quality_log import MatchQualityLog
from mmrl.rollout import FullPath
from mmrl.tasks.plane import PlaneVectorEnv

from test_envs import ref_match


@pytest.fixture(scope="module")
def db():
    return mmrl.default_database()


def _last_step_transitions(env):
    t, c = np.zeros(env.num_envs, np.uint8), np.zeros(env.num_envs, np.float32)
    env._core.last_step_transitions(t, c)
    return t, c


@pytest.mark.parametrize("task_name, stage", [("plane", None), ("obstacles", 10)])
def test_fast_path_flag_and_cost_equal_the_full_path_controller(db, task_name, stage):
    task = mmrl.get_task(task_name)
    run = FullPath(task, db, stage=stage, seed=4, config=task.config_type(max_steps=12), record=False)
    run.env.pop_match_stats()
    rng = np.random.default_rng(1)
    valid = np.flatnonzero(db.valid_mask)
    transitions = ends = 0
    costs = []
    for t in range(120):
        noise = 0.3 if t % 2 else 2.0
        action = (db.normalized_features[rng.choice(valid), 15:] + rng.normal(0, noise, 12)).astype(np.float32)
        out = run.step(action)
        flag, cost = _last_step_transitions(run.env)
        assert bool(flag[0]) == out["res"].transition, f"step {t}"
        assert cost[0] == np.float32(out["res"].cost), f"step {t}"
        transitions += out["res"].transition
        costs.append(np.float32(out["res"].cost))
        ends += out["done"]
    assert 10 < transitions < 120 and ends >= 5  # both kinds of decision, through episode ends
    stats = run.env.pop_match_stats()
    assert stats["decisions"] == 120 and stats["transitions"] == transitions
    assert stats["cost_sum"] == pytest.approx(float(np.sum(np.array(costs, np.float64))), rel=1e-12)
    assert run.env.pop_match_stats() == {"decisions": 0, "transitions": 0, "cost_sum": 0.0, "frames": 0}


class RecordingPlaneEnv(PlaneVectorEnv):
    """The plane env, remembering each step's frames before the step, actions and frames played."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.log = []

    def step(self, actions):
        before = self.current_frames()
        out = super().step(actions)
        self.log.append((before, np.array(actions, np.float32), self.step_frames))
        return out


def test_training_csv_columns_equal_a_recomputation_from_the_env(db, tmp_path):
    n, num_steps, iterations = 4, 16, 3
    env = RecordingPlaneEnv(n, db=db, num_threads=1, max_steps=10)
    cfg = ppo.PPOConfig(total_steps=n * num_steps * iterations, num_steps=num_steps, num_minibatches=2,
                        update_epochs=1, progress=False, tensorboard=False, seed=5)
    ppo.train(env, cfg, tmp_path / "run", callbacks=[MatchQualityLog(env)])
    with open(tmp_path / "run" / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == iterations and len(env.log) == num_steps * iterations
    low, high = env.single_action_space.low.astype(np.float64), env.single_action_space.high.astype(np.float64)
    for k, row in enumerate(rows):
        transitions, cost, frames = 0, 0.0, 0
        for before, actions, played in env.log[k * num_steps:(k + 1) * num_steps]:
            for i in range(n):
                j, costs = ref_match(db, int(before[i]), np.clip(actions[i].astype(np.float64), low, high))
                transitions += j != before[i]
                cost += costs[j]
                frames += int(played[i])
        assert float(row["transitions_per_s"]) == pytest.approx(transitions * db.fps / frames, rel=1e-9)
        assert float(row["matched_cost"]) == pytest.approx(cost / (n * num_steps), rel=1e-4)
        assert transitions > 0


def test_mmrl_train_logs_the_columns_to_csv_and_tensorboard(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from mmrl.cli import main

    out = tmp_path / "run"
    assert main(["train", "plane", "--steps", "2048", "--envs", "8", "--out", str(out), "--no-progress",
                 "--threads", "1"]) == 0
    with open(out / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        assert 0.0 < float(row["transitions_per_s"]) <= db_fps()  # a step plays at least one frame
        assert float(row["matched_cost"]) > 0.0
    events = EventAccumulator(str(out))
    events.Reload()
    assert {"charts/transitions_per_s", "charts/matched_cost"} <= set(events.Tags()["scalars"])


def db_fps():
    return float(mmrl.default_database().fps)


def test_the_callback_refuses_envs_without_decision_statistics():
    from _toyenv import PointMassTargetVecEnv

    with pytest.raises(TypeError, match="envs"):
        MatchQualityLog(PointMassTargetVecEnv(2))
