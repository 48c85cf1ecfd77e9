"""One policy for every request (issue 26): training conditioned on tag groups (``mmrl train
--tags``), the request code in the observation, ``mmrl eval --request`` / ``--per-request``, the
ONNX graph's request input, ``mmrl play``'s live switch, the runtime file's request groups and the
moving-obstacles task with a request. On the package's synthetic data (tags content and gait)."""
import json

import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.cli import main
from mmrl.export.runtime_export import read_controller
from mmrl.rl.policies import JoystickPolicy
from mmrl.runs import RunDir
from mmrl.tasks.plane import PlaneVectorEnv
from runtime_helpers import drive_both


@pytest.fixture(scope="module")
def gait_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("requests") / "gait"
    assert main(["train", "plane", "--request-groups", "gait", "--steps", "8192", "--seed", "0", "--out", str(out),
                 "--no-progress"]) == 0
    return out


def test_the_run_observes_the_request_code(gait_run):
    run = RunDir(gait_run)
    config = run.task_config(run.task)
    assert config.request_groups == "gait"
    env = PlaneVectorEnv(3, db=run.database(), config=config, num_threads=1)
    assert env.request_dim == 2 and env.obs_dim == 17 + 2 and env.request_tags == ["gait=run", "gait=walk"]
    assert mmrl.load_policy(gait_run / "latest.pt").obs_normalizer.scale.shape[0] == 19
    # The mix: free with request_any, else each gait (every combination selects frames).
    mix = dict(env.request_mix())
    assert mix == pytest.approx({"": 0.125, "gait=run": 0.4375, "gait=walk": 0.4375})
    obs = env.set_request(0, "gait=walk")
    np.testing.assert_array_equal(obs[-2:], [0, 1])
    obs = env.set_request(1, "gait=run|walk")
    np.testing.assert_array_equal(obs[-2:], [1, 1])
    env.reset(seed=0)
    seen = set()
    for _ in range(200):
        obs, *_ = env.step(np.zeros((3, 12), np.float32))
        seen.add(tuple(obs[2, -2:]))
        np.testing.assert_array_equal(obs[0, -2:], [0, 1])
    assert seen <= {(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)} and len(seen) >= 2  # env 2 draws its requests
    with pytest.raises(ValueError, match="request_groups: no tag group 'style'"):
        PlaneVectorEnv(1, db=run.database(), config=config.replace(request_groups="style"))


