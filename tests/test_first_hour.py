"""A new user's first hour on the command line: every ordinary mistake ends in one line
(``... error: ...``), exit code 2 and no traceback; nothing silently does nonsense; every flag has
one meaning, help and its default; eval says what it ran and ends in a verdict; runs survive a
move; output folders are made. Each case runs the real ``mmrl`` entry point (``mmrl.cli.main``)."""
import json
import shutil

import numpy as np
import pytest

from mmrl import synth
from mmrl.cli import build_parser, main
from test_import_axes_fps import other_skeleton, read_clip


def run(capsys, *argv):
    """(exit code, stdout, stderr) of ``mmrl ARGV``; argparse's exits are caught too."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_error(capsys, argv, *needles):
    code, _, err = run(capsys, *argv)
    assert code == 2, err
    lines = [line for line in err.splitlines() if "warning:" not in line]
    assert len(lines) == 1 and "error:" in lines[0] and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Two clips in artists' folders (one name with a space), and the second skeleton's clip."""
    root = tmp_path_factory.mktemp("first-hour")
    (root / "data" / "Slow Walk").mkdir(parents=True)
    (root / "data" / "Run").mkdir()
    synth.write_clip(root / "data" / "Slow Walk" / "walk.bvh", speed=1.2, turn_rate=0.3, seconds=4.0, seed=1)
    synth.write_clip(root / "data" / "Run" / "run.bvh", speed=3.0, turn_rate=-0.2, seconds=4.0, seed=2)
    (root / "other").mkdir()
    synth.write_clip(root / "walk.synth.bvh", speed=1.2, seconds=4.0, seed=3)
    (root / "other" / "mixamo.bvh").write_text(other_skeleton(read_clip((root / "walk.synth.bvh").read_text())).text())
    synth.write_clip(root / "short.bvh", speed=1.0, seconds=1.0, seed=4)
    return root


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("first-hour-run") / "run"
    assert main(["train", "plane", "--steps", "1024", "--envs", "8", "--out", str(out), "--no-progress"]) == 0
    return out


# ---------------------------------------------------------------------- 1. data mistakes
@pytest.mark.parametrize("text, needle", [
    ("not_a_file.bvh,style=x\n", "tags.csv:1: no clip 'not_a_file.bvh'"),
    ("file,tags\nwalk\n", "tags.csv:2: expected 'file,tags'"),
    ("walk,fast\n", "tags.csv:1: tag: 'fast' is not group=value"),
])
def test_a_bad_tag_file_is_one_line_naming_file_and_line(data, tmp_path, capsys, text, needle):
    (tmp_path / "tags.csv").write_text(text)
    one_line_error(capsys, ["db", "build", data / "data", "-o", tmp_path / "db.npz", "--tag-file",
                            tmp_path / "tags.csv"], needle)
    assert not (tmp_path / "db.npz").exists()


def test_a_folder_name_with_spaces_becomes_a_tag(data, tmp_path, capsys):
    assert run(capsys, "db", "build", data / "data", "-o", tmp_path / "db.npz", "--tag-folder", "style")[0] == 0
    from mmrl import Database

    db = Database.load(tmp_path / "db.npz")
    assert {"style=Slow_Walk", "style=Run"} <= set(db.tag_names)
    one_line_error(capsys, ["db", "build", data / "data", "-o", tmp_path / "x.npz", "--tag-folder", "a b"],
                   "--tag-folder")


def test_two_skeletons_in_one_build_are_one_line(data, tmp_path, capsys):
    one_line_error(capsys, ["db", "build", data / "data", data / "other", "-o", tmp_path / "db.npz"],
                   "different skeleton", "mixamo.bvh")


# ---------------------------------------------------------------------- 2. --db given something else
def test_db_given_bvh_or_a_folder_says_what_it_is_and_what_to_do(data, capsys):
    bvh = data / "data" / "Run" / "run.bvh"
    one_line_error(capsys, ["train", "plane", "--db", bvh, "--steps", 64], "a BVH file, not a database",
                   f"--data {bvh}", "mmrl db build")
    one_line_error(capsys, ["eval", "--db", data / "data"], "a folder, not a database file", "--data",
                   "mmrl db build")


def test_db_info_reads_a_database_saved_under_another_extension(data, tmp_path, capsys):
    assert run(capsys, "db", "build", data / "data", "-o", tmp_path / "db.npz")[0] == 0
    shutil.copy(tmp_path / "db.npz", tmp_path / "db.data")
    code, out, _ = run(capsys, "db", "info", tmp_path / "db.data")
    assert code == 0 and "clips        2" in out
    assert "unit         centimeters (scale 0.01" in out  # the synthetic files are in centimeters


