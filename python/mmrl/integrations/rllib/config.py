"""The settings of ``mmrl train --backend rllib`` and its presets.

``RLlibConfig`` is to RLlib what ``mmrl.rl.ppo.PPOConfig`` is to our trainer; ``mmrl train
--backend rllib --set KEY=VALUE`` sets its fields, and ``config.json`` records them under
``"rllib"``. The defaults follow our PPO's choices where RLlib has the same knob (GAE 0.95,
clip 0.2, 8 epochs, observation normalization, actions in the box's standardized units); the
``paper-rllib`` preset is RLlib's own PPO defaults, as the paper's authors trained.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple


@dataclass
class RLlibConfig:
    seed: int = 0
    """Seeds RLlib (``config.debugging(seed=...)``) and the envs."""
    total_steps: int = 1_000_000
    """Stop after this many env steps (summed over workers); or ``max_seconds``, whichever first."""
    max_seconds: Optional[float] = None
    """Wall-clock training budget (training time, summed over resumes); checked between iterations."""
    workers: int = 1
    """RLlib EnvRunners (0 = sample in the driver process)."""
    envs_per_worker: Optional[int] = None
    """Characters per EnvRunner, stepped together by one C++ vector env. None: 64 in all
    (our trainer's default), split over the workers."""
    rollout_fragment_length: int = 32
    """Steps per env per sample call; the train batch is workers x envs x this (at least 1 worker)."""
    lr: float = 2e-3
    anneal_lr: bool = False
    """Decay the learning rate linearly to 0 over total_steps (an RLlib lr schedule)."""
    gamma: float = 0.99
    lambda_: float = 0.95
    clip_param: float = 0.2
    num_minibatches: int = 4
    minibatch_size: Optional[int] = None
    """None: the train batch / num_minibatches."""
    num_epochs: int = 8
    vf_loss_coeff: float = 0.5
    vf_clip_param: Optional[float] = None
    """RLlib caps the squared value error at this; None: no cap (the +1000 bonus needs large values)."""
    entropy_coeff: float = 0.0
    use_kl_loss: bool = False
    kl_coeff: float = 0.2
    kl_target: float = 0.01
    grad_clip: Optional[float] = 0.5
    train_batch_size: Optional[int] = None
    """None: workers x envs_per_worker x rollout_fragment_length."""
    reward_scale: float = 0.01
    """Rewards are multiplied by this before RLlib sees them (RLlib has no return normalization;
    our trainer divides by a running return std). Logged returns are unscaled."""
    obs_filter: bool = True
    """Normalize observations with RLlib's MeanStdFilter (its statistics go into latest.pt)."""
    obs_filter_exclude: Optional[Tuple[int, int]] = None
    """Observation entries [a, b) the filter leaves as they are (the task's obs_norm_exclude:
    the obstacles' binary sensor maps)."""
    normalize_actions: bool = True
    """The policy acts in the action box's standardized units (RLlib's default; our rescale_actions)."""
    init_log_std: float = 0.0
    env_threads: int = 1
    """C++ threads per worker's vector env (the parallelism is across workers)."""
    torch_threads: int = 1
    """torch threads of the learner in the driver (0 keeps torch's setting); each worker uses 1."""
    checkpoint_interval_steps: int = 100_000
    snapshot_steps: Tuple[int, ...] = ()
    max_worker_restarts: int = 100
    """A worker that dies is restarted by RLlib up to this many times in a run."""
    device: str = "auto"
    """The learner's device: "auto" = CUDA if available, else CPU."""
    progress: bool = True
    tensorboard: bool = True

    def envs(self) -> int:
        """Characters per worker."""
        if self.envs_per_worker is not None:
            return int(self.envs_per_worker)
        return max(1, 64 // max(self.workers, 1))

    def batch_size(self) -> int:
        if self.train_batch_size is not None:
            return int(self.train_batch_size)
        return max(self.workers, 1) * self.envs() * self.rollout_fragment_length

    def minibatch(self) -> int:
        if self.minibatch_size is not None:
            return int(self.minibatch_size)
        return max(1, self.batch_size() // max(self.num_minibatches, 1))

    def check(self) -> None:
        if self.workers < 0 or self.envs() < 1 or self.rollout_fragment_length < 1:
            raise ValueError("rllib: workers must be >= 0, envs_per_worker and rollout_fragment_length >= 1")
        if self.minibatch() < 1 or self.num_epochs < 1 or self.batch_size() < self.minibatch():
            raise ValueError(f"rllib: need 1 <= minibatch size ({self.minibatch()}) <= train batch "
                             f"({self.batch_size()}) and num_epochs >= 1")
        if not self.reward_scale > 0:
            raise ValueError(f"rllib: reward_scale must be > 0, got {self.reward_scale}")
        self.snapshot_steps = tuple(int(s) for s in self.snapshot_steps)


#: ``--backend rllib --preset NAME``. ``paper-rllib``: RLlib's PPO defaults as the paper used
#: them (ray 2.5-2.10, the same in each: ../shared/reference/NOTES.md) on 11 workers with one
#: env each: lr 5e-5, lambda 1.0, clip 0.3, KL penalty 0.2 toward 0.01, batch 4000, minibatch
#: 128, 30 epochs, value loss 1.0 capped at 10, no observation filter, raw rewards. Two
#: differences, both so the result loads in ``mmrl eval``: the paper's 32 x 32 networks (as
#: the paper says) with a free log-std parameter instead of RLlib's log-std output.
RLLIB_PRESETS: Dict[str, Dict[str, Any]] = {
    "paper-rllib": {"workers": 11, "envs_per_worker": 1, "lr": 5e-5, "gamma": 0.99, "lambda_": 1.0,
                    "clip_param": 0.3, "use_kl_loss": True, "kl_coeff": 0.2, "kl_target": 0.01,
                    "train_batch_size": 4000, "rollout_fragment_length": 364, "minibatch_size": 128,
                    "num_epochs": 30, "vf_loss_coeff": 1.0, "vf_clip_param": 10.0, "entropy_coeff": 0.0,
                    "grad_clip": None, "reward_scale": 1.0, "obs_filter": False},
}
