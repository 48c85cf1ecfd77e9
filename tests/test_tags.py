"""Tags on clips and requests over them (issue 26; mmrl.motion.tags, cpp/include/mmrl/tags.hpp).

Tags from folders, file-name patterns and sidecar files against hand-written answers, on the
package's skeleton and on a second one (Mixamo names, other channel orders) with a sidecar;
the database and controller files keep them, mirrored clips included; requests keep every
decision of the env, the full path and the runtime inside the requested clips, and the runtime
decides as the full path does under a request; bad input names the file and line or lists the
tags available."""
import json
import subprocess
import sys

import numpy as np
import pytest

import mmrl
from mmrl import _core, synth
from mmrl.export.runtime_export import read_controller, write_controller
from mmrl.motion.tags import TagFileError, TagRules, clip_tags_for_files, compile_pattern
from mmrl.tasks.plane import PlaneConfig, PlaneVectorEnv
from runtime_helpers import drive_both
from test_import_axes_fps import other_skeleton, read_clip
from test_runtime import random_plane_policy


def tags_of(db):
    """{clip name without folder: sorted tags} of a database."""
    out = {}
    for c, name in enumerate(db.clip_names):
        key = name.replace("\\", "/").rsplit("/", 1)[-1]
        out.setdefault(key, []).append(sorted(t for t, on in zip(db.tag_names, db.clip_tags[c]) if on))
    return out


@pytest.fixture(scope="module")
def mixamo_dir(tmp_path_factory):
    """Four clips on the second skeleton in two folders, and a sidecar CSV naming them."""
    root = tmp_path_factory.mktemp("mixamo-tags")
    clips = [("old", "walk_a", 0.9, 0.2), ("old", "walk_b", 1.0, -0.4), ("young", "run_a", 3.0, 0.1),
             ("young", "walk_c", 1.3, 0.5)]
    for folder, name, speed, turn in clips:
        (root / folder).mkdir(exist_ok=True)
        tmp = root / f"{name}.synth.bvh"
        synth.write_clip(tmp, speed=speed, turn_rate=turn, seconds=5.0, seed=len(name))
        (root / folder / f"{name}.bvh").write_text(other_skeleton(read_clip(tmp.read_text())).text())
        tmp.unlink()
    (root / "tags.csv").write_text("file,tags\n# a comment\nold/walk_a.bvh,gait=walk mood=calm\nwalk_b,gait=walk\n"
                                   "run_a.bvh,gait=run;mood=eager\nyoung/walk_c.bvh,gait=walk\n")
    return root


def test_sidecar_folder_and_pattern_tags_on_a_second_skeleton(mixamo_dir, tmp_path):
    rules = TagRules(folder="style", patterns=("{gait2}_*",), sidecars=(mixamo_dir / "tags.csv",))
    db = mmrl.Database.from_bvh(mixamo_dir, tags=rules)
    assert db.joint_names[0].startswith("mixamorig")  # the second skeleton
    assert db.tag_names == ["gait=run", "gait=walk", "gait2=run", "gait2=walk", "mood=calm", "mood=eager",
                            "style=old", "style=young"]
    assert tags_of(db) == {
        "walk_a.bvh": [["gait2=walk", "gait=walk", "mood=calm", "style=old"]],
        "walk_b.bvh": [["gait2=walk", "gait=walk", "style=old"]],
        "run_a.bvh": [["gait2=run", "gait=run", "mood=eager", "style=young"]],
        "walk_c.bvh": [["gait2=walk", "gait=walk", "style=young"]],
    }
    # Saved and loaded; mirrored clips keep their originals' tags; the runtime file keeps them.
    db.save(tmp_path / "db.npz")
    back = mmrl.Database.load(tmp_path / "db.npz")
    assert back.tag_names == db.tag_names
    np.testing.assert_array_equal(back.clip_tags, db.clip_tags)
    mirrored = mmrl.Database.from_bvh(mixamo_dir, tags=rules, mirror=True)
    assert mirrored.num_clips == 2 * db.num_clips
    np.testing.assert_array_equal(mirrored.clip_tags[:db.num_clips], db.clip_tags)
    np.testing.assert_array_equal(mirrored.clip_tags[db.num_clips:], db.clip_tags)
    assert mirrored.clip_mirrored[db.num_clips:].all()
    write_controller(tmp_path / "c.mmrl", db, random_plane_policy(0), "plane", PlaneConfig())
    c = read_controller(tmp_path / "c.mmrl")
    assert c.db.tag_names == db.tag_names
    np.testing.assert_array_equal(c.db.clip_tags, db.clip_tags)


