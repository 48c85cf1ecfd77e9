"""A compressed controller in the C++ runtime (issue 27): ``mmrl export RUN --compressed FILE``
writes the networks in place of the database; the runtime then equals Python's compressed full
path (same file, same targets) over 1,000 decisions, and refuses a broken file with the reason."""
import numpy as np
import pytest
import torch

import mmrl
from mmrl import _core
from mmrl.cli import main
from mmrl.compress import CompressConfig, train_compressed
from mmrl.compress.model import CompressedModel
from mmrl.export.runtime_export import read_controller
from mmrl.export.runtime_file import read_sections, write_sections
from mmrl.runs import RunDir
from runtime_helpers import drive_both


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("compressed-runtime")
    run = out / "plane"
    assert main(["train", "plane", "--steps", "65536", "--seed", "0", "--out", str(run), "--no-progress"]) == 0
    db = RunDir(run).database()
    cfg = CompressConfig(iterations=800, hidden=(64, 64), latent=8, stepper_iterations=400, projector_iterations=600,
                         stepper_hidden=(64, 64), projector_hidden=(64, 64), stepper_window=8)
    train_compressed(db, out / "c.pt", cfg, progress=False)
    assert main(["export", str(run), "--compressed", str(out / "c.pt"), "-o", str(out / "c.mmrl")]) == 0
    return run, out / "c.pt", out / "c.mmrl"


def test_the_runtime_equals_the_python_compressed_path_for_1000_decisions(exported):
    run, cpt, path = exported
    r = RunDir(run)
    db = r.database()
    controller = _core.RuntimeController.load(str(path))
    assert controller.compressed and controller.num_frames == 8 * 31  # the start windows only
    source = read_sections(path)["lmm.start_sources"]
    out = drive_both(path, r.task, db, r.task_config(), controller.act, 1000,
                     compressed=CompressedModel(cpt, db), start=(int(source[0]), 0))
    assert out["obs_error"] == 0.0
    assert out["root_error"] <= 1e-4 and out["pose_error"] <= 1e-4, out
    assert (out["rt_matches"] == -1).all() and (out["py_matches"] == -1).all()
    assert out["targets_reached"] >= 10  # not vacuous: the character walked


def test_a_broken_compressed_file_is_refused_with_the_reason(exported, tmp_path):
    run, cpt, path = exported
    sections = read_sections(path)

    def refused(change, match):
        s = dict(sections)
        change(s)
        bad = tmp_path / "bad.mmrl"
        write_sections(bad, s)
        with pytest.raises(ValueError, match=match):
            _core.RuntimeController.load(str(bad))

    def version(s):
        s["lmm.header"] = np.array([9, *s["lmm.header"][1:]], np.int32)

    refused(version, "bad.mmrl.*compressed sections of version 9")
    refused(lambda s: s.update({"lmm.stepper.0.weight": s["lmm.stepper.0.weight"][:, :3].copy()}),
            "bad.mmrl.*compressed networks do not fit")
    refused(lambda s: s.pop("lmm.frame_states"), "bad.mmrl.*lmm.frame_states")
    states = sections["lmm.frame_states"].copy()
    states[0, 0] = np.nan
    refused(lambda s: s.update({"lmm.frame_states": states}), "bad.mmrl.*not finite")


def test_the_commands_take_a_compressed_controller(exported, tmp_path, capsys):
    import json

    run, cpt, path = exported
    assert main(["eval", str(run), "--compressed", str(cpt), "--episodes", "3", "--line", "0", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["compressed"] == str(cpt) and res["episodes"] == 3 and 0.0 <= res["success_rate"] <= 1.0
    assert res["transitions_per_s"] >= 0 and res["pose_jump_p99_cm"] >= 0
    out = tmp_path / "c.bvh"
    assert main(["export-bvh", str(run), "--compressed", str(cpt), "--length", "2", "-o", str(out)]) == 0
    assert out.is_file() and "Frames: 6" in out.read_text()[:20000]
    capsys.readouterr()
    # Refused with the reason, naming the file: a request, a missing file, a corrupt one.
    assert main(["eval", str(run), "--compressed", str(cpt), "--request", "gait=walk"]) == 2
    assert "keeps to no tags" in capsys.readouterr().err
    assert main(["eval", str(run), "--compressed", str(tmp_path / "none.pt")]) == 2
    assert "none.pt" in capsys.readouterr().err
    bad = tmp_path / "bad.pt"
    bad.write_bytes(cpt.read_bytes()[:200])
    assert main(["eval", str(run), "--compressed", str(bad)]) == 2
    assert "bad.pt: corrupt" in capsys.readouterr().err


def test_the_file_holds_float16_weights_and_a_float32_one_plays_the_same(exported, tmp_path):
    """The exported weights are float16 (what the core runs); a file with float32 weight sections
    (as written before) loads to the same networks and plays the same frames; a float32 weight
    beyond float16's range is refused with the reason."""
    run, cpt, path = exported
    sections = read_sections(path)
    weights = [k for k in sections if k.startswith("lmm.") and k.endswith(".weight")]
    assert len(weights) >= 6 and all(sections[k].dtype == np.float16 for k in weights)
    wide = {k: (v.astype(np.float32) if k in weights else v) for k, v in sections.items()}
    p32 = tmp_path / "f32.mmrl"
    write_sections(p32, wide)
    assert p32.stat().st_size > path.stat().st_size
    chars = [_core.RuntimeCharacter(_core.RuntimeController.load(str(p)), 0.0, 0.0, 0.0, 0) for p in (path, p32)]
    for k in range(300):
        for ch in chars:
            if k % 60 == 0:
                ch.set_target(3.0 * np.cos(k), 3.0 * np.sin(k))
            ch.advance_frame()
        np.testing.assert_array_equal(chars[0].global_positions(), chars[1].global_positions())
    huge = dict(wide)
    w = huge[weights[0]].copy()
    w[0, 0] = 1e5
    huge[weights[0]] = w
    bad = tmp_path / "huge.mmrl"
    write_sections(bad, huge)
    with pytest.raises(ValueError, match="huge.mmrl.*beyond float16's range"):
        _core.RuntimeController.load(str(bad))


def test_the_loader_counts_the_networks_and_start_states_of_a_compressed_file(exported, tmp_path):
    """The same file without its lmm.* sections is a database controller over the start frames:
    it loads, is not compressed, and holds exactly the networks and the start states fewer bytes."""
    run, cpt, path = exported
    sections = read_sections(path)
    plain_path = tmp_path / "plain.mmrl"
    write_sections(plain_path, {k: v for k, v in sections.items() if not k.startswith("lmm.")})
    compressed, plain = (_core.RuntimeController.load(str(p)) for p in (path, plain_path))
    assert compressed.compressed and not plain.compressed
    states = sections["lmm.frame_states"]
    model = CompressedModel(cpt, RunDir(run).database())
    assert compressed.memory_bytes - plain.memory_bytes == model.memory_bytes + 4 * states.size
    ch = _core.RuntimeCharacter(plain, 0.0, 0.0, 0.0, 0)
    for _ in range(30):
        ch.advance_frame()  # the database controller plays its own frames