# ---------------------------------------------------------------------- 3. no silent nonsense
@pytest.mark.parametrize("argv, needle", [
    (["train", "plane", "--seconds", "-1"], "--seconds"),
    (["train", "plane", "--seconds", "0"], "--seconds"),
    (["train", "plane", "--steps", "-5"], "--steps"),
    (["train", "plane", "--steps", "2.5"], "not a whole number"),
    (["train", "plane", "--envs", "0"], "--envs"),
    (["train", "plane", "--steps", "64", "--set", "max_steps=1.5"], "--set max_steps=1.5: expected a whole number"),
    (["train", "plane", "--steps", "64", "--set", "learning_rate=nan"], "learning_rate"),
    (["train", "arrive", "--steps", "64", "--set", "success_radius=0.15,stand_radius=0.15"],
     "--set success_radius=0.15,stand_radius=0.15: expected a number"),
    (["train", "arrive", "--steps", "64", "--set", "success_radius=none"], "--set success_radius=none: expected a number"),
    (["train", "plane", "--steps", "64", "--set", "learning_rate=none"], "--set learning_rate=none: expected a number"),
    (["eval", "--episodes", "0"], "--episodes"),
    (["render", "--length", "-2", "-o", "x.gif"], "--length"),
    (["view", "x", "--port", "70000"], "--port"),
    (["db", "build", "x", "-o", "y.npz", "--scale", "0"], "--scale"),
    (["db", "build", "x", "-o", "y.npz", "--fps", "-30"], "--fps"),
    (["compress", "-o", "x.pt", "--iterations", "0"], "--iterations"),
    (["train", "plane", "--steps", "64", "--set", "device=cpu"], "--set device: use --device instead"),
    (["train", "plane", "--steps", "64", "--set", "gamma=2"], "--set gamma=2.0: expected a value above 0 up to 1"),
    (["train", "plane", "--steps", "64", "--set", "learning_rate=-1"], "learning_rate"),
    (["train", "plane", "--steps", "64", "--set", "log_interval=0"], "log_interval"),
    (["train", "plane", "--steps", "64", "--set", "hidden=0"], "layer widths >= 1"),
    (["train", "plane", "--seed", "-1"], "expected a seed from 0 to 4294967295"),
    (["train", "plane", "--envs", "1e30"], "--envs"),
    (["train", "plane", "--threads", "100000"], "--threads"),
    (["train", "plane", "--steps", "1e30"], "--steps"),
    (["train", "plane", "--db", "x.npz", "--mirror"], "--mirror applies to --data"),
    (["eval", "--episodes", "1e9"], "--episodes"),
    (["render", "--length", "1e9", "-o", "x.gif"], "--length"),
    (["db", "build", "x", "-o", "y.npz", "--fps", "0.5"], "--fps"),
    (["compress", "-o", "x.pt", "--stages", "foo"], "no stage 'foo'; the stages are decompressor, stepper"),
    (["train"], "name the task"),
    (["train", "plane", "--bogus"], "unrecognized arguments: --bogus"),
])
def test_values_are_checked_where_they_are_read(tmp_path, monkeypatch, capsys, argv, needle):
    monkeypatch.chdir(tmp_path)
    one_line_error(capsys, argv, needle)
    assert not (tmp_path / "runs").exists()  # nothing was written


def test_a_wrong_unit_warns_with_the_likely_scale(data, tmp_path, capsys):
    code, _, err = run(capsys, "db", "build", data / "data", "-o", tmp_path / "db.npz", "--scale", "100")
    assert code == 0
    warning = [line for line in err.splitlines() if "warning:" in line]
    assert len(warning) == 1 and "median speed" in warning[0] and "--scale 0.01" in warning[0]
    # The right unit warns about nothing.
    assert "warning" not in run(capsys, "db", "build", data / "data", "-o", tmp_path / "ok.npz")[2]


def test_a_tag_pattern_that_matches_nothing_and_data_too_short_are_errors(data, tmp_path, capsys):
    one_line_error(capsys, ["db", "build", data / "data", "-o", tmp_path / "db.npz", "--tag-pattern", "take_{n}_*"],
                   "matches none of the 2 files")
    one_line_error(capsys, ["db", "build", data / "short.bvh", "-o", tmp_path / "db.npz"],
                   "no clip is long enough to match", "longest of the 1 has 30")
    assert not (tmp_path / "db.npz").exists()


