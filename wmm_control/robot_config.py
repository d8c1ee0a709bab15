"""Robot descriptions: a URDF and the YAML file beside it, loaded and validated.

The URDF is the source of truth for the kinematics: the arm is the joint chain from the
``arm.root`` link to the ``arm.tool`` link (any number of joints from 6 up: revolute,
continuous or prismatic), and its position and velocity limits are the URDF's ``<limit>``.
The base (:data:`Base`: one of :class:`SteerableBase`, :class:`MecanumBase`,
:class:`DifferentialBase`) has its geometry (hips, wheel radius, steer offset, Mecanum wheel
positions, track) read from the wheel and steer joints' origins and the wheel links'
collision cylinders. The YAML
names those joints and links and gives what a URDF cannot: acceleration limits (default
:data:`DEFAULT_ACCEL_PER_VELOCITY` × the velocity limit), base twist limits, the dexterous
posture, the start state, the control period and the default method; optionally the folders
``package://`` mesh paths are looked up in first (``package_dirs``,
:mod:`wmm_control.resources`), the link pairs the collision model checks
(``collision.pairs``) and the positions of the joints outside the arm and the base (head,
fingers, a second arm: ``held_joints``, :func:`held_joint_positions`; by default each one's
URDF zero clipped into its limits), where every model of the robot, the simulator and its
``/joint_states`` hold them. Any URDF value may be overridden in the YAML (``arm.position_lower`` …,
``steerable.hips`` …).

URDF conventions the base geometry relies on (``wmm_robot init`` writes YAMLs for them):

* ``base_link`` x forward, z up; the base moves in its x-y plane.
* steerable: each steer joint turns about z, its origin's (x, y) in ``base_link`` is the
  module's hip; its drive joint turns about the steer link's y axis and sits ``d`` along −y
  from the steer axis (the wheel offset of Sorour Table I); the drive link's collision
  cylinder (or sphere) gives the wheel radius.
* mecanum: N ≥ 3 wheel joints about y, in any order (the command order); each wheel's
  position is its origin's (x, y), its roller angle γ (``mecanum.roller_angles``, see
  :class:`MecanumBase`) by default the usual pattern of Xing eq (16): π/4 for a wheel with
  x y > 0 (front-left, rear-right), −π/4 for x y < 0. ``mecanum.d1`` / ``d2``, when given,
  set every wheel's |x| / |y| (Xing's half wheelbase and half track).
* differential: a left and a right wheel joint about y on one axle through ``base_link``'s
  origin (x = 0); the track is the distance between them. Casters are fixed links and play
  no part in the kinematics.

A robot is named by a YAML file's stem in ``config/robots`` (``steerable``, ``mecanum``,
``ur_mecanum``, ``panda_diff``), by the aliases ``A`` and ``B`` of the two papers' robots,
or by a path to a robot YAML; its ``urdf`` path is relative to that YAML.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import yaml

from wmm_control.errors import ConfigError
from wmm_control.paths import config_path, parse_yaml, robot_names
from wmm_control.resources import check_resources, yaml_package_dirs
from wmm_control.urdf import MOVING_TYPES, UrdfTree

if TYPE_CHECKING:  # the rolling models read a base section: imported where they are built
    from wmm_control.base.differential import DifferentialKinematics
    from wmm_control.base.mecanum import MecanumKinematics
    from wmm_control.base.steerable_kinematics import SteerableGeometry

__all__ = [
    'ArmConfig',
    'StartState',
    'Base',
    'BaseSection',
    'SteerableBase',
    'FixedWheelBase',
    'MecanumBase',
    'DifferentialBase',
    'RobotConfig',
    'load_robot',
    'robot_names',
    'BASE_FAMILIES',
    'ALIASES',
    'MIN_ARM_JOINTS',
    'DEFAULT_ACCEL_PER_VELOCITY',
    'read_yaml_section',
    'usual_roller_angles',
    'resolve_robot_yaml',
    'held_joint_positions',
]

ALIASES = {'a': 'steerable', 'b': 'mecanum'}
MIN_ARM_JOINTS = 6
#: [1/s] an acceleration limit the YAML does not give is this times the velocity limit
#: (full speed in half a second).
DEFAULT_ACCEL_PER_VELOCITY = 2.0
#: [m] the wheel axle of a differential base may miss base_link's origin by this much.
_AXLE_TOL = 1e-3
_TWIST_AXES = ('vx', 'vy', 'ω')


def _vec(raw, key, size, where):
    try:
        arr = np.asarray(raw[key], dtype=float)
    except KeyError as exc:
        raise ConfigError(f'{where}: missing key {key!r}') from exc
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{where}.{key}: not a list of numbers: {raw[key]!r}') from exc
    if arr.shape != (size,):
        raise ConfigError(f'{where}.{key}: expected {size} numbers, got shape {arr.shape}')
    if np.isnan(arr).any():
        raise ConfigError(f'{where}.{key}: NaN entries: {arr.tolist()}')
    return arr


def _positive(arr, key, where):
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise ConfigError(f'{where}.{key}: every entry must be finite and > 0, got {arr.tolist()}')
    return arr


def _scalar(raw, key, where, positive=True):
    try:
        val = float(raw[key])
    except KeyError as exc:
        raise ConfigError(f'{where}: missing key {key!r}') from exc
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{where}.{key}: not a number: {raw[key]!r}') from exc
    if not np.isfinite(val) or (positive and val <= 0.0):
        raise ConfigError(f'{where}.{key}: must be finite{" and > 0" if positive else ""}, got {val}')
    return val


def _word(raw, key, where):
    val = raw.get(key)
    if not isinstance(val, str) or not val:
        raise ConfigError(f'{where}: key {key!r} must be a name, got {val!r}')
    return val


def _section(raw, key, where):
    sec = raw.get(key) if isinstance(raw, dict) else None
    if not isinstance(sec, dict):
        raise ConfigError(f'{where}: missing section {key!r}')
    return sec


def _optional_vec(raw, key, size, where, default):
    return default if raw.get(key) is None else _vec(raw, key, size, where)


def _optional_scalar(raw, key, where, default, positive=True):
    if raw.get(key) is None:
        if default is None:
            raise ConfigError(f'{where}: missing key {key!r} (and the URDF does not give it)')
        return float(default)
    return _scalar(raw, key, where, positive)


@dataclass(frozen=True)
class ArmConfig:
    """The arm: the URDF chain from ``root`` to ``tool``, its limits and dexterous posture.

    Attributes:
        joints: the n arm joint names, root first.
        types: each joint's URDF type (revolute, continuous or prismatic).
        root, tool: the chain's first and last links; ``tool`` is the end-effector frame.
        position_lower, position_upper: [rad or m], ±inf for a continuous joint. Shape (n,).
        velocity: [rad/s or m/s]. Shape (n,).
        acceleration: [rad/s² or m/s²]. Shape (n,).
        dexterous: the dexterous posture (Sorour's q_a,dex). Shape (n,).
    """

    joints: tuple
    types: tuple
    root: str
    tool: str
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    dexterous: np.ndarray

    @property
    def n(self) -> int:
        """Number of arm joints."""
        return len(self.joints)


@dataclass(frozen=True)
class StartState:
    """The start state: base pose (x, y, θ), arm joints; optionally the expected world EE pose
    (xyz + RPY) and its tolerance [m, rad] (the papers' start states are checked against it)."""

    base_pose: np.ndarray
    arm: np.ndarray
    ee_pose: np.ndarray | None = None
    ee_tolerance: tuple | None = None


@dataclass(frozen=True)
class BaseSection(ABC):
    """What every base family has and what callers ask of it, whatever its wheels.

    One of :class:`SteerableBase`, :class:`MecanumBase`, :class:`DifferentialBase` (the
    :data:`Base` union) is a robot's ``base``; its ``family`` names it.

    Attributes:
        velocity: base twist limits |vx|, |vy|, |ω| [m/s, m/s, rad/s] in the base frame; 0 on
            an axis the base cannot follow. Shape (3,).
        acceleration: base twist acceleration limits [m/s², m/s², rad/s²]. Shape (3,).
    """

    velocity: np.ndarray
    acceleration: np.ndarray

    #: the base family, the YAML's ``base_type``
    family: ClassVar[str]
    #: indices of the twist (vx, vy, ω) the base can follow
    axes: ClassVar[tuple[int, ...]] = (0, 1, 2)

    @property
    @abstractmethod
    def command_groups(self) -> dict[str, tuple]:
        """Ordered mapping group name → joint names in command order: the groups of the
        simulator's ``command_groups`` and of the ``/<group>_controller/commands`` topics."""

    @property
    @abstractmethod
    def rate_limits(self) -> dict[str, float]:
        """|q̇| bound [rad/s] per command group."""

    @property
    @abstractmethod
    def rolling_joints(self) -> tuple:
        """The joints whose links roll on the floor (the drive or wheel joints)."""

    @abstractmethod
    def rolling_model(self) -> SteerableGeometry | MecanumKinematics | DifferentialKinematics:
        """The map from the rolling joints' motion to the base's twist (vx, vy, ω): the
        base's rolling model, which a simulator's odometry and kinematic mode integrate."""

    @property
    def roller_axes(self) -> np.ndarray:
        """The axis (x, y) in the base frame, unit, of the free roller each rolling joint's wheel
        touches the floor with: its traction acts along that axis only (a simulator's tyre
        model). Empty, shape (0, 2), for wheels that grip the floor with their whole tread."""
        return np.zeros((0, 2))

    def steer_headings(self, twists: np.ndarray) -> np.ndarray:
        """The heading [rad] each steered wheel must point along for each twist (vx, vy, ω)
        (rows, base frame), defined modulo π (a wheel drives both ways); with the steer rate
        and acceleration limits of :attr:`steer_limits`, what a base path's timing must leave
        the steering time for. No columns for a base without steered wheels. Shape (K, N)."""
        return np.zeros((len(twists), 0))

    @property
    def steer_limits(self) -> tuple[float, float]:
        """(|β̇|, |β̈|) bounds of the steered wheels [rad/s, rad/s²] (:meth:`steer_headings`)."""
        return math.inf, math.inf

    @property
    def sideways(self) -> bool:
        """Whether the base can follow a sideways twist vy (vy is one of its :attr:`axes`)."""
        return 1 in self.axes

    @property
    def path_turning_radius(self) -> float | None:
        """ρ [m], the least radius a path of the base may turn on: None for a base that moves
        sideways (its paths go straight from pose to pose while the heading turns: SE(2));
        for one that cannot, v_max / ω_max, the radius on which it turns at both limits (its
        paths are Reeds–Shepp curves of that radius, which it follows without sliding).

        Raises:
            ValueError: a base that moves neither sideways nor both forward and round.
        """
        if self.sideways:
            return None
        v, w = float(self.velocity[0]), float(self.velocity[2])
        if not (v > 0.0 and w > 0.0):
            raise ValueError(f'a base needs forward and turn rate limits > 0, got {v}, {w}')
        return v / w

    @property
    def joints(self) -> tuple:
        """Every wheel-side joint name, in command order (the groups one after the other)."""
        return tuple(name for names in self.command_groups.values() for name in names)

    @property
    def joint_velocity_limits(self) -> dict:
        """Velocity limit [rad/s] by joint name, for every wheel-side joint."""
        limits = self.rate_limits
        return {name: limits[group] for group, names in self.command_groups.items() for name in names}


@dataclass(frozen=True)
class SteerableBase(BaseSection):
    """Steerable base of N ≥ 2 steer + drive modules (Sorour §IV, Table I for robot A).

    Attributes:
        steer_joints, drive_joints: the modules' joints, in the same order.
        hips: module hip positions (hx, hy) in the base frame [m]. Shape (N, 2).
        wheel_radius, wheel_offset: r_w and d [m].
        steer_rate_limit, steer_accel_limit: β̇ and β̈ bounds [rad/s, rad/s²].
        drive_rate_limit: |φ̇| bound [rad/s]; ``drive_accel_limit`` [rad/s²] is the drive
            deceleration used to ramp the wheels to rest after a controller failure.
    """

    steer_joints: tuple
    drive_joints: tuple
    hips: np.ndarray
    wheel_radius: float
    wheel_offset: float
    steer_rate_limit: float
    steer_accel_limit: float
    drive_rate_limit: float
    drive_accel_limit: float

    family: ClassVar[str] = 'steerable'

    @property
    def n_modules(self) -> int:
        """Number of steer + drive modules N."""
        return len(self.steer_joints)

    @property
    def command_groups(self) -> dict[str, tuple]:
        return {'steer': self.steer_joints, 'drive': self.drive_joints}

    @property
    def rate_limits(self) -> dict[str, float]:
        return {'steer': self.steer_rate_limit, 'drive': self.drive_rate_limit}

    @property
    def rolling_joints(self) -> tuple:
        return self.drive_joints

    def rolling_model(self) -> SteerableGeometry:
        """The modules' geometry (its twist from the steer angles and rates and the drive rates)."""
        from wmm_control.base.steerable_kinematics import SteerableGeometry

        return SteerableGeometry.from_config(self)

    def steer_headings(self, twists: np.ndarray) -> np.ndarray:
        """Each module's hip velocity direction (vx − ω hy, vy + ω hx) [rad] per twist: where
        the ICR controller (Sorour §IV) steers the module, modulo π. Shape (K, N)."""
        twists = np.asarray(twists, dtype=float).reshape(-1, 3)
        vx, vy, wz = (twists[:, k, None] for k in range(3))
        return np.arctan2(vy + wz * self.hips[:, 0], vx - wz * self.hips[:, 1])

    @property
    def steer_limits(self) -> tuple[float, float]:
        return self.steer_rate_limit, self.steer_accel_limit


@dataclass(frozen=True)
class FixedWheelBase(BaseSection):
    """A base whose wheels turn on fixed axles, one command group ``wheel``: the common part of
    :class:`MecanumBase` and :class:`DifferentialBase`.

    Attributes:
        wheel_joints: the wheel joints, in command order.
        wheel_radius: r [m].
        wheel_rate_limit: |φ̇| bound [rad/s].
    """

    wheel_joints: tuple
    wheel_radius: float
    wheel_rate_limit: float

    @property
    def command_groups(self) -> dict[str, tuple]:
        return {'wheel': self.wheel_joints}

    @property
    def rate_limits(self) -> dict[str, float]:
        return {'wheel': self.wheel_rate_limit}

    @property
    def rolling_joints(self) -> tuple:
        return self.wheel_joints

    @abstractmethod
    def rolling_model(self) -> MecanumKinematics | DifferentialKinematics:
        """The wheel map (its twist from the wheel rates)."""


@dataclass(frozen=True)
class MecanumBase(FixedWheelBase):
    """Mecanum base of N ≥ 3 wheels on axles along the base's y axis (Xing eq 16 for four).

    Attributes:
        positions: each wheel's contact point (x, y) in the base frame [m], from its joint
            origin. Shape (N, 2).
        roller_angles: γ_i [rad], the angle from wheel i's axle (+y) to the axis of its roller
            touching the floor, counter-clockwise about +z seen from above (± π/4 for the usual
            wheel). Shape (N,).
    """

    positions: np.ndarray
    roller_angles: np.ndarray

    family: ClassVar[str] = 'mecanum'

    @property
    def roller_axes(self) -> np.ndarray:
        """(−sin γ_i, cos γ_i): the axle's +y turned by γ_i. Shape (N, 2)."""
        angles = np.asarray(self.roller_angles, dtype=float)
        return np.column_stack((-np.sin(angles), np.cos(angles)))

    def rolling_model(self) -> MecanumKinematics:
        """Xing eq (16)'s wheel map (its twist from the wheel rates)."""
        from wmm_control.base.mecanum import MecanumKinematics

        return MecanumKinematics.from_config(self)


@dataclass(frozen=True)
class DifferentialBase(FixedWheelBase):
    """Differential-drive base: two wheels (left, right) on one axle through base_link's origin.

    Attributes:
        track: distance between the two wheels' contact points [m].
    """

    track: float

    family: ClassVar[str] = 'differential'
    axes: ClassVar[tuple[int, ...]] = (0, 2)

    def rolling_model(self) -> DifferentialKinematics:
        """The two wheels' map (its twist from the wheel rates)."""
        from wmm_control.base.differential import DifferentialKinematics

        return DifferentialKinematics.from_config(self)


#: A robot's base: one of the three families, told apart by ``family``.
Base = SteerableBase | MecanumBase | DifferentialBase


@dataclass(frozen=True)
class RobotConfig:
    """One robot: its URDF, frames, control period, default redundancy resolution method, arm,
    base (its family, geometry and twist limits) and start state."""

    name: str
    description: str
    yaml_path: Path
    urdf_path: Path
    base_link: str
    ee_frame: str
    ground_z: float
    period: float
    method: str
    arm: ArmConfig
    base: Base
    start: StartState
    raw: dict | None = field(default=None, repr=False, compare=False)
    #: folders ``package://`` mesh paths are looked up in first (:mod:`wmm_control.resources`)
    package_dirs: tuple[Path, ...] = ()
    #: the link pairs the collision model checks (``collision.pairs``); None: its own rules
    collision_pairs: tuple[tuple[str, str], ...] | None = None
    #: [rad or m] every movable joint outside the arm and the base, by name, at the position it
    #: is held at (``held_joints``, :func:`held_joint_positions`), mimic joints included
    held_joints: dict[str, float] = field(default_factory=dict)

    @property
    def joint_velocity_limits(self) -> dict:
        """Velocity limit [rad/s] by joint name, for every actuated joint."""
        return dict(zip(self.arm.joints, self.arm.velocity.tolist())) | self.base.joint_velocity_limits


def _urdf_velocity(tree, name, role):
    joint = tree.joint(name, role)
    if joint.type not in ('continuous', 'revolute'):
        raise ConfigError(f'{tree.path.name}: {role} {name!r} must be continuous or revolute, not {joint.type!r}')
    return joint.velocity


def _parse_arm(raw, tree, where_top):
    arm = _section(raw, 'arm', where_top)
    w = 'arm'
    root = arm.get('root')
    tool = arm.get('tool', raw.get('ee_frame'))
    if not isinstance(root, str) or not isinstance(tool, str):
        raise ConfigError(f'{w}: give the chain as arm.root and arm.tool link names, got {root!r}, {tool!r}')
    chain = tree.arm_chain(root, tool)
    names = tuple(j.name for j in chain)
    n = len(names)
    if n < MIN_ARM_JOINTS:
        raise ConfigError(
            f'{w}: the chain {root!r} → {tool!r} has {n} joints {list(names)}; an arm needs at least {MIN_ARM_JOINTS}'
        )
    if arm.get('joints') is not None and tuple(arm.get('joints')) != names:
        raise ConfigError(f'{w}.joints: {arm.get("joints")!r} is not the URDF chain {root!r} → {tool!r}: {list(names)}')

    def urdf_limit(attr: str) -> np.ndarray | None:
        vals = [getattr(j, attr) for j in chain]
        return None if any(v is None for v in vals) else np.array(vals, dtype=float)

    lower = _optional_vec(arm, 'position_lower', n, w, urdf_limit('lower'))
    upper = _optional_vec(arm, 'position_upper', n, w, urdf_limit('upper'))
    velocity = _optional_vec(arm, 'velocity', n, w, urdf_limit('velocity'))
    for key, val, what in (
        ('position_lower', lower, 'lower'),
        ('position_upper', upper, 'upper'),
        ('velocity', velocity, 'velocity'),
    ):
        if val is None:
            missing = [j.name for j in chain if getattr(j, what) is None]
            raise ConfigError(
                f'{w}: joint {missing[0]!r} has no <limit {what}> in the URDF and arm.{key} does not override it'
            )
    if np.any(lower >= upper):
        raise ConfigError(f'{w}: position_lower must be below position_upper: {lower.tolist()} vs {upper.tolist()}')
    velocity = _positive(velocity, 'velocity', w)
    acceleration = _positive(
        _optional_vec(arm, 'acceleration', n, w, DEFAULT_ACCEL_PER_VELOCITY * velocity), 'acceleration', w
    )
    dex = _vec(arm, 'dexterous', n, w)
    _within(dex, lower, upper, f'{w}.dexterous', names)
    return ArmConfig(
        joints=names,
        types=tuple(j.type for j in chain),
        root=root,
        tool=tool,
        position_lower=lower,
        position_upper=upper,
        velocity=velocity,
        acceleration=acceleration,
        dexterous=dex,
    )


def _within(values, lower, upper, item, names):
    bad = np.flatnonzero((values < lower) | (values > upper))
    if bad.size:
        i = int(bad[0])
        raise ConfigError(
            f'{item}: outside the position limits: {names[i]} = {values[i]:.6g} not in [{lower[i]:.6g}, {upper[i]:.6g}]'
        )


def _parse_start(raw, arm):
    st = _section(raw, 'start', 'robot')
    w = 'start'
    q = _vec(st, 'arm', arm.n, w)
    _within(q, arm.position_lower, arm.position_upper, f'{w}.arm', arm.joints)
    ee_pose = _optional_vec(st, 'ee_pose', 6, w, None)
    tol = _optional_vec(st, 'ee_tolerance', 2, w, None)
    return StartState(
        base_pose=_vec(st, 'base_pose', 3, w),
        arm=q,
        ee_pose=ee_pose,
        ee_tolerance=None if tol is None else (float(tol[0]), float(tol[1])),
    )


def _wheel_radius(tree, name, role):
    radius = tree.wheel_radius(tree.joint(name, role).child)
    if radius is not None and not radius > 0.0:
        raise ConfigError(f'{tree.path.name}: {role} {name!r}: wheel radius must be > 0, got {radius}')
    return radius


def _wheel_origins(tree, base_link, names, role):
    """(x, y) of each wheel joint's origin in base_link [m], every joint checked to exist."""
    return np.array([tree.placement(tree.joint(n, role).child, base_link)[1][:2] for n in names])


def _joint_names(sec, key, where, size=None, minimum=None):
    names = sec.get(key)
    ok = isinstance(names, list) and all(isinstance(n, str) and n for n in names)
    if not ok or (size is not None and len(names) != size) or (minimum is not None and len(names) < minimum):
        want = f'{size}' if size is not None else f'at least {minimum}'
        raise ConfigError(f'{where}.{key}: expected a list of {want} joint names, got {names!r}')
    return tuple(names)


def _parse_steerable(raw, tree, base_link):
    s = _section(raw, 'steerable', 'robot')
    w = 'steerable'
    steer = _joint_names(s, 'steer_joints', w, minimum=2)
    drive = _joint_names(s, 'drive_joints', w, size=len(steer))
    urdf_hips = _wheel_origins(tree, base_link, steer, 'steer joint')
    for name in drive:
        tree.joint(name, 'drive joint')
    try:
        hips = np.asarray(s['hips'], dtype=float) if s.get('hips') is not None else urdf_hips
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{w}.hips: expected {len(steer)} pairs (hx, hy)') from exc
    if hips.shape != (len(steer), 2) or not np.all(np.isfinite(hips)):
        raise ConfigError(f'{w}.hips: expected shape ({len(steer)}, 2), one per steer joint, got {hips.shape}')
    radius, drive_v = _common_wheel_values(tree, drive, 'drive joint')
    offset = _one({round(-tree.joint(n).xyz[1], 9) for n in drive})
    steer_rate = _optional_scalar(
        s, 'steer_rate_limit', w, _one({_urdf_velocity(tree, n, 'steer joint') for n in steer})
    )
    drive_rate = _optional_scalar(s, 'drive_rate_limit', w, drive_v)
    return dict(
        steer_joints=steer,
        drive_joints=drive,
        hips=hips,
        wheel_radius=_optional_scalar(s, 'wheel_radius', w, radius),
        wheel_offset=_optional_scalar(s, 'wheel_offset', w, offset, positive=False),
        steer_rate_limit=steer_rate,
        steer_accel_limit=_optional_scalar(s, 'steer_accel_limit', w, DEFAULT_ACCEL_PER_VELOCITY * steer_rate),
        drive_rate_limit=drive_rate,
        drive_accel_limit=_optional_scalar(s, 'drive_accel_limit', w, DEFAULT_ACCEL_PER_VELOCITY * drive_rate),
    )


def _one(values):
    """The value every wheel shares, None when they differ or the URDF lacks it."""
    return next(iter(values)) if len(values) == 1 and None not in values else None


def _common_wheel_values(tree, names, role):
    """(radius, velocity limit) the URDF gives every wheel joint ``names``, None where they differ."""
    for name in names:
        tree.require_wheel_axis(tree.joint(name, role), role)
    return (_one({_wheel_radius(tree, n, role) for n in names}), _one({_urdf_velocity(tree, n, role) for n in names}))


def _fixed_wheels(sec, tree, base_link, where, **count):
    """(names, origins (N, 2), wheel_radius, wheel_rate_limit) of a base on fixed wheel axles."""
    names = _joint_names(sec, 'wheel_joints', where, **count)
    origins = _wheel_origins(tree, base_link, names, 'wheel joint')
    radius, rate = _common_wheel_values(tree, names, 'wheel joint')
    return (
        names,
        origins,
        _optional_scalar(sec, 'wheel_radius', where, radius),
        _optional_scalar(sec, 'wheel_rate_limit', where, rate),
    )


def usual_roller_angles(positions: np.ndarray) -> np.ndarray:
    """γ_i [rad] of the usual Mecanum rollers (Xing eq 16) for wheels at ``positions`` (x, y),
    shape (N, 2): π/4 where x y > 0 (front-left, rear-right), −π/4 where x y < 0, and 0 (rollers
    along the axle, which no base accepts) for a wheel on an axis (x y = 0). Shape (N,)."""
    xy = np.asarray(positions, dtype=float)
    return np.pi / 4 * np.sign(xy[:, 0] * xy[:, 1])


def _parse_mecanum(raw, tree, base_link):
    from wmm_control.base.mecanum import MecanumKinematics  # the base package imports this module

    m = _section(raw, 'mecanum', 'robot')
    w = 'mecanum'
    names, origins, radius, rate = _fixed_wheels(m, tree, base_link, w, minimum=3)
    positions = origins.copy()
    for k, key in enumerate(('d1', 'd2')):  # Xing's half wheelbase and half track: every wheel's |x|, |y|
        if m.get(key) is not None:
            positions[:, k] = np.sign(origins[:, k]) * _scalar(m, key, w)
    if m.get('roller_angles') is None:
        on_axis = [n for n, (x, y) in zip(names, positions) if x * y == 0.0]
        if on_axis:
            raise ConfigError(
                f'{w}: wheels {on_axis} sit on an axis of {base_link}: the usual roller pattern (γ = π/4 '
                'front-left and rear-right, −π/4 front-right and rear-left) does not place them; give '
                f'{w}.roller_angles'
            )
    angles = _optional_vec(m, 'roller_angles', len(names), w, usual_roller_angles(positions))
    if not np.all(np.isfinite(angles)):
        raise ConfigError(f'{w}.roller_angles: every entry must be finite, got {angles.tolist()}')
    try:
        MecanumKinematics(radius, positions, angles)
    except ConfigError as exc:
        raise ConfigError(f'{w}.roller_angles / wheel positions: {exc}') from exc
    return dict(
        wheel_joints=names,
        wheel_radius=radius,
        wheel_rate_limit=rate,
        positions=positions,
        roller_angles=angles,
    )


def _parse_differential(raw, tree, base_link):
    d = _section(raw, 'differential', 'robot')
    w = 'differential'
    names, origins, radius, rate = _fixed_wheels(d, tree, base_link, w, size=2)
    if np.any(np.abs(origins[:, 0]) > _AXLE_TOL) or origins[0, 1] <= origins[1, 1]:
        raise ConfigError(
            f'{w}.wheel_joints: the left and right wheels must sit on one axle through '
            f'{base_link} (x = 0, left at +y); the URDF puts them at {origins.round(4).tolist()}'
        )
    return dict(
        wheel_joints=names,
        wheel_radius=radius,
        wheel_rate_limit=rate,
        track=_optional_scalar(d, 'track', w, float(origins[0, 1] - origins[1, 1])),
    )


#: Each base family's class and the parser of its YAML section (the fields of the class but the limits).
_BASES = {
    SteerableBase.family: (SteerableBase, _parse_steerable),
    MecanumBase.family: (MecanumBase, _parse_mecanum),
    DifferentialBase.family: (DifferentialBase, _parse_differential),
}
BASE_FAMILIES = tuple(_BASES)


def _parse_base(raw, family, tree, base_link):
    """The robot's base of ``family``: its family's section, with the twist limits of section ``base``."""
    cls, parse = _BASES[family]
    fields = parse(raw, tree, base_link)
    base = _section(raw, 'base', 'robot')
    limits = {key: _vec(base, key, 3, 'base') for key in ('velocity', 'acceleration')}
    still = [k for k in range(3) if k not in cls.axes]
    for key, arr in limits.items():
        _positive(arr[list(cls.axes)], key, 'base')
        if np.any(arr[still] != 0.0):
            raise ConfigError(
                f'base.{key}: a {family} base cannot follow {[_TWIST_AXES[k] for k in still]}: '
                f'their entries must be 0, got {arr.tolist()}'
            )
    return cls(**limits, **fields)


def _collision_pairs(raw, tree):
    """``collision.pairs``: a list of [link, link] (a link of the URDF, or ``floor``); None when absent."""
    pairs = raw.get('collision', {}).get('pairs') if isinstance(raw.get('collision'), dict) else None
    if pairs is None:
        return None
    ok = isinstance(pairs, list) and all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p) for p in pairs
    )
    if not ok:
        raise ConfigError(f'collision.pairs: expected a list of [link, link] pairs, got {pairs!r}')
    for a, b in pairs:
        for name in (a, b):
            if name != 'floor':
                tree.require_link(name, 'collision.pairs')
    return tuple((a, b) for a, b in pairs)


