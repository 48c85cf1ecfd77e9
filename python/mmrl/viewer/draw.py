"""What the browser viewer draws for one frame, on a :class:`~mmrl.viewer.scene.Scene`.

The same shown values as the MP4 renderer (:func:`mmrl.viz.render.recording_frame`): the figure
as shaded limbs, one capsule per bone sized from its length (:func:`limb_radii`), colored by side
(:func:`mmrl.viz.render.skeleton_bones`, :func:`mmrl.viz.render.joint_sides`), and a head,
the target as a ring of the success radius, obstacles as low boxes, the sensor map (occupied
cells orange), the policy's three trajectory points with their facing directions (green, red
when inside an obstacle) and the matched frame's three (blue), in ``mmrl play`` the played clip's
own path if it continued (violet, red from where the collision-aware search's test finds it
inside an obstacle), and foot contacts (a dot under each planted ankle). World meters, Y up.
"""
from __future__ import annotations

from typing import Dict, Optional, Sequence

import numpy as np

from ..viz.render import OBSTACLE_HEIGHT, SIDE_COLORS, joint_sides, skeleton_bones

TARGET = (0.85, 0.2, 0.2)
QUERY = (0.1, 0.6, 0.2)
MATCHED = (0.15, 0.35, 0.85)
HIT_INSIDE = (0.9, 0.1, 0.1)
OBSTACLE = (0.55, 0.52, 0.62)
SENSOR_FREE, SENSOR_OCCUPIED = (0.55, 0.55, 0.6), (0.95, 0.55, 0.1)
CONTACT = (0.95, 0.75, 0.1)
TRAJECTORY = (0.35, 0.35, 0.45)
CONTINUATION = (0.6, 0.45, 0.8)
#: Camera offset from the character (meters): close behind it, or higher above an obstacle
#: scene (as the MP4 renderer does) so the boxes do not hide it.
CAMERA_OFFSET, CAMERA_OFFSET_OBSTACLES = (2.6, 1.1, 2.6), (3.0, 4.0, 3.0)
LIFT = 0.01  # meters above the ground for flat marks, so they do not flicker against the grid


def _flat(xz: np.ndarray, y: float = LIFT) -> np.ndarray:
    xz = np.asarray(xz, np.float64).reshape(-1, 2)
    return np.column_stack([xz[:, 0], np.full(len(xz), y), xz[:, 1]])


def ring(center_xz, radius: float, n: int = 32) -> np.ndarray:
    """(n, 2, 3) segments of a circle of ``radius`` meters on the ground around ``center_xz``."""
    a = np.linspace(0, 2 * np.pi, n + 1)
    p = _flat(np.column_stack([center_xz[0] + radius * np.cos(a), center_xz[1] + radius * np.sin(a)]))
    return np.stack([p[:-1], p[1:]], 1)


def arrow(start_xz, yaw: float, length: float) -> np.ndarray:
    """(3, 2, 3) segments of an arrow on the ground from ``start_xz`` along world yaw ``yaw``
    (forward = (sin yaw, cos yaw)): its shaft and two barbs."""
    f = np.array([np.sin(yaw), np.cos(yaw)])
    tip = np.asarray(start_xz, np.float64) + length * f
    side = np.array([f[1], -f[0]])
    barbs = [tip - 0.2 * length * f + s * 0.12 * length * side for s in (1.0, -1.0)]
    pts = _flat(np.array([start_xz, tip, barbs[0], barbs[1]], np.float64))
    return np.stack([pts[[0, 1, 1]], pts[[1, 2, 3]]], 1)


def capsule_mesh(length: float, radius: float, sides: int = 10, cap_rings: int = 3):
    """Vertices (V, 3) and faces (F, 3) of a capsule along +Z from 0 to ``length`` meters: a
    cylinder of ``radius`` closed by half spheres around both ends."""
    a = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    rings = []  # (z, radius) from the bottom pole's first ring to the top pole's last
    for k in range(cap_rings, 0, -1):
        t = np.pi / 2 * k / (cap_rings + 1)
        rings.append((-radius * np.sin(t), radius * np.cos(t)))
    rings += [(0.0, radius), (length, radius)]
    for k in range(1, cap_rings + 1):
        t = np.pi / 2 * k / (cap_rings + 1)
        rings.append((length + radius * np.sin(t), radius * np.cos(t)))
    verts = [[0.0, 0.0, -radius]]
    for z, r in rings:
        verts += [[r * np.cos(x), r * np.sin(x), z] for x in a]
    verts.append([0.0, 0.0, length + radius])
    faces = [[0, 1 + (i + 1) % sides, 1 + i] for i in range(sides)]
    for k in range(len(rings) - 1):
        b, c = 1 + k * sides, 1 + (k + 1) * sides
        for i in range(sides):
            j = (i + 1) % sides
            faces += [[b + i, b + j, c + j], [b + i, c + j, c + i]]
    top, last = len(verts) - 1, 1 + (len(rings) - 1) * sides
    faces += [[last + i, last + (i + 1) % sides, top] for i in range(sides)]
    return np.asarray(verts, np.float32), np.asarray(faces, np.uint32)


