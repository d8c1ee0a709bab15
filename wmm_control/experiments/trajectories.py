"""End-effector reference trajectories of Xing et al. §4, relative to the start pose.

Each is a function of time returning a :class:`~wmm_control.resolvers.PoseTarget` with the
pose, the twist and the acceleration (world frame), ω = π/20 rad/s:

* ``circle`` (§4.2–4.3): ``x_d(t) = x0 + [−R(cos ωt − 1), −R sin ωt, 0]``, orientation held;
* ``pose`` (§4.4): ``x_d(t) = x0 + [0.15 sin ωt, 0, 0]`` and a rotation of ``π/4 sin ωt``
  about the world y axis applied to the start orientation, ``R_y(π/4 sin ωt) R₀`` (robot B's
  start orientation has pitch π/2, the RPY singularity, so no RPY angles are involved).
"""

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.errors import ConfigError
from wmm_control.resolvers.interface import PoseTarget

__all__ = ['make_trajectory', 'TRAJECTORY_KINDS', 'OMEGA']

OMEGA = math.pi / 20.0
TRAJECTORY_KINDS = ('circle', 'pose')
_Y = np.array([0.0, 1.0, 0.0])


def _circle(x0, r0, radius):
    def at(t: float) -> PoseTarget:
        c, s = math.cos(OMEGA * t), math.sin(OMEGA * t)
        return PoseTarget(
            x0 + radius * np.array([1.0 - c, -s, 0.0]),
            r0,
            velocity=radius * OMEGA * np.array([s, -c, 0.0, 0.0, 0.0, 0.0]),
            acceleration=radius * OMEGA**2 * np.array([c, s, 0.0, 0.0, 0.0, 0.0]),
        )

    return at


def _pose(x0, r0, amplitude=0.15, angle=math.pi / 4):
    def at(t: float) -> PoseTarget:
        c, s = math.cos(OMEGA * t), math.sin(OMEGA * t)
        rot = pin.exp3(angle * s * _Y) @ r0
        vel = np.concatenate((amplitude * OMEGA * c * np.array([1.0, 0.0, 0.0]), angle * OMEGA * c * _Y))
        acc = np.concatenate((-amplitude * OMEGA**2 * s * np.array([1.0, 0.0, 0.0]), -angle * OMEGA**2 * s * _Y))
        return PoseTarget(x0 + amplitude * s * np.array([1.0, 0.0, 0.0]), rot, velocity=vel, acceleration=acc)

    return at


def make_trajectory(spec: Any, start_position: ArrayLike, start_rotation: ArrayLike) -> Callable[[float], PoseTarget]:
    """The trajectory ``t -> PoseTarget`` of a scenario's ``trajectory`` entry.

    Args:
        spec: ``{kind: circle, radius: R}`` or ``{kind: pose}``.
        start_position, start_rotation: the end effector's start pose x0, R₀ (world).

    Raises:
        ConfigError: unknown kind or a bad radius.
    """
    kind = spec.get('kind') if isinstance(spec, dict) else None
    x0 = np.asarray(start_position, dtype=float)
    r0 = np.asarray(start_rotation, dtype=float)
    if kind == 'circle':
        radius = spec.get('radius')
        if isinstance(radius, bool) or not isinstance(radius, (int, float)) or not 0 < radius < 10:
            raise ConfigError(f'trajectory circle: radius must be a number in (0, 10) m, got {radius!r}')
        return _circle(x0, r0, float(radius))
    if kind == 'pose':
        return _pose(x0, r0)
    raise ConfigError(f'trajectory: kind must be one of {TRAJECTORY_KINDS}, got {spec!r}')