def _limits(joint) -> tuple[float, float]:
    """A joint's position limits [rad or m], ±inf where the URDF gives none."""
    return (-math.inf if joint.lower is None else joint.lower, math.inf if joint.upper is None else joint.upper)


def held_joint_positions(
    tree: UrdfTree, arm: Iterable[str], base: Iterable[str] = (), given: Any = None
) -> dict[str, float]:
    """The position of every joint held still: each movable (revolute, continuous, prismatic) joint
    of ``tree`` but the ``arm`` joints and the ``base`` ones (wheels, steer joints) and the mimic
    joints that follow a base joint (they turn with the wheels, as before).

    A joint takes its value in ``given`` (the YAML's ``held_joints``: joint name → position [rad
    or m]), else its URDF zero clipped into its ``<limit>`` (0 for a continuous joint); a mimic
    joint follows its leader, ``multiplier · q + offset`` (the URDF's ``<mimic>``), and is never
    given itself.

    Raises:
        ConfigError: ``given`` is not a mapping of joint names to numbers, or names a joint the
            URDF lacks, a fixed one, an arm or base joint or a mimic joint, or puts a joint outside
            its limits; or a mimic joint follows an arm joint, a joint that does not move, or
            (through others) itself.
    """
    where = 'held_joints'
    arm, base = set(arm), set(base)
    movable = {n: j for n, j in tree.joints.items() if j.type in MOVING_TYPES}

    def leader(name):
        """The joint a chain of mimics from ``name`` ends at (``name`` itself when it mimics none)."""
        chain = [name]
        while movable[chain[-1]].mimic is not None:
            follows = movable[chain[-1]].mimic
            if follows not in movable or follows in chain:
                raise ConfigError(
                    f'{tree.path.name}: joint {chain[-1]!r} mimics {follows!r}, which '
                    + ('it follows already (a loop of mimics)' if follows in chain else 'is not a movable joint')
                )
            chain.append(follows)
        return chain[-1]

    held = {}
    for name, joint in movable.items():
        first = leader(name)
        if name in arm or name in base or first in base:
            continue
        if first in arm:
            raise ConfigError(
                f'{tree.path.name}: joint {name!r} mimics the arm joint {first!r}: a joint that moves with '
                'the arm cannot be held still (make the arm chain end below it)'
            )
        held[name] = joint
    given = {} if given is None else given
    if not isinstance(given, dict):
        raise ConfigError(f'{where}: expected a mapping of joint names to positions, got {given!r}')
    values = {}
    for name in given:
        listed = tree.joints.get(name) if isinstance(name, str) else None
        if listed is None:
            raise ConfigError(f'{where}: {name!r} is not a joint of {tree.path.name}')
        if name in arm or name in base:
            raise ConfigError(f'{where}: {name!r} is an arm or base joint, which the controllers drive: not held')
        if listed.type not in MOVING_TYPES:
            raise ConfigError(f'{where}: {name!r} is a {listed.type} joint: only a movable joint is held')
        if listed.mimic is not None:
            raise ConfigError(
                f'{where}: {name!r} mimics {listed.mimic!r} (the URDF\'s <mimic>): give {leader(name)!r} instead'
            )
        value = _scalar(given, name, where, positive=False)
        lower, upper = _limits(listed)
        if not lower <= value <= upper:
            raise ConfigError(f'{where}.{name}: {value:.6g} is outside its limits [{lower:.6g}, {upper:.6g}]')
        values[name] = value

    def position(name):
        joint = held[name]
        if joint.mimic is not None:
            return joint.mimic_multiplier * position(joint.mimic) + joint.mimic_offset
        if name in values:
            return values[name]
        lower, upper = _limits(joint)
        return min(max(0.0, lower), upper)

    return {name: float(position(name)) for name in held}


