"""Training with Ray RLlib (mmrl.integrations.rllib, extra mmrl[rllib]).

One local Ray instance (2 CPUs) serves the module. In CI the extra is installed and these
tests must run; elsewhere they skip with one line when Ray is missing.
"""
import csv
import os
import pickle
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

import mmrl
from mmrl.cli import main
from mmrl.logs import MetricsLogger

if os.environ.get("CI"):
    import ray  # noqa: F401  (CI installs mmrl[rllib]: a missing Ray fails here)
else:
    pytest.importorskip("ray.rllib", reason="needs Ray RLlib: pip install 'mmrl[rllib]'")


def _shared_copy(db):
    """The arrays as a worker gets them from the object store: unpickled, read-only."""
    arrays = pickle.loads(pickle.dumps(db.shared_arrays(), protocol=5))
    for value in arrays.values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return arrays


def _other_skeleton_db(tmp_path):
    from test_import_axes_fps import other_skeleton_database

    return other_skeleton_database(tmp_path)


@pytest.mark.parametrize("which", ["synthetic", "mixamo"])
def test_a_database_from_shared_arrays_borrows_them_and_matches_the_same(which, tmp_path):
    db = mmrl.default_database() if which == "synthetic" else _other_skeleton_db(tmp_path)
    arrays = _shared_copy(db)
    shared = mmrl.Database.from_shared_arrays(arrays)
    assert sorted(shared.borrowed_arrays) == sorted(["bone_translations", "bone_rotations", "root_positions",
                                                     "root_yaws", "root_deltas", "features", "normalized"])
    # Borrowed: the database reads the very memory of the arrays it was given.
    assert np.shares_memory(shared.normalized_features, arrays["normalized"])
    assert np.shares_memory(shared.bone_rotations, arrays["bone_rotations"])
    assert db.borrowed_arrays == []
    rng = np.random.default_rng(0)
    queries = db.normalized_features[rng.integers(0, db.num_frames, 200)] + rng.normal(0, 0.3, (200, 27))
    queries = queries.astype(np.float32)
    np.testing.assert_array_equal(shared.match(queries, normalized=True)[0], db.match(queries, normalized=True)[0])
    for name in ("features", "bone_translations", "root_deltas", "contacts", "clip_ranges"):
        np.testing.assert_array_equal(getattr(shared, name), getattr(db, name))
    # A normalized array that is not the features' own is refused, naming it.
    bad = dict(arrays)
    bad["normalized"] = arrays["normalized"].copy()
    bad["normalized"][3, 4] += 1e-3
    with pytest.raises(ValueError, match="'normalized' disagrees"):
        mmrl.Database.from_shared_arrays(bad)


@pytest.fixture(scope="module")
def local_ray():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


def _rows(run):
    with open(run / "metrics.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_rllib_trains_the_plane_and_the_run_loads_like_any_other(local_ray, tmp_path, capsys):
    from mmrl.integrations.rllib.envs import process_memory  # noqa: F401
    from mmrl.runs import RunDir
    from mmrl.rl.trained_policy import load_policy

    run = tmp_path / "run"
    assert main(["train", "plane", "--backend", "rllib", "--workers", "2", "--envs-per-worker", "8",
                 "--steps", "3000", "--out", str(run), "--no-progress", "--set", "checkpoint_interval_steps=1000"]) == 0
    config = RunDir(run).config
    assert config["backend"] == "rllib" and config["rllib"]["workers"] == 2 and config["task"] == "plane"
    rows = _rows(run)
    assert list(rows[0])[:len(MetricsLogger.BASE_COLUMNS)] == list(MetricsLogger.BASE_COLUMNS)
    assert {"transitions_per_s", "matched_cost"} <= set(rows[0])
    steps = [int(r["step"]) for r in rows]
    assert steps == sorted(set(steps)) and steps[-1] >= 3000
    assert any(f.name.startswith("events.out.tfevents") for f in run.iterdir())
    # The exported policy is the policy RLlib trained: filter, network mean and unsquashing.
    policy = load_policy(run / "latest.pt")
    env = mmrl.get_task("plane").make_vector_env(16, db=mmrl.default_database())
    obs, _ = env.reset(seed=5)
    state = torch.load(run / "latest.pt", weights_only=True)
    rms = state["obs_normalizer"]["rms"]
    normalized = np.clip((obs - rms["mean"].numpy()) / (np.sqrt(rms["var"].numpy()) + 1e-8), -10, 10)
    net = policy.model
    with torch.no_grad():
        mean = net.actor_mean(torch.as_tensor(normalized, dtype=torch.float32)).numpy()
    low, high = env.single_action_space.low, env.single_action_space.high
    expected = low + (mean + 1.0) * (high - low) / 2.0  # RLlib's unsquash_action
    np.testing.assert_allclose(policy.act(obs), expected, rtol=1e-4, atol=1e-4)
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "3"]) == 0
    out = capsys.readouterr().out  # the plain text of mmrl eval (its JSON keeps success_rate)
    assert "  success  " in out and "verdict: " in out
    assert main(["export", str(run), "-o", str(tmp_path / "plane.mmrl")]) == 0  # into the C++ runtime
    assert (tmp_path / "plane.mmrl").stat().st_size > 0