# ---------------------------------------------------------------------- 5. one meaning per flag
def _options():
    parser = build_parser()
    for name, sub in parser._subparsers._group_actions[0].choices.items():
        nested = [a for a in sub._actions if a.__class__.__name__ == "_SubParsersAction"]
        parsers = nested[0].choices.items() if nested else [(None, sub)]
        for sub_name, p in parsers:
            for a in p._actions:
                if a.option_strings and a.dest != "help":
                    yield " ".join(filter(None, [name, sub_name])), p, a


def test_every_option_has_help_and_shows_its_default():
    import argparse

    for command, parser, action in _options():
        if action.help == argparse.SUPPRESS:  # a deprecated alias
            continue
        assert action.help, f"mmrl {command} {action.option_strings[0]} has no help"
        shown = parser.formatter_class("x")._get_help_string(action)
        if action.default not in (None, False, [], "", argparse.SUPPRESS) and action.nargs != 0:
            assert "default" in shown, f"mmrl {command} {action.option_strings[0]} hides its default"


def test_each_flag_means_one_thing_across_commands():
    meanings = {}
    for command, _, action in _options():
        if action.help == "==SUPPRESS==":
            continue
        for flag in action.option_strings:
            meanings.setdefault(flag, set()).add(action.dest)
    assert meanings["--seconds"] == {"seconds"} and meanings["--length"] == {"length"}
    assert "--tags" not in meanings and "--env" not in meanings  # deprecated spellings only
    assert {dest for flag, dests in meanings.items() for dest in dests if flag == "--policy"} == {"policy"}
    policy_choices = {tuple(a.choices) for _, _, a in _options() if "--policy" in a.option_strings}
    assert policy_choices == {("trained", "joystick", "joystick-run")}


def test_old_spellings_still_work_with_one_line_of_warning(small_run, tmp_path, capsys):
    code, _, err = run(capsys, "export-bvh", small_run, "--seconds", "0.5", "--env", "plane", "-o", tmp_path / "a.bvh")
    assert code == 0 and (tmp_path / "a.bvh").is_file()
    assert err.count("warning: --seconds is deprecated") == 1 and err.count("warning: --env is deprecated") == 1
    assert "it is now --task" in err and "it is now --length" in err


def test_resume_needs_no_task_and_the_runs_wording_is_one(small_run, tmp_path, capsys):
    code, out, _ = run(capsys, "train", "--resume", small_run, "--steps", "2048", "--no-progress")
    assert code == 0 and "trained 2,048 steps" in out and "the step budget (--steps) is done" in out
    (tmp_path / "empty").mkdir()
    for argv in (["eval", tmp_path / "empty"], ["export", tmp_path / "nothing", "-o", tmp_path / "x.mmrl"],
                 ["train", "--resume", tmp_path / "empty"], ["view", tmp_path / "empty"]):
        one_line_error(capsys, argv, "not a training run (", "runs are made by mmrl train")


# ---------------------------------------------------------------------- 6. output a person reads
def test_eval_runs_only_what_it_prints_and_ends_in_a_verdict(small_run, monkeypatch, capsys):
    import mmrl.rollout as rollout

    calls = []
    real = rollout.evaluate_full_path

    def counted(task, db, policy, *, episodes, **kw):
        calls.append((type(policy).__name__, episodes))
        return real(task, db, policy, episodes=episodes, **kw)

    monkeypatch.setattr(rollout, "evaluate_full_path", counted)
    code, out, _ = run(capsys, "eval", small_run, "--episodes", "3")
    assert code == 0
    assert calls == [("TrainedPolicy", 3), ("JoystickPolicy", 3)] or [c[1] for c in calls] == [3, 3]
    assert "joystick at the same speed" in out and "first 3 of the same episodes" in out
    verdict = [line for line in out.splitlines() if line.startswith("verdict: ")]
    assert len(verdict) == 1 and "% of episodes" in verdict[0] and "raw mocap" in verdict[0]
    calls.clear()
    assert run(capsys, "eval", small_run, "--episodes", "3", "--no-peer")[0] == 0
    assert len(calls) == 1
    calls.clear()
    assert run(capsys, "eval", "--policy", "joystick", "--episodes", "2")[0] == 0
    assert len(calls) == 1  # a joystick is its own peer


