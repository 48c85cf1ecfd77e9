"""Motion quality while training: the fast path's transitions per second and matched cost.

:class:`MatchQualityLog` is a PPO trainer callback (``mmrl train`` adds it for every task).
Each PPO iteration it drains the running sums the vector env keeps of its decisions
(:meth:`mmrl.tasks.base.TargetVectorEnv.pop_match_stats`, read from the C++ envs after every
step) into two columns of ``metrics.csv`` (and TensorBoard ``charts/``):

- ``transitions_per_s``: decisions whose match was not the continuation of the clip being
  played, per second of played motion (frames played / fps, each step up to the frame that
  ended its episode), over every env of the iteration's rollout; the definition of
  :mod:`mmrl.metrics` on the fast path;
- ``matched_cost``: the mean squared distance of the decisions' queries to their matched
  frames (normalized, weighted feature space).

Both cost nothing beyond a few in-place numpy adds per step; the full-path evaluation
(``mmrl eval``) gives the pose metrics.
"""
from __future__ import annotations

from typing import Dict

from ..metrics import rate_per_second


class MatchQualityLog:
    """PPO trainer callback: ``on_iteration`` returns ``{"transitions_per_s", "matched_cost"}``
    for the env steps since the previous iteration (NaN for an iteration without steps)."""

    def __init__(self, envs):
        self.envs = getattr(envs, "unwrapped", envs)
        if not hasattr(self.envs, "pop_match_stats"):
            raise TypeError(f"envs: {type(self.envs).__name__} keeps no decision statistics "
                            "(expected an mmrl.tasks.base.TargetVectorEnv)")
        self.envs.pop_match_stats()  # count from the first training step

    def on_iteration(self, stats) -> Dict[str, float]:
        s = self.envs.pop_match_stats()
        if not s["decisions"]:
            return {"transitions_per_s": float("nan"), "matched_cost": float("nan")}
        return {"transitions_per_s": rate_per_second(s["transitions"], s["frames"], self.envs.db.fps),
                "matched_cost": s["cost_sum"] / s["decisions"]}
