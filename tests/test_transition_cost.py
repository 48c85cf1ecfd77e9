"""The transition cost (``transition_cost``): another frame replaces the current clip's
continuation only when it matches better by more than the cost. Checked against a numpy
brute force with the same rule, and the fast and full paths still agree step for step."""
import numpy as np
import pytest

from mmrl import Character, default_database, get_task
from mmrl.rl.policies import JoystickPolicy
from mmrl.rollout import FullPath
from mmrl.tasks.plane import PlaneVectorEnv


@pytest.fixture(scope="module")
def db():
    return default_database()


def brute_force_decision(db, frame: int, action: np.ndarray, low, high, transition_cost: float):
    """(frame to play from, margin to the rule's threshold) by the rule of decision.hpp."""
    rows = np.asarray(db.normalized_features, np.float64)
    query = np.concatenate([rows[frame, :15], np.clip(action, low, high)])
    cost = ((rows - query) ** 2).sum(1)
    allowed = np.asarray(db.valid_mask, bool).copy()
    c = int(db.frame_clip[frame])
    start, stop = db.clip_ranges[c]
    allowed[max(start, frame - 20):min(stop, frame + 21)] = False
    best = int(np.flatnonzero(allowed)[np.argmin(cost[allowed])])
    if not db.valid_mask[frame]:
        return best, np.inf
    threshold = cost[frame] - transition_cost
    return (best if cost[best] < threshold else frame), abs(cost[best] - threshold)


@pytest.mark.parametrize("transition_cost", [0.0, 0.5, 3.0])
def test_env_decisions_follow_the_rule_by_brute_force(db, transition_cost):
    env = PlaneVectorEnv(8, db=db, num_threads=1, transition_cost=transition_cost)
    obs, _ = env.reset(seed=4)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    joy = JoystickPolicy(db, layout=env.observation_layout)
    checked = 0
    for _ in range(40):
        frames = env.current_frames()
        actions = (joy.act(obs) + rng.normal(0, 0.8, (8, 12))).astype(np.float32)
        obs, _, term, trunc, _ = env.step(actions)
        for i in range(8):
            if term[i] or trunc[i]:  # reset since: its state is the next episode's
                continue
            want, slack = brute_force_decision(db, int(frames[i]), actions[i], low, high, transition_cost)
            if slack < 1e-3:  # float32 in C++ against float64 here: skip near-ties
                continue
            assert env.env_state(i)["last_match"] == want
            checked += 1
    assert checked > 250


def test_a_larger_transition_cost_means_fewer_transitions(db):
    rng = np.random.default_rng(1)
    actions = rng.normal(0, 1.0, (300, 16, 12)).astype(np.float32)
    counts = []
    for cost in (0.0, 1.0, 10.0):
        env = PlaneVectorEnv(16, db=db, num_threads=1, transition_cost=cost, max_steps=10**6)
        env.reset(seed=2)
        transitions = np.zeros(16, np.uint8)
        costs = np.zeros(16, np.float32)
        total = 0
        for t in range(300):
            env.step(actions[t])
            env._core.last_step_transitions(transitions, costs)
            total += int(transitions.sum())
        counts.append(total)
    assert counts[2] < counts[1] < counts[0], counts


@pytest.mark.parametrize("task_name", ["plane", "obstacles"])
def test_fast_and_full_paths_agree_with_a_transition_cost(db, task_name):
    task = get_task(task_name)
    run = FullPath(task, db, config=task.default_config().replace(transition_cost=2.0), seed=5, record=False)
    rng = np.random.default_rng(5)
    joy = JoystickPolicy(db, layout=run.env.observation_layout)
    low, high = run.env.single_action_space.low, run.env.single_action_space.high
    checked = 0
    for _ in range(150):
        a = np.clip(joy.act(run.obs[None])[0] + rng.normal(0, 0.5, 12), low, high).astype(np.float32)
        out = run.step(a)
        if out["done"]:
            continue
        frame_diff, root_diff = run.root_error()
        assert frame_diff == 0 and root_diff < 1e-5
        checked += 1
    assert checked > 60