def test_eval_with_a_request_and_per_request(gait_run, capsys):
    assert main(["eval", str(gait_run), "--request", "gait=walk", "--episodes", "4", "--line", "0", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["request"] == "gait=walk" and res["request_fidelity"] == 1.0
    assert main(["eval", str(gait_run), "--per-request", "--episodes", "3", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["per_request"]
    assert [r["request"] for r in rows] == ["gait=run", "gait=walk"]
    assert all(r["request_fidelity"] == 1.0 for r in rows)
    assert main(["eval", str(gait_run), "--request", "gait=crawl", "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert "--request" in err and "no tag 'gait=crawl'" in err and "gait=run|walk" in err


def test_render_and_export_bvh_keep_the_request(gait_run, tmp_path):
    db = RunDir(gait_run).database()
    out = tmp_path / "walk.bvh"
    assert main(["export-bvh", str(gait_run), "--request", "gait=run", "--length", "4", "-o", str(out)]) == 0
    frames = np.load(out.with_suffix(".npz"))["frames"]
    run_clips = db.clip_tags[:, db.tag_names.index("gait=run")]
    assert run_clips[db.frame_clip[frames]].all()


def test_onnx_takes_the_request_as_its_own_input(gait_run, tmp_path, capsys):
    ort = pytest.importorskip("onnxruntime")
    path = tmp_path / "p.onnx"
    assert main(["export", str(gait_run), "--onnx", str(path)]) == 0
    assert "inputs 'obs' and 'request' (2 floats: gait=run, gait=walk)" in capsys.readouterr().out
    import onnx

    model = onnx.load(str(path))
    assert json.loads({p.key: p.value for p in model.metadata_props}["mmrl.request_tags"]) == ["gait=run",
                                                                                              "gait=walk"]
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()] == ["obs", "request"]
    policy = mmrl.load_policy(gait_run / "latest.pt")
    obs = np.random.default_rng(0).normal(0, 1, (16, 19)).astype(np.float32)
    obs[:, 17:] = np.eye(2, dtype=np.float32)[np.arange(16) % 2]
    action = session.run(["action"], {"obs": obs[:, :17], "request": obs[:, 17:]})[0]
    np.testing.assert_allclose(action, policy.act(obs), atol=1e-4)


def test_runtime_file_carries_the_groups_and_decides_as_the_full_path(gait_run, tmp_path):
    path = tmp_path / "c.mmrl"
    assert main(["export", str(gait_run), "-o", str(path)]) == 0
    back = read_controller(path)
    assert list(back.sections["task.request_groups"]) == ["gait"]
    run = RunDir(gait_run)
    policy = mmrl.load_policy(gait_run / "latest.pt")
    config = run.task_config(run.task)
    for request in ("gait=walk", "gait=run"):
        out = drive_both(path, run.task, back.db, config, lambda o: policy.act(o[None])[0], 300, request=request)
        np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
        assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5 and out["obs_error"] <= 1e-5
    # A file whose policy reads another size than the groups give is refused, naming them.
    sections = dict(back.sections)
    sections["task.request_groups"] = ["content"]
    from mmrl.export.runtime_file import write_sections

    bad = tmp_path / "bad.mmrl"
    write_sections(bad, sections)
    contents = sum(t.startswith("content=") for t in back.db.tag_names)  # one code per content value
    with pytest.raises(ValueError, match=f"request code of {contents}"):
        _core.RuntimeController.load(str(bad))


def test_play_switches_the_request_at_the_next_decision():
    from mmrl.viewer.live import LiveSession

    db = mmrl.default_database()
    task = mmrl.get_task("plane")
    s = LiveSession(task, db, JoystickPolicy.preset(db, "joystick"), config=task.default_config(),
                    request="gait=walk")
    walk = db.clip_tags[:, db.tag_names.index("gait=walk")]
    run = db.clip_tags[:, db.tag_names.index("gait=run")]
    for k in range(60):
        if k % 30 == 0:
            s.set_target(3.0 * (k // 30 + 1), 2.0)
        s.step()
        assert walk[db.frame_clip[s.run.character.frame]]
    with pytest.raises(ValueError, match="no tag 'gait=hop'"):
        s.set_request("gait=hop")
    s.set_request("gait=run")
    while s.k < s.F:  # the frames of the current decision play out
        s.step()
    s.step()  # the next decision: matched inside the new request
    assert s.request == "gait=run" and run[db.frame_clip[s.last.match]]
    for _ in range(60):
        s.step()
        assert run[db.frame_clip[s.run.character.frame]]


def test_obstacles_take_requests_too():
    db = mmrl.default_database()
    task = mmrl.get_task("obstacles")
    env = task.make_vector_env(2, db=db, config=task.default_config().replace(request_groups="gait"), num_threads=1)
    assert env.layout[-1] == ("request", 2) and env.obs_dim == 529 + 2
    env.set_request(0, "gait=run")
    obs, _ = env.reset(seed=0)
    run = db.clip_tags[:, db.tag_names.index("gait=run")]
    joy = JoystickPolicy(db, layout=env.observation_layout)
    for _ in range(100):
        obs, *_ = env.step(joy.act(obs))
        assert run[db.frame_clip[env.current_frames()[0]]]
        np.testing.assert_array_equal(obs[0, -2:], [1, 0])


def test_the_default_network_takes_other_hidden_sizes(tmp_path):
    out = tmp_path / "wide"
    assert main(["train", "plane", "--steps", "2048", "--set", "hidden=48,24", "--out", str(out), "--no-progress"]) == 0
    policy = mmrl.load_policy(out / "latest.pt")
    widths = [m.out_features for m in policy.model.actor if hasattr(m, "out_features")]
    assert widths == [48, 24, 12]
    path = tmp_path / "wide.mmrl"
    assert main(["export", str(out), "-o", str(path)]) == 0  # the runtime reads any dense widths
    ch = _core.RuntimeCharacter(_core.RuntimeController.load(str(path)), 0.0, 0.0, 0.0)
    obs = np.asarray(ch.observe(), np.float32)
    np.testing.assert_allclose(_core.RuntimeController.load(str(path)).act(obs), policy.act(obs[None])[0], atol=1e-5)


def test_a_conditioned_run_stops_its_updates_past_the_task_kl(gait_run, tmp_path):
    # docs/styles.md: one policy for many requests needs smaller updates (plane: target_kl 0.05).
    assert RunDir(gait_run).config["ppo"]["target_kl"] == 0.05
    runs = {}
    for name, extra in (("own", ["--request-groups", "gait", "--set", "target_kl=0.2"]), ("plain", []),
                        ("off", ["--request-groups", "gait", "--set", "target_kl=none"])):
        runs[name] = tmp_path / name
        assert main(["train", "plane", "--steps", "64", "--envs", "2", "--out", str(runs[name]), "--no-progress",
                     *extra]) == 0
    assert RunDir(runs["own"]).config["ppo"]["target_kl"] == 0.2
    assert RunDir(runs["plain"]).config["ppo"]["target_kl"] is None
    assert RunDir(runs["off"]).config["ppo"]["target_kl"] is None
