"""``mmrl play``: a :class:`~mmrl.viewer.live.LiveSession` on a Scene, at 30 frames per second.

Click the ground to place the target; on an arrive run, shift+drag places it where the drag
begins, facing along the drag (shift+click turns the facing toward the click). On an obstacles run, shift+click picks the nearest
obstacle and puts a drag gizmo on it; a checkbox pauses the obstacles' motion. Toggles
switch IK (with foot locking) and inertialization; a menu switches between the trained
policy and the joystick baseline (which follows the same clicks). A panel shows the live
quality numbers (:func:`mmrl.metrics.quality` over the last 10 s) and the frame cost.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Deque, Dict, Optional

import numpy as np

from .draw import CAMERA_OFFSET, CAMERA_OFFSET_OBSTACLES, Painter
from .live import TIMING_SAMPLES, LiveSession
from .scene import Scene

QUALITY_EVERY = 30  # frames between quality panel updates (1 s)


class PlayApp:
    def __init__(self, scene: Scene, session: LiveSession):
        self.scene, self.session = scene, session
        db = session.db
        from ..metrics import body_joints, feet

        self.painter = Painter(scene, db.parents, db.joint_names, body_joints=body_joints(db), feet=feet(db),
                               success_radius=float(session.config.success_radius))
        # The last 10 minutes of frames (live.TIMING_SAMPLES): unbounded lists grew for as long as play ran.
        self.frame_ms: Dict[str, Deque[float]] = {k: deque(maxlen=TIMING_SAMPLES)
                                                  for k in ("session", "scene", "quality", "frame")}
        self.picked: Optional[int] = None
        self.dragging = False  # a shift+drag is setting the facing: the camera holds still
        self.started = self.frames = 0
        scene.ground()
        self._controls()
        scene.on_ground_click(self.click)
        if session.has_obstacles:
            scene.on_ground_click(self.pick_obstacle, shift=True)
        if session.takes_facing:
            scene.on_ground_click(self.face, shift=True)
            scene.on_ground_drag(self.drag_facing)
        self.painter.show(session.shown)

    def _controls(self) -> None:
        s, sess = self.scene, self.session
        help_text = "**click the ground** to place the target"
        if sess.has_obstacles:
            help_text += "; **shift+click** picks an obstacle to drag"
        if sess.takes_facing:
            help_text += ("; **shift+drag** from a spot places the target there facing along the drag (the "
                          "arrow); **shift+click** turns the facing toward the click")
        s.text(f"**{sess.task.name}** · {help_text}")
        self.policy_menu = s.dropdown("policy", list(sess.policies), sess.policy_name)
        if sess.db.tag_names:  # a request switches the character at its next decision (docs/styles.md)
            options = ["any"] + list(sess.db.tag_names)
            self.request_menu = s.dropdown("request", options, sess.request if sess.request in options else "any")
            self.request_menu.on_change(
                lambda: sess.set_request("" if self.request_menu.value == "any" else str(self.request_menu.value)))
        self.ik_box = s.checkbox("IK + foot locking", True)
        self.inert_box = s.checkbox("inertialization", True)
        self.follow_box = s.checkbox("camera follows", True)
        self.policy_menu.on_change(lambda: sess.set_policy(str(self.policy_menu.value)))
        self.ik_box.on_change(lambda: sess.set_options(ik=bool(self.ik_box.value)))
        self.inert_box.on_change(lambda: sess.set_options(inertialization=bool(self.inert_box.value)))
        if sess.has_obstacles:
            self.pause_box = s.checkbox("pause obstacles", False)
            self.pause_box.on_change(lambda: sess.pause_obstacles(bool(self.pause_box.value)))
        self.status = s.text("")
        self.quality_text = s.text("quality: measuring...")

    # ------------------------------------------------------------------ input
    def click(self, x: float, z: float) -> None:
        self.session.set_target(x, z)

    def face(self, x: float, z: float) -> None:
        """The facing to arrive with: from the target toward the click (forward = (sin yaw, cos yaw))."""
        tx, tz = self.session.target
        if np.hypot(x - tx, z - tz) > 1e-3:
            self.session.set_facing(float(np.arctan2(x - tx, z - tz)))

    def drag_facing(self, phase: str, start: tuple, end: tuple) -> None:
        """A shift+drag: the target where it began, the facing along it once it is 10 cm long.
        The camera holds still during a drag (the ground point under the pointer is read from it)."""
        self.dragging = phase != "end"
        if phase == "start":
            self.session.set_target(*start)
        dx, dz = end[0] - start[0], end[1] - start[1]
        if np.hypot(dx, dz) > 0.1:
            self.session.set_facing(float(np.arctan2(dx, dz)))

    def pick_obstacle(self, x: float, z: float) -> None:
        centres = self.session.obstacle_centres()
        if len(centres) == 0:
            return
        i = int(np.argmin(np.hypot(centres[:, 0] - x, centres[:, 1] - z)))
        self.picked = i
        cx, cz = centres[i]
        self.scene.gizmo("/obstacle_gizmo", (cx, 0.35, cz), lambda gx, gz: self.session.move_obstacle(i, gx, gz))

    # ------------------------------------------------------------------ loop
    def tick(self) -> None:
        """One frame: the session's step, then the scene update (timed separately)."""
        t0 = time.perf_counter()
        shown = self.session.step()
        t1 = time.perf_counter()
        self.painter.show(shown)
        if self.follow_box.value and not self.dragging:
            root = self.session.root
            offset = CAMERA_OFFSET_OBSTACLES if self.session.has_obstacles else CAMERA_OFFSET
            self.scene.follow((root[0], 0.9, root[1]), offset)
        self.frames += 1
        sess = self.session
        x, z, _ = sess.root
        tx, tz = sess.target
        self.status.set_text(f"t {sess.frames_shown / sess.fps:.1f} s · decision {sess.decisions} · "
                             f"{sess.policy_name} · distance to target {np.hypot(tx - x, tz - z):.2f} m")
        t2 = time.perf_counter()
        if self.frames % QUALITY_EVERY == 0:
            self._quality()
        t3 = time.perf_counter()
        for key, value in (("session", t1 - t0), ("scene", t2 - t1), ("quality", t3 - t2), ("frame", t3 - t0)):
            self.frame_ms[key].append(1000.0 * value)

    def _quality(self) -> None:
        q = self.session.quality()
        fmt = lambda v: "n/a" if v is None else f"{v:.2f}"  # noqa: E731
        self.quality_text.set_text(
            f"last {q.get('seconds', 0):.0f} s: "
            f"transitions/s **{fmt(q.get('transitions_per_s'))}** · "
            f"foot sliding **{fmt(q.get('foot_sliding_cm_per_s'))}** cm/s "
            f"(IK off {fmt(q.get('foot_sliding_ik_off_cm_per_s'))}) · "
            f"matched cost **{fmt(q.get('matched_cost_mean'))}**")

    def run(self, stop: Optional[threading.Event] = None) -> None:
        """Tick at the database's frame rate until ``stop`` is set (a late frame is not made up)."""
        stop = stop or threading.Event()
        period = 1.0 / self.session.fps
        self.started = time.perf_counter()
        next_due = self.started
        while not stop.is_set():
            self.tick()
            next_due = max(next_due + period, time.perf_counter() - period)
            stop.wait(max(0.0, next_due - time.perf_counter()))

    def timing_report(self) -> str:
        """The measured per-frame cost (ms) by part over the last 10 minutes, and the frame rate held."""
        if not self.frames:
            return "no frames played"
        sess = self.session
        per_decision = sess.timing_ms()
        mean = {k: float(np.mean(v)) for k, v in self.frame_ms.items() if v}
        p95 = float(np.percentile(self.frame_ms["frame"], 95))
        wall = time.perf_counter() - self.started
        lines = [f"played {self.frames} frames in {wall:.1f} s: {self.frames / wall:.1f} fps "
                 f"(target {sess.fps:g})",
                 f"per frame (ms, mean): total {mean['frame']:.2f} (p95 {p95:.2f}) = session step "
                 f"{mean['session']:.2f} + scene update {mean['scene']:.2f} + quality panel {mean['quality']:.2f}",
                 "per decision every %d frames (ms): policy %.2f, env + controller %.2f (controller: matching, "
                 "inertialization, IK %.2f)" % (sess.F, per_decision.get("policy", 0), per_decision.get(
                     "env_and_controller", 0), per_decision.get("controller", 0))]
        if sess.timing.get("click_to_decision"):
            lat = 1000.0 * np.asarray(sess.timing["click_to_decision"])
            lines.append(f"click -> decision (ms): mean {lat.mean():.0f}, max {lat.max():.0f} over {lat.size} clicks "
                         f"(+ one frame, {1000 / sess.fps:.0f} ms, to show)")
        return "\n".join(lines)
