"""The one module that calls viser (``mmrl[viewer]``): a change in viser's API touches this file only.

:class:`Scene` is a viser server with what mmrl draws: a ground grid, line segments (bones,
trajectories, obstacle outlines), point sets (sensors, contacts), boxes as meshes, a drag
gizmo, ground clicks, a few GUI controls (:class:`Control`), and recording to a standalone
HTML page. World space is mmrl's: meters, Y up, the ground at y = 0.

The server binds 127.0.0.1 unless told otherwise; a busy port is replaced by the next free
one (viser's own search), and :attr:`Scene.port` says which. viser's share-URL service is
never called.
"""
from __future__ import annotations

import contextlib
import io
import ipaddress
import warnings
from typing import Callable, Optional, Sequence

import numpy as np

from ..errors import InputError, require_extra

LOCALHOST = "127.0.0.1"


def check_port(port: int) -> int:
    if not isinstance(port, int) or not 0 <= port <= 65535:
        raise InputError(f"--port must be an integer in 0..65535, got {port!r}")
    return port


def check_host(host: str) -> str:
    """``host`` if it is an IP address or 'localhost'; warns when it opens the viewer beyond this machine."""
    if host != "localhost":
        try:
            addr = ipaddress.ip_address(host)
        except ValueError:
            raise InputError(f"--host must be an IP address, got {host!r}") from None
        if not addr.is_loopback:
            warnings.warn(f"the viewer is served on {host}: anyone who can reach this machine can watch and steer "
                          f"it (there is no authentication)", UserWarning, stacklevel=2)
    return host


class Control:
    """A GUI control: ``value`` (read and write) and ``on_change(fn)`` (``fn()`` after a user edit)."""

    def __init__(self, handle):
        self._handle = handle

    @property
    def value(self):
        return self._handle.value

    @value.setter
    def value(self, v) -> None:
        self._handle.value = v

    def on_change(self, fn: Callable[[], None]) -> None:
        """``fn()`` after a user's edit (a button press), not after a ``value`` set by code."""
        if hasattr(self._handle, "on_click"):
            self._handle.on_click(lambda _event: fn())
        else:
            self._handle.on_update(lambda event: fn() if event.client is not None else None)

    def set_range(self, low: float, high: float) -> None:
        self._handle.min, self._handle.max = low, high

    def set_options(self, options: Sequence[str]) -> None:
        self._handle.options = tuple(options)

    def set_text(self, text: str) -> None:
        self._handle.content = text

    def set_label(self, label: str) -> None:
        self._handle.label = label


class Recording:
    """Scene updates recorded with timestamps, written as one standalone HTML page."""

    def __init__(self, serializer):
        self._serializer = serializer

    def sleep(self, seconds: float) -> None:
        """Advance the recording's clock (the playback bar's time) by ``seconds``."""
        self._serializer.insert_sleep(float(seconds))

    def html(self) -> str:
        """The page: viser's built client (one self-contained file in the wheel) plus the
        recording inlined as base64, so it opens from file:// with no network."""
        return self._serializer.as_html()


