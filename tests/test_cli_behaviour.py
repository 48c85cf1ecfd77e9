"""Command-line behaviour a new user hits: resumed runs record their changed options, bad
input is one line while bugs keep their traceback, and the core works without the viz extra."""
import json
import subprocess
import sys
import textwrap

import pytest

from mmrl.cli import main
from mmrl.runs import RunDir


def test_resume_with_set_rewrites_config_json(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "plane", "--steps", "1024", "--envs", "8", "--out", str(run), "--no-progress"]) == 0
    assert json.loads((run / "config.json").read_text())["task_config"]["max_steps"] == 100
    assert main(["train", "plane", "--resume", str(run), "--steps", "2048", "--no-progress",
                 "--set", "max_steps=150", "--set", "learning_rate=0.0005"]) == 0
    saved = json.loads((run / "config.json").read_text())
    assert saved["task_config"]["max_steps"] == 150 and saved["ppo"]["learning_rate"] == 0.0005
    assert saved["ppo"]["total_steps"] == 2048 and saved["num_envs"] == 8
    # eval and render read the run's options through RunDir: they see the change.
    assert RunDir(run).task_config().max_steps == 150
    # A resumed run keeps its options unless told otherwise: a second resume without --set keeps 150.
    assert main(["train", "plane", "--resume", str(run), "--steps", "3072", "--no-progress"]) == 0
    assert json.loads((run / "config.json").read_text())["task_config"]["max_steps"] == 150


def test_bad_input_is_one_line_and_bugs_keep_their_traceback(monkeypatch, capsys, tmp_path):
    assert main(["eval", str(tmp_path / "missing"), "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mmrl: error:") and err.count("\n") == 1 and "missing" in err

    def buggy(args):
        raise ValueError("an internal bug")

    import mmrl.commands.run as run_commands

    monkeypatch.setattr(run_commands, "cmd_eval", buggy)
    with pytest.raises(ValueError, match="an internal bug"):
        main(["eval", "--episodes", "1"])


def test_bad_task_options_are_input_errors(tmp_path, capsys):
    assert main(["train", "obstacles", "--steps", "64", "--out", str(tmp_path / "o"), "--set", "num_obstacles=-3"]) == 2
    assert "num_obstacles" in capsys.readouterr().err


BLOCK_VIZ = textwrap.dedent('''
    import importlib.abc, sys
    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in ("matplotlib", "imageio", "imageio_ffmpeg", "tensorboard"):
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    sys.meta_path.insert(0, Block())
''')


def _run_without_viz(code: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-W", "default", "-c", BLOCK_VIZ + textwrap.dedent(code)], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_core_trains_evaluates_and_exports_without_the_viz_extra(tmp_path):
    r = _run_without_viz('''
        import json, sys
        import mmrl
        from mmrl.cli import main
        assert not any(m.split(".")[0] in ("matplotlib", "imageio", "tensorboard") for m in sys.modules)
        assert main(["train", "plane", "--steps", "1024", "--envs", "8", "--out", "run", "--no-progress"]) == 0
        assert main(["eval", "run", "--episodes", "2", "--json"]) == 0
        assert main(["export-bvh", "run", "--length", "0.5", "-o", "out.bvh"]) == 0
        assert main(["render", "run", "--length", "0.5", "-o", "out.gif"]) == 2
    ''', tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "run" / "metrics.csv").is_file() and (tmp_path / "out.bvh").is_file()
    assert "pip install 'mmrl[viz]'" in r.stderr  # render says which extra it needs
    assert not list((tmp_path / "run").glob("events.out.tfevents*"))  # no TensorBoard without it
