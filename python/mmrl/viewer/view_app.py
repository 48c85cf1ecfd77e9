"""``mmrl view``: play a :class:`~mmrl.viewer.clips.Playback` in the browser.

Controls: clip selection, play/pause, a frame slider (within the clip) and a speed slider.
A ticker thread shows frames at the clip's frame rate times the speed; the slider follows.
"""
from __future__ import annotations

import threading
import time
from typing import Optional

import numpy as np

from .clips import Playback
from .draw import CAMERA_OFFSET, CAMERA_OFFSET_OBSTACLES, Painter
from .scene import Scene


class ViewApp:
    """The playback state (clip, frame, playing, speed) and its controls on a Scene."""

    def __init__(self, scene: Scene, playback: Playback):
        self.scene, self.pb = scene, playback
        self.painter = Painter(scene, playback.parents, playback.joint_names, body_joints=playback.body_joints,
                               feet=playback.feet, success_radius=playback.success_radius)
        self.clip = 0
        self.t = 0.0  # frames into the clip (fractional while playing)
        self.playing = True
        self.shown = -1  # absolute frame last drawn
        self._lock = threading.RLock()
        scene.ground()
        self._controls()
        self.select_clip(0)

    def _controls(self) -> None:
        s, pb = self.scene, self.pb
        s.text(f"**{pb.name}** · {len(pb.clips)} clip(s) · {pb.fps:g} fps")
        self.clip_menu = s.dropdown("clip", [self._clip_label(i) for i in range(len(pb.clips))])
        self.play_button = s.button("pause")
        self.frame_slider = s.slider("frame", 0, max(1, self._clip_len() - 1), 1, 0)
        self.speed_slider = s.slider("speed", 0.1, 4.0, 0.1, 1.0)
        self.follow = s.checkbox("camera follows", True)
        self.status = s.text("")
        self.clip_menu.on_change(lambda: self.select_clip(self._clip_index(self.clip_menu.value)))
        self.play_button.on_change(self.toggle)
        self.frame_slider.on_change(self._seek)

    def _clip_label(self, i: int) -> str:
        name, a, b = self.pb.clips[i]
        return f"{i + 1}: {name} ({(b - a) / self.pb.fps:.1f} s)"

    def _clip_index(self, label: str) -> int:
        return int(str(label).split(":", 1)[0]) - 1

    def _clip_len(self) -> int:
        _, a, b = self.pb.clips[self.clip]
        return b - a

    # ------------------------------------------------------------------ state changes
    def select_clip(self, i: int) -> None:
        with self._lock:
            self.clip = int(i)
            self.t = 0.0
            _, a, b = self.pb.clips[self.clip]
            self.painter.trajectory(self.pb.ground_path(a, b))
            n = max(1, b - a - 1)
            self.frame_slider.set_range(0, n)
            self._show(0)

    def toggle(self) -> None:
        self.playing = not self.playing
        self.play_button.set_label("pause" if self.playing else "play")

    def _seek(self) -> None:
        with self._lock:
            frame = int(self.frame_slider.value)
            if frame != int(self.t):
                self.t = float(frame)
                self._show(frame)

    def _show(self, k: int) -> None:
        _, a, b = self.pb.clips[self.clip]
        k = int(np.clip(k, 0, b - a - 1))
        self.shown = a + k
        self.painter.show(self.pb.frame(a + k))
        if self.follow.value:
            xz = self.pb.ground_path(a + k, a + k + 1)[0]
            offset = CAMERA_OFFSET_OBSTACLES if "obstacles" in self.pb.recording else CAMERA_OFFSET
            self.scene.follow((xz[0], 0.9, xz[1]), offset)
        self.status.set_text(f"frame {k} / {b - a - 1} · {k / self.pb.fps:.2f} s")

    def advance(self, seconds: float) -> None:
        """Move the clock by ``seconds`` of wall time (looping the clip) and draw the frame."""
        with self._lock:
            if not self.playing:
                return
            n = self._clip_len()
            self.t = (self.t + seconds * self.pb.fps * float(self.speed_slider.value)) % max(n, 1)
            k = int(self.t)
            self._show(k)
            self.frame_slider.value = k

    def run(self, stop: Optional[threading.Event] = None) -> None:
        """Tick at the clip's frame rate until ``stop`` is set."""
        stop = stop or threading.Event()
        period = 1.0 / self.pb.fps
        last = time.perf_counter()
        while not stop.wait(max(0.0, period - (time.perf_counter() - last))):
            now = time.perf_counter()
            self.advance(now - last)
            last = now