class Scene:
    """A viser server drawing mmrl's scene. ``close()`` stops it."""

    def __init__(self, host: str = LOCALHOST, port: int = 8080, *, title: str = "mmrl"):
        viser = require_extra("viser", "viewer", "the browser viewer")
        check_port(port)
        host = check_host(host)
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner; the command prints the address
            self.server = viser.ViserServer(host=host, port=port, label=title, verbose=False)
        # A client may ask for a share URL (a tunnel through viser's servers): never.
        self.server.request_share_url = lambda *_args, **_kwargs: None
        self.host = host
        self.port = int(self.server.get_port())
        self.server.scene.set_up_direction("+y")
        self.server.gui.configure_theme(control_width="medium", show_share_button=False)
        self._nodes = {}
        self._placed = set()  # clients whose camera was placed
        self._ground_pick = None  # the quad ground drags start on (on_ground_drag)

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        return f"http://{host}:{self.port}/"

    def close(self) -> None:
        self.server.stop()

    def atomic(self):
        """Updates inside ``with scene.atomic():`` reach the browser together (one frame)."""
        return self.server.atomic()

    # ------------------------------------------------------------------ scene objects
    def ground(self, size: float = 60.0, name: str = "/ground") -> None:
        """A ground grid of ``size`` meters, lines every 0.5 m, sections every 1 m, on y = 0."""
        self.server.scene.add_grid(name, size, size, plane="xz", cell_size=0.5, section_size=1.0,
                                   plane_color=(236, 236, 230), plane_opacity=1.0, shadow_opacity=0.0)

    def camera(self, position: Sequence[float], look_at: Sequence[float]) -> None:
        """Initial camera of every client (world meters)."""
        cam = self.server.initial_camera
        cam.position = tuple(float(v) for v in position)
        cam.look_at = tuple(float(v) for v in look_at)

    def follow(self, look_at: Sequence[float], offset: Sequence[float] = (2.6, 1.1, 2.6)) -> None:
        """Translate every client's camera so it looks at ``look_at`` (world meters), keeping
        the view the user orbited to; a client seen for the first time gets ``offset``."""
        target = np.asarray(look_at, np.float64)
        for client_id, client in self.server.get_clients().items():
            cam = client.camera
            with client.atomic():
                if client_id not in self._placed:
                    self._placed.add(client_id)
                    cam.position = tuple(target + np.asarray(offset, np.float64))
                    cam.look_at = tuple(target)
                else:  # the position setter moves look_at along
                    cam.position = tuple(np.asarray(cam.position) + target - np.asarray(cam.look_at))

    def lines(self, name: str, segments: np.ndarray, colors, thickness: float = 0.02) -> None:
        """Line segments (N, 2, 3) world meters; colors one RGB 0..1 or (N, 3); thickness in meters.
        The first call creates the node, the next ones update it."""
        seg = np.asarray(segments, np.float32).reshape(-1, 2, 3)
        col = np.asarray(colors, np.float32)
        if col.ndim == 2:
            col = np.repeat(col[:, None, :], 2, axis=1)
        if len(seg) == 0:  # viser needs one segment: a zero-length one is invisible
            seg, col = np.zeros((1, 2, 3), np.float32), np.zeros(3, np.float32)
        col_u8 = np.clip(col * 255.0, 0, 255).astype(np.uint8)
        node = self._nodes.get(name)
        if node is not None and node[0] == "lines" and node[2] == seg.shape[0]:
            node[1].points = seg
            node[1].colors = col_u8
            return
        handle = self.server.scene.add_line_segments(name, seg, col_u8, thickness=thickness)
        self._nodes[name] = ("lines", handle, seg.shape[0])

    def points(self, name: str, points: np.ndarray, colors, size: float = 0.05) -> None:
        """Points (N, 3) world meters drawn as discs of ``size`` meters; colors RGB 0..1 or (N, 3)."""
        p = np.asarray(points, np.float32).reshape(-1, 3)
        col = np.broadcast_to(np.asarray(colors, np.float32), p.shape) if len(p) else np.zeros((0, 3), np.float32)
        if len(p) == 0:
            p, col = np.full((1, 3), -1000.0, np.float32), np.zeros((1, 3), np.float32)  # out of sight
        col_u8 = np.clip(np.asarray(col) * 255.0, 0, 255).astype(np.uint8)
        node = self._nodes.get(name)
        if node is not None and node[0] == "points" and node[2] == p.shape[0]:
            node[1].points = p
            node[1].colors = col_u8
            return
        handle = self.server.scene.add_point_cloud(name, p, col_u8, point_size=size, point_shape="circle",
                                                   precision="float32")
        self._nodes[name] = ("points", handle, p.shape[0])

    def mesh(self, name: str, vertices: np.ndarray, faces: np.ndarray, color, opacity: float = 1.0) -> None:
        """A triangle mesh (V, 3) world meters, faces (F, 3); recreated when the face count changes."""
        v = np.asarray(vertices, np.float32).reshape(-1, 3)
        f = np.asarray(faces, np.uint32).reshape(-1, 3)
        if len(f) == 0:
            v, f = np.full((3, 3), -1000.0, np.float32), np.array([[0, 1, 2]], np.uint32)
        node = self._nodes.get(name)
        if node is not None and node[0] == "mesh" and node[2] == f.shape[0]:
            node[1].vertices = v
            return
        rgb = tuple(int(255 * c) for c in color)
        handle = self.server.scene.add_mesh_simple(name, v, f, color=rgb, opacity=None if opacity >= 1 else opacity,
                                                   flat_shading=True, side="double")
        self._nodes[name] = ("mesh", handle, f.shape[0])

    def body_part(self, name: str, vertices: np.ndarray, faces: np.ndarray, color) -> None:
        """A smooth-shaded mesh in its own frame (vertices (V, 3) meters, faces (F, 3)), placed
        later by :meth:`move`: the limbs of the figure, sent once."""
        self.remove(name)
        rgb = tuple(int(255 * c) for c in color)
        handle = self.server.scene.add_mesh_simple(name, np.asarray(vertices, np.float32),
                                                   np.asarray(faces, np.uint32), color=rgb, flat_shading=False)
        self._nodes[name] = ("part", handle, 0)

    def move(self, name: str, position: Sequence[float], wxyz: Sequence[float]) -> None:
        """Places a node made by :meth:`body_part`: its origin at ``position`` (world meters),
        turned by the unit quaternion ``wxyz``."""
        node = self._nodes.get(name)
        if node is None:
            raise KeyError(f"no scene node {name!r}")
        node[1].position = tuple(float(v) for v in position)
        node[1].wxyz = tuple(float(v) for v in wxyz)

    def frame(self, name: str, position: Sequence[float]) -> None:
        """A parent node at ``position`` (world meters): its children move with it."""
        node = self._nodes.get(name)
        pos = tuple(float(v) for v in position)
        if node is None:
            handle = self.server.scene.add_frame(name, show_axes=False, position=pos)
            self._nodes[name] = ("frame", handle, 0)
        else:
            node[1].position = pos

    def visible(self, name: str, on: bool) -> None:
        node = self._nodes.get(name)
        if node is not None:
            node[1].visible = bool(on)

    def gizmo(self, name: str, position: Sequence[float], on_move: Callable[[float, float], None]) -> None:
        """A drag gizmo moving in the ground plane; ``on_move(x, z)`` after each drag update."""
        self.remove(name)
        handle = self.server.scene.add_transform_controls(
            name, scale=0.8, active_axes=(True, False, True), disable_rotations=True, disable_sliders=False,
            depth_test=False, position=tuple(float(v) for v in position))

        @handle.on_update
        def _(_event) -> None:
            x, _y, z = handle.position
            on_move(float(x), float(z))

        self._nodes[name] = ("gizmo", handle, 0)

    def remove(self, name: str) -> None:
        node = self._nodes.pop(name, None)
        if node is not None:
            node[1].remove()

    def on_ground_click(self, fn: Callable[[float, float], None], *, shift: bool = False) -> None:
        """``fn(x, z)``: the world point where a click's ray meets the ground (y = 0); clicks that
        miss the ground (at or above the horizon) are ignored. ``shift``: shift-clicks only."""
        @self.server.scene.on_click(modifier="shift" if shift else None)
        def _(event) -> None:
            hit = ground_hit(event.ray_origin, event.ray_direction)
            if hit is not None:
                fn(*hit)

    def on_ground_drag(self, fn: Callable[[str, tuple, tuple], None], *, shift: bool = True) -> None:
        """``fn(phase, start, end)`` while the user drags over the ground (``shift``: with shift
        held, so a plain drag still orbits the camera): ``phase`` "start", "update" or "end",
        ``start`` the world (x, z) where the drag began, ``end`` where the pointer's ray meets
        the ground now (updates whose ray misses the ground are ignored; a start or an end that
        misses it comes with ``end`` = ``start``)."""
        if self._ground_pick is None:  # an invisible quad the drags start on (a grid takes no pointer)
            h = 500.0
            v = np.array([[-h, -1e-3, -h], [h, -1e-3, -h], [h, -1e-3, h], [-h, -1e-3, h]], np.float32)
            f = np.array([[0, 2, 1], [0, 3, 2]], np.uint32)
            self._ground_pick = self.server.scene.add_mesh_simple("/ground_pick", v, f, opacity=0.0,
                                                                  side="double")

        @self._ground_pick.on_drag("left", modifier="shift" if shift else None)
        def _(event) -> None:
            # end_position lies on the pointer's ray (on a plane facing the camera): the ray is
            # the camera's position toward it.
            cam = np.asarray(event.client.camera.position, np.float64)
            end = ground_hit(cam, np.asarray(event.end_position, np.float64) - cam)
            if end is not None or event.phase != "update":
                fn(event.phase, (float(event.start_position[0]), float(event.start_position[2])),
                   end if end is not None else (float(event.start_position[0]), float(event.start_position[2])))

    # ------------------------------------------------------------------ GUI
    def folder(self, label: str):
        return self.server.gui.add_folder(label)

    def button(self, label: str) -> Control:
        return Control(self.server.gui.add_button(label))

    def checkbox(self, label: str, value: bool) -> Control:
        return Control(self.server.gui.add_checkbox(label, initial_value=bool(value)))

    def slider(self, label: str, low: float, high: float, step: float, value: float) -> Control:
        return Control(self.server.gui.add_slider(label, min=low, max=high, step=step, initial_value=value))

    def dropdown(self, label: str, options: Sequence[str], value: Optional[str] = None) -> Control:
        options = tuple(options)
        return Control(self.server.gui.add_dropdown(label, options, initial_value=value or options[0]))

    def text(self, markdown: str) -> Control:
        return Control(self.server.gui.add_markdown(markdown))

    # ------------------------------------------------------------------ recording
    @contextlib.contextmanager
    def recording(self):
        """``with scene.recording() as rec:`` records every scene update made inside (GUI excluded)."""
        yield Recording(self.server.get_scene_serializer())


def ground_hit(origin: Sequence[float], direction: Sequence[float]) -> Optional[tuple]:
    """World (x, z) where the ray origin + s * direction (s > 0) meets y = 0, or None."""
    o = np.asarray(origin, np.float64)
    d = np.asarray(direction, np.float64)
    if not d[1] < -1e-6:
        return None
    s = -o[1] / d[1]
    if s <= 0:
        return None
    p = o + s * d
    return float(p[0]), float(p[2])
