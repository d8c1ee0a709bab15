"""Robot descriptions: the YAML file beside each URDF, loaded and validated.

A robot is named ``steerable`` (robot A: steerable wheeled base, Sorour 2019) or
``mecanum`` (robot B: Mecanum base, Xing et al.); ``A`` and ``B`` are accepted as
aliases. A path to a YAML file of the same schema works too.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from wmm_control.errors import ConfigError
from wmm_control.paths import config_path

__all__ = [
    'ArmConfig', 'BaseLimits', 'StartState', 'SteerableConfig', 'MecanumConfig',
    'RobotConfig', 'load_robot', 'ROBOT_NAMES',
]

ROBOT_NAMES = {'steerable': 'steerable', 'a': 'steerable', 'mecanum': 'mecanum', 'b': 'mecanum'}
N_ARM = 7
N_WHEELS = 4


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


def _names(raw, key, size, where):
    names = raw.get(key)
    if not isinstance(names, list) or len(names) != size or not all(isinstance(n, str) for n in names):
        raise ConfigError(f'{where}.{key}: expected a list of {size} joint names, got {names!r}')
    return tuple(names)


@dataclass(frozen=True)
class ArmConfig:
    """The 7-DOF arm: joint names and limits (rad, rad/s, rad/s²), dexterous posture."""

    joints: tuple
    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    dexterous: np.ndarray


@dataclass(frozen=True)
class BaseLimits:
    """Base twist limits, (vx, vy, ω) in the base frame: [m/s, m/s, rad/s] and per second."""

    velocity: np.ndarray
    acceleration: np.ndarray


@dataclass(frozen=True)
class StartState:
    """The paper's start state: base pose (x, y, θ), arm joints, expected world EE pose (xyz + RPY)."""

    base_pose: np.ndarray
    arm: np.ndarray
    ee_pose: np.ndarray
    ee_tolerance: tuple