def test_the_known_datasets_are_tagged_automatically():
    db = mmrl.default_database()
    tags = tags_of(db)
    assert tags["synth_001_run.bvh"] == [["content=run", "gait=run"]]
    assert tags["synth_002_walk-turn-left.bvh"] == [["content=walk-turn-left", "gait=walk"]]
    assert tags["synth_008_stand.bvh"] == [["content=stand"]]
    names, m = clip_tags_for_files(["/x/normal/dataset-2_walk-turn-left_normal_007.bvh",
                                    "/x/elderly/dataset-2_run_elderly_012.bvh"])
    assert names == ["content=run", "content=walk-turn-left", "gait=run", "gait=walk", "style=elderly",
                     "style=normal"]
    np.testing.assert_array_equal(m, [[0, 1, 0, 1, 0, 1], [1, 0, 1, 0, 1, 0]])
    assert clip_tags_for_files(["/x/dataset-2_run_elderly_012.bvh"], rules=TagRules(auto=False)) == ([], pytest.approx(
        np.zeros((1, 0))))


def test_patterns():
    rx = compile_pattern("dataset-2_{gait:walk|run}*_{style}_*")
    assert rx.fullmatch("dataset-2_walk-turn-left_elderly_003").groupdict() == {"gait": "walk", "style": "elderly"}
    assert rx.fullmatch("dataset-2_jump_elderly_003") is None
    for bad in ("no_groups", "{a}_{a}", "{a", "{a-b}_x", "{a:x y}"):
        with pytest.raises(ValueError, match="tag pattern"):
            compile_pattern(bad)


@pytest.mark.parametrize("text, fragment", [
    ("file,tags\nold/walk_a.bvh,gait=walk\nnope.bvh,gait=walk\n", "tags.csv:3: no clip 'nope.bvh'"),
    ("walk_a,gaitwalk\n", "tags.csv:1: tag: 'gaitwalk' is not group=value"),
    ("walk_a\n", "tags.csv:1: expected 'file,tags'"),
])
def test_bad_sidecars_name_file_and_line(mixamo_dir, tmp_path, text, fragment):
    sc = tmp_path / "tags.csv"
    sc.write_text(text)
    with pytest.raises(TagFileError) as e:
        mmrl.Database.from_bvh(mixamo_dir, tags=TagRules(sidecars=(sc,), auto=False))
    assert fragment in str(e.value)


def test_json_sidecars(mixamo_dir, tmp_path):
    sc = tmp_path / "tags.json"
    sc.write_text(json.dumps({"walk_a": ["gait=walk"], "run_a.bvh": "gait=run"}, indent=1))
    db = mmrl.Database.from_bvh(mixamo_dir, tags=TagRules(sidecars=(sc,), auto=False))
    assert tags_of(db)["run_a.bvh"] == [["gait=run"]] and tags_of(db)["walk_b.bvh"] == [[]]
    sc.write_text('{"walk_a": ["gait=walk"],\n "run_a": [1]}')
    with pytest.raises(TagFileError, match=r"tags.json:2: the tags of 'run_a'"):
        mmrl.Database.from_bvh(mixamo_dir, tags=TagRules(sidecars=(sc,), auto=False))
    sc.write_text('{"walk_a": ["gait=walk"],\n "run_a": [}')
    with pytest.raises(TagFileError, match=r"tags.json:2: not valid JSON"):
        mmrl.Database.from_bvh(mixamo_dir, tags=TagRules(sidecars=(sc,), auto=False))


