"""``wmm_model``: load a robot and print its joints, limits and start-state kinematics.

Usage: ``wmm_model [--robot steerable|mecanum|A|B|PATH] [--arm q1 ... q7] [--base x y θ]``
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

import numpy as np

# the kinematics (pinocchio) are imported where they are used, once the arguments are parsed
from wmm_control.errors import WmmError

if TYPE_CHECKING:
    from wmm_control.robot_config import Base

__all__ = ['main', 'describe']


def _fmt(values, digits=4):
    return (
        '[' + ', '.join(f'{v: .{digits}f}' if np.isfinite(v) else (' inf' if v > 0 else '-inf') for v in values) + ']'
    )


def _describe_base(base: Base) -> str:
    """One line on the base's geometry and wheel limits."""
    from wmm_control.robot_config import DifferentialBase, MecanumBase, SteerableBase

    match base:
        case SteerableBase():
            return (
                f'steerable modules ({base.n_modules}): hips {base.hips.tolist()}, r_w {base.wheel_radius} m, '
                f'd {base.wheel_offset} m, steer ≤ {base.steer_rate_limit} rad/s, ≤ {base.steer_accel_limit} rad/s², '
                f'drive ≤ {base.drive_rate_limit} rad/s'
            )
        case DifferentialBase():
            return (
                f'differential wheels {list(base.wheel_joints)}: r {base.wheel_radius} m, track {base.track} m, '
                f'≤ {base.wheel_rate_limit} rad/s (no sideways motion)'
            )
        case MecanumBase():
            return (
                f'mecanum wheels ({len(base.wheel_joints)}): R {base.wheel_radius} m, positions '
                f'{base.positions.round(4).tolist()} m, roller angles {np.degrees(base.roller_angles).round(2).tolist()}°, '
                f'≤ {base.wheel_rate_limit} rad/s'
            )


def describe(model, base_pose, q_arm):
    """Text report of a robot and one state of it."""
    cfg = model.config
    model.update(base_pose, q_arm)
    lines = [
        f'robot: {cfg.name} ({cfg.base.family} base, {cfg.arm.n} arm joints) - {cfg.description}',
        f'urdf: {cfg.urdf_path}',
        f'end-effector frame: {model.ee_frame}',
        '',
        f'{"arm joint":<16}{"lower":>9}{"upper":>9}{"vel":>8}{"acc":>8}   units',
    ]
    a = cfg.arm
    for i, name in enumerate(a.joints):
        unit = 'm, m/s, m/s²' if a.types[i] == 'prismatic' else 'rad, rad/s, rad/s²'
        lines.append(
            f'{name:<16}{a.position_lower[i]:>9.3f}{a.position_upper[i]:>9.3f}'
            f'{a.velocity[i]:>8.3f}{a.acceleration[i]:>8.3f}   {unit}'
        )
    if cfg.held_joints:
        from wmm_control.urdf import UrdfTree

        tree = UrdfTree(cfg.urdf_path)
        width = max(16, *(len(name) + 1 for name in cfg.held_joints))
        lines.append(f'{"held joint":<{width}}{"at":>9}   unit (held_joints: outside the arm and the base)')
        for name, value in cfg.held_joints.items():
            joint = tree.joint(name)
            unit = 'm' if joint.type == 'prismatic' else 'rad'
            follows = f' (mimic of {joint.mimic})' if joint.mimic is not None else ''
            lines.append(f'{name:<{width}}{value:>9.3f}   {unit}{follows}')
    lines.append(f'base velocity limits (vx, vy, ω): {_fmt(cfg.base.velocity, 3)}')
    lines.append(f'base acceleration limits:         {_fmt(cfg.base.acceleration, 3)}')
    lines.append(_describe_base(cfg.base))
    pose_w = model.ee_pose_world()
    lines += [
        '',
        f'base pose (x, y, θ):      {_fmt(base_pose)}',
        f'arm joints:               {_fmt(q_arm)}',
        f'EE pose world (xyz, RPY): {_fmt(pose_w)}',
        f'EE pose base  (xyz, RPY): {_fmt(model.ee_pose_base())}',
    ]
    if (
        cfg.start.ee_pose is not None
        and np.allclose(q_arm, cfg.start.arm)
        and np.allclose(base_pose, cfg.start.base_pose)
    ):
        err = np.linalg.norm(pose_w[:3] - cfg.start.ee_pose[:3])
        lines.append(f"paper's start EE pose:    {_fmt(cfg.start.ee_pose)}  (position error {err * 1e3:.3f} mm)")
    from wmm_control.kinematics.tasks import ManipulabilityTask

    position, full = ManipulabilityTask(model, 'position'), ManipulabilityTask(model, 'full')
    lines += [
        f'manipulability det(J_m J_mᵀ), position rows: {position.value():.6f}',
        f'manipulability det(J_m J_mᵀ), all six rows:  {full.value():.3e}',
        f'σ_min(J_m) position rows: {position.sigma_min():.4f}, all six rows: {full.sigma_min():.4f}',
    ]
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='wmm_model', description=__doc__.splitlines()[0])
    parser.add_argument('--robot', default='steerable', help='a robot name, A | B, or a path to a robot YAML')
    parser.add_argument('--arm', type=float, nargs='+', metavar='Q', help='arm joints [rad] (default: start state)')
    parser.add_argument('--base', type=float, nargs=3, metavar='X', help='base x y θ (default: start state)')
    args = parser.parse_args(argv)
    from wmm_control.kinematics import KinematicModel

    try:
        model = KinematicModel(args.robot)
        cfg = model.config
        base = np.array(args.base) if args.base else cfg.start.base_pose
        arm = np.array(args.arm) if args.arm else cfg.start.arm
        print(describe(model, base, arm))
    except WmmError as exc:
        print(f'wmm_model: error: {exc}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
