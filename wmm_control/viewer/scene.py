"""The robot of the viewer, from its URDF: the shapes to draw and where they are (ROS-free).

The visual geometry of any URDF pinocchio loads (``pin.buildGeomFromUrdf``, VISUAL) becomes
a list of :class:`Shape` (boxes, cylinders, spheres, and triangle meshes for mesh files), in
the URDF's colours. :class:`RobotScene` places them: joint positions by name (every joint of
the URDF that one number moves: arm, steer, drive and wheel joints alike; a continuous one by
its angle) and the pose of the base link in the world give the world pose of each shape and of
the end-effector frame; the joints no joint state names stay where they are held (the robot
YAML's ``held_joints``: head, fingers). Nothing here knows a link name but the two it is given.

Quaternions are (w, x, y, z), as the browser scene takes them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from wmm_control.errors import NonFiniteError, UnknownFrameError
from wmm_control.geometry import (
    continuous_from_q,
    set_joint_position,
    matrix_from_quaternion,
    quaternion_from_matrix,
    unit_quaternion,
)
from wmm_control.kinematics.model import held_configuration, pinocchio_model
from wmm_control.resources import load_geometry

__all__ = [
    'Shape',
    'RobotScene',
    'ScenePoses',
    'Trail',
    'segments',
    'unit_wxyz',
    'finite_pose',
    'wxyz_from_xyzw',
    'xyzw_from_wxyz',
]


@dataclass(frozen=True)
class Shape:
    """One visual element of the URDF.

    Attributes:
        name: pinocchio's name of the geometry object (``<link>_<index>``).
        kind: 'box', 'cylinder', 'sphere' or 'mesh'.
        size: box: its full extents (x, y, z); cylinder: (radius, length along its z axis);
            sphere: (radius,); mesh: () (the vertices are scaled already).
        color: RGB, 0–255.
        opacity: 0 (invisible) to 1 (opaque), the URDF colour's alpha.
        vertices: mesh: (n, 3) vertices in the shape's frame [m]; else empty.
        faces: mesh: (m, 3) vertex indices of its triangles; else empty.
    """

    name: str
    kind: str
    size: tuple[float, ...]
    color: tuple[int, int, int]
    opacity: float
    vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False, compare=False)
    faces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int32), repr=False, compare=False)


@dataclass(frozen=True)
class ScenePoses:
    """World poses of every shape (in :attr:`RobotScene.shapes` order) and of the end effector."""

    positions: np.ndarray  # (n, 3)
    wxyz: np.ndarray  # (n, 4)
    ee_position: np.ndarray  # (3,)
    ee_wxyz: np.ndarray  # (4,)


def wxyz_from_xyzw(quat) -> np.ndarray:
    """(w, x, y, z) of a quaternion given as (x, y, z, w)."""
    x, y, z, w = (float(v) for v in quat)
    return np.array([w, x, y, z])


def xyzw_from_wxyz(quat) -> np.ndarray:
    """(x, y, z, w) of a quaternion given as (w, x, y, z)."""
    w, x, y, z = (float(v) for v in quat)
    return np.array([x, y, z, w])


def unit_wxyz(quat) -> np.ndarray | None:
    """``quat`` (w, x, y, z) scaled to unit norm; None when it is not finite or (near) zero.

    The norm does not overflow for entries near the largest double (``np.hypot``).
    """
    q = np.asarray(quat, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        return None
    return unit_quaternion(q, min_norm=1e-9)[0]


def finite_pose(position, wxyz) -> tuple[np.ndarray, np.ndarray] | None:
    """(position (3,) [m], unit quaternion (w, x, y, z)) of a pose; None when the position is not
    three finite numbers or the quaternion is not finite or (near) zero (:func:`unit_wxyz`)."""
    pos = np.asarray(position, dtype=float).reshape(-1)
    quat = unit_wxyz(wxyz)
    if quat is None or pos.shape != (3,) or not np.all(np.isfinite(pos)):
        return None
    return pos, quat


def _se3(position, wxyz) -> pin.SE3:
    pose = finite_pose(position, wxyz)
    if pose is None:
        raise NonFiniteError(
            f'not a pose: position {np.asarray(position).tolist()}, quaternion (w, x, y, z) {np.asarray(wxyz).tolist()}'
        )
    return pin.SE3(matrix_from_quaternion(xyzw_from_wxyz(pose[1])), pose[0])


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    return wxyz_from_xyzw(quaternion_from_matrix(rotation))


def _rgb(color) -> tuple[tuple[int, int, int], float]:
    rgba = np.clip(np.nan_to_num(np.asarray(color, dtype=float), nan=1.0), 0.0, 1.0)
    red, green, blue = (int(round(255 * c)) for c in rgba[:3])
    return (red, green, blue), float(rgba[3])


def _mesh_arrays(geometry) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)
    faces = np.array(
        [[tri[0], tri[1], tri[2]] for tri in (geometry.tri_indices(i) for i in range(geometry.num_tris))],
        dtype=np.int32,
    ).reshape(-1, 3)
    return vertices, faces


def _shape(obj) -> Shape | None:
    """The :class:`Shape` of a pinocchio geometry object; None for a kind it has no drawing of."""
    geometry = obj.geometry
    color, opacity = _rgb(obj.meshColor)
    kind = type(geometry).__name__
    if kind == 'Box':
        return Shape(obj.name, 'box', tuple(float(2.0 * v) for v in geometry.halfSide), color, opacity)
    if kind == 'Cylinder':
        return Shape(obj.name, 'cylinder', (float(geometry.radius), float(2.0 * geometry.halfLength)), color, opacity)
    if kind == 'Sphere':
        return Shape(obj.name, 'sphere', (float(geometry.radius),), color, opacity)
    if kind.startswith('BVHModel') and geometry.num_tris > 0:
        vertices, faces = _mesh_arrays(geometry)
        return Shape(obj.name, 'mesh', (), color, opacity, vertices, faces)
    return None


class RobotScene:
    """A URDF's visual shapes and their world poses for given joint positions and base pose.

    Args:
        urdf_path: the URDF.
        base_link: the link whose world pose is given (odometry's child frame).
        ee_frame: the end-effector frame (a link or joint of the URDF).
        package_dirs: folders that ``package://`` mesh paths are looked up in first (the robot
            YAML's; :mod:`wmm_control.resources`).
        held: [rad or m] the joints outside the arm and the base by name, at the positions the
            robot holds them at (:attr:`~wmm_control.robot_config.RobotConfig.held_joints`)
            until a joint state moves them; the other joints start at zero.

    Raises:
        ConfigError: the URDF cannot be loaded.
        UnknownFrameError: ``base_link`` or ``ee_frame`` is not in it.
    """

    def __init__(
        self,
        urdf_path: str | Path,
        base_link: str = 'base_link',
        ee_frame: str = 'ee_link',
        package_dirs: Iterable[str | Path] = (),
        held: Mapping[str, float] | None = None,
    ) -> None:
        urdf = Path(urdf_path)
        self.model = pinocchio_model(urdf, planar_root=False)  # shared, read-only; data of its own
        self.geometry = load_geometry(self.model, urdf, pin.GeometryType.VISUAL, package_dirs)
        self.data = self.model.createData()
        self.geometry_data = pin.GeometryData(self.geometry)
        self._base_frame = self._frame(base_link)
        self._ee_frame = self._frame(ee_frame)
        shapes, drawn, skipped = [], [], []
        for index, obj in enumerate(self.geometry.geometryObjects):
            shape = _shape(obj)
            if shape is None:
                skipped.append(f'{obj.name} ({type(obj.geometry).__name__})')
            else:
                shapes.append(shape)
                drawn.append(index)
        #: The shapes drawn, in the order of :attr:`ScenePoses.positions`.
        self.shapes: tuple[Shape, ...] = tuple(shapes)
        #: Geometry objects without a drawing (name and kind), e.g. a convex hull.
        self.skipped: tuple[str, ...] = tuple(skipped)
        self._drawn = drawn
        # Joints one number moves: (name, q index, 1 or 2 (cos, sin of a continuous joint)).
        self._slots = {}
        for joint_id in range(1, self.model.njoints):
            joint = self.model.joints[joint_id]
            if joint.nv == 1 and joint.nq in (1, 2):
                self._slots[self.model.names[joint_id]] = (joint.idx_q, joint.nq)
        #: Names of the joints a joint state can move.
        self.joint_names: tuple[str, ...] = tuple(self._slots)
        self.q = held_configuration(self.model, held or {})

    def _frame(self, name: str) -> int:
        if not self.model.existFrame(name):
            raise UnknownFrameError(
                f'frame {name!r} is not in the URDF; its frames: {sorted({f.name for f in self.model.frames})}'
            )
        return self.model.getFrameId(name)

    def set_joints(self, names, positions) -> list[str]:
        """Set the joints named ``names`` to ``positions`` [rad or m]; the others keep theirs.

        Returns:
            The names that are not joints of the URDF (ignored).

        Raises:
            NonFiniteError: a position of a known joint is NaN or infinite (nothing is set).
            ValueError: ``names`` and ``positions`` differ in length.
        """
        names = list(names)
        values = np.asarray(positions, dtype=float).reshape(-1)
        if len(names) != values.size:
            raise ValueError(f'{len(names)} names for {values.size} positions')
        known = [(self._slots[n], v) for n, v in zip(names, values) if n in self._slots]
        bad = [n for n, v in zip(names, values) if n in self._slots and not math.isfinite(v)]
        if bad:
            raise NonFiniteError(f'non-finite positions of joints {bad}')
        for (index, nq), value in known:
            set_joint_position(self.q, index, nq, float(value))
        return [n for n in names if n not in self._slots]

    def joint_positions(self) -> dict[str, float]:
        """Every joint :meth:`set_joints` can set, and its current position."""
        out = {}
        for name, (index, nq) in self._slots.items():
            out[name] = continuous_from_q(self.q[index], self.q[index + 1]) if nq == 2 else float(self.q[index])
        return out

    def poses(self, base_position, base_wxyz) -> ScenePoses:
        """World poses of the shapes and of the end effector, the base link at the given pose.

        Raises:
            NonFiniteError: the base pose is not finite, or its quaternion is zero.
        """
        world_base = _se3(base_position, base_wxyz)
        pin.forwardKinematics(self.model, self.data, self.q)
        pin.updateFramePlacements(self.model, self.data)
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)
        # The URDF's root sits wherever puts the base link at its world pose.
        world_root = world_base * self.data.oMf[self._base_frame].inverse()
        positions = np.empty((len(self._drawn), 3))
        wxyz = np.empty((len(self._drawn), 4))
        for row, index in enumerate(self._drawn):
            placement = world_root * self.geometry_data.oMg[index]
            positions[row] = placement.translation
            wxyz[row] = _wxyz(placement.rotation)
        ee = world_root * self.data.oMf[self._ee_frame]
        return ScenePoses(positions, wxyz, ee.translation.copy(), _wxyz(ee.rotation))


class Trail:
    """A path drawn behind a moving point: a point is kept when it is ``min_step`` from the last
    one kept, up to ``max_points`` (the oldest go first)."""

    def __init__(self, max_points: int, min_step: float) -> None:
        if max_points < 2 or not min_step > 0.0:
            raise ValueError(f'a trail needs at least 2 points and a positive step, got {max_points}, {min_step}')
        self.max_points = int(max_points)
        self.min_step = float(min_step)
        self._points = np.zeros((0, 3))

    def __len__(self) -> int:
        return len(self._points)

    def add(self, point) -> bool:
        """Keep ``point`` when it is finite and far enough from the last one; True when kept."""
        p = np.asarray(point, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)):
            return False
        if len(self._points) and np.linalg.norm(p - self._points[-1]) < self.min_step:
            return False
        self._points = np.vstack((self._points[-(self.max_points - 1) :], p))
        return True

    def clear(self) -> None:
        self._points = np.zeros((0, 3))

    @property
    def points(self) -> np.ndarray:
        """The points kept, oldest first. Shape (n, 3)."""
        return self._points.copy()

    def segments(self) -> np.ndarray:
        """Consecutive points as line segments (:func:`segments`). Shape (n − 1, 2, 3)."""
        return segments(self._points)


def segments(points: np.ndarray) -> np.ndarray:
    """The line segments between consecutive ``points`` (shape (n, 3)), none for fewer than two.
    Shape (max(n − 1, 0), 2, 3)."""
    return np.stack((points[:-1], points[1:]), axis=1)
