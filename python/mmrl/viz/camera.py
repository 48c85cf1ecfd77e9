"""The small perspective camera of :mod:`mmrl.viz.render` (numpy): world points to pixels."""
from __future__ import annotations

from typing import Optional

import numpy as np


class Camera:
    """A pinhole camera looking at ``focus`` from ``distance`` meters away at a fixed azimuth."""

    def __init__(self, width: int = 640, height: int = 360, fov_deg: float = 45.0, distance: float = 5.5,
                 elevation_deg: float = 22.0, azimuth_deg: float = 35.0):
        self.width, self.height = int(width), int(height)
        self.focal = 0.5 * self.height / np.tan(np.radians(fov_deg) / 2)
        el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
        self.offset = distance * np.array([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)])
        self.near = 0.1
        self.look_at(np.zeros(3))

    def look_at(self, focus) -> None:
        self.focus = np.asarray(focus, np.float64)
        self.eye = self.focus + self.offset
        f = self.focus - self.eye
        f /= np.linalg.norm(f)
        r = np.cross(f, [0.0, 1.0, 0.0])
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        self.rotation = np.stack([r, u, f])  # rows: camera x (right), y (up), z (forward)

    def to_camera(self, p: np.ndarray) -> np.ndarray:
        return (np.asarray(p, np.float64) - self.eye) @ self.rotation.T

    def project(self, pc: np.ndarray) -> np.ndarray:
        """Camera-space points (..., 3) with z > 0 -> pixels (..., 2), origin bottom-left."""
        z = np.maximum(pc[..., 2], 1e-6)
        return np.stack([0.5 * self.width + self.focal * pc[..., 0] / z,
                         0.5 * self.height + self.focal * pc[..., 1] / z], axis=-1)

    def segments(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """World segments (n, 3) -> pixel segments (m, 2, 2), clipped at the near plane."""
        ca, cb = self.to_camera(a), self.to_camera(b)
        za, zb = ca[:, 2], cb[:, 2]
        keep = (za > self.near) | (zb > self.near)
        ca, cb, za, zb = ca[keep], cb[keep], za[keep], zb[keep]
        # Where z = near along a -> b; at most one end is behind the plane.
        t = ((self.near - za) / np.where(np.abs(zb - za) > 1e-9, zb - za, 1e-9))[:, None]
        cut = ca + (cb - ca) * t
        ca = np.where((za < self.near)[:, None], cut, ca)
        cb = np.where((zb < self.near)[:, None], cut, cb)
        return np.stack([self.project(ca), self.project(cb)], axis=1)

    def polygon(self, pts: np.ndarray) -> Optional[np.ndarray]:
        """A world polygon (n, 3) -> pixel polygon clipped at the near plane (None if hidden)."""
        c = self.to_camera(pts)
        out = []
        n = len(c)
        for i in range(n):
            p, q = c[i], c[(i + 1) % n]
            pin, qin = p[2] > self.near, q[2] > self.near
            if pin:
                out.append(p)
            if pin != qin:
                t = (self.near - p[2]) / (q[2] - p[2])
                out.append(p + (q - p) * t)
        if len(out) < 3:
            return None
        return self.project(np.array(out))
