"""Checkpoints: loading never imports or calls what a file names, old checkpoints still load,
users register their own networks, and Ctrl-C saves the state of the last completed iteration."""
from __future__ import annotations

import importlib
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _toyenv import PointMassTargetVecEnv, read_rows  # noqa: E402
from _toyenv import quiet_config as _quiet_config  # noqa: E402

from mmrl.rl import networks  # noqa: E402
from mmrl.rl.checkpoints import CheckpointError, load_checkpoint, save_checkpoint  # noqa: E402
from mmrl.rl.networks import ObstacleActorCritic, PlaneActorCritic, network_class, register_network  # noqa: E402
from mmrl.rl.ppo import PPOConfig, load_policy, train  # noqa: E402

VARYING = ("wall_s", "sps", "env_us", "act_us", "update_us")  # wall time and speed


def quiet_config(**overrides) -> PPOConfig:
    return _quiet_config(**{"total_steps": 1024, **overrides})


def deterministic(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in VARYING} for row in rows]


@pytest.fixture
def registry(monkeypatch):
    """A copy of the network registry, so a test's registrations do not leak."""
    monkeypatch.setattr(networks, "_NETWORKS", dict(networks._NETWORKS))


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("trained")
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=256), out)
    return out / "latest.pt"


# ----------------------------------------------------------------------------- loading never executes code

@pytest.mark.parametrize("model_class", ["os:system", "subprocess:run", "collections:OrderedDict", "EchoNet",
                                         "mmrl.rl.networks:_ObstacleTower", "mmrl.rl.networks:PlaneActorCritic.x"])
def test_checkpoint_naming_an_unregistered_class_is_refused_without_importing_or_calling(
        tmp_path, trained, monkeypatch, model_class):
    state = load_checkpoint(trained)
    marker = tmp_path / "executed"
    state.update(model_class=model_class, model_kwargs={"command": f"touch {marker}"})
    path = save_checkpoint(state, tmp_path / "evil.pt")

    calls = []
    monkeypatch.setattr(importlib, "import_module", lambda *a, **k: calls.append(("import", a)))
    monkeypatch.setattr(os, "system", lambda *a, **k: calls.append(("system", a)))
    with pytest.raises(CheckpointError, match=r"evil\.pt.*not registered.*ObstacleActorCritic, PlaneActorCritic"):
        load_policy(path)
    assert calls == [] and not marker.exists()


def test_old_checkpoints_naming_module_and_class_still_load(tmp_path, trained):
    state = load_checkpoint(trained)
    assert state["model_class"] == "PlaneActorCritic"
    state["model_class"] = "mmrl.rl.networks:PlaneActorCritic"  # what checkpoints stored before the registry
    old = save_checkpoint(state, tmp_path / "old.pt")
    obs = np.random.default_rng(0).standard_normal((5, 4)).astype(np.float32)
    np.testing.assert_array_equal(load_policy(old).act(obs), load_policy(trained).act(obs))
    assert network_class("mmrl.rl.networks:ObstacleActorCritic") is ObstacleActorCritic


class UserNet(torch.nn.Module):
    """A user's own actor-critic, outside mmrl."""

    def __init__(self, obs_dim, act_dim, hidden=8):
        super().__init__()
        self.init_kwargs = dict(obs_dim=obs_dim, act_dim=act_dim, hidden=hidden)
        self.actor = torch.nn.Sequential(torch.nn.Linear(obs_dim, hidden), torch.nn.Tanh(),
                                         torch.nn.Linear(hidden, act_dim))
        self.critic = torch.nn.Linear(obs_dim, 1)
        self.log_std = torch.nn.Parameter(torch.zeros(act_dim))

    def actor_mean(self, obs):
        return self.actor(obs)

    def value(self, obs):
        return self.critic(obs).squeeze(-1)


def test_users_register_their_own_networks(tmp_path, registry):
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=256), tmp_path / "a", policy_factory=UserNet)
    assert load_checkpoint(tmp_path / "a" / "latest.pt")["model_class"] == f"{__name__}:UserNet"
    with pytest.raises(CheckpointError, match="'test_checkpoints:UserNet' is not registered.*register_network"):
        load_policy(tmp_path / "a" / "latest.pt")

    assert register_network(UserNet) is UserNet
    assert load_policy(tmp_path / "a" / "latest.pt").act(np.zeros(4, np.float32)).shape == (2,)  # old name maps
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=256), tmp_path / "b", policy_factory=UserNet)
    assert load_checkpoint(tmp_path / "b" / "latest.pt")["model_class"] == "UserNet"
    assert isinstance(load_policy(tmp_path / "b" / "latest.pt").model, UserNet)


