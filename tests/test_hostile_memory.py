"""Arrays freed or changed while C++ holds them (issue 18, item 5): every object that keeps a
numpy array or another object (a tree its points, a matcher its rows and mask, an env or a
character its database and matcher, a runtime character its controller, a view its owner)
keeps it alive; answers after the Python references are gone, and the memory reused, equal
those of an untouched twin."""
import gc

import numpy as np
import pytest

import mmrl
from mmrl import _core


def _reuse_freed_memory():
    """Drop the last references and fill freed memory with other numbers."""
    gc.collect()
    return [np.full((4096, 8), 7.5e7, np.float32) for _ in range(64)]


@pytest.fixture()
def fresh_db():
    return mmrl.Database.from_bvh(mmrl.motion.synth.default_dataset_dir())


def test_kdtree_and_matcher_outlive_their_arrays():
    rng = np.random.default_rng(0)
    points = rng.random((700, 5), dtype=np.float32)
    twin_points = points.copy()
    tree, twin_tree = _core.KDTree(points), _core.KDTree(twin_points)
    mask = rng.random(700) < 0.7
    matcher, twin = _core.Matcher(points, mask), _core.Matcher(twin_points, mask.copy())
    del points, mask
    junk = _reuse_freed_memory()
    queries = rng.random((50, 5), dtype=np.float32)
    for a, b in ((tree.query(queries, 3), twin_tree.query(queries, 3)), (matcher.match(queries), twin.match(queries)),
                 (matcher.brute_force(queries), twin.brute_force(queries))):
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
    assert junk


def test_views_outlive_their_owners(fresh_db):
    expected = fresh_db.features.copy(), fresh_db.normalized_features.copy(), fresh_db.valid_mask.copy()
    views = fresh_db.features, fresh_db.normalized_features, fresh_db.valid_mask
    motion = mmrl.load_bvh(sorted(mmrl.motion.synth.default_dataset_dir().glob("*.bvh"))[0])
    rotations, rotations_copy = motion.local_rotations, np.array(motion.local_rotations)
    del fresh_db, motion
    junk = _reuse_freed_memory()
    for view, copy in zip(views, expected):
        np.testing.assert_array_equal(view, copy)
        assert not view.flags.writeable  # C++-owned memory is never written through a view
    np.testing.assert_array_equal(rotations, rotations_copy)
    assert junk


@pytest.mark.parametrize("task", ["plane", "obstacles"])
def test_env_core_outlives_database_matcher_and_python_env(task):
    def make():
        db = mmrl.Database.from_bvh(mmrl.motion.synth.default_dataset_dir())
        env = mmrl.get_task(task).make_vector_env(3, db=db, num_threads=1)
        env.reset(seed=4)
        return env

    env, twin = make(), make()
    core, twin_core = env.unwrapped._core, twin.unwrapped._core
    del env
    junk = _reuse_freed_memory()
    buffers = [dict(actions=np.full((3, 12), 0.2, np.float32), obs=np.zeros((3, c.obs_dim), np.float32),
                    rewards=np.zeros(3, np.float32), terminated=np.zeros(3, np.uint8),
                    truncated=np.zeros(3, np.uint8), success=np.zeros(3, np.uint8),
                    **({"collision": np.zeros(3, np.uint8), "hits": np.zeros(3, np.int32)} if task == "obstacles"
                       else {}),
                    final_obs=np.zeros((3, c.obs_dim), np.float32), episode_return=np.zeros(3, np.float32),
                    episode_length=np.zeros(3, np.int32)) for c in (core, twin_core)]
    for _ in range(40):
        core.step(**buffers[0])
        twin_core.step(**buffers[1])
        np.testing.assert_array_equal(buffers[0]["obs"], buffers[1]["obs"])
        np.testing.assert_array_equal(buffers[0]["rewards"], buffers[1]["rewards"])
    twin.close()
    assert junk


def test_character_outlives_its_database_and_matcher():
    def make():
        db = mmrl.Database.from_bvh(mmrl.motion.synth.default_dataset_dir())
        character = _core.Character(db._db, _core.CharacterOptions())
        character.reset(100, 0.0, 0.0, 0.0)
        return character, _core.Decider(db._db, db.matcher)

    (character, decider), (twin, twin_decider) = make(), make()
    junk = _reuse_freed_memory()
    query = np.linspace(-1, 1, 12).astype(np.float32)
    for _ in range(30):
        character.play(*decider.decide(character.frame, query))
        twin.play(*twin_decider.decide(twin.frame, query))
        assert character.frame == twin.frame
        np.testing.assert_array_equal(character.current_pose()[0], twin.current_pose()[0])
    assert junk


def test_runtime_character_outlives_its_controller(tmp_path):
    from mmrl.export.runtime_export import write_controller
    from mmrl.tasks.plane import PlaneConfig
    from test_runtime import random_plane_policy

    path = tmp_path / "plane.mmrl"
    write_controller(path, mmrl.default_database(), random_plane_policy(2), "plane", PlaneConfig())
    character = _core.RuntimeCharacter(_core.RuntimeController.load(str(path)), 0.0, 0.0, 0.0)
    twin = _core.RuntimeCharacter(_core.RuntimeController.load(str(path)), 0.0, 0.0, 0.0)
    junk = _reuse_freed_memory()
    for target in ((3.0, 1.0), (-2.0, 4.0)):
        character.set_target(*target)
        twin.set_target(*target)
        for _ in range(60):
            character.update(1 / 30)
            twin.update(1 / 30)
            assert character.frame == twin.frame and character.root == twin.root
    assert junk
