"""Obstacles around the robot: boxes, spheres and cylinders fixed in the world frame.

The controller keeps the robot off them (:class:`~wmm_control.kinematics.collision.CollisionModel`),
the simulator loads the same ones (``sim_bridge``) so the ground truth can measure clearance,
and a goal inside one is rejected.

Obstacle file (``obstacles:=`` parameter of the resolver and the simulator, ``obstacles:`` of
a scenario, ``--obstacles`` of ``wmm_randomized``: a path, or the name of a file shipped in
``config/obstacles``)::

    obstacles:
      - {name: table, shape: box, size: [0.8, 1.2, 0.72], pose: [1.6, 0.0, 0.36]}
      - {name: pillar, shape: cylinder, size: [0.1, 2.0], pose: [1.0, -0.8, 1.0, 0, 0, 0]}
      - {name: ball, shape: sphere, size: [0.15], pose: [0.9, 0.6, 1.1]}

* ``shape``: ``box`` (``size`` = full edge lengths along its x, y, z [m]), ``sphere``
  (``size`` = [radius]) or ``cylinder`` (``size`` = [radius, length], along its z axis),
  as a URDF ``<geometry>`` has them.
* ``pose``: the shape's centre in the world frame, ``[x, y, z]`` or ``[x, y, z, roll,
  pitch, yaw]`` [m, rad] (RPY as in URDF: fixed axes x, y, z).
* ``name``: optional (default ``obstacle_<i>``), unique.

Every size entry is finite and > 0, and it and every coordinate of the centre at most
:data:`MAX_EXTENT` (1 km): far beyond it the simulator's single-precision geometry and the
distances lose the robot's scale (a 1 m box 1e15 m away was measured 1 m from the robot), so a
larger one is refused rather than taken wrongly.

A file may also give ``goal_region: {centre: [x, y], radius: r}`` [m]: where ``wmm_randomized``
draws the bases of its goals' configurations (:func:`load_goal_region`), and ``random_boxes``:
boxes drawn by a seed beside the fixed obstacles (:func:`draw_boxes`)::

    random_boxes: {count: 10, size: [0.3, 0.8], area: [0.8, 3.8, -1.8, 1.8],
                   keep_clear: {centre: [0.0, 0.0], radius: 1.0}, floor: -0.4}

* ``count`` boxes, each with its three edge lengths drawn uniformly in ``size`` = [min, max]
  [m] (its height above z = 0; it reaches down to ``floor``, so that it stands on every robot's
  floor), its centre uniformly in ``area`` = [x_min, x_max, y_min, y_max] [m] and its yaw
  uniformly in (−π, π];
* none within ``keep_clear``: a box is drawn again while its footprint's circumscribed circle
  comes within ``radius`` [m] of ``centre`` (the start pose).

The seed is the caller's (``wmm_randomized --seed``; 0 where none is given), so a draw is
reproduced by its seed; :func:`obstacle_text` writes a seed's draw as a file of fixed obstacles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml
from wmm_control.errors import ConfigError
from wmm_control.geometry import matrix_from_rpy, rotation_z, rpy_from_matrix, se3_from_planar
from wmm_control.paths import config_path
from wmm_control.robot_config import read_yaml

__all__ = [
    'MAX_EXTENT',
    'Obstacle',
    'SHAPES',
    'around_base',
    'draw_boxes',
    'is_drawn',
    'load_goal_region',
    'load_obstacles',
    'obstacle_file',
    'obstacle_text',
    'parse_obstacles',
]

#: The shapes an obstacle may have, with the number of ``size`` entries of each.
SHAPES = {'box': 3, 'sphere': 1, 'cylinder': 2}
#: [m] the largest size entry and centre coordinate of an obstacle (module docstring).
MAX_EXTENT = 1000.0


@dataclass(frozen=True)
class Obstacle:
    """One obstacle.

    Attributes:
        name: unique name.
        shape: ``'box'``, ``'sphere'`` or ``'cylinder'``.
        size: box: edge lengths (x, y, z); sphere: (radius,); cylinder: (radius, length) [m].
        position: centre in the world frame [m]. Shape (3,).
        rotation: orientation in the world frame. Shape (3, 3).
    """

    name: str
    shape: str
    size: tuple[float, ...]
    position: np.ndarray
    rotation: np.ndarray

    def __post_init__(self):
        if self.shape not in SHAPES:
            raise ConfigError(f'obstacle {self.name!r}: shape must be one of {sorted(SHAPES)}, got {self.shape!r}')
        if len(self.size) != SHAPES[self.shape]:
            raise ConfigError(
                f'obstacle {self.name!r}: a {self.shape} takes {SHAPES[self.shape]} size entries, got {list(self.size)}'
            )
        if not all(math.isfinite(v) and 0.0 < v <= MAX_EXTENT for v in self.size):
            raise ConfigError(
                f'obstacle {self.name!r}: every size entry must be finite, > 0 and at most {MAX_EXTENT:g} [m], '
                f'got {list(self.size)}'
            )
        position = np.asarray(self.position, dtype=float)
        rotation = np.asarray(self.rotation, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)) or np.max(np.abs(position)) > MAX_EXTENT:
            raise ConfigError(
                f'obstacle {self.name!r}: position must be 3 finite numbers, each within ±{MAX_EXTENT:g} m, '
                f'got {self.position!r}'
            )
        if rotation.shape != (3, 3) or not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6):
            raise ConfigError(f'obstacle {self.name!r}: rotation must be a rotation matrix')
        object.__setattr__(self, 'position', position)
        object.__setattr__(self, 'rotation', rotation)

    @property
    def placement(self) -> pin.SE3:
        """The shape's frame in the world."""
        return pin.SE3(self.rotation, self.position)

    def geometry(self) -> pin.coal.ShapeBase:
        """The shape as coal has it (its Box and Cylinder take full lengths, as the file does)."""
        if self.shape == 'box':
            return pin.coal.Box(*self.size)
        if self.shape == 'sphere':
            return pin.coal.Sphere(self.size[0])
        return pin.coal.Cylinder(self.size[0], self.size[1])

    def signed_distance(self, point) -> float:
        """Distance of the world point ``point`` [m] from the shape's surface; negative inside."""
        local = self.rotation.T @ (np.asarray(point, dtype=float) - self.position)
        if self.shape == 'sphere':
            return float(np.linalg.norm(local) - self.size[0])
        if self.shape == 'cylinder':
            radial = math.hypot(local[0], local[1]) - self.size[0]
            axial = abs(local[2]) - 0.5 * self.size[1]
            return _box_distance(np.array([radial, axial]))
        return _box_distance(np.abs(local) - 0.5 * np.asarray(self.size))


