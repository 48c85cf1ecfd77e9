"""Video and still images of characters: a shaded stick figure on a ground grid.

A small perspective camera (numpy) projects everything; matplotlib's Agg canvas only draws
2-d collections, whose data is replaced every frame (no figure rebuilds), so a frame costs a
few milliseconds. The camera looks at the character from a fixed direction and follows it
with some lag. Shown: the figure (bones as shaded capsules, depth-sorted, with a ground
shadow), the ground grid, the target(s) (discs of the success radius), obstacles (a list of
rectangles, drawn as low boxes) and each query's three future trajectory points with
their facing directions.

- :func:`render_frame`: one RGB image (gymnasium ``render()``);
- :func:`render_video`: MP4 (imageio-ffmpeg) or GIF from a recording (see
  :func:`mmrl.rollout.follow`);
- :func:`render_topdown`: the older top-down overview of many environments.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np

from ..errors import require_extra
from .camera import Camera
from ..io import atomic_path
from ..tasks.drawing import register_drawing

SKY = (0.86, 0.90, 0.95)
GROUND = (0.80, 0.80, 0.77)
GRID = (0.62, 0.62, 0.60)
QUERY = (0.1, 0.6, 0.2)
HIT_INSIDE, HIT_OUTSIDE = (0.9, 0.1, 0.1), (0.1, 0.75, 0.25)
OBSTACLE_SIDE, OBSTACLE_TOP = (0.45, 0.42, 0.5), (0.62, 0.60, 0.68)
OBSTACLE_HEIGHT = 0.3  # meters, drawing only: low enough to see the character and the sensors between them
OBSTACLE_VIEW_RADIUS = 16.0  # meters from the camera focus; farther boxes are not drawn
LEFT, RIGHT, CENTER = np.array([0.25, 0.45, 0.85]), np.array([0.90, 0.50, 0.20]), np.array([0.70, 0.70, 0.72])


#: Bone colors by side: center, left, right (RGB 0..1).
SIDE_COLORS = (CENTER, LEFT, RIGHT)


def skeleton_bones(parents: Sequence[int], body_joints: Optional[Sequence[int]] = None) -> np.ndarray:
    """(B, 2) (joint, parent) pairs of the drawn bones: both ends among ``body_joints`` (default all)."""
    parents = np.asarray(parents, np.int64)
    in_body = np.zeros(len(parents), bool)
    in_body[np.arange(len(parents)) if body_joints is None else np.asarray(body_joints, np.int64)] = True
    return np.array([(j, p) for j, p in enumerate(parents) if p >= 0 and in_body[j] and in_body[p]],
                    np.int64).reshape(-1, 2)


def joint_sides(joint_names: Sequence[str]) -> np.ndarray:
    """(J,) side of each joint from its name: 0 center, 1 left, 2 right, read as the joint roles
    read it (``_core.joint_side``: ``L``/``R``/``Left``/``Right`` tokens anywhere in the name)."""
    from .. import _core

    return np.array([_core.joint_side(n)[0] + 1 for n in joint_names], np.int64)


def _rectangle_corners(rect) -> np.ndarray:
    """(4, 2) world (x, z) corners of an obstacle: (x_min, z_min, x_max, z_max) or 4 corners."""
    r = np.asarray(rect, np.float64)
    if r.shape == (4,):
        x0, z0, x1, z1 = r
        return np.array([[x0, z0], [x1, z0], [x1, z1], [x0, z1]])
    if r.shape == (4, 2):
        return r
    raise ValueError(f"an obstacle is (x_min, z_min, x_max, z_max) or (4, 2) corners, got shape {r.shape}")


def _as_verts(polys: list):
    """Polygons for ``PolyCollection.set_verts``: one (n, k, 2) array when all have k vertices
    (matplotlib then builds the paths vectorized, several times faster), else the list."""
    if polys and all(len(p) == len(polys[0]) for p in polys):
        return np.asarray(polys)
    return polys


class Renderer:
    """Draws frames of one or more characters on a reusable matplotlib Agg canvas."""

    def __init__(self, parents: Sequence[int], *, body_joints: Optional[Sequence[int]] = None,
                 joint_names: Optional[Sequence[str]] = None, width: int = 640, height: int = 360,
                 follow_lag: float = 0.9, success_radius: float = 0.5, camera_distance: float = 5.5,
                 camera_elevation_deg: float = 22.0):
        matplotlib = require_extra("matplotlib", "viz", "rendering")
        matplotlib.use("Agg", force=False)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.collections import LineCollection, PolyCollection
        from matplotlib.figure import Figure

        self.parents = np.asarray(parents, np.int64)
        body = np.arange(len(self.parents)) if body_joints is None else np.asarray(body_joints, np.int64)
        self.bones = skeleton_bones(self.parents, body)
        self.body = body
        names = [n.lower() for n in (joint_names or [""] * len(self.parents))]
        side = joint_sides(names)
        self.bone_color = np.array([SIDE_COLORS[side[j]] for j, _ in self.bones]).reshape(-1, 3)
        self.head = next((j for j, n in enumerate(names) if "head" in n), None)
        self.camera = Camera(width, height, distance=camera_distance, elevation_deg=camera_elevation_deg)
        self.follow_lag = follow_lag
        self.success_radius = success_radius
        self._focus = None

        dpi = 100
        self.fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=SKY)
        self.canvas = FigureCanvasAgg(self.fig)
        ax = self.fig.add_axes((0, 0, 1, 1))
        ax.set_xlim(0, width)
        ax.set_ylim(0, height)
        ax.set_axis_off()
        ax.set_facecolor(SKY)
        self.ax = ax
        self.ground = PolyCollection([], facecolors=[GROUND], edgecolors="none", zorder=0)
        self.grid = LineCollection([], colors=[GRID], linewidths=0.8, zorder=1)
        self.targets = PolyCollection([], facecolors=[(0.85, 0.2, 0.2, 0.55)], edgecolors=[(0.6, 0.1, 0.1)],
                                      linewidths=1.0, zorder=2)
        self.shadow = LineCollection([], colors=[(0.3, 0.3, 0.3, 0.35)], capstyle="round", zorder=3)
        self.query = LineCollection([], colors=[(0.1, 0.6, 0.2)], linewidths=2.0, zorder=4)
        self.query_pts = ax.scatter([], [], s=30, c=[QUERY], edgecolors=[(0.1, 0.1, 0.1)], linewidths=0.5, zorder=6)
        # Occupied sensor cells are drawn over the obstacles that occupy them (zorder above).
        self.sensor_cells = PolyCollection([], facecolors=[(0.95, 0.55, 0.1, 0.6)], edgecolors="none", zorder=5.5)
        self.sensor_dots = ax.scatter([], [], s=2, c=[(0.35, 0.35, 0.4)], zorder=2)
        self.sensor_frame = LineCollection([], colors=[(0.95, 0.55, 0.1)], linewidths=1.0, zorder=2)
        self.obstacles = PolyCollection([], facecolors=[OBSTACLE_SIDE], edgecolors=[(0.2, 0.2, 0.25)],
                                        linewidths=0.6, zorder=5)
        self.outline = LineCollection([], colors=[(0.15, 0.15, 0.2)], capstyle="round", zorder=6)
        self.limbs = LineCollection([], capstyle="round", zorder=7)
        self.head_patch = ax.scatter([], [], s=1, c=[CENTER], edgecolors=[(0.15, 0.15, 0.2)], zorder=8)
        self.text = ax.text(8, height - 8, "", va="top", ha="left", fontsize=9, color=(0.2, 0.2, 0.25), zorder=9)
        for a in (self.ground, self.grid, self.targets, self.sensor_cells, self.sensor_frame, self.shadow, self.query,
                  self.obstacles, self.outline, self.limbs):
            ax.add_collection(a)

    # ------------------------------------------------------------------ drawing
    def _circle(self, center_xz, radius, y=0.01, n=28) -> np.ndarray:
        a = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return np.stack([center_xz[0] + radius * np.cos(a), np.full(n, y), center_xz[1] + radius * np.sin(a)], 1)

    def _ground_quads(self, quads: np.ndarray, y: float) -> tuple:
        """Horizontal quads (n, 4, 2) world (x, z) at height y -> as :meth:`_faces`."""
        return self._faces(np.concatenate([quads[..., :1], np.full(quads.shape[:-1] + (1,), y), quads[..., 1:]], -1))

    def _faces(self, faces: np.ndarray) -> tuple:
        """World polygons (n, k, 3) -> pixel polygons clipped at the near plane (hidden ones
        dropped), their mean camera depths and indices into ``faces``; vectorized where no
        clipping is needed."""
        cam = self.camera
        if len(faces) == 0:
            return [], np.zeros(0), np.zeros(0, np.int64)
        c = (faces - cam.eye) @ cam.rotation.T
        z = c[..., 2]
        front = (z > cam.near).all(1)
        partly = ~front & (z > cam.near).any(1)
        polys = list(cam.project(c[front]))
        depth = list(z[front].mean(1))
        index = list(np.flatnonzero(front))
        for i in np.flatnonzero(partly):
            pp = cam.polygon(faces[i])
            if pp is not None:
                polys.append(pp)
                depth.append(float(z[i].mean()))
                index.append(i)
        return polys, np.asarray(depth), np.asarray(index, np.int64)

    def _draw_obstacles(self, obstacles) -> None:
        """Boxes OBSTACLE_HEIGHT high: the faces that look at the camera, depth-sorted far to near."""
        if obstacles is None or len(obstacles) == 0:
            self.obstacles.set_verts([])
            return
        if isinstance(obstacles, np.ndarray) and obstacles.ndim == 3:
            corners = obstacles.astype(np.float64)
        else:
            corners = np.array([_rectangle_corners(r) for r in obstacles], np.float64)
        # Only boxes near the camera's focus matter (the ground drawn is 40 m wide).
        centre = corners.mean(1)
        near = np.hypot(centre[:, 0] - self._focus[0], centre[:, 1] - self._focus[2]) < OBSTACLE_VIEW_RADIUS
        corners = corners[near]
        n = len(corners)
        if n == 0:
            self.obstacles.set_verts([])
            return
        lo = np.concatenate([corners[..., :1], np.zeros((n, 4, 1)), corners[..., 1:]], -1)
        hi = lo + np.array([0.0, OBSTACLE_HEIGHT, 0.0])
        nxt = np.roll(np.arange(4), -1)
        sides = np.stack([lo, lo[:, nxt], hi[:, nxt], hi], 2)  # (n, 4 sides, 4 corners, 3)
        # A side faces the camera when its outward normal points toward the eye (corners may
        # wind either way, so outward = away from the box centre).
        mid = sides.mean(2)
        box_centre = lo.mean(1)[:, None]
        outward = mid - box_centre
        outward[..., 1] = 0.0
        facing = np.einsum("nsk,nsk->ns", outward, self.camera.eye - mid) > 0
        faces = np.concatenate([sides[facing], hi])
        shade = np.concatenate([np.full(int(facing.sum()), 0), np.ones(n, np.int64)])
        polys, depth, index = self._faces(faces)
        order = np.argsort(depth)[::-1]
        self.obstacles.set_verts(_as_verts([polys[i] for i in order]))
        self.obstacles.set_facecolor(np.array([OBSTACLE_SIDE, OBSTACLE_TOP])[shade[index[order]]])

    def _draw_sensors(self, sensors) -> None:
        """The sensor map's square outline, free sensors as dots, occupied cells as squares."""
        if sensors is None:
            self.sensor_cells.set_verts([])
            self.sensor_dots.set_offsets(np.zeros((0, 2)))
            self.sensor_frame.set_segments([])
            return
        pos = np.asarray(sensors["positions"], np.float64).reshape(-1, 2)
        occupied = np.asarray(sensors["map"], bool).reshape(-1)
        side = int(round(np.sqrt(len(pos))))
        grid = pos.reshape(side, side, 2)
        # Half pitch vectors along rows (forward) and columns (left), from neighbouring sensors.
        half_row = 0.5 * (grid[1, 0] - grid[0, 0])
        half_col = 0.5 * (grid[0, 1] - grid[0, 0])
        cam = self.camera
        cells = pos[occupied]
        q = np.stack([cells - half_row - half_col, cells - half_row + half_col, cells + half_row + half_col,
                      cells + half_row - half_col], 1) if len(cells) else np.zeros((0, 4, 2))
        polys, _, _ = self._ground_quads(0.9 * q + 0.1 * cells[:, None] if len(cells) else q, 0.015)
        self.sensor_cells.set_verts(_as_verts(polys))
        free = pos[~occupied]
        fc = cam.to_camera(np.column_stack([free[:, 0], np.full(len(free), 0.012), free[:, 1]]))
        vis = fc[:, 2] > cam.near
        self.sensor_dots.set_offsets(cam.project(fc[vis]) if vis.any() else np.zeros((0, 2)))
        a, b = grid[0, 0] - half_row - half_col, grid[0, -1] - half_row + half_col
        c, d = grid[-1, -1] + half_row + half_col, grid[-1, 0] + half_row - half_col
        ring = np.array([a, b, c, d])
        p3 = np.column_stack([ring[:, 0], np.full(4, 0.015), ring[:, 1]])
        self.sensor_frame.set_segments(cam.segments(p3, np.roll(p3, -1, axis=0)))

    def draw(self, positions: np.ndarray, *, targets=None, query_points=None, query_directions=None,
             obstacles=None, sensors=None, hit_inside=None, text: str = "", snap_camera: bool = False) -> np.ndarray:
        """One frame: positions (J, 3) world meters; returns (H, W, 3) uint8.

        obstacles: rectangles, each (x_min, z_min, x_max, z_max) or (4, 2) world corners, or an
        (n, 4, 2) array; sensors: ``{"positions": (16, 16, 2) world (x, z), "map": (16, 16)}``;
        hit_inside: (3,) bools coloring the query points (red inside an obstacle, green outside).
        """
        p = np.asarray(positions, np.float64)
        self._follow(p, snap_camera)
        self._draw_ground()
        self._draw_targets(targets)
        self._draw_obstacles(obstacles)
        self._draw_sensors(sensors)
        self._draw_queries(query_points, query_directions, hit_inside)
        self._draw_figure(p)
        self.text.set_text(text)

        self.canvas.draw()
        buf = np.asarray(self.canvas.buffer_rgba())
        return buf[..., :3].copy()

    def _follow(self, p: np.ndarray, snap: bool) -> None:
        """Aim the camera 0.9 m above the body's ground centre, with lag unless `snap`."""
        body = p[self.body]
        root = np.array([body[:, 0].mean(), 0.0, body[:, 2].mean()])
        focus = root + np.array([0.0, 0.9, 0.0])
        if self._focus is None or snap:
            self._focus = focus
        else:
            self._focus = self.follow_lag * self._focus + (1 - self.follow_lag) * focus
        self.camera.look_at(self._focus)

    def _draw_ground(self) -> None:
        """Ground and grid: a 40 m square around the focus, lines every meter."""
        cam = self.camera
        cx, cz = np.round(self._focus[[0, 2]])
        R = 20.0
        quad = np.array([[cx - R, 0, cz - R], [cx + R, 0, cz - R], [cx + R, 0, cz + R], [cx - R, 0, cz + R]])
        poly = cam.polygon(quad)
        self.ground.set_verts([] if poly is None else [poly])
        k = np.arange(-R, R + 1)
        a = np.concatenate([np.stack([cx + k, np.zeros_like(k), np.full_like(k, cz - R)], 1),
                            np.stack([np.full_like(k, cx - R), np.zeros_like(k), cz + k], 1)])
        b = np.concatenate([np.stack([cx + k, np.zeros_like(k), np.full_like(k, cz + R)], 1),
                            np.stack([np.full_like(k, cx + R), np.zeros_like(k), cz + k], 1)])
        self.grid.set_segments(cam.segments(a, b))

    def _draw_targets(self, targets) -> None:
        polys = []
        for t in ([] if targets is None else np.asarray(targets, np.float64).reshape(-1, 2)):
            pp = self.camera.polygon(self._circle(t, self.success_radius))
            if pp is not None:
                polys.append(pp)
        self.targets.set_verts(polys)

    def _draw_queries(self, query_points, query_directions, hit_inside) -> None:
        """Queries: three future points and their facing directions."""
        cam = self.camera
        if query_points is None:
            self.query_pts.set_offsets(np.zeros((0, 2)))
            self.query.set_segments([])
            return
        qp = np.asarray(query_points, np.float64).reshape(-1, 2)
        q3 = np.column_stack([qp[:, 0], np.full(len(qp), 0.02), qp[:, 1]])
        qc = cam.to_camera(q3)
        vis = qc[:, 2] > cam.near
        self.query_pts.set_offsets(cam.project(qc[vis]) if vis.any() else np.zeros((0, 2)))
        if hit_inside is None:
            self.query_pts.set_facecolors([QUERY])
        else:  # hit points: red inside an obstacle, green outside
            inside = np.asarray(hit_inside, bool).reshape(-1)[vis]
            self.query_pts.set_facecolors(np.where(inside[:, None], HIT_INSIDE, HIT_OUTSIDE))
        if query_directions is not None:
            qd = np.asarray(query_directions, np.float64).reshape(-1, 2)
            tips = q3 + 0.35 * np.column_stack([qd[:, 0], np.zeros(len(qd)), qd[:, 1]])
            self.query.set_segments(cam.segments(q3, tips))

    def _draw_figure(self, p: np.ndarray) -> None:
        """Figure: shadow, then bones far to near, outline under fill; widths by perspective."""
        cam = self.camera
        bones = self.bones
        pa, pb = p[bones[:, 0]], p[bones[:, 1]]
        shadow_a, shadow_b = pa * [1, 0, 1] + [0, 0.005, 0], pb * [1, 0, 1] + [0, 0.005, 0]
        self.shadow.set_segments(cam.segments(shadow_a, shadow_b))
        ca, cb = cam.to_camera(pa), cam.to_camera(pb)
        depth = 0.5 * (ca[:, 2] + cb[:, 2])
        order = np.argsort(depth)[::-1]
        width = np.clip(cam.focal * 0.07 / np.maximum(depth, cam.near), 1.0, 40.0)
        self.shadow.set_linewidths(width * 0.8)
        segs = np.stack([cam.project(ca), cam.project(cb)], 1)[order]
        d = cb - ca
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        light = np.array([0.4, 0.8, -0.45])
        light /= np.linalg.norm(light)
        shade = 0.55 + 0.45 * np.sqrt(np.clip(1 - (d @ light) ** 2, 0, 1))  # a capsule lit from the side
        colors = np.clip(self.bone_color * shade[:, None], 0, 1)[order]
        self.outline.set_segments(segs)
        self.outline.set_linewidths(width[order] + 2.0)
        self.limbs.set_segments(segs)
        self.limbs.set_linewidths(width[order])
        self.limbs.set_color(colors)
        if self.head is not None:
            hc = cam.to_camera(p[self.head][None] + [0, 0.08, 0])
            self.head_patch.set_offsets(cam.project(hc))
            self.head_patch.set_sizes([(cam.focal * 0.2 / max(hc[0, 2], cam.near)) ** 2])

