"""kill -9 and resume (issue 18, item 4): ``mmrl train``, ``mmrl db build`` and ``mmrl data
fetch`` are killed with SIGKILL at seeded random moments inside chosen phases, then run again.

Nothing on disk may be torn: every checkpoint file present loads, ``latest.pt`` never goes
back, every snapshot it lists exists, ``metrics.csv`` holds one row per iteration up to the
checkpoint (rows after it are dropped on resume) and, at the end, exactly one row per iteration;
the step count, the iteration and the curriculum stage continue from the checkpoint; an npz or a
downloaded file is the old one, the new one or absent, never partial.

The children are forked from a server that imported torch once (tests/_kill_child.py, ~0.1 s
per run instead of ~5 s); it marks each phase (startup, rollout, update, log, checkpoint, save,
download) and slows file writes and env steps so that a kill lands inside the phase aimed at.
The phase each kill actually landed in is read from the markers and counted. ``MMRL_KILLS``
multiplies the number of kills (the CI default 1: 24 plane + 6 obstacles + 6 db build + 6
fetch kills; bench/README.md has the long variant).
"""
import hashlib
import os
import random
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from killing import ForkServer, Saved, check_finished_run, check_run_dir, visible

SCALE = max(1, int(os.environ.get("MMRL_KILLS", "1")))
BATCH = 8 * 16  # --envs 8, num_steps=16
# Typical phase lengths with the slowdowns below (measured: rollout ~40 ms with 2 ms per env
# step, update ~60 ms, checkpoint ~100 ms with 0.3 ms per write, a CSV row ~1 ms): each kill
# comes at a uniform moment within most of the phase.
PHASE_DELAY_S = {"startup": 0.3, "rollout": 0.03, "update": 0.05, "log": 0.001, "checkpoint": 0.09}
SLOW = {"slow_write_s": 0.0003, "slow_step_s": 0.002}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    server = ForkServer(tmp_path_factory.mktemp("kill"))
    yield server
    server.close()


def _kill_and_resume(server, run: Path, batch: int, fresh: list, resume: list, kills: int, phases: list, rng,
                     occurrences=(1, 3), **options):
    """Kill ``kills`` times, cycling through ``phases``; each time check the run directory.
    Returns the checkpoints the children died with and the phase each kill landed in."""
    saves, landed, previous = [], Counter(), Saved(0, 0, None)
    for k in range(kills):
        phase = phases[k % len(phases)]
        occurrence = 1 if phase == "startup" else rng.randint(*occurrences)
        argv = resume if (run / "config.json").exists() else fresh
        outcome = server.run(argv, kill_at=(phase, occurrence, rng.uniform(0, PHASE_DELAY_S[phase])), **SLOW,
                             **options)
        assert outcome.killed, f"kill {k}: the run finished before the kill (raise --steps)"
        landed[outcome.killed_in[-1] if outcome.killed_in else "between"] += 1
        previous = check_run_dir(run, batch, previous)
        saves.append(previous)
    return saves, landed


def test_train_plane_survives_sigkill_in_every_phase(server):
    rng = random.Random(18)
    run = server.workdir / "plane"
    total = BATCH * 64 * SCALE
    common = ["--steps", total, "--threads", 1, "--no-progress"]
    fresh = ["train", "plane", "--out", run, "--envs", 8, *common, "--set", "num_steps=16", "--set",
             "checkpoint_interval_steps=1", "--set", "snapshot_steps=512,1536,3072", "--set", "torch_threads=1"]
    resume = ["train", "plane", "--resume", run, *common]
    phases = ["rollout", "update", "checkpoint", "log", "checkpoint", "startup"]
    saves, landed = _kill_and_resume(server, run, BATCH, fresh, resume, 24 * SCALE, phases, rng)
    assert server.run(resume).code == 0
    check_finished_run(run, BATCH, total, saves, snapshot_steps=(512, 1536, 3072))
    print(f"plane: {sum(landed.values())} kills, by phase {dict(landed)}")
    for phase in ("rollout", "update", "checkpoint"):
        assert landed[phase] >= 3, f"too few kills landed in {phase}: {dict(landed)}"
    # Temp files of killed checkpoint writes are removed when the next run starts.
    assert not [p for p in run.iterdir() if p.name.endswith(".tmp") and p.name.startswith(".latest")]