def limb_radii(lengths: np.ndarray, torso: np.ndarray, hip_width: float) -> np.ndarray:
    """Radius (m) of each bone's capsule: limbs a sixth of their length (2.5 to 6 cm); the torso's
    bones (hips to head) a third of the hip width, so a short spine segment is not a thread."""
    r = np.clip(np.asarray(lengths, np.float64) / 6.0, 0.025, 0.06)
    return np.where(np.asarray(torso, bool), np.clip(hip_width / 3.0, 0.04, 0.12), r)


def rotation_from_z(d: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (w, x, y, z) turning +Z onto each of the (N, 3) directions."""
    d = np.asarray(d, np.float64)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where(n > 1e-9, d / np.maximum(n, 1e-9), [0.0, 0.0, 1.0])
    w = 1.0 + d[:, 2]
    q = np.column_stack([w, -d[:, 1], d[:, 0], np.zeros(len(d))])  # (1 + z.d, z x d)
    flip = w < 1e-6  # straight down: half a turn about X
    q[flip] = [0.0, 1.0, 0.0, 0.0]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def box_mesh(corners: np.ndarray, height: float = OBSTACLE_HEIGHT):
    """Vertices (8n, 3) and faces (10n, 3) of boxes ``height`` m high over (n, 4, 2) ground corners
    (sides and top; the bottom lies on the ground)."""
    c = np.asarray(corners, np.float64).reshape(-1, 4, 2)
    n = len(c)
    lo = np.concatenate([c[..., :1], np.zeros((n, 4, 1)), c[..., 1:]], -1)
    hi = lo + np.array([0.0, height, 0.0])
    verts = np.concatenate([lo, hi], 1).reshape(-1, 3)
    one = [[k, (k + 1) % 4, 4 + (k + 1) % 4] for k in range(4)] + [[k, 4 + (k + 1) % 4, 4 + k] for k in range(4)]
    one += [[4, 5, 6], [4, 6, 7]]
    faces = (np.array(one)[None] + 8 * np.arange(n)[:, None, None]).reshape(-1, 3)
    return verts, faces


class Painter:
    """Draws frames of one character (and its task's scene) on a Scene."""

    def __init__(self, scene, parents: Sequence[int], joint_names: Sequence[str], *,
                 body_joints: Optional[Sequence[int]] = None, feet: Optional[Sequence[int]] = None,
                 success_radius: float = 0.5, root: str = ""):
        self.scene = scene
        self.root = root  # scene-tree parent of every node ("/world" when the export moves the world)
        self.bones = skeleton_bones(parents, body_joints)
        side = joint_sides(joint_names)
        self.bone_colors = np.array([SIDE_COLORS[side[j]] for j, _ in self.bones], np.float32).reshape(-1, 3)
        names = [n.lower() for n in joint_names]
        self.head = next((j for j, n in enumerate(names) if "head" in n), None)
        self.parents = np.asarray(parents, np.int64)
        self.names = names
        self.limbs: Optional[np.ndarray] = None  # per bone (length, radius), from the first pose shown
        self.feet = None if feet is None else np.asarray(feet, np.int64)
        self.success_radius = float(success_radius)

    def _limb_sizes(self, p: np.ndarray) -> np.ndarray:
        """(B, 2) length and radius of each bone's capsule, from the first pose shown (bone lengths
        do not change: the skeleton is rigid, and leg IK keeps them)."""
        lengths = np.linalg.norm(p[self.bones[:, 0]] - p[self.bones[:, 1]], axis=1)
        torso_joints = set()
        j = self.head
        while j is not None and j >= 0:  # the chain from the head up to the root
            torso_joints.add(int(j))
            j = int(self.parents[j]) if self.parents[j] >= 0 else None
        torso = np.array([int(a) in torso_joints and int(b) in torso_joints for a, b in self.bones], bool)
        legs = [j for j, n in enumerate(self.names) if ("upleg" in n or "thigh" in n or "upperleg" in n)]
        hip_width = float(np.linalg.norm(p[legs[0]] - p[legs[1]])) if len(legs) >= 2 else 0.2
        return np.column_stack([lengths, limb_radii(lengths, torso, hip_width)])

    def figure(self, positions: np.ndarray) -> None:
        """The body as one shaded capsule per bone (created once, then only moved), and the head."""
        p = np.asarray(positions, np.float64)
        if self.limbs is None:
            self.limbs = self._limb_sizes(p)
            for b, (length, radius) in enumerate(self.limbs):
                v, f = capsule_mesh(float(length), float(radius))
                self.scene.body_part(f"{self.root}/figure/limb{b}", v, f, self.bone_colors[b])
            if self.head is not None:
                size = float(np.median(self.limbs[:, 1])) * 2.2
                v, f = capsule_mesh(size * 0.4, size)
                self.scene.body_part(f"{self.root}/figure/head", v, f, (0.8, 0.78, 0.74))
        start, end = p[self.bones[:, 1]], p[self.bones[:, 0]]  # parent -> joint
        q = rotation_from_z(end - start)
        for b in range(len(self.bones)):
            self.scene.move(f"{self.root}/figure/limb{b}", start[b], q[b])
        if self.head is not None:
            self.scene.move(f"{self.root}/figure/head", p[self.head] + [0, 0.05, 0], (1.0, 0.0, 0.0, 0.0))

    def contacts(self, positions: np.ndarray, contacts: Optional[np.ndarray]) -> None:
        if self.feet is None or contacts is None:
            return
        planted = np.asarray(contacts, bool).reshape(2)
        ankles = np.asarray(positions, np.float64)[self.feet][planted]
        self.scene.points(self.root + "/figure/contacts", _flat(ankles[:, [0, 2]], 0.05), CONTACT, size=0.1)

    def target(self, target, facing: Optional[float] = None) -> None:
        """The target's ring, and an arrow along its facing (world yaw, radians) when it has one."""
        if target is None:
            self.scene.visible(self.root + "/target", False)
            return
        t = np.asarray(target, np.float64).reshape(-1, 2)[0]
        marks = np.concatenate([ring(t, self.success_radius), ring(t, 0.05, 8)]
                               + ([arrow(t, float(facing), 0.8)] if facing is not None else []))
        self.scene.lines(self.root + "/target", marks, TARGET, thickness=0.04)
        self.scene.visible(self.root + "/target", True)

    def obstacles(self, corners: Optional[np.ndarray]) -> None:
        if corners is None:
            return
        v, f = box_mesh(corners)
        self.scene.mesh(self.root + "/obstacles", v, f, OBSTACLE, opacity=0.85)

    def sensors(self, sensors: Optional[Dict[str, np.ndarray]]) -> None:
        if sensors is None:
            return
        pos = _flat(np.asarray(sensors["positions"]).reshape(-1, 2), 0.03)
        occupied = np.asarray(sensors["map"], bool).reshape(-1)
        colors = np.where(occupied[:, None], SENSOR_OCCUPIED, SENSOR_FREE)
        self.scene.points(self.root + "/sensors", pos, colors, size=0.05)

    def queries(self, name: str, points, directions, color, hit_inside=None) -> None:
        """Three trajectory points (3, 2) with facing directions (3, 2), world (x, z); None hides them."""
        if points is None:
            self.scene.visible(name + "/points", False)
            self.scene.visible(name + "/directions", False)
            return
        p = _flat(points, 0.05)  # discs face the camera: lifted by their radius to sit on the ground
        colors = np.tile(np.asarray(color, np.float64), (len(p), 1))
        if hit_inside is not None:
            colors[np.asarray(hit_inside, bool).reshape(-1)] = HIT_INSIDE
        self.scene.points(name + "/points", p, colors, size=0.1)
        if directions is not None:
            tips = p + 0.35 * _flat(directions, 0.0)
            self.scene.lines(name + "/directions", np.stack([p, tips], 1), colors, thickness=0.02)
        self.scene.visible(name + "/points", True)
        self.scene.visible(name + "/directions", True)

    def continuation(self, path: Optional[Dict[str, np.ndarray]]) -> None:
        """The clip's own path if it continued (``points`` (9, 2) world (x, z), ``inside`` (9,)
        red from the collision-aware search's first hit on); None hides it."""
        name = self.root + "/continuation"
        if path is None:
            self.scene.visible(name, False)
            return
        p = _flat(path["points"], 0.03)
        colors = np.tile(np.asarray(CONTINUATION, np.float64), (len(p), 1))
        colors[np.asarray(path["inside"], bool).reshape(-1)] = HIT_INSIDE
        self.scene.points(name, p, colors, size=0.06)
        self.scene.visible(name, True)

    def trajectory(self, xz: np.ndarray) -> None:
        """The root's path over the ground, (T, 2) world (x, z)."""
        p = _flat(np.asarray(xz, np.float64)[::2], 0.005)
        segments = np.stack([p[:-1], p[1:]], 1) if len(p) > 1 else np.zeros((0, 2, 3))
        self.scene.lines(self.root + "/trajectory", segments, TRAJECTORY, thickness=0.015)

    def show(self, shown: Dict[str, object]) -> None:
        """One frame of :func:`mmrl.viz.render.recording_frame` (plus ``contacts`` and the matched
        frame's ``match_points`` / ``match_directions``, when present)."""
        with self.scene.atomic():
            self.figure(shown["positions"])
            self.contacts(shown["positions"], shown.get("contacts"))
            if "targets" in shown:
                self.target(shown["targets"], shown.get("facing"))
            self.obstacles(shown.get("obstacles"))
            self.sensors(shown.get("sensors"))
            if "query_points" in shown:
                self.queries(self.root + "/query", shown["query_points"], shown.get("query_directions"), QUERY,
                             shown.get("hit_inside"))
            if "continuation_path" in shown:
                self.continuation(shown["continuation_path"])
            if "match_points" in shown:
                self.queries(self.root + "/matched", shown["match_points"], shown.get("match_directions"), MATCHED)