def render_frame(positions: np.ndarray, parents: Sequence[int], *, body_joints=None, joint_names=None,
                 targets=None, query_points=None, query_directions=None, obstacles=None,
                 width: int = 640, height: int = 360, text: str = "") -> np.ndarray:
    """One RGB image (H, W, 3) uint8 of a pose (J, 3) in world meters (see :class:`Renderer`)."""
    r = Renderer(parents, body_joints=body_joints, joint_names=joint_names, width=width, height=height)
    return r.draw(positions, targets=targets, query_points=query_points, query_directions=query_directions,
                  obstacles=obstacles, text=text, snap_camera=True)


def render_state(db, state: dict, *, width: int = 640, height: int = 360) -> np.ndarray:
    """An env state (``env_state()``: root x, z, yaw, database frame, target) as one RGB image.

    The database pose of the frame is placed at the root by the map from the frame's
    character frame to the world root (no inertialization or IK: the env's fast path keeps no
    pose history).
    """
    from .. import _core
    from ..metrics import body_joints

    f = int(state["frame"])
    q = _core.database_global_positions(db._db, np.array([f], np.int64))[0].astype(np.float64)
    a = float(state["yaw"]) - float(db.root_yaws[f])
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    p = (q - db.root_positions[f]) @ rot.T + np.array([state["x"], 0.0, state["z"]])
    return render_frame(p, db.parents, body_joints=body_joints(db), joint_names=db.joint_names,
                        targets=state.get("target"), obstacles=state.get("obstacles"), width=width, height=height,
                        text=f"step {state.get('steps', 0)}")


