"""The paper's obstacle curriculum (section 5) as a PPO trainer callback.

Works with any vector env that has ``set_stage(*stage_params, label=k)`` and
``pop_finished_episodes()`` (``mmrl.tasks.obstacles.ObstaclesVectorEnv``).
"""
from __future__ import annotations

from collections import deque
from typing import Optional

import numpy as np


def stage_params(stage: int, num_stages: int = 10) -> tuple:
    """(obstacle max speed m/s, target half-extent m) of curriculum stage 1..num_stages."""
    return Curriculum(None, num_stages=num_stages).stage_params(stage)


class Curriculum:
    """The paper's obstacle curriculum, as a PPO trainer callback.

    Stage k (1..num_stages) has obstacle max speed and target square half-extent linearly
    interpolated from ``first`` (stage 1: static obstacles, targets in a 5 x 5 m square) to
    ``last`` (stage 10: 0.5 m/s, 10 x 10 m). The stage is applied to the envs at once and each
    env picks it up at its next reset.

    Advancing: after each PPO iteration (``on_iteration``), if at least ``window`` episodes
    that *ran at the current stage* have finished, and the success ratio of the last
    ``window`` of them (across all envs) exceeds ``threshold`` (40%), the next stage starts
    and the window is cleared. Episodes still running with the previous stage are ignored.
    At most one advance per iteration. ``enabled=False`` (``--no-curriculum``) starts and
    stays at the last stage.

    Completion: the last stage is *passed* (``complete``, and every stage with it) the first
    time its window is full and exceeds the threshold; ``complete_step`` is the env step of
    that iteration when the trainer's stats give it. Training goes on at the last stage.

    ``on_iteration(stats)`` returns ``{"curriculum_stage": k, "curriculum_complete": 0 or 1}``:
    the stage after this iteration's update (the one the next iteration trains on).
    """

    def __init__(self, envs=None, *, num_stages: int = 10, first=(0.0, 2.5), last=(0.5, 5.0),
                 threshold: float = 0.4, window: int = 200, enabled: bool = True):
        if num_stages < 1:
            raise ValueError(f"num_stages must be >= 1, got {num_stages}")
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        if not 0.0 <= threshold < 1.0:
            raise ValueError(f"threshold must be in [0, 1), got {threshold}")
        self.num_stages = int(num_stages)
        self.first = (float(first[0]), float(first[1]))
        self.last = (float(last[0]), float(last[1]))
        self.threshold = float(threshold)
        self.window = int(window)
        self.enabled = bool(enabled)
        self.envs = getattr(envs, "unwrapped", envs)
        self.stage = 1 if self.enabled else self.num_stages
        self.complete = False
        self.complete_step: Optional[int] = None
        self._recent: deque = deque(maxlen=self.window)
        self._apply()

    def stage_params(self, stage: int) -> tuple:
        """(max_speed m/s, target_half_extent m) of stage 1..num_stages."""
        if not 1 <= stage <= self.num_stages:
            raise ValueError(f"stage must be in 1..{self.num_stages}, got {stage}")
        t = 0.0 if self.num_stages == 1 else (stage - 1) / (self.num_stages - 1)
        return (self.first[0] + t * (self.last[0] - self.first[0]),
                self.first[1] + t * (self.last[1] - self.first[1]))

    def _apply(self) -> None:
        if self.envs is not None:
            self.envs.set_stage(*self.stage_params(self.stage), label=self.stage)

    @property
    def success_ratio(self) -> float:
        """Success ratio of the current window (NaN when empty)."""
        return float(np.mean(self._recent)) if self._recent else float("nan")

    def record(self, success, stages=None) -> None:
        """Add finished episodes (successes, and the stage each ran with if known)."""
        success = np.asarray(success, bool).reshape(-1)
        if stages is not None:
            success = success[np.asarray(stages).reshape(-1) == self.stage]
        self._recent.extend(success.tolist())

    def advance_if_ready(self) -> bool:
        """Go to the next stage if the window is full and its success ratio exceeds the
        threshold (at the last stage: mark the curriculum complete and stay)."""
        if len(self._recent) < self.window or not self.success_ratio > self.threshold:
            return False
        if self.stage >= self.num_stages:
            self.complete = True
            return False
        if not self.enabled:
            return False
        self.stage += 1
        self._recent.clear()
        self._apply()
        return True

    def on_iteration(self, stats: Optional[dict] = None) -> dict:
        """Trainer hook: record the iteration's finished episodes, maybe advance, report the stage.

        With envs attached, episodes come from ``envs.pop_finished_episodes()`` (which knows the
        stage each ran with); otherwise from the trainer's ``stats["episode_data"]["success"]``.
        """
        if self.envs is not None and hasattr(self.envs, "pop_finished_episodes"):
            stages, success = self.envs.pop_finished_episodes()
            self.record(success, stages)
        elif stats is not None and isinstance(stats.get("episode_data"), dict):
            self.record(stats["episode_data"].get("success", ()))
        was_complete = self.complete
        self.advance_if_ready()
        if self.complete and not was_complete and stats is not None and "step" in stats:
            self.complete_step = int(stats["step"])
        return {"curriculum_stage": self.stage, "curriculum_complete": int(self.complete)}

    def describe(self) -> str:
        """One line for the end of ``mmrl train``."""
        if self.complete_step is not None:
            passed = f"all stages passed at step {self.complete_step:,}"
        else:
            passed = "all stages passed" if self.complete else "the last stage not passed yet"
        return f"curriculum: stage {self.stage} of {self.num_stages}; {passed}"

    def state_dict(self) -> dict:
        return {"stage": self.stage, "recent": list(self._recent), "enabled": self.enabled,
                "complete": self.complete, "complete_step": self.complete_step}

    def load_state_dict(self, state: dict) -> None:
        stage = int(state["stage"])
        if not 1 <= stage <= self.num_stages:
            raise ValueError(f"curriculum state: stage {stage} outside 1..{self.num_stages}")
        self.stage = stage
        self.enabled = bool(state.get("enabled", self.enabled))
        self.complete = bool(state.get("complete", False))
        self.complete_step = state.get("complete_step")
        self._recent = deque((bool(s) for s in state.get("recent", ())), maxlen=self.window)
        if self.envs is not None and hasattr(self.envs, "pop_finished_episodes"):
            self.envs.pop_finished_episodes()  # episodes of the old stage setting
        self._apply()