def around_base(obstacles, base_pose) -> list[pin.SE3]:
    """Each obstacle's placement in the frame of a base at ``base_pose`` (x, y, θ) in the world
    (the root link's frame: the world's, turned by θ about z and moved by (x, y))."""
    world_to_base = se3_from_planar(base_pose).inverse()
    return [world_to_base * obstacle.placement for obstacle in obstacles]


def _box_distance(excess: np.ndarray) -> float:
    """Signed distance from per-axis excesses over the half extents (the usual box formula)."""
    outside = np.linalg.norm(np.maximum(excess, 0.0))
    return float(outside if outside > 0.0 else np.max(excess))


def parse_obstacles(entries, where: str) -> tuple[Obstacle, ...]:
    """Obstacles from the list ``entries`` of an obstacle file or scenario (``where`` names
    it in errors).

    Raises:
        ConfigError: not a list, an unknown key, shape or a bad number, or a repeated name.
    """
    if entries is None:
        return ()
    if not isinstance(entries, list):
        raise ConfigError(f'{where}: obstacles must be a list, got {type(entries).__name__}')
    out, names = [], set()
    for i, entry in enumerate(entries):
        at = f'{where}: obstacles[{i}]'
        if not isinstance(entry, dict):
            raise ConfigError(f'{at}: expected a mapping with shape, size and pose, got {entry!r}')
        unknown = set(entry) - {'name', 'shape', 'size', 'pose'}
        if unknown:
            raise ConfigError(f'{at}: unknown keys {sorted(unknown)} (known: name, shape, size, pose)')
        name = str(entry.get('name', f'obstacle_{i}'))
        if name in names:
            raise ConfigError(f'{at}: the name {name!r} is used twice')
        names.add(name)
        size = _numbers(entry.get('size'), None, f'{at}.size')
        pose = _numbers(entry.get('pose'), (3, 6), f'{at}.pose')
        rotation = matrix_from_rpy(pose[3:]) if len(pose) == 6 else np.eye(3)
        try:
            out.append(Obstacle(name, str(entry.get('shape')), tuple(size), np.array(pose[:3]), rotation))
        except ConfigError as exc:
            raise ConfigError(f'{at}: {exc}') from exc
    return tuple(out)