def render_video(path: "str | os.PathLike[str]", recording: Dict[str, np.ndarray], db, *, obstacles=None,
                 width: int = 640, height: int = 360, fps: Optional[float] = None,
                 success_radius: float = 0.5, still: "str | os.PathLike[str] | None" = None,
                 still_frame: Optional[int] = None) -> int:
    """Write a recording (see :func:`mmrl.rollout.follow`) as ``.mp4`` or ``.gif``.

    A moving-obstacles recording (:func:`mmrl.rollout.follow` on the obstacles task) also
    shows its per-frame ``obstacles``, each decision's sensor map (``sensor_positions``,
    ``sensor_maps``) and hit points colored by ``hit_inside``; the camera snaps at each new
    ``episode``. ``still``: also write frame ``still_frame`` (default: the middle one) as an
    image, exactly as in the video. Returns the number of frames written.
    """
    iio = require_extra("imageio.v2", "viz", "writing videos")
    require_extra("imageio_ffmpeg", "viz", "writing videos")

    from ..metrics import body_joints

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".mp4", ".gif"):
        raise ValueError(f"{path}: the output must end in .mp4 or .gif")
    pos = recording["positions"]
    fps = float(fps or recording.get("fps", db.fps))
    if suffix == ".mp4":  # H.264 with 4:2:0 chroma needs even sizes
        width, height = width - width % 2, height - height % 2
    qframes = recording.get("query_frames")
    frame_obstacles = recording.get("obstacles")
    # Obstacle scenes: a higher, farther camera shows the layout around the character.
    view = dict(camera_distance=8.0, camera_elevation_deg=40.0) if frame_obstacles is not None else {}
    renderer = Renderer(db.parents, body_joints=body_joints(db), joint_names=db.joint_names, width=width,
                        height=height, success_radius=success_radius, **view)
    path.parent.mkdir(parents=True, exist_ok=True)
    still_image = None
    with atomic_path(path) as tmp:  # a video is complete or absent, never half written
        if suffix == ".mp4":
            writer = iio.get_writer(str(tmp), fps=fps, codec="libx264", quality=7, macro_block_size=2,
                                    ffmpeg_log_level="error", pixelformat="yuv420p")
        else:
            writer = iio.get_writer(str(tmp), mode="I", duration=1000.0 / fps, loop=0)
        q = -1
        try:
            for t in range(pos.shape[0]):
                if qframes is not None:
                    while q + 1 < len(qframes) and qframes[q + 1] <= t:
                        q += 1
                img = _draw_recording_frame(renderer, recording, t, q, fps, obstacles)
                writer.append_data(img)
                if still is not None and t == (pos.shape[0] // 2 if still_frame is None else still_frame):
                    still_image = img
        finally:
            writer.close()
    if still_image is not None:
        with atomic_path(still) as tmp:
            iio.imwrite(str(tmp), still_image)
    return pos.shape[0]


def recording_frame(recording: Dict[str, np.ndarray], t: int, q: int) -> Dict[str, object]:
    """What frame t of a recording shows (the video and the browser viewer draw the same):
    ``positions`` (J, 3), ``targets``, ``obstacles`` ((n, 4, 2) world corners or None), and
    of decision q (shown only within its own episode, else None): ``query_points``,
    ``query_directions`` (3, 2), ``sensors`` ({positions, map}) and ``hit_inside`` (3,);
    ``new_episode`` is True on an episode's first frame."""
    episode = recording.get("episode")
    qframes = recording.get("query_frames")
    frame_obstacles = recording.get("obstacles")
    targets = recording.get("targets")
    has_q = q >= 0 and (episode is None or episode[qframes[q]] == episode[t])
    sensors = None
    if has_q and "sensor_maps" in recording:
        sensors = {"positions": recording["sensor_positions"][q], "map": recording["sensor_maps"][q]}
    return {"positions": recording["positions"][t], "targets": None if targets is None else targets[t],
            "query_points": recording["query_points"][q] if has_q else None,
            "query_directions": recording["query_directions"][q] if has_q else None,
            "obstacles": frame_obstacles[t] if frame_obstacles is not None else None, "sensors": sensors,
            "hit_inside": recording["hit_inside"][q] if has_q and "hit_inside" in recording else None,
            "new_episode": t == 0 or (episode is not None and episode[t] != episode[t - 1])}


def _draw_recording_frame(renderer: "Renderer", recording: Dict[str, np.ndarray], t: int, q: int, fps: float,
                          obstacles) -> np.ndarray:
    """Frame t of a recording, with decision q's query (see :func:`recording_frame`)."""
    shown = recording_frame(recording, t, q)
    episode = recording.get("episode")
    text = f"{t / fps:5.2f} s"
    if episode is not None:
        text += f"   episode {int(episode[t]) + 1}"
    new_episode = shown.pop("new_episode")
    if shown["obstacles"] is None:
        shown["obstacles"] = obstacles
    return renderer.draw(shown.pop("positions"), text=text, snap_camera=new_episode, **shown)


def render_topdown(states, size: int = 256, extent: float = 8.0) -> np.ndarray:
    """A simple top-down RGB image of characters (dots and headings) and their targets."""
    img = np.full((size, size, 3), 235, np.uint8)

    def px(x, z):
        return int(size / 2 - x / extent * size / 2), int(size / 2 - z / extent * size / 2)

    for s in states:
        tx, tz = s["target"]
        u, v = px(tx, tz)
        img[max(0, v - 3):v + 4, max(0, u - 3):u + 4] = (220, 40, 40)
        u, v = px(s["x"], s["z"])
        img[max(0, v - 3):v + 4, max(0, u - 3):u + 4] = (40, 40, 200)
    return img


register_drawing("topdown", render_topdown)
register_drawing("state", render_state)