def _obstacles_run(tmp_path, workers=2, resume=False, steps=2000):
    from mmrl.integrations.rllib import RLlibConfig, RLlibRun

    task = mmrl.get_task("obstacles")
    cfg = RLlibConfig(workers=workers, envs_per_worker=4, rollout_fragment_length=16, num_epochs=1,
                      total_steps=steps, progress=False, tensorboard=False)
    callbacks = list(task.callbacks(None, {}))
    db = mmrl.default_database()
    return RLlibRun(task, db, task.default_config(), cfg, tmp_path, callbacks=callbacks, resume=resume), callbacks[0]


def _worker_stages(run):
    from mmrl.integrations.rllib import envs as rllib_envs

    def stages(_runner):
        return [log.env.unwrapped._stage_label for log in rllib_envs._WORKER_ENVS]
    return run.algo.env_runner_group.foreach_env_runner(stages, local_env_runner=False)


def test_workers_borrow_the_database_and_a_killed_worker_is_replaced(local_ray, tmp_path):
    from mmrl.integrations.rllib import envs as rllib_envs

    run, curriculum = _obstacles_run(tmp_path)
    try:
        handle = run.db_handle
        borrowed = run.algo.env_runner_group.foreach_env_runner(
            lambda r: rllib_envs.worker_database(handle).borrowed_arrays, local_env_runner=False)
        assert len(borrowed) == 2 and all(len(b) == 7 for b in borrowed)
        # The curriculum is the driver's: a stage it sets reaches every worker.
        curriculum.stage = 4
        run._push_stage()
        assert _worker_stages(run) == [[4], [4]]
        run.cfg.total_steps = 10**9
        run.algo.train()
        before = sorted(run.worker_pids())
        os.kill(before[0], signal.SIGKILL)
        deadline = time.time() + 120
        pids = before
        while time.time() < deadline:  # RLlib notices the death during sampling and restarts the worker
            run._train_once()
            pids = sorted(run.worker_pids())
            if len(pids) == 2 and before[0] not in pids:
                break
        assert len(pids) == 2 and before[0] not in pids, (before, pids)
        assert _worker_stages(run) == [[4], [4]]  # the new worker got the current stage
        step_before = run.algo.train()["env_runners"]["num_env_steps_sampled_lifetime"]
        assert step_before > 0
    finally:
        run.stop()


def test_resume_continues_steps_metrics_and_curriculum(local_ray, tmp_path):
    run, curriculum = _obstacles_run(tmp_path, steps=1200)
    try:
        curriculum.stage = 3
        run._push_stage()
        run.train()
        saved_step = run.global_step
    finally:
        run.stop()
    state = torch.load(tmp_path / "latest.pt", weights_only=True)
    assert state["global_step"] == saved_step and state["callbacks"][0]["stage"] == 3
    run, curriculum = _obstacles_run(tmp_path, steps=2400, resume=True)
    try:
        assert run.global_step == saved_step and curriculum.stage == 3
        assert _worker_stages(run) == [[3], [3]]
        np.testing.assert_array_equal(run.checkpoint_state()["model"]["log_std"].numpy(),
                                      state["model"]["log_std"].numpy())
        run.train()
        assert run.global_step >= 2400
    finally:
        run.stop()
    steps = [int(r["step"]) for r in _rows(tmp_path)]
    assert steps == sorted(set(steps)) and steps[-1] == run.global_step
    assert saved_step in steps and [r for r in _rows(tmp_path) if int(r["step"]) > saved_step]
    assert all(int(r["curriculum_stage"]) >= 3 for r in _rows(tmp_path))


