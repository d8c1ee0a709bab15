"""Headless pictures of a :class:`~sim_bridge.world.SimWorld` with PyBullet's TinyRenderer.

The TinyRenderer is PyBullet's CPU rasteriser: it needs no display and no GPU, so it works
in ``p.DIRECT`` worlds and in CI. The PNG is written with ``zlib`` (no imaging library).

Views (camera aimed at the robot base, following its heading θ):

* ``iso``   — from front-left, 35° above the horizon;
* ``top``   — straight down, robot x to the right;
* ``side``  — from the robot's left, nearly level;
* ``front`` — from ahead of the robot, nearly level.
"""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pybullet as p
from numpy.typing import ArrayLike

from wmm_control.errors import ConfigError

if TYPE_CHECKING:
    from sim_bridge.world import SimWorld

__all__ = ['VIEWS', 'render_rgb', 'render_png', 'write_png']

# view -> (camera yaw relative to the robot heading [deg], pitch [deg])
VIEWS = {
    'iso': (135.0, -35.0),
    'top': (0.0, -89.9),
    'side': (180.0, -8.0),
    'front': (90.0, -8.0),
}
_DISTANCE = 2.8  # camera distance from the target [m]
_TARGET_UP = 0.55  # target height above the floor [m]
_FOV = 50.0  # vertical field of view [deg]


def render_rgb(
    world: SimWorld, view: str = 'iso', width: int = 640, height: int = 480, distance: float = _DISTANCE
) -> np.ndarray:
    """Render the world to an RGB image.

    Args:
        world: a :class:`~sim_bridge.world.SimWorld` (open).
        view: one of :data:`VIEWS`.
        width: image width [px], >= 16.
        height: image height [px], >= 16.
        distance: camera distance from the target [m], > 0.

    Returns:
        uint8 array, shape (height, width, 3).

    Raises:
        ConfigError: unknown view, bad size, or a closed world.
    """
    if view not in VIEWS:
        raise ConfigError(f'unknown view {view!r}; views: {sorted(VIEWS)}')
    width, height = int(width), int(height)
    if width < 16 or height < 16:
        raise ConfigError(f'image size must be at least 16 x 16 px, got {width} x {height}')
    if not (math.isfinite(distance) and distance > 0.0):
        raise ConfigError(f'distance must be finite and > 0 [m], got {distance}')
    cid = world.client_id
    if cid < 0:
        raise ConfigError('render: the world is closed')
    x, y, th = world.base_pose()
    yaw, pitch = VIEWS[view]
    target = [float(x), float(y), world.robot.ground_z + _TARGET_UP]
    view_m = p.computeViewMatrixFromYawPitchRoll(
        target, distance, math.degrees(th) + yaw, pitch, 0.0, 2, physicsClientId=cid
    )
    proj_m = p.computeProjectionMatrixFOV(_FOV, width / height, 0.05, 50.0, physicsClientId=cid)
    img = p.getCameraImage(
        width,
        height,
        view_m,
        proj_m,
        shadow=0,
        lightDirection=[1.0, 1.0, 2.0],
        renderer=p.ER_TINY_RENDERER,
        physicsClientId=cid,
    )
    rgba = np.reshape(np.asarray(img[2], dtype=np.uint8), (height, width, 4))
    return np.ascontiguousarray(rgba[:, :, :3])


def write_png(path: str | Path, rgb: ArrayLike) -> Path:
    """Write an RGB uint8 image (shape (h, w, 3)) to ``path`` as an 8-bit PNG."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ConfigError(f'write_png: expected shape (h, w, 3), got {rgb.shape}')
    h, w, _ = rgb.shape
    raw = b''.join(b'\x00' + rgb[r].tobytes() for r in range(h))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack('>I', len(data)) + tag + data + struct.pack('>I', zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = (
        b'\x89PNG\r\n\x1a\n'
        + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 2, 0, 0, 0))
        + chunk(b'IDAT', zlib.compress(raw, 6))
        + chunk(b'IEND', b'')
    )
    path = Path(path)
    path.write_bytes(png)
    return path


def render_png(world: SimWorld, path: str | Path, view: str = 'iso', width: int = 640, height: int = 480) -> Path:
    """Render the world from a named viewpoint and save it as a PNG.

    Args:
        world: a :class:`~sim_bridge.world.SimWorld`.
        path: output file path.
        view: ``'iso'``, ``'top'``, ``'side'`` or ``'front'``.
        width: image width [px].
        height: image height [px].

    Returns:
        The written path (:class:`pathlib.Path`).
    """
    return write_png(path, render_rgb(world, view, width, height))
