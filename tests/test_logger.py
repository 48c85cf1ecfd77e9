"""mmrl.logs: the progress bar counts what bounds the run; TensorBoard is optional."""
from __future__ import annotations

import io
import sys
import warnings
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from _toyenv import PointMassTargetVecEnv  # noqa: E402

from mmrl import logs as logger  # noqa: E402
from mmrl.logs import ProgressBar, progress_settings  # noqa: E402
from mmrl.rl.ppo import PPOConfig, train  # noqa: E402

ROW = {"sps": 300.0, "episode_return": 12.3, "success_rate": 0.25}


def test_time_budget_bar_counts_seconds_of_the_budget():
    # `mmrl train --seconds 30` sets total_steps to a placeholder 10**12
    settings = progress_settings(10**12, 30.0)
    assert (settings["total"], settings["unit"], settings["initial"]) == (30.0, "s", 0.0)
    assert progress_settings(10**12, 30.0, global_step=5000, wall_s=12.5)["initial"] == 12.5  # resumed
    assert progress_settings(10**12, 30.0, wall_s=31.0)["initial"] == 30.0


def test_step_budget_bar_counts_steps():
    settings = progress_settings(5000, None, global_step=1000, wall_s=3.0)
    assert (settings["total"], settings["unit"], settings["initial"]) == (5000, "step", 1000)
    assert progress_settings(5000, None, global_step=6000)["initial"] == 5000


def render(bar_args: tuple, step: int, wall_s: float) -> str:
    out = io.StringIO()
    bar = ProgressBar(*bar_args, file=out)
    bar.update(step, wall_s, ROW)
    bar.close()
    return out.getvalue().rsplit("\r", 1)[-1]


def test_rendered_bars_show_budget_seconds_or_steps():
    line = render((10**12, 30.0, 0, 0.0), step=2048, wall_s=7.4)
    assert "7/30 s" in line and "step=2,048" in line and "1000000000000" not in line
    line = render((4096, None, 0, 0.0), step=2048, wall_s=7.4)
    assert "2048/4096" in line and " s [" not in line


def test_training_without_tensorboard_logs_csv_and_warns_once(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # as if not installed
    monkeypatch.setattr(logger, "_warned_no_tensorboard", False)
    cfg = PPOConfig(total_steps=256, num_steps=32, progress=False, tensorboard=True)
    with pytest.warns(UserWarning, match="tensorboard package is not importable"):
        train(PointMassTargetVecEnv(4), cfg, tmp_path / "a")
    assert len((tmp_path / "a" / "metrics.csv").read_text().splitlines()) == 3  # header + 2 iterations
    assert not list((tmp_path / "a").glob("events.out.tfevents.*"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        train(PointMassTargetVecEnv(4), cfg, tmp_path / "b")
    assert [w for w in caught if "tensorboard" in str(w.message)] == []
