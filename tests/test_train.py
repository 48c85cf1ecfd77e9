"""End-to-end training on the synthetic data through the command line, resume and plots."""
import csv
import json

import numpy as np
import pytest

import mmrl
from mmrl.cli import main
from mmrl.rollout import evaluate_fast


def evaluate_plane(policy, db, **kwargs):
    return evaluate_fast(mmrl.get_task("plane"), db, policy, **kwargs)


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "plane"
    # The paper's rule (--preset paper): the thresholds and the seed notes below were set with it.
    assert main(["train", "plane", "--steps", "120000", "--seed", "0", "--out", str(out), "--no-progress",
                 "--preset", "paper"]) == 0
    return out


def test_training_reaches_targets(trained_run, tmp_path):
    # A random policy succeeds in a few percent of episodes; trained, nearly all. Judged on the
    # median of three seeds: a deterministic policy can settle into a limit cycle short of the
    # target (seed 0 of the portable build: 48% deterministic, 100% sampled, while a -march=native
    # build of the same seed, whose floats round differently, reaches 100%), so one seed alone
    # tests the rounding as much as the training.
    results = [evaluate_plane(mmrl.load_policy(trained_run / "latest.pt"), mmrl.default_database(), episodes=300,
                              seed=99)]
    for seed in (1, 2):
        out = tmp_path / f"seed{seed}"
        assert main(["train", "plane", "--steps", "120000", "--seed", str(seed), "--out", str(out),
                     "--no-progress", "--preset", "paper"]) == 0
        results.append(evaluate_plane(mmrl.load_policy(out / "latest.pt"), mmrl.default_database(), episodes=300,
                                      seed=99))
    result = sorted(results, key=lambda r: r["success_rate"])[1]
    assert result["success_rate"] >= 0.9, results
    assert result["mean_time_to_target_s"] < 6.0, results


def test_run_directory_contents(trained_run):
    cfg = json.loads((trained_run / "config.json").read_text())
    assert cfg["task"] == "plane" and cfg["data"] == {"synthetic": mmrl.motion.synth.SYNTH_VERSION}
    with open(trained_run / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    for col in ("step", "wall_s", "episode_return", "episode_length", "success_rate"):
        assert col in rows[0]
    steps = [int(r["step"]) for r in rows]
    assert steps == sorted(steps) and steps[-1] >= 120000
    assert (trained_run / "snapshot_20000.pt").exists() and (trained_run / "snapshot_100000.pt").exists()
    assert list(trained_run.glob("events.out.tfevents.*")), "TensorBoard events missing"


def test_resume_continues(tmp_path):
    out = tmp_path / "r"
    assert main(["train", "plane", "--steps", "4096", "--out", str(out), "--no-progress"]) == 0
    # A second run into the same directory is refused with a clear error (exit code 2).
    assert main(["train", "plane", "--steps", "4096", "--out", str(out), "--no-progress"]) == 2
    assert main(["train", "plane", "--resume", str(out), "--steps", "8192", "--no-progress"]) == 0
    with open(out / "metrics.csv") as f:
        steps = [int(r["step"]) for r in csv.DictReader(f)]
    assert steps[-1] >= 8192 and steps == sorted(steps) and len(set(steps)) == len(steps)
    import torch

    state = torch.load(out / "latest.pt", weights_only=True)
    assert state["global_step"] >= 8192


def test_same_seed_same_result(tmp_path):
    def run(name, seed):
        out = tmp_path / name
        main(["train", "plane", "--steps", "8192", "--seed", str(seed), "--out", str(out), "--no-progress",
              "--threads", "2"])
        with open(out / "metrics.csv") as f:
            return [(r["step"], r["episode_return"], r["policy_loss"]) for r in csv.DictReader(f)]

    a = run("a", 3)
    assert a == run("b", 3)
    assert a != run("c", 4)


def test_plot(trained_run, tmp_path):
    assert main(["plot", str(trained_run), "-o", str(tmp_path)]) == 0
    import matplotlib.image as mpimg

    for name in ("learning.png", "trajectories.png"):
        img = mpimg.imread(tmp_path / name)
        assert img.shape[0] > 200 and img.shape[1] > 200
        assert np.std(img) > 0.01  # not blank


def test_bad_overrides(tmp_path, capsys):
    assert main(["train", "plane", "--steps", "10", "--out", str(tmp_path / "x"), "--set", "nope=1"]) == 2
    assert "unknown option 'nope'" in capsys.readouterr().err


def test_eval_trained_run_json(trained_run, capsys):
    assert main(["eval", str(trained_run), "--episodes", "5", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("success_rate", "mean_time_to_target_s", "foot_sliding_cm_per_s", "max_pose_jump_cm",
                "transitions_per_s"):
        assert key in out
    assert out["success_rate"] >= 0.6