def test_bad_transition_cost_is_refused(db):
    with pytest.raises(ValueError, match="transition_cost"):
        PlaneVectorEnv(2, db=db, transition_cost=-1.0)
    from mmrl import Character

    with pytest.raises(ValueError, match="transition_cost"):
        Character(db, transition_cost=float("nan"))


def test_plane_quality_preset_sets_its_options(tmp_path):
    import json

    from mmrl.cli import main
    from mmrl.tasks.plane import PLANE_PRESETS

    run = tmp_path / "q"
    assert main(["train", "plane", "--steps", "512", "--envs", "8", "--out", str(run), "--no-progress", "--preset",
                 "quality"]) == 0
    saved = json.loads((run / "config.json").read_text())
    # A plain `mmrl train plane` uses the quality preset; --preset paper is the paper's rule.
    assert main(["train", "plane", "--steps", "512", "--envs", "8", "--out", str(tmp_path / "d"), "--no-progress"]) == 0
    default = json.loads((tmp_path / "d" / "config.json").read_text())
    assert main(["train", "plane", "--steps", "512", "--envs", "8", "--out", str(tmp_path / "p"), "--no-progress",
                 "--preset", "paper"]) == 0
    paper = json.loads((tmp_path / "p" / "config.json").read_text())
    assert paper["task_config"]["transition_cost"] == 0.0 and paper["ppo"]["gamma"] == 0.99
    for key, value in PLANE_PRESETS["quality"].items():
        section = "ppo" if key in saved["ppo"] else "task_config"
        assert saved[section][key] == value, key
        assert default[section][key] == value, key
    assert main(["train", "plane", "--steps", "512", "--envs", "8", "--out", str(tmp_path / "s"), "--no-progress",
                 "--preset", "smooth"]) == 0
    smooth = json.loads((tmp_path / "s" / "config.json").read_text())
    assert smooth["task_config"]["transition_pose_weight"] == 10.0 and smooth["task_config"]["transition_cost"] == 60.0


@pytest.mark.parametrize("task_name", ["plane", "obstacles"])
def test_transition_pose_weight_charges_the_pose_distance_of_each_jump(db, task_name):
    """The reward term is -weight x the squared distance between the pose features (the first
    15 normalized columns) of the continuation and of the matched frame, by numpy; 0 when the
    clip continues. Two envs with the same seed and actions differ by exactly that."""
    task = get_task(task_name)
    envs = [task.make_vector_env(6, db=db, num_threads=1, transition_pose_weight=w) for w in (0.0, 0.25)]
    for e in envs:
        e.reset(seed=11)
    rows = np.asarray(db.normalized_features, np.float64)
    rng = np.random.default_rng(1)
    jumps = 0
    for _ in range(30):
        before = [envs[0].env_state(i)["frame"] for i in range(6)]
        a = (rng.normal(size=(6, 12)) * 0.7).astype(np.float32)
        r0 = envs[0].step(a)[1]
        r1 = envs[1].step(a)[1]
        for i in range(6):
            st = envs[0].env_state(i)
            match = st["last_match"] if st["steps"] else None
            if match is None:  # the episode ended and the env reset: read the kept decision
                continue
            expected = 0.0 if match == before[i] else ((rows[before[i], :15] - rows[match, :15]) ** 2).sum()
            jumps += match != before[i]
            assert st["last_pose_jump"] == pytest.approx(expected, rel=1e-4, abs=1e-4)
            assert r0[i] - r1[i] == pytest.approx(0.25 * expected, rel=1e-3, abs=1e-3)
    assert jumps > 20


def test_transition_pose_weight_is_checked(db):
    with pytest.raises(ValueError, match="transition_pose_weight must be finite and >= 0"):
        PlaneVectorEnv(2, db=db, transition_pose_weight=-1.0)


def test_controller_transition_cost_is_settable_and_checked(db):
    ctrl = Character(db, transition_cost=2.0)
    ctrl.transition_cost = 7.5
    assert ctrl.transition_cost == 7.5
    for bad in (-1.0, float("nan"), "x"):
        with pytest.raises(ValueError, match="transition_cost must be finite and >= 0"):
            ctrl.transition_cost = bad
