"""A third task added as a plug-in, as docs/architecture.md describes: its own module (here,
the top of this file) plus one registration line. Training, evaluation, rendering and
gymnasium then work with it without a change anywhere else."""
import csv
import json
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

from mmrl import get_task, register_task
from mmrl.cli import main
from mmrl.tasks import SingleEnv, Task, TaskFlag, task_names, unregister_task
from mmrl.tasks.plane import PlaneConfig, PlaneVectorEnv


# ------------------------------------------------------------------ the toy task, in a few dozen lines
@dataclass
class ShortWalkConfig(PlaneConfig):
    task_label = "short-walk"
    target_half_extent: float = 1.5  # near targets
    max_steps: int = 15              # 3 s


class ShortWalkVectorEnv(PlaneVectorEnv):
    config_type = ShortWalkConfig

    def _task_infos(self, done):
        return {"timeout": self._truncated.astype(bool)}  # an outcome of its own


class ShortWalkEnv(SingleEnv):
    vector_type = ShortWalkVectorEnv


class IterationCounter:
    """A trainer callback with state that survives a resume."""

    def __init__(self):
        self.count = 0

    def on_iteration(self, stats):
        self.count += 1
        return {"toy_iterations": self.count}

    def state_dict(self):
        return {"count": self.count}

    def load_state_dict(self, state):
        self.count = state["count"]


SHORT_WALK = Task(
    name="short-walk", summary="reach a near target within 3 s", config_type=ShortWalkConfig,
    vector_env=ShortWalkVectorEnv, env=ShortWalkEnv, gym_id="mmrl/ShortWalk-v0",
    presets={"wide": {"success_radius": 0.8}},
    flags=(TaskFlag("--far", "target_half_extent", 4.0, "targets up to 4 m away"),),
    callbacks=lambda envs, options: [IterationCounter()], outcomes=("timeout",),
)


@pytest.fixture
def short_walk():
    register_task(SHORT_WALK)  # the one line that makes it known
    yield SHORT_WALK
    unregister_task("short-walk")


# ------------------------------------------------------------------ what works without further code
def test_gymnasium_makes_the_plugged_in_task(short_walk):
    envs = gym.make_vec("mmrl/ShortWalk-v0", num_envs=8)
    obs, _ = envs.reset(seed=0)
    truncations = 0
    for _ in range(40):
        obs, _, term, trunc, infos = envs.step(np.zeros((8, 12), np.float32))  # stand still: mostly timeouts
        if (term | trunc).any():
            ended = term | trunc
            np.testing.assert_array_equal(infos["timeout"][ended], (trunc & ~term)[ended])
            truncations += int(trunc.sum())
    assert truncations > 0
    envs.close()


def test_train_eval_render_through_the_cli(short_walk, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "short-walk", "--steps", "4096", "--out", str(run), "--no-progress", "--preset", "wide",
                 "--far"]) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["task"] == "short-walk"
    assert cfg["task_config"]["success_radius"] == 0.8 and cfg["task_config"]["target_half_extent"] == 4.0
    with open(run / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["toy_iterations"]) for r in rows] == list(range(1, len(rows) + 1))
    capsys.readouterr()

    assert main(["eval", str(run), "--episodes", "4", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["env"] == "short-walk" and res["episodes"] == 4
    # Every episode ends by success or by the timeout (truncation), never both.
    assert res["success_rate"] + res["timeout_rate"] == pytest.approx(1.0)
    assert main(["render", str(run), "--length", "0.4", "--size", "96x64", "-o", str(tmp_path / "a.gif")]) == 0
    assert (tmp_path / "a.gif").stat().st_size > 0


def test_flags_of_one_task_are_refused_by_another(short_walk, tmp_path, capsys):
    assert main(["train", "plane", "--steps", "64", "--out", str(tmp_path / "p"), "--far"]) == 2
    assert "--far applies to the short-walk task only" in capsys.readouterr().err
    assert get_task("short-walk") is SHORT_WALK


def test_a_default_preset_must_be_one_of_the_tasks_presets():
    import dataclasses

    bad = dataclasses.replace(SHORT_WALK, name="short-walk-bad", gym_id=None, default_preset="fast")
    with pytest.raises(ValueError, match="default_preset 'fast' of the short-walk-bad task is not one of its presets"):
        register_task(bad)
    assert "short-walk-bad" not in task_names()
