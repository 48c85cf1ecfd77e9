"""How the full path shows what the env decided, whatever its motion source.

The batched env decides through its motion source (the database, or a compressed controller:
docs/architecture.md); the full path's :class:`~mmrl.character.Character` then shows that
decision with poses. A *playback* is the one object that knows how a source's decision is
shown, so :class:`mmrl.rollout.FullPath`, ``mmrl play`` and the recordings never ask which
source they have. Two implement it: :class:`DatabasePlayback` here and
:class:`mmrl.compress.playback.CompressedPlayback` (a compressed controller's decoded rows).

Every method takes the env (a task's vector env) and the index of its env; roots are world
``(x, z, yaw)``.
"""
from __future__ import annotations

from typing import Dict, Optional

import numpy as np

from .database import POSE_DIM, TRAJECTORY_DIM, Database


class DatabasePlayback:
    """The database's frames: the character plays the env's matched frame."""

    def __init__(self, db: Database):
        self.db = db

    def attach(self, env) -> None:
        """Sets the env's motion source (the database: what a new env plays already)."""

    def check_request(self, request: str) -> None:
        """Raises ValueError when this source cannot keep to ``request`` (the database can)."""

    def start(self, character, env, i: int, root) -> None:
        """Shows env i's episode start on ``character`` at ``root``."""
        self.restart(character, env, i, int(env.env_state(i)["frame"]), root)

    def restart(self, character, env, i: int, frame: int, root) -> None:
        """Shows what a previous character showed (its database ``frame``) on a new one."""
        character.reset(int(frame), (float(root[0]), float(root[1])), float(root[2]))

    def play(self, character, env, i: int, match: int, cost: float, query: np.ndarray):
        """Plays env i's last decision (``match``, ``cost``) on ``character``: its StepResult."""
        return character.play(match, cost, query, anchor=env.last_step_anchor(i))

    def keep_played(self, env, i: int) -> None:
        """Makes env i's motion what its last playback ended on (the database: the env's frame)."""

    def chosen_features(self, env, i: int, match: int) -> np.ndarray:
        """The normalized 27 features of what env i's last decision chose."""
        return self.db.normalized_features[int(match)]

    def step_values(self, env, i: int, match: int) -> Dict[str, np.ndarray]:
        """Per-step values a recording keeps of env i's last decision (``match``): the chosen
        trajectory's normalized features (``match_features``, 12)."""
        return {"match_features": np.array(self.chosen_features(env, i, match)[POSE_DIM:POSE_DIM + TRAJECTORY_DIM],
                                           np.float32)}

    def continuation(self, env, i: int) -> Optional[tuple]:
        """The path env i's motion takes if it continues (character frame, (9, 2)) and the
        collision-aware search's hit (frames ahead of its first hit, 0 when clear), or None when
        it cannot continue. Needs an env with obstacles (``path_hits``)."""
        frame = int(env.env_state(i)["frame"])
        if not self.db.valid_mask[frame]:
            return None
        local = np.asarray(self.db.path_samples[frame], np.float64)
        return local, int(env.path_hits(i, np.array([frame], np.int64))[0])


def playback_of(db: Database, compressed=None):
    """The playback of a full path: a compressed controller's (``compressed``, a
    :class:`~mmrl.compress.model.CompressedModel`) or the database's."""
    return DatabasePlayback(db) if compressed is None else compressed.playback(db)


__all__ = ["DatabasePlayback", "playback_of"]
