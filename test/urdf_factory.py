"""URDFs of made-up mobile manipulators, written on the fly for tests (none is in the repo).

:func:`write_urdf` builds a base of any family (a steerable base with N modules on a circle,
Mecanum wheels, four by default, or a differential pair with two casters) and an arm of n joints whose
axes alternate z, y, y, z, y, z, ... (an anthropomorphic-like chain), optionally on a
prismatic lift, and optionally a head outside the arm (:data:`HEAD_PAN`). Shapes are primitive;
every link has an inertial.
"""

import math
import struct
from pathlib import Path

import yaml

#: The four Mecanum wheels of :func:`write_urdf` by default: (tag, x, y) [m].
MECANUM_WHEELS = (('fl', 0.22, 0.2), ('fr', 0.22, -0.2), ('rl', -0.22, 0.2), ('rr', -0.22, -0.2))
#: Six Mecanum wheels, a pair on the y axis, and roller angles [rad] that make every twist.
SIX_MECANUM_WHEELS = (
    ('fl', 0.3, 0.25),
    ('fr', 0.3, -0.25),
    ('ml', 0.0, 0.25),
    ('mr', 0.0, -0.25),
    ('rl', -0.3, 0.25),
    ('rr', -0.3, -0.25),
)
SIX_ROLLER_ANGLES = (math.pi / 4, -math.pi / 4, math.pi / 3, -math.pi / 3, -math.pi / 4, math.pi / 4)
#: The head of :func:`write_urdf` (``head=True``): ``head_pan_joint`` turns about z at this (x, y, z)
#: on ``chassis_link`` [m], within these limits [rad] (zero is outside them: it is held at the lower
#: one by default); ``head_link``'s collision sphere of this radius sits this far along the head's
#: x axis, level with the arm's first link (a vertical cylinder of radius ARM_RADIUS about the
#: chassis' (0.1, 0)); ``head_visor_joint`` mimics the pan joint (multiplier, offset).
HEAD_PAN = {'origin': (-0.2, 0.0, 0.1), 'limits': (0.25, 2.0), 'radius': 0.05, 'reach': 0.1, 'height': 0.175}
HEAD_MIMIC = (0.5, 0.1)
ARM_RADIUS = 0.035
ARM_AXIS_XY = (0.1, 0.0)


def _inertial(mass=1.0):
    return (
        f'<inertial><mass value="{mass}"/><origin xyz="0 0 0"/>'
        '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
    )


def _link(name, geometry='', origin='0 0 0', rpy='0 0 0', mass=1.0):
    shape = (
        f'<visual><origin xyz="{origin}" rpy="{rpy}"/><geometry>{geometry}</geometry></visual>'
        f'<collision><origin xyz="{origin}" rpy="{rpy}"/><geometry>{geometry}</geometry></collision>'
        if geometry
        else ''
    )
    return f'<link name="{name}">{_inertial(mass)}{shape}</link>'


def _joint(name, jtype, parent, child, xyz, axis='0 0 1', rpy='0 0 0', limit=''):
    return (
        f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{limit}</joint>'
    )


def _wheel(name, parent, xyz, radius, rate):
    return [
        _joint(
            f'{name}_joint',
            'continuous',
            parent,
            f'{name}_link',
            xyz,
            '0 1 0',
            limit=f'<limit effort="20" velocity="{rate}"/>',
        ),
        _link(f'{name}_link', f'<cylinder radius="{radius}" length="0.04"/>', rpy=f'{math.pi / 2} 0 0', mass=0.5),
    ]