def _check_unique(cfg):
    names = list(cfg.arm.joints) + list(cfg.base.joints)
    seen = set()
    for name in names:
        if name in seen:
            raise ConfigError(f'joint {name!r} is named twice among the arm and base joints')
        seen.add(name)


def read_yaml(path: Path, what: str) -> Any:
    """The document of the YAML file ``path``.

    Raises:
        ConfigError: the file is missing or not YAML (``what`` names the kind of file in the
            message).
    """
    if not path.is_file():
        raise ConfigError(f'{what} not found: {path}')
    try:
        return parse_yaml(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f'{path}: not valid YAML: {str(exc).splitlines()[0] if str(exc) else exc}') from exc


def read_yaml_section(path: Path, key: str, what: str) -> dict:
    """The mapping under top-level ``key`` of the YAML file ``path``.

    Raises:
        ConfigError: the file is missing or not YAML, or has no such mapping (``what`` names
            the kind of file in the message).
    """
    doc = read_yaml(path, what)
    raw = doc.get(key) if isinstance(doc, dict) else None
    if not isinstance(raw, dict):
        raise ConfigError(f'{path}: top-level key "{key}" missing')
    return raw


def resolve_robot_yaml(robot: str | Path) -> Path:
    """Map a robot name, alias (A/B) or YAML path to the YAML file path."""
    key = str(robot).strip()
    name = ALIASES.get(key.lower(), key.lower())
    if name in robot_names():
        return config_path('robots', f'{name}.yaml')
    path = Path(key).expanduser()
    if path.suffix in ('.yaml', '.yml'):
        return path
    raise ConfigError(
        f'unknown robot {robot!r}: use one of {robot_names()}, an alias A/B, or a path to a robot YAML file'
    )