def _numbers(value, sizes, where):
    if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise ConfigError(f'{where}: expected a list of numbers, got {value!r}')
    if sizes is not None and len(value) not in sizes:
        raise ConfigError(f'{where}: expected {" or ".join(map(str, sizes))} numbers, got {len(value)}')
    if not all(math.isfinite(v) for v in value):
        raise ConfigError(f'{where}: every entry must be finite, got {value!r}')
    return [float(v) for v in value]


def obstacle_file(name_or_path) -> Path:
    """The file of ``name_or_path``: a ``.yaml`` path, or the name of one in ``config/obstacles``."""
    text = str(name_or_path)
    return Path(text) if text.endswith(('.yaml', '.yml')) else config_path('obstacles', f'{text}.yaml')


def load_obstacles(name_or_path, seed: int = 0) -> tuple[Obstacle, ...]:
    """The obstacles of the file ``name_or_path`` (:func:`obstacle_file`; schema in the module
    docstring), with its ``random_boxes`` drawn by ``seed``; ``()`` for an empty name.

    Raises:
        ConfigError: the file is missing, not YAML, or holds an invalid entry.
    """
    if not str(name_or_path):
        return ()
    path = obstacle_file(name_or_path)
    doc = _document(path)
    fixed = parse_obstacles(doc['obstacles'], path.name)
    drawn = draw_boxes(doc['random_boxes'], seed, path.name) if 'random_boxes' in doc else ()
    return fixed + drawn


def is_drawn(name_or_path) -> bool:
    """Whether the file ``name_or_path`` draws obstacles by a seed (``random_boxes``)."""
    return bool(str(name_or_path)) and 'random_boxes' in _document(obstacle_file(name_or_path))


def obstacle_text(name_or_path, seed: int = 0) -> str:
    """The file ``name_or_path`` with its obstacles drawn by ``seed`` as fixed ones (YAML text):
    what a simulator, a node or a record reads for that draw."""
    path = obstacle_file(name_or_path)
    doc = _document(path)
    if 'random_boxes' not in doc:
        return path.read_text()
    entries = [
        {
            'name': o.name,
            'shape': o.shape,
            'size': [round(v, 6) for v in o.size],
            'pose': [round(float(v), 6) + 0.0 for v in (*o.position, *rpy_from_matrix(o.rotation))],
        }
        for o in load_obstacles(path, seed)
    ]
    out = {'obstacles': entries}
    if 'goal_region' in doc:
        out['goal_region'] = doc['goal_region']
    return f'# {path.name} drawn with seed {seed}\n' + yaml.safe_dump(
        out, sort_keys=False, default_flow_style=None, width=120
    )


_BOXES = {'count', 'size', 'area', 'keep_clear', 'floor'}