def write_urdf(
    path, base='steerable', modules=4, arm_joints=7, prismatic_lift=False, wheels=MECANUM_WHEELS, head=False
):
    """Write a URDF at ``path``; returns the path. Links: ``base_link`` (on the floor),
    ``arm_base_link`` (the arm root), ``tool_link`` (the tool). A Mecanum base has a wheel
    ``wheel_<tag>_joint`` at each ``(tag, x, y)`` of ``wheels``; ``head`` adds the head of
    :data:`HEAD_PAN`."""
    r = 0.08
    parts = [
        _link('base_link', mass=0.1),
        _joint('chassis_joint', 'fixed', 'base_link', 'chassis_link', f'0 0 {r + 0.15}'),
        _link('chassis_link', '<box size="0.6 0.45 0.2"/>', mass=20.0),
    ]
    if base == 'steerable':
        for i in range(modules):
            a = 2 * math.pi * (i + 0.5) / modules
            hx, hy = 0.26 * math.cos(a), 0.2 * math.sin(a)
            parts += [
                _joint(
                    f'steer_{i}_joint',
                    'continuous',
                    'base_link',
                    f'steer_{i}_link',
                    f'{hx:.6f} {hy:.6f} {r}',
                    limit='<limit effort="20" velocity="1.5"/>',
                ),
                _link(f'steer_{i}_link', mass=0.3),
            ]
            parts += _wheel(f'drive_{i}', f'steer_{i}_link', '0 -0.03 0', r, 12.0)
    elif base == 'mecanum':
        for tag, x, y in wheels:
            parts += _wheel(f'wheel_{tag}', 'base_link', f'{x} {y} {r}', r, 12.0)
    else:
        parts += _wheel('wheel_left', 'base_link', f'0 0.24 {r}', r, 12.0)
        parts += _wheel('wheel_right', 'base_link', f'0 -0.24 {r}', r, 12.0)
        for tag, x in (('front', 0.25), ('rear', -0.25)):
            parts += [
                _joint(f'caster_{tag}_joint', 'fixed', 'base_link', f'caster_{tag}_link', f'{x} 0 0.04'),
                _link(f'caster_{tag}_link', '<sphere radius="0.04"/>', mass=0.2),
            ]
    if head:
        lower, upper = HEAD_PAN['limits']
        multiplier, offset = HEAD_MIMIC
        parts += [
            _joint(
                'head_pan_joint',
                'revolute',
                'chassis_link',
                'head_link',
                ' '.join(str(v) for v in HEAD_PAN['origin']),
                limit=f'<limit lower="{lower}" upper="{upper}" effort="5" velocity="1.0"/>',
            ),
            _link(
                'head_link',
                f'<sphere radius="{HEAD_PAN["radius"]}"/>',
                origin=f'{HEAD_PAN["reach"]} 0 {HEAD_PAN["height"]}',
                mass=0.5,
            ),
            _joint(
                'head_visor_joint',
                'revolute',
                'head_link',
                'head_visor_link',
                '0.05 0 0.2',
                '0 1 0',
                limit='<limit lower="-1" upper="1" effort="1" velocity="1.0"/>',
            ).replace(
                '</joint>', f'<mimic joint="head_pan_joint" multiplier="{multiplier}" offset="{offset}"/></joint>'
            ),
            _link('head_visor_link', mass=0.05),
        ]
    parts += [
        _joint('arm_mount_joint', 'fixed', 'chassis_link', 'arm_base_link', '0.1 0 0.1'),
        _link('arm_base_link', '<cylinder radius="0.06" length="0.1"/>', origin='0 0 0.05'),
    ]
    parent, n = 'arm_base_link', arm_joints
    lengths = [0.15] + [0.32 if k in (1, 3) else 0.12 for k in range(1, n)]
    for k in range(n):
        name = f'arm_joint_{k + 1}'
        child = f'arm_link_{k + 1}'
        if k == 0 and prismatic_lift:
            parts.append(
                _joint(
                    name,
                    'prismatic',
                    parent,
                    child,
                    '0 0 0.1',
                    '0 0 1',
                    limit='<limit lower="0.0" upper="0.4" effort="100" velocity="0.2"/>',
                )
            )
        else:
            axis = '0 0 1' if (k - int(prismatic_lift)) % 3 == 0 else '0 1 0'
            parts.append(
                _joint(
                    name,
                    'revolute',
                    parent,
                    child,
                    f'0 0 {lengths[k - 1] if k else 0.1}',
                    axis,
                    limit='<limit lower="-2.6" upper="2.6" effort="50" velocity="1.8"/>',
                )
            )
        length = lengths[k]
        parts.append(
            _link(
                child,
                f'<cylinder radius="0.035" length="{0.6 * length:.4f}"/>',
                origin=f'0 0 {0.5 * length:.4f}',
                mass=1.0,
            )
        )
        parent = child
    parts += [_joint('tool_joint', 'fixed', parent, 'tool_link', f'0 0 {lengths[-1]}'), _link('tool_link', mass=0.05)]
    path = Path(path)
    path.write_text('<?xml version="1.0"?>\n<robot name="made_up">\n  ' + '\n  '.join(parts) + '\n</robot>\n')
    return path


def write_mecanum_robot(folder, wheels, roller_angles=None):
    """Write a URDF (:func:`write_urdf`, a Mecanum base with ``wheels`` and a 7-joint arm) and its
    robot YAML in ``folder``; returns the YAML's path. ``roller_angles`` [rad]: the YAML's
    ``mecanum.roller_angles``, omitted when None."""
    folder = Path(folder)
    write_urdf(folder / 'mecanum_n.urdf', 'mecanum', wheels=wheels)
    posture = [0.0, 0.5, 0.0, 1.0, 0.0, 0.5, 0.0]
    mecanum = {'wheel_joints': [f'wheel_{tag}_joint' for tag, _, _ in wheels]}
    if roller_angles is not None:
        mecanum['roller_angles'] = [float(a) for a in roller_angles]
    robot = {
        'name': 'mecanum_n',
        'urdf': 'mecanum_n.urdf',
        'base_type': 'mecanum',
        'period': 0.025,
        'method': 'pinv',
        'arm': {'root': 'arm_base_link', 'tool': 'tool_link', 'dexterous': posture},
        'base': {'velocity': [0.3, 0.3, 0.6], 'acceleration': [0.6, 0.6, 1.2]},
        'start': {'base_pose': [0.0, 0.0, 0.0], 'arm': posture},
        'mecanum': mecanum,
    }
    path = folder / 'mecanum_n.yaml'
    path.write_text(yaml.safe_dump({'robot': robot}))
    return path


def write_box_stl(path):
    """Write a binary STL (what PyBullet and pinocchio both read) of the unit cube centred on the
    origin, 12 triangles; returns the path."""
    corners = [(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    # two triangles per face, counter-clockwise seen from outside
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    data = bytearray(b'box'.ljust(80, b' ')) + struct.pack('<I', len(faces))
    for face in faces:
        data += struct.pack('<12fH', 0.0, 0.0, 0.0, *(c for i in face for c in corners[i]), 0)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_bytes(bytes(data))
    return Path(path)
