"""mmrl export --onnx: the policy as one ONNX graph (raw observation -> the env's action),
checked with onnxruntime against the torch policy (mmrl.load_policy(...).act)."""
import numpy as np
import pytest
import torch

import mmrl
from mmrl.cli import main
from mmrl.commands.export import sample_observations
from mmrl.export.onnx_export import check_onnx, export_onnx
from mmrl.rl.networks import ObstacleActorCritic
from mmrl.runs import RunDir
from mmrl.rl.trained_policy import ObsNormalizer, Policy

import onnxruntime as ort  # the onnx extra: CI installs it (.ci/run)


@pytest.fixture(scope="module")
def plane_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("onnx") / "plane"
    assert main(["train", "plane", "--steps", "8192", "--seed", "0", "--out", str(out), "--no-progress"]) == 0
    return out


def action_box(task, db, config):
    env = task.make_vector_env(1, db=db, config=config, num_threads=1)
    box = env.single_action_space.low, env.single_action_space.high
    env.close()
    return box


def test_plane_policy_onnx_matches_torch(plane_run, tmp_path, capsys):
    path = tmp_path / "policy.onnx"
    assert main(["export", str(plane_run), "--onnx", str(path)]) == 0
    assert "onnxruntime vs torch" in capsys.readouterr().out
    run = RunDir(plane_run)
    policy, db, task = mmrl.load_policy(plane_run / "latest.pt"), run.database(), run.task
    config = run.task_config(task)
    obs = sample_observations(task, db, config, policy, 1000, seed=3)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    action, clipped = session.run(["action", "clipped_action"], {"obs": obs})
    ref = policy.act(obs)
    low, high = action_box(task, db, config)
    assert action.shape == ref.shape == (1000, 12)
    # The env's action (clipped to its box) within 1e-5; the raw action within 1e-5 of its
    # magnitude (a barely trained policy writes raw actions of tens of units, where one float32
    # ulp is 2e-6).
    assert np.max(np.abs(clipped - np.clip(ref, low, high))) <= 1e-5
    assert np.max(np.abs(action - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-5
    # The check is not vacuous: the actions vary, and clipping bites on some of them.
    assert np.ptp(ref, axis=0).min() > 1e-3
    # The normalization is inside the graph: the same graph on pre-normalized input differs.
    wrong = session.run(["action"], {"obs": policy.obs_normalizer(torch.from_numpy(obs)).numpy()})[0]
    assert np.max(np.abs(wrong - ref)) > 1e-2


def test_obstacle_cnn_policy_onnx_matches_torch(tmp_path):
    torch.manual_seed(0)
    model = ObstacleActorCritic(12)
    with torch.no_grad():  # a last layer that is not near zero, so the check sees real outputs
        model.actor.head[-1].weight.normal_(0, 0.3)
    norm = ObsNormalizer(529, True, ObstacleActorCritic.map_range(), 10.0, torch.device("cpu"))
    rng = np.random.default_rng(0)
    norm.rms.mean = rng.normal(0, 1, 529)
    norm.rms.var = rng.uniform(0.5, 2, 529)
    norm.refresh()
    policy = Policy(model, norm, torch.device("cpu"), rng.normal(0, 0.1, 12).astype(np.float32),
                    rng.uniform(1, 3, 12).astype(np.float32))
    obs = np.concatenate([rng.integers(0, 2, (300, 512)), rng.normal(0, 1, (300, 17))], 1).astype(np.float32)
    path = tmp_path / "obstacles.onnx"
    low, high = -np.ones(12, np.float32), np.ones(12, np.float32)
    export_onnx(policy, path, low, high)
    error = check_onnx(path, policy, obs, low, high)
    assert error["action"] <= 1e-5 and error["clipped_action"] <= 1e-5, error
    assert np.ptp(policy.act(obs), axis=0).min() > 1e-2


def test_export_needs_an_output_and_a_run(tmp_path, capsys):
    assert main(["export", str(tmp_path)]) == 2
    assert "nothing to write" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "missing"), "--onnx", str(tmp_path / "p.onnx")]) == 2
    assert "no such run directory" in capsys.readouterr().err
