"""``mmrl render --html``: a Playback as one standalone HTML page with a playback bar.

The page is viser's built web client (a single self-contained file in the viser wheel)
with the recorded scene inlined (zstd, base64): it opens from file:// in any browser with
no network and no Python. The world moves under a fixed camera so that the character stays
in view (a recorded page has no server to move the camera); the camera can still orbit.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..io import atomic_write_text
from .clips import Playback
from .draw import CAMERA_OFFSET, CAMERA_OFFSET_OBSTACLES, Painter
from .scene import LOCALHOST, Scene

WORLD = "/world"


def playback_html(playback: Playback) -> str:
    """The page for every frame of ``playback`` at its frame rate."""
    scene = Scene(LOCALHOST, 0, title=playback.name)  # any free port; nothing connects to it
    try:
        painter = Painter(scene, playback.parents, playback.joint_names, body_joints=playback.body_joints,
                          feet=playback.feet, success_radius=playback.success_radius, root=WORLD)
        scene.frame(WORLD, (0.0, 0.0, 0.0))
        scene.ground(200.0, name=WORLD + "/ground")
        offset = CAMERA_OFFSET_OBSTACLES if "obstacles" in playback.recording else CAMERA_OFFSET
        scene.camera(np.array(offset) + (0.0, 0.9, 0.0), (0.0, 0.9, 0.0))
        starts = {a: b for _, a, b in playback.clips}
        painter.trajectory(playback.ground_path(0, playback.clips[0][2]))
        with scene.recording() as rec:
            for t in range(playback.num_frames):
                if t in starts:  # each episode (clip) shows its own path
                    painter.trajectory(playback.ground_path(t, starts[t]))
                x, z = playback.ground_path(t, t + 1)[0]
                scene.frame(WORLD, (-x, 0.0, -z))  # the character's ground point stays at the origin
                painter.show(playback.frame(t))
                rec.sleep(1.0 / playback.fps)
            return rec.html()
    finally:
        scene.close()


def write_html(path: "str | os.PathLike[str]", playback: Playback) -> int:
    """Write the page atomically; returns its size in bytes."""
    page = playback_html(playback)
    check_offline(page)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, page)
    return path.stat().st_size


def check_offline(page: str) -> None:
    """Refuse a page that would fetch anything from the network (a script, style or font URL)."""
    remote = re.findall(r"""(?:src|href)\s*=\s*["']?(https?:)?//""", page)
    if remote:
        raise RuntimeError("the exported page references the network; the viser client build is not standalone")
