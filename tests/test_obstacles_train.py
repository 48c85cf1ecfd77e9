"""A short obstacles training run through the command line leaves curriculum stage 1, logs
the stage, stores it in the checkpoint and restores it on resume."""
import csv

import torch

from mmrl.cli import main


def stages(run):
    with open(run / "metrics.csv") as f:
        return [int(r["curriculum_stage"]) for r in csv.DictReader(f)]


def test_short_training_run_leaves_stage_1(tmp_path):
    run = tmp_path / "obstacles"
    # The mechanism under test is training -> success statistics -> curriculum -> logs ->
    # checkpoint -> resume. The paper's scene needs ~300k steps to leave stage 1 (bench/), so
    # this run uses a nearly empty one (2 obstacles, episodes capped at 12 s, a 1 m success
    # radius) on the synthetic data, with the success bonus the benchmarks use.
    common = ["--envs", "64", "--no-progress", "--preset", "paper", "--set", "success_bonus=1000", "--set", "num_obstacles=2",
              "--set", "max_steps=60", "--set", "success_radius=1.0", "--set", "update_epochs=4",
              "--set", "learning_rate=0.002"]
    assert main(["train", "obstacles", "--steps", "60000", "--out", str(run), *common]) == 0
    s = stages(run)
    assert s[0] == 1, "the curriculum starts at stage 1"
    assert max(s) >= 2, f"never left stage 1: {s}"
    assert s == sorted(s), "stages never go back"
    state = torch.load(run / "latest.pt", weights_only=True)
    saved = [cb for cb in state["callbacks"].values() if "stage" in cb]
    assert saved and saved[0]["stage"] + 1 == s[-1] or saved[0]["stage"] == s[-1]
    assert main(["train", "obstacles", "--resume", str(run), "--steps", "62000", "--no-progress"]) == 0
    after = stages(run)
    assert after[len(s)] >= s[-1], "resume restored the stage"


def test_no_curriculum_starts_at_the_last_stage(tmp_path):
    run = tmp_path / "nocur"
    assert main(["train", "obstacles", "--steps", "2048", "--envs", "16", "--out", str(run), "--no-progress",
                 "--no-curriculum"]) == 0
    assert set(stages(run)) == {10}


def test_presets_set_their_options_and_set_overrides_them(tmp_path, capsys):
    import json

    from mmrl.tasks.obstacles import OBSTACLE_PRESETS

    def config(name, *extra):
        run = tmp_path / name
        assert main(["train", "obstacles", "--steps", "512", "--envs", "8", "--out", str(run), "--no-progress",
                     *extra]) == 0
        return json.loads((run / "config.json").read_text())

    paper = config("paper", "--preset", "paper")
    assert paper["task_config"]["success_bonus"] == 10.0 and not paper["task_config"]["hit_penalty"]
    ours = config("mmrl", "--preset", "mmrl", "--set", "hit_weight=3")
    default = config("default")  # a plain `mmrl train obstacles` trains with the preset that works
    for key, value in OBSTACLE_PRESETS["mmrl"].items():
        section = "ppo" if key in ours["ppo"] else "task_config"
        assert ours[section][key] == (3.0 if key == "hit_weight" else value), key
        assert default[section][key] == value, key
        assert paper[section][key] != value, key
    capsys.readouterr()
    assert main(["train", "plane", "--steps", "512", "--out", str(tmp_path / "p"), "--preset", "mmrl"]) == 2
    assert "--preset mmrl: the plane task has presets paper, quality, smooth (mmrl is a preset of the obstacles task)" in capsys.readouterr().err
    assert main(["train", "obstacles", "--steps", "512", "--out", str(tmp_path / "b"), "--set", "hit_penalty=maybe"]) == 2
    assert "expected true or false, got 'maybe'" in capsys.readouterr().err