def test_requests_keep_every_decision_inside_and_bad_ones_list_the_tags():
    db = mmrl.default_database()
    env = PlaneVectorEnv(4, db=db, config=PlaneConfig(transition_cost=1.0), num_threads=1)
    run_clips = np.flatnonzero(db.clip_tags[:, db.tag_names.index("gait=run")])
    env.set_request(0, "gait=run")
    env.set_request(1, " content = walk | walk-turn-left & gait=walk")
    assert env.request(1) == "content=walk|walk-turn-left & gait=walk"
    with pytest.raises(ValueError) as e:
        env.set_request(2, "style=elderly")
    assert "no tag group 'style'" in str(e.value) and "gait=run|walk" in str(e.value)
    with pytest.raises(ValueError, match="selects no frame"):
        env.set_request(2, "gait=run & content=walk")
    with pytest.raises(TypeError, match="request"):
        env.set_request(2, None)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    walk_clips = np.flatnonzero(db.clip_tags[:, db.tag_names.index("content=walk")] |
                                db.clip_tags[:, db.tag_names.index("content=walk-turn-left")])
    seen = {0: set(), 1: set(), 3: set()}
    for _ in range(300):
        env.step(rng.normal(0, 1.5, (4, 12)).astype(np.float32))
        frames = env.current_frames()
        for i in seen:
            seen[i].add(int(db.frame_clip[frames[i]]))
    assert seen[0] <= set(run_clips.tolist()) and len(seen[0]) > 2
    assert seen[1] <= set(walk_clips.tolist()) and len(seen[1]) > 2
    assert not seen[3] <= set(run_clips.tolist())  # unrestricted: it leaves the run clips


def test_runtime_under_a_request_decides_as_the_full_path(tmp_path):
    db = mmrl.default_database()
    config = PlaneConfig(transition_cost=1.0)
    path = tmp_path / "tagged.mmrl"
    write_controller(path, db, random_plane_policy(2), "plane", config)
    c = _core.RuntimeController.load(str(path))
    out = drive_both(path, mmrl.get_task("plane"), db, config, c.act, 400, request="gait=walk")
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5
    walk = db.clip_tags[:, db.tag_names.index("gait=walk")]
    assert walk[db.frame_clip[np.asarray(out["rt_matches"])]].all()
    ch = _core.RuntimeCharacter(c, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="gait=run|walk"):
        ch.set_request("gait=jog")
    ch.set_request("gait=run")
    assert ch.request == "gait=run"


def test_a_runtime_file_without_tags_refuses_a_request(tmp_path, mixamo_dir):
    db = mmrl.Database.from_bvh(mixamo_dir, tags=TagRules(auto=False))
    assert db.tag_names == []
    path = tmp_path / "plain.mmrl"
    write_controller(path, db, random_plane_policy(0), "plane", PlaneConfig())
    ch = _core.RuntimeCharacter(_core.RuntimeController.load(str(path)), 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="has no tags"):
        ch.set_request("gait=walk")


def test_db_build_and_info_print_the_tags(mixamo_dir, tmp_path):
    out = tmp_path / "t.npz"
    r = subprocess.run([sys.executable, "-m", "mmrl", "db", "build", str(mixamo_dir), "-o", str(out), "--tag-folder",
                        "style", "--tag-file", str(mixamo_dir / "tags.csv")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    info = subprocess.run([sys.executable, "-m", "mmrl", "db", "info", str(out)], capture_output=True, text=True)
    assert info.returncode == 0, info.stderr
    lines = {ln.split()[0]: ln for ln in info.stdout.splitlines() if ln.startswith("  ") and "=" in ln}
    frames = mmrl.Database.load(out)
    old = frames.clip_tags[:, frames.tag_names.index("style=old")]
    n_old = int(np.diff(frames.clip_ranges, axis=1)[old].sum())
    assert "2 clips" in lines["style=old"] and f"{n_old} frames" in lines["style=old"]
    bad = subprocess.run([sys.executable, "-m", "mmrl", "db", "build", str(mixamo_dir), "-o", str(out),
                          "--tag-pattern", "{a}_{a}"], capture_output=True, text=True)
    assert bad.returncode != 0 and "appears twice" in bad.stderr