def test_bad_input_gives_one_line_and_what_to_do(tmp_path):
    # An address where nothing answers: refused at once, not after Ray's minutes of retries.
    t0 = time.time()
    out = subprocess.run([sys.executable, "-m", "mmrl", "train", "plane", "--backend", "rllib", "--address",
                          "127.0.0.1:9", "--steps", "10", "--out", str(tmp_path / "a"), "--no-progress"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and time.time() - t0 < 60
    lines = [line for line in out.stderr.splitlines() if "127.0.0.1:9" in line]
    assert lines and "ray start --head" in lines[0] and "Traceback" not in out.stderr
    assert not (tmp_path / "a").exists()  # refused before anything was written
    # The extra is missing: say what to install.
    code = ("import sys; sys.modules['ray'] = None; from mmrl.cli import main; "
            "sys.exit(main(['train', 'plane', '--backend', 'rllib', '--steps', '10', '--out', sys.argv[1]]))")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "b")], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2 and "pip install 'mmrl[rllib]'" in out.stderr and "Traceback" not in out.stderr
    # Options of one backend with the other.
    assert main(["train", "plane", "--workers", "2", "--steps", "10", "--out", str(tmp_path / "c")]) == 2
    assert main(["train", "plane", "--preset", "paper-rllib", "--steps", "10", "--out", str(tmp_path / "d")]) == 2


def test_a_worker_that_cannot_be_restarted_stops_the_run_resumably(local_ray, tmp_path):
    from mmrl.integrations.rllib import RLlibConfig, RLlibRun, WorkerLost

    task = mmrl.get_task("plane")
    cfg = RLlibConfig(workers=1, envs_per_worker=4, rollout_fragment_length=16, num_epochs=1, total_steps=10**9,
                      max_worker_restarts=0, checkpoint_interval_steps=64, progress=False, tensorboard=False)
    run = RLlibRun(task, mmrl.default_database(), task.default_config(), cfg, tmp_path)
    try:
        run.save()
        os.kill(run.worker_pids()[0], signal.SIGKILL)
        with pytest.raises(WorkerLost, match="latest.pt holds step"):
            run.train()
    finally:
        run.stop()
    state = torch.load(tmp_path / "latest.pt", weights_only=True)
    assert state["backend"] == "rllib"


def test_paper_rllib_is_the_papers_task_with_rllibs_defaults():
    import argparse

    from mmrl.commands.train_rllib import _configs
    from mmrl.integrations.rllib import RLLIB_PRESETS

    task = mmrl.get_task("plane")
    args = argparse.Namespace(seed=3, preset="paper-rllib", set=["num_epochs=7"], **{
        f.flag.lstrip("-").replace("-", "_"): False for name in mmrl.tasks.task_names()
        for f in mmrl.get_task(name).flags})
    task_cfg, cfg, _ = _configs(task, args, {})
    assert task_cfg == task.default_config()  # the paper's task: the config classes' values
    for key, value in RLLIB_PRESETS["paper-rllib"].items():
        if key != "num_epochs":
            assert getattr(cfg, key) == value, key
    assert cfg.num_epochs == 7 and cfg.seed == 3 and cfg.workers == 11 and cfg.batch_size() == 4000
    # Without a preset: the task's default preset, its trainer options in RLlib's names.
    args.preset, args.set = None, []
    task_cfg, cfg, _ = _configs(task, args, {})
    quality = task.presets[task.default_preset]
    assert task_cfg.transition_cost == quality["transition_cost"] and cfg.gamma == quality["gamma"]
    obstacles = mmrl.get_task("obstacles")
    _, cfg, _ = _configs(obstacles, args, {})
    assert (cfg.num_epochs, cfg.num_minibatches, cfg.lr, cfg.anneal_lr) == (2, 2, 1e-3, True)