def test_register_network_refuses_bad_classes_and_name_clashes(registry):
    with pytest.raises(TypeError, match="nn.Module"):
        register_network(dict)
    with pytest.raises(TypeError, match="lacks actor_mean, value"):
        register_network(torch.nn.Linear)
    with pytest.raises(ValueError, match="invalid name"):
        register_network(UserNet, name="a:b")
    with pytest.raises(ValueError, match="already registered for mmrl.rl.networks:PlaneActorCritic"):
        register_network(UserNet, name="PlaneActorCritic")
    register_network(PlaneActorCritic)  # the same class again is fine
    assert network_class("PlaneActorCritic") is PlaneActorCritic


# ----------------------------------------------------------------------------- Ctrl-C

class InterruptAtStep(PointMassTargetVecEnv):
    """Raises KeyboardInterrupt from its ``step_call``-th step, as Ctrl-C in the env would."""

    def __init__(self, num_envs, step_call):
        super().__init__(num_envs)
        self.calls, self.step_call = 0, step_call

    def step(self, actions):
        self.calls += 1
        if self.calls == self.step_call:
            raise KeyboardInterrupt
        return super().step(actions)


class StageCounter:
    def __init__(self):
        self.stage = 1

    def on_iteration(self, stats):
        self.stage += 1
        return {"stage": self.stage}

    def state_dict(self):
        return {"stage": self.stage}

    def load_state_dict(self, state):
        self.stage = state["stage"]


def test_ctrl_c_mid_rollout_saves_the_last_completed_iteration_and_resumes_like_a_clean_stop(tmp_path):
    # 8 envs x 32 steps = 256 env steps per iteration; Ctrl-C at step 10 of iteration 4.
    cfg = quiet_config(total_steps=1536)
    with pytest.raises(KeyboardInterrupt):
        train(InterruptAtStep(8, step_call=3 * 32 + 10), cfg, tmp_path / "interrupted", callbacks=[StageCounter()])
    state = load_checkpoint(tmp_path / "interrupted" / "latest.pt")
    rows = read_rows(tmp_path / "interrupted" / "metrics.csv")
    assert (state["global_step"], state["iteration"], state["callbacks"][0]) == (768, 3, {"stage": 4})
    assert [int(r["step"]) for r in rows] == [256, 512, 768]
    assert round(state["wall_s"], 4) == float(rows[-1]["wall_s"])
    assert state["obs_normalizer"]["rms"]["count"] == pytest.approx(1e-4 + 768)  # 3 rollouts of observations
    assert state["return_rms"]["count"] == pytest.approx(1e-4 + 768)

    # The same run stopped cleanly at step 768 holds the same state, RNG included...
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=768), tmp_path / "clean", callbacks=[StageCounter()])
    clean = load_checkpoint(tmp_path / "clean" / "latest.pt")
    for key in ("torch", "ppo_generator"):
        assert torch.equal(state["rng"][key], clean["rng"][key])
    assert state["rng"]["python"] == clean["rng"]["python"]
    for name, tensor in clean["model"].items():
        assert torch.equal(state["model"][name], tensor)

    # ...so resuming either gives the same later metrics and weights. (Not those of a run
    # never stopped: a resume resets the envs, whose state is not checkpointed.)
    for run in ("interrupted", "clean"):
        train(PointMassTargetVecEnv(8), cfg, tmp_path / run, resume=True, callbacks=[StageCounter()])
    interrupted_rows = deterministic(read_rows(tmp_path / "interrupted" / "metrics.csv"))
    assert [int(r["step"]) for r in interrupted_rows] == list(range(256, 1537, 256))
    assert interrupted_rows == deterministic(read_rows(tmp_path / "clean" / "metrics.csv"))
    final = [load_checkpoint(tmp_path / run / "latest.pt")["model"] for run in ("interrupted", "clean")]
    assert all(torch.equal(final[0][name], final[1][name]) for name in final[1])


class CtrlCAfterIteration(StageCounter):
    """Sends SIGINT to this process while the trainer handles iteration ``at``'s results."""

    def __init__(self, at):
        super().__init__()
        self.at, self.iterations = at, 0

    def on_iteration(self, stats):
        self.iterations += 1
        if self.iterations == self.at:
            os.kill(os.getpid(), signal.SIGINT)
        return super().on_iteration(stats)


def test_ctrl_c_during_the_update_finishes_the_iteration_first(tmp_path):
    # Python's default handler, what a terminal run has (a background job or nohup ignores SIGINT).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        callback = CtrlCAfterIteration(at=2)
        with pytest.raises(KeyboardInterrupt):
            train(PointMassTargetVecEnv(8), quiet_config(), tmp_path, callbacks=[callback])
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored
    finally:
        signal.signal(signal.SIGINT, previous)
    state = load_checkpoint(tmp_path / "latest.pt")
    rows = read_rows(tmp_path / "metrics.csv")
    assert callback.stage == 3 and state["callbacks"][0] == {"stage": 3}
    assert (state["global_step"], state["iteration"]) == (512, 2)
    assert [int(r["step"]) for r in rows] == [256, 512] and rows[-1]["stage"] == "3"