def draw_boxes(spec, seed: int, where: str = 'random_boxes') -> tuple[Obstacle, ...]:
    """The boxes of a ``random_boxes`` entry ``spec`` drawn by ``seed`` (module docstring),
    named ``box_<i>``.

    Raises:
        ConfigError: a key missing or unknown, or a bad number.
    """
    at = f'{where}: random_boxes'
    if not isinstance(spec, dict) or set(spec) != _BOXES:
        raise ConfigError(f'{at} must have exactly the keys {sorted(_BOXES)}, got {spec!r}')
    count = spec['count']
    if not isinstance(count, int) or isinstance(count, bool) or not 0 <= count <= 1000:
        raise ConfigError(f'{at}.count must be an integer in [0, 1000], got {count!r}')
    low, high = _numbers(spec['size'], (2,), f'{at}.size')
    x0, x1, y0, y1 = _numbers(spec['area'], (4,), f'{at}.area')
    floor = _numbers([spec['floor']], (1,), f'{at}.floor')[0]
    clear = spec['keep_clear']
    if not isinstance(clear, dict) or set(clear) != {'centre', 'radius'}:
        raise ConfigError(f'{at}.keep_clear must be {{centre: [x, y], radius: r}}, got {clear!r}')
    centre = np.array(_numbers(clear['centre'], (2,), f'{at}.keep_clear.centre'))
    radius = _numbers([clear['radius']], (1,), f'{at}.keep_clear.radius')[0]
    if not (0.0 < low <= high and x0 < x1 and y0 < y1 and radius >= 0.0 and floor < low):
        raise ConfigError(
            f'{at}: needs 0 < size[0] <= size[1], area x_min < x_max and y_min < y_max, '
            f'keep_clear.radius >= 0 and floor below the boxes\' tops, got {spec!r}'
        )
    rng = np.random.default_rng(seed)
    boxes: list[Obstacle] = []
    while len(boxes) < count:
        for _ in range(10_000):
            sx, sy, height = rng.uniform(low, high, 3)
            xy = rng.uniform((x0, y0), (x1, y1))
            yaw = rng.uniform(-math.pi, math.pi)
            if np.linalg.norm(xy - centre) - 0.5 * math.hypot(sx, sy) >= radius:
                break
        else:
            raise ConfigError(f'{at}: no box of the area keeps clear of keep_clear')
        position = np.array((xy[0], xy[1], 0.5 * (height + floor)))
        boxes.append(
            Obstacle(
                f'box_{len(boxes)}', 'box', (float(sx), float(sy), float(height - floor)), position, rotation_z(yaw)
            )
        )
    return tuple(boxes)


def _document(path: Path) -> dict:
    doc = read_yaml(path, 'obstacle file')
    if not isinstance(doc, dict) or 'obstacles' not in doc:
        raise ConfigError(f'{path}: top-level key "obstacles" missing')
    unknown = set(doc) - {'obstacles', 'goal_region', 'random_boxes'}
    if unknown:
        raise ConfigError(f'{path}: unknown keys {sorted(unknown)} (known: obstacles, goal_region, random_boxes)')
    return doc


def load_goal_region(name_or_path) -> tuple[np.ndarray, float] | None:
    """``(centre (x, y) [m], radius [m])`` of the file's ``goal_region``; None without one.

    Raises:
        ConfigError: the file is missing or invalid, or the region is.
    """
    if not str(name_or_path):
        return None
    path = obstacle_file(name_or_path)
    region = _document(path).get('goal_region')
    if region is None:
        return None
    if not isinstance(region, dict) or set(region) != {'centre', 'radius'}:
        raise ConfigError(f'{path.name}: goal_region must be {{centre: [x, y], radius: r}}, got {region!r}')
    centre = _numbers(region['centre'], (2,), f'{path.name}: goal_region.centre')
    radius = _numbers([region['radius']], (1,), f'{path.name}: goal_region.radius')[0]
    if radius <= 0.0:
        raise ConfigError(f'{path.name}: goal_region.radius must be > 0, got {radius}')
    return np.array(centre), radius
