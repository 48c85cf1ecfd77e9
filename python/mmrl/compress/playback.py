"""How the full path shows a compressed controller's decisions (docs/compressed.md): the
character plays the pose rows the env's stepper and decompressor produced, and starts from the
decoded state. The database's twin, and the interface both keep, is
:class:`mmrl.motion.playback.DatabasePlayback`."""
from __future__ import annotations

from typing import Dict, Optional

import numpy as np

from .. import _core
from ..motion.database import POSE_DIM, TRAJECTORY_DIM


class CompressedPlayback:
    """The decoded rows of ``model`` (a :class:`~mmrl.compress.model.CompressedModel` of ``db``)."""

    def __init__(self, model, db):
        if model.num_joints != db.num_joints:
            raise ValueError(f"compressed: {model.path} has {model.num_joints} joints, the database {db.num_joints}")
        self.model, self.db = model, db

    def attach(self, env) -> None:
        env._core.set_compressed(self.model.core)

    def check_request(self, request: str) -> None:
        if request.strip():
            raise ValueError("request: a compressed controller keeps to no tags (its projector searches every clip "
                             "it learned; docs/compressed.md); play requests with the database")

    def start(self, character, env, i: int, root) -> None:
        self.restart(character, env, i, -1, root)

    def restart(self, character, env, i: int, frame: int, root) -> None:
        """Shows env i's state now (decoded) on ``character``; ``frame`` is -1 here."""
        row = self.model.decode(env._core.compressed_state(i)[None])[0]
        character.reset_row(row, (float(root[0]), float(root[1])), float(root[2]))

    def play(self, character, env, i: int, match: int, cost: float, query: np.ndarray):
        transition = bool(env._step_transitions[i])
        return character.play_rows(env._core.compressed_rows(i), transition, cost, query,
                                   anchor=env.last_step_anchor(i))

    def keep_played(self, env, i: int) -> None:
        """Where the playback ended (the env's autoreset drew a new start since)."""
        env._core.set_compressed_state(i, env._core.compressed_played(i))

    def chosen_features(self, env, i: int, match: int) -> np.ndarray:
        """The state the decision chose: the projection, or the continuation."""
        return env._core.compressed_chosen(i)[:POSE_DIM + TRAJECTORY_DIM]

    def step_values(self, env, i: int, match: int) -> Dict[str, np.ndarray]:
        chosen = self.chosen_features(env, i, match)
        return {"match_features": chosen[POSE_DIM:POSE_DIM + TRAJECTORY_DIM].astype(np.float32)}

    def continuation(self, env, i: int) -> Optional[tuple]:
        """The state's own path: the quadratic through its trajectory features."""
        feats = np.ascontiguousarray(env._core.compressed_state(i)[:POSE_DIM + TRAJECTORY_DIM])
        raw = np.ascontiguousarray(self.db.denormalize(feats)[POSE_DIM:], np.float32)
        local = np.asarray(_core.trajectory_path(raw), np.float64)
        return local, int(env.state_path_hits(i, feats[None])[0])


__all__ = ["CompressedPlayback"]