@dataclass(frozen=True)
class SteerableConfig:
    """Steerable base geometry (Sorour Table I): hips (4, 2) [m], r_w, d [m], steer/drive limits.

    ``drive_accel_limit`` [rad/s²] is the drive deceleration used to ramp the wheels to rest
    after a controller failure.
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


@dataclass(frozen=True)
class MecanumConfig:
    """Mecanum base geometry (Xing eq 16): R, d1 (half wheelbase), d2 (half track) [m]."""

    wheel_joints: tuple
    wheel_radius: float
    d1: float
    d2: float
    wheel_rate_limit: float


@dataclass(frozen=True)
class RobotConfig:
    """One robot: its URDF, frames, control period, default redundancy resolution method, arm,
    base limits, start state and base geometry."""

    name: str
    description: str
    yaml_path: Path
    urdf_path: Path
    base_type: str
    base_link: str
    ee_frame: str
    ground_z: float
    period: float
    method: str
    arm: ArmConfig
    base: BaseLimits
    start: StartState
    steerable: SteerableConfig = None
    mecanum: MecanumConfig = None
    raw: dict = field(default=None, repr=False, compare=False)

    @property
    def wheel_joints(self):
        """Every wheel-side joint name, in command order (steer then drive, or the 4 wheels)."""
        if self.steerable is not None:
            return self.steerable.steer_joints + self.steerable.drive_joints
        return self.mecanum.wheel_joints

    @property
    def joint_velocity_limits(self):
        """Velocity limit [rad/s] by joint name, for every actuated joint."""
        limits = dict(zip(self.arm.joints, self.arm.velocity.tolist()))
        if self.steerable is not None:
            s = self.steerable
            limits.update({n: s.steer_rate_limit for n in s.steer_joints})
            limits.update({n: s.drive_rate_limit for n in s.drive_joints})
        else:
            limits.update({n: self.mecanum.wheel_rate_limit for n in self.mecanum.wheel_joints})
        return limits


def _parse_arm(raw, where):
    arm = _section(raw, 'arm', where)
    w = f'{where}.arm'
    lower = _vec(arm, 'position_lower', N_ARM, w)
    upper = _vec(arm, 'position_upper', N_ARM, w)
    if np.any(lower >= upper):
        raise ConfigError(f'{w}: position_lower must be below position_upper: {lower.tolist()} vs {upper.tolist()}')
    dex = _vec(arm, 'dexterous', N_ARM, w)
    if np.any(dex < lower) or np.any(dex > upper):
        raise ConfigError(f'{w}.dexterous: outside the position limits: {dex.tolist()}')
    return ArmConfig(
        joints=_names(arm, 'joints', N_ARM, w),
        position_lower=lower,
        position_upper=upper,
        velocity=_positive(_vec(arm, 'velocity', N_ARM, w), 'velocity', w),
        acceleration=_positive(_vec(arm, 'acceleration', N_ARM, w), 'acceleration', w),
        dexterous=dex,
    )


def _parse_start(raw, where):
    st = _section(raw, 'start', where)
    w = f'{where}.start'
    tol = _vec(st, 'ee_tolerance', 2, w)
    return StartState(
        base_pose=_vec(st, 'base_pose', 3, w),
        arm=_vec(st, 'arm', N_ARM, w),
        ee_pose=_vec(st, 'ee_pose', 6, w),
        ee_tolerance=(float(tol[0]), float(tol[1])),
    )


def _parse_steerable(raw, where):
    s = _section(raw, 'steerable', where)
    w = f'{where}.steerable'
    try:
        hips = np.asarray(s['hips'], dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(f'{w}.hips: expected 4 pairs (hx, hy)') from exc
    if hips.shape != (N_WHEELS, 2) or not np.all(np.isfinite(hips)):
        raise ConfigError(f'{w}.hips: expected shape (4, 2), got {hips.shape}')
    return SteerableConfig(
        steer_joints=_names(s, 'steer_joints', N_WHEELS, w),
        drive_joints=_names(s, 'drive_joints', N_WHEELS, w),
        hips=hips,
        wheel_radius=_scalar(s, 'wheel_radius', w),
        wheel_offset=_scalar(s, 'wheel_offset', w, positive=False),
        steer_rate_limit=_scalar(s, 'steer_rate_limit', w),
        steer_accel_limit=_scalar(s, 'steer_accel_limit', w),
        drive_rate_limit=_scalar(s, 'drive_rate_limit', w),
        drive_accel_limit=_scalar(s, 'drive_accel_limit', w),
    )


def _parse_mecanum(raw, where):
    m = _section(raw, 'mecanum', where)
    w = f'{where}.mecanum'
    return MecanumConfig(
        wheel_joints=_names(m, 'wheel_joints', N_WHEELS, w),
        wheel_radius=_scalar(m, 'wheel_radius', w),
        d1=_scalar(m, 'd1', w),
        d2=_scalar(m, 'd2', w),
        wheel_rate_limit=_scalar(m, 'wheel_rate_limit', w),
    )


def read_yaml_section(path, key, what):
    """The mapping under top-level ``key`` of the YAML file ``path``.

    Raises:
        ConfigError: the file is missing or not YAML, or has no such mapping (``what`` names
            the kind of file in the message).
    """
    if not path.is_file():
        raise ConfigError(f'{what} not found: {path}')
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f'{path}: not valid YAML: {exc}') from exc
    raw = doc.get(key) if isinstance(doc, dict) else None
    if not isinstance(raw, dict):
        raise ConfigError(f'{path}: top-level key "{key}" missing')
    return raw


def resolve_robot_yaml(robot):
    """Map a robot name, alias (A/B) or YAML path to the YAML file path."""
    key = str(robot).strip().lower()
    if key in ROBOT_NAMES:
        return config_path('robots', f'{ROBOT_NAMES[key]}.yaml')
    path = Path(robot)
    if path.suffix in ('.yaml', '.yml'):
        return path
    raise ConfigError(
        f'unknown robot {robot!r}: use one of {sorted(set(ROBOT_NAMES.values()))}, '
        f'an alias A/B, or a path to a robot YAML file')


def load_robot(robot='steerable'):
    """Load and validate a robot description.

    Args:
        robot: ``'steerable'`` / ``'A'``, ``'mecanum'`` / ``'B'``, or a YAML path.

    Raises:
        ConfigError: unknown name, missing file, or a missing/invalid key (the
            message names the key).
    """
    path = resolve_robot_yaml(robot)
    raw = read_yaml_section(path, 'robot', 'robot description')
    where = path.name
    base_type = raw.get('base_type')
    if base_type not in ('steerable', 'mecanum'):
        raise ConfigError(f'{where}.base_type: expected "steerable" or "mecanum", got {base_type!r}')
    urdf = raw.get('urdf')
    if not isinstance(urdf, str):
        raise ConfigError(f'{where}: missing key "urdf"')
    urdf_path = (path.parent / urdf).resolve()
    if not urdf_path.is_file():
        raise ConfigError(f'{where}.urdf: file not found: {urdf_path}')
    base = _section(raw, 'base', where)
    return RobotConfig(
        name=str(raw.get('name', path.stem)),
        description=str(raw.get('description', '')),
        yaml_path=path.resolve(),
        urdf_path=urdf_path,
        base_type=base_type,
        base_link=str(raw.get('base_link', 'base_link')),
        ee_frame=str(raw.get('ee_frame', 'ee_link')),
        ground_z=float(raw.get('ground_z', 0.0)),
        period=_scalar(raw, 'period', where),
        method=_word(raw, 'method', where),
        arm=_parse_arm(raw, where),
        base=BaseLimits(
            velocity=_positive(_vec(base, 'velocity', 3, f'{where}.base'), 'velocity', f'{where}.base'),
            acceleration=_positive(_vec(base, 'acceleration', 3, f'{where}.base'), 'acceleration',
                                   f'{where}.base'),
        ),
        start=_parse_start(raw, where),
        steerable=_parse_steerable(raw, where) if base_type == 'steerable' else None,
        mecanum=_parse_mecanum(raw, where) if base_type == 'mecanum' else None,
        raw=raw,
    )