def test_train_obstacles_keeps_its_curriculum_stage_across_kills(server):
    rng = random.Random(19)
    run = server.workdir / "obstacles"
    batch = 4 * 16
    total = batch * 40 * SCALE
    common = ["--steps", total, "--threads", 1, "--no-progress"]
    fresh = ["train", "obstacles", "--out", run, "--envs", 4, *common, "--set", "num_steps=16", "--set",
             "checkpoint_interval_steps=1", "--set", "torch_threads=1"]
    resume = ["train", "obstacles", "--resume", run, *common]
    saves, landed = _kill_and_resume(server, run, batch, fresh, resume, 6 * SCALE,
                                     ["update", "checkpoint", "rollout"], rng, occurrences=(3, 6),
                                     easy_curriculum=True)
    assert server.run(resume, easy_curriculum=True).code == 0
    rows = check_finished_run(run, batch, total, saves)
    stages = [s.stage for s in saves if s.stage is not None]
    print(f"obstacles: {sum(landed.values())} kills, by phase {dict(landed)}, stages at the kills {stages}, "
          f"final stage {rows[-1]['curriculum_stage']}")
    assert max(stages) >= 2, "the curriculum never advanced: the stage check tested nothing"


def test_db_build_npz_is_old_new_or_absent_after_sigkill(server):
    from mmrl.motion.database import Database
    from mmrl.motion.synth import write_dataset

    rng = random.Random(20)
    bvh = server.workdir / "bvh"
    write_dataset(bvh, num_clips=3, seconds_per_clip=2.0)
    out = server.workdir / "db" / "walk.npz"
    out.parent.mkdir()
    build = ["db", "build", bvh, "-o", out]
    landed = Counter()

    def kill(argv, phase):
        occurrence_delay = rng.uniform(0, 0.2 if phase == "save" else 0.3)
        outcome = server.run(argv, kill_at=(phase, 1, occurrence_delay), slow_write_s=0.01)
        assert outcome.killed
        landed[outcome.killed_in[-1] if outcome.killed_in else "between"] += 1

    for phase in ("save", "startup"):  # no file yet: none may appear
        kill(build, phase)
        assert visible(out.parent, "*") == []
    assert server.run(build).code == 0
    old = Database.load(out)
    for k in range(4 * SCALE):  # rebuilding with mirrored clips: the old file stays whole
        kill(build + ["--mirror"], "save" if k % 4 else "startup")
        assert Database.load(out).num_clips == old.num_clips
    assert server.run(build + ["--mirror"]).code == 0
    assert Database.load(out).num_clips == 2 * old.num_clips
    np.testing.assert_array_equal(Database.load(out).features[: old.num_frames], old.features)
    print(f"db build: {sum(landed.values())} kills, by phase {dict(landed)}")
    assert landed["save"] >= 3


def test_data_fetch_never_leaves_a_partial_file_after_sigkill(server):
    from conftest import require_shared_data
    from mmrl import data
    from mmrl.motion.database import find_bvh_files

    from test_data_fetch import serving_httpd

    rng = random.Random(21)
    manifest = data.dataset_manifest("bandai-namco-2")
    entries = {f["name"]: f for f in manifest["files"] if f["style"] == "youthful" and f["content"] == "run"}
    dest = server.workdir / "fetched"
    landed = Counter()
    with serving_httpd(require_shared_data()) as (_, url):
        fetch = ["data", "fetch", "bandai-namco-2", "--styles", "youthful", "--contents", "run", "--dest", dest,
                 "--base-url", url, "--url-template", data.STYLE_DIR_URL_TEMPLATE, "--no-progress"]
        while sum(landed.values()) < 6 * SCALE:
            outcome = server.run(fetch, kill_at=("download", rng.randint(1, 8), rng.uniform(0, 0.03)),
                                 slow_write_s=0.01)
            if not outcome.killed:  # all files were fetched before the kill (long variant): start again
                shutil.rmtree(dest)
                continue
            landed[outcome.killed_in[-1] if outcome.killed_in else "between"] += 1
            files = visible(dest / "youthful", "*") if (dest / "youthful").exists() else []
            for path in files:  # only whole, verified files under their final names
                entry = entries[path.name]
                assert hashlib.sha256(path.read_bytes()).hexdigest() == entry["sha256"], path
            if files:
                assert find_bvh_files(dest) == files  # hidden temp files are no clips
        assert server.run(fetch).code == 0
    files = visible(dest / "youthful", "*")
    assert [p.name for p in files] == sorted(entries)
    assert all(hashlib.sha256(p.read_bytes()).hexdigest() == entries[p.name]["sha256"] for p in files)
    assert "Bandai Namco" in (dest / "NOTICE.txt").read_text()
    print(f"data fetch: {sum(landed.values())} kills, by phase {dict(landed)}")
    assert landed["download"] >= 5 * SCALE
