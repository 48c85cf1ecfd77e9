"""One rule, one place: the batched env's fast path, the full path and the engine runtime make the
same decisions, for 1,000 decisions per task and across episode ends.

- fast path: env 0 of a 4-env, 2-thread vector env, stepped with the full path's actions (the
  other envs act at random), equals the full path's one-env env step for step: decision, cost,
  frame and root;
- full path: the Character plays the env's decision (it never decides again), so its shown
  frames are the match's and its root is the env's;
- runtime: a RuntimeCharacter started where each episode starts, given the same target and (on
  the obstacles task) the env's obstacles with their velocities before every decision, writes
  the same observation bit for bit, decides the same frames and shows the same roots.

The configs switch on every rule that changes a match: a transition cost, the obstacles'
look-ahead and hit disc, a clip-cost filter, (a third config) the collision-aware search, and (a
fourth) the deployed search's twenty escapes, whose table the runtime reads from the file; the
arrive task's stand moves the root at its transitions (stand_anchor) on every path."""
import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.export.runtime_export import write_controller
from mmrl.rollout import FullPath, apply_stage
from test_runtime import random_obstacle_policy, random_plane_policy


def configs(db):
    # A clip the random policies below pick often (a stop: walk to stand), made dearer.
    busy = next(name for name in db.clip_names if name.endswith("_stop.bvh"))
    plane = mmrl.get_task("plane").default_config().replace(transition_cost=3.0, clip_costs=f"{busy}=0.5",
                                                            max_steps=40)
    obstacles = mmrl.get_task("obstacles").default_config().replace(
        transition_cost=5.0, hit_lookahead=True, hit_radius=0.3, num_obstacles=40,
        obstacle_max_speed=1.0, clip_costs=f"{busy}=0.5", max_steps=60)
    # The collision-aware search (tasks/path_filter.hpp) on top, and the foot-jump rule: every rule at once.
    path = obstacles.replace(path_filter=True, path_cost=50.0, path_candidates=32, foot_jump_limit=0.3)
    # The deployed search's escapes (the runtime reads their table from the file).
    escapes = obstacles.replace(path_filter=True, path_cost=10000.0, path_escapes=20, path_fan_candidates=2)
    # The arrive task (a plug-in core): its hold ends episodes mid-step, its facing is an input.
    # (Its clip-cost rule is the same chain as the plane's: the plane config covers it.)
    arrive = mmrl.get_task("arrive").default_config().replace(transition_cost=3.0,
                                                              max_steps=40, success_radius=2.0, stop_speed=3.0,
                                                              facing_tolerance=1.5, hold_time=1.0,
                                                              target_half_extent=3.0)
    return {"plane": (plane, random_plane_policy(4)), "obstacles": (obstacles, random_obstacle_policy(5)),
            "obstacles-path": (path, random_obstacle_policy(5)),
            "obstacles-escapes": (escapes, random_obstacle_policy(5)), "arrive": (arrive, random_plane_policy(6, 19))}


def hand_obstacles(character, env):
    o = env.obstacles(0)
    character.set_obstacles(*(np.ascontiguousarray(o[k], np.float32)
                              for k in ("centres", "half_sizes", "angles", "velocities")))


@pytest.mark.parametrize("kind", ["plane", "obstacles", "obstacles-path", "obstacles-escapes", "arrive"])
def test_fast_path_full_path_and_runtime_agree_for_1000_decisions(kind, tmp_path):
    db = mmrl.default_database()
    task_name = kind.split("-")[0]
    task = mmrl.get_task(task_name)
    config, policy = configs(db)[kind]
    path = tmp_path / f"{task_name}.mmrl"
    write_controller(path, db, policy, task_name, config)
    controller = _core.RuntimeController.load(str(path))
    fp = FullPath(task, db, config=config, seed=11, record=False)
    fast = task.make_vector_env(4, db=db, config=config, num_threads=2)
    apply_stage(task, fast, None)  # the full path's stage: the last
    fast.reset(seed=11)
    rng = np.random.default_rng(0)
    decisions = episodes = transitions = filtered = successes = anchored = 0
    while decisions < 1000:
        character = _core.RuntimeCharacter(controller, *fp.character.root, fp.character.frame)  # each episode's start
        character.set_target(*fp.target)
        if character.takes_facing:
            character.set_facing(fp.env.env_state(0)["facing"])
        episodes += 1
        while True:
            if task_name == "obstacles":
                hand_obstacles(character, fp.env)
            np.testing.assert_array_equal(character.observe(), fp.obs)
            action = controller.act(fp.obs)
            actions = np.concatenate([action[None], rng.normal(0, 1, (3, 12))]).astype(np.float32)
            fast_obs, *_ = fast.step(actions)
            out = fp.step(action)
            match, cost = fp.env.last_step_decision(0)
            # fast path == the full path's env
            assert fast.last_step_decision(0) == (match, cost)
            assert fast.last_step_anchor(0) == fp.env.last_step_anchor(0)
            anchored += fp.env.last_step_anchor(0) != (0.0, 0.0)
            np.testing.assert_array_equal(fast_obs[0], fp.obs)
            # full path plays the env's decision
            res = out["res"]
            assert res.match == match and res.cost == cost
            np.testing.assert_array_equal(res.frames, match + 1 + np.arange(res.frames.size))
            # runtime
            for k in range(out["step_frames"]):
                character.advance_frame()
                assert character.frame == res.frames[k]
                np.testing.assert_allclose(character.root, res.roots[k], atol=1e-5)
            assert character.last_decision()["match"] == match
            decisions += 1
            transitions += res.transition
            filtered += int(not config.clip_costs or db.clip_names[db.frame_clip[match]] == config.clip_costs.split("=")[0])
            if out["done"]:
                successes += out["terminated"]
                break
            assert fp.root_error() == (0, 0.0)
    # Not vacuous: many episodes and clip changes; the filtered clip still plays sometimes.
    assert episodes >= 10 and transitions >= 50 and filtered >= 1, (episodes, transitions, filtered)
    assert successes >= 5 or task_name != "arrive", successes  # the hold ends episodes mid-step
    # The arrive task's stand moves the root to keep planted feet (stand_anchor) on every path.
    assert anchored >= 3 or task_name != "arrive", (anchored, successes, episodes)