def load_robot(robot: str | Path | RobotConfig) -> RobotConfig:
    """Load and validate a robot description.

    Args:
        robot: a shipped robot's name (``'steerable'`` / ``'A'``, ``'mecanum'`` / ``'B'``,
            ``'ur_mecanum'``, ``'panda_diff'``) or a robot YAML path.

    Raises:
        ConfigError: unknown name, missing or unreadable file, or an invalid item. The message
            is one line that names the YAML file and the item.
    """
    if isinstance(robot, RobotConfig):
        return robot
    path = resolve_robot_yaml(robot)
    raw = read_yaml_section(path, 'robot', 'robot description')
    try:
        return _parse(path, raw)
    except ConfigError as exc:
        raise ConfigError(f'{path}: {exc}') from exc


def _parse(path, raw):
    family = raw.get('base_type')
    if family not in BASE_FAMILIES:
        raise ConfigError(f'base_type: unknown base family {family!r}; expected one of {list(BASE_FAMILIES)}')
    urdf = raw.get('urdf')
    if not isinstance(urdf, str):
        raise ConfigError('missing key "urdf" (the URDF path, relative to this file)')
    urdf_path = (path.parent / urdf).resolve()
    if not urdf_path.is_file():
        raise ConfigError(f'urdf: file not found: {urdf_path}')
    tree = UrdfTree(urdf_path)
    package_dirs = yaml_package_dirs(raw, path)
    check_resources(urdf_path, package_dirs)
    tree.require_masses()
    base_link = raw.get('base_link', 'base_link')
    tree.require_link(base_link, 'base')
    arm = _parse_arm(raw, tree, 'robot')
    base = _parse_base(raw, family, tree, base_link)
    cfg = RobotConfig(
        name=str(raw.get('name', path.stem)),
        description=str(raw.get('description', '')),
        yaml_path=path.resolve(),
        urdf_path=urdf_path,
        base_link=base_link,
        ee_frame=arm.tool,
        ground_z=_optional_scalar(raw, 'ground_z', 'robot', 0.0, positive=False),
        period=_scalar(raw, 'period', 'robot'),
        method=_word(raw, 'method', 'robot'),
        arm=arm,
        base=base,
        start=_parse_start(raw, arm),
        raw=raw,
        package_dirs=package_dirs,
        collision_pairs=_collision_pairs(raw, tree),
        held_joints=held_joint_positions(tree, arm.joints, base.joints, raw.get('held_joints')),
    )
    _check_unique(cfg)
    return cfg