def test_the_messages_people_read(data, tmp_path, capsys, monkeypatch):
    from mmrl.commands.db import fps_text

    assert fps_text(1 / 0.033333) == "30" and fps_text(29.97) == "29.97"
    code, out, _ = run(capsys, "db", "build", data / "data", "-o", tmp_path / "db.npz")
    assert code == 0 and "<mmrl.Database" not in out and out.startswith("built 2 clips")
    assert "unit         centimeters" in out
    # Ctrl+C during training says what was saved and how to continue.
    import mmrl.rl.ppo as ppo

    real, count = ppo.collect_rollout, []

    def interrupted(*a, **kw):
        count.append(1)
        if len(count) == 3:
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(ppo, "collect_rollout", interrupted)
    code, _, err = run(capsys, "train", "plane", "--steps", "100000", "--envs", "8", "--out", tmp_path / "r",
                       "--no-progress")
    assert code == 130 and (tmp_path / "r" / "latest.pt").is_file()
    assert f"continue with: mmrl train --resume {tmp_path / 'r'}" in err and "saved step 512" in err


# ---------------------------------------------------------------------- 7. paths
def test_outputs_make_their_folders_and_runs_survive_a_move(small_run, data, tmp_path, capsys):
    run_dir = tmp_path / "project" / "runs" / "mine"
    assert run(capsys, "db", "build", data / "data", "-o", tmp_path / "project" / "db.npz")[0] == 0
    assert run(capsys, "train", "plane", "--db", tmp_path / "project" / "db.npz", "--steps", "512", "--envs", "4",
               "--out", run_dir, "--no-progress")[0] == 0
    assert json.loads((run_dir / "config.json").read_text())["data"]["from_run"]["db"] == "../../db.npz"
    moved = tmp_path / "moved"
    shutil.move(tmp_path / "project", moved)
    assert run(capsys, "export", moved / "runs" / "mine", "-o", tmp_path / "new" / "deeper" / "c.mmrl")[0] == 0
    assert (tmp_path / "new" / "deeper" / "c.mmrl").is_file()
    (moved / "db.npz").unlink()
    one_line_error(capsys, ["eval", moved / "runs" / "mine", "--episodes", "1"], "db.npz is missing",
                   "pass it with --db FILE")
    assert run(capsys, "export-bvh", small_run, "--length", "0.5", "-o", tmp_path / "a" / "b" / "m.bvh")[0] == 0
    one_line_error(capsys, ["export-bvh", small_run, "-o", tmp_path / "m.txt"], "must end in .bvh")
    assert np.load(tmp_path / "a" / "b" / "m.npz")["positions"].ndim == 3


def test_outputs_of_the_wrong_kind_are_refused(small_run, data, tmp_path, capsys):
    one_line_error(capsys, ["export", small_run, "-o", tmp_path / "m.onnx"], "for a .onnx file use --onnx")
    one_line_error(capsys, ["export", small_run, "--onnx", tmp_path / "m.mmrl"], "for a .mmrl file use -o")
    one_line_error(capsys, ["export", small_run, "-o", tmp_path / "m.mmrl", "--starts", "3"],
                   "--starts applies with --compressed only")
    one_line_error(capsys, ["db", "build", data / "data", "-o", tmp_path / "x.bvh"], "name it .npz")
    assert not any(tmp_path.iterdir())
    # export-bvh writes positions beside the BVH: never over a database of that name.
    assert run(capsys, "db", "build", data / "data", "-o", tmp_path / "walk.npz")[0] == 0
    one_line_error(capsys, ["export-bvh", small_run, "--length", "0.4", "-o", tmp_path / "walk.bvh"],
                   "walk.npz exists and is not an earlier export-bvh output")
    from mmrl import Database

    assert Database.load(tmp_path / "walk.npz").num_clips == 2  # untouched
    assert run(capsys, "export-bvh", small_run, "--length", "0.4", "-o", tmp_path / "m.bvh")[0] == 0
    assert run(capsys, "export-bvh", small_run, "--length", "0.4", "-o", tmp_path / "m.bvh")[0] == 0  # its own: replaced


def test_a_database_given_as_data_and_a_corrupt_checkpoint_say_what_to_do(small_run, data, tmp_path, capsys):
    assert run(capsys, "db", "build", data / "data", "-o", tmp_path / "db.npz")[0] == 0
    one_line_error(capsys, ["eval", "--data", tmp_path / "db.npz"], "a database file, not BVH", "--db")
    broken = tmp_path / "broken"
    shutil.copytree(small_run, broken)
    (broken / "latest.pt").write_bytes(b"PK\x03\x04 not a checkpoint")
    one_line_error(capsys, ["eval", broken, "--episodes", "1"], "latest.pt", "train again")


def test_a_task_option_of_the_wrong_type_is_named():
    """A config built in Python (or read from a config.json) with a wrong type reaches the C++
    core as one error naming the option, not pybind11's list of signatures."""
    import mmrl

    config = mmrl.get_task("arrive").default_config().replace(success_radius=None)
    with pytest.raises(ValueError, match="option success_radius: expected a number, got None"):
        config.to_core()
