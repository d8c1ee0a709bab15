"""What the robot description needs from a URDF: its joint tree, limits and wheel shapes.

A small reader over the standard library's XML parser. It answers the questions a robot
set-up asks — the joint chain between two links, each joint's type and ``<limit>``, the
cylinder a wheel link rolls on, where a joint sits on the base — and raises
:class:`~wmm_control.errors.ConfigError` with the file and the item when the URDF cannot
answer them. Kinematics proper (frames, Jacobians) is pinocchio's job
(:mod:`wmm_control.kinematics.model`), on the same file.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from wmm_control.errors import ConfigError
from wmm_control.geometry import matrix_from_rpy

__all__ = ['UrdfJoint', 'UrdfTree', 'MOVING_TYPES']

MOVING_TYPES = ('revolute', 'continuous', 'prismatic')


def _floats(text: str | None, size: int, default: tuple) -> np.ndarray:
    if text is None:
        return np.array(default, dtype=float)
    vals = np.array([float(v) for v in text.split()], dtype=float)
    if vals.shape != (size,):
        raise ValueError(f'expected {size} numbers, got {text!r}')
    return vals


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>``: its type, links, origin (parent frame), axis and ``<limit>``.

    ``lower``/``upper`` are ±inf for a continuous joint, None where the URDF has none;
    ``velocity`` is None where the URDF has no ``<limit velocity>``; a mimic joint's position is
    ``mimic_multiplier`` times the position of joint ``mimic`` plus ``mimic_offset``.
    """

    name: str
    type: str
    parent: str
    child: str
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray
    lower: float | None
    upper: float | None
    velocity: float | None
    mimic: str | None
    mimic_multiplier: float = 1.0
    mimic_offset: float = 0.0


class UrdfTree:
    """The joint tree of a URDF file.

    Args:
        path: the URDF file.

    Raises:
        ConfigError: the file cannot be read or parsed, or a joint is malformed (the message
            names the file and the joint).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            root = ET.parse(self.path).getroot()
        except OSError as exc:
            raise ConfigError(f'{self.path}: URDF unreadable: {exc.strerror or exc}') from exc
        except ET.ParseError as exc:
            raise ConfigError(f'{self.path}: URDF unreadable: not valid XML ({exc})') from exc
        if root.tag != 'robot':
            raise ConfigError(f'{self.path}: URDF unreadable: the root element is <{root.tag}>, not <robot>')
        self.name = root.get('name', self.path.stem)
        self.links: dict[str, ET.Element] = {}
        for link in root.findall('link'):
            name = cast(str, link.get('name'))  # None only for a nameless <link> (not a valid URDF)
            if name in self.links:
                raise ConfigError(f'{self.path}: link {name!r} is defined twice')
            self.links[name] = link
        self.joints: dict[str, UrdfJoint] = {}
        for elem in root.findall('joint'):
            joint = self._joint(elem)
            if joint.name in self.joints:
                raise ConfigError(f'{self.path}: duplicate joint name {joint.name!r}')
            self.joints[joint.name] = joint
        self._by_child = {j.child: j for j in self.joints.values()}
        roots = [name for name in self.links if name not in self._by_child]
        self.root_link = roots[0] if len(roots) == 1 else None

    def _joint(self, elem: ET.Element) -> UrdfJoint:
        name = elem.get('name')
        where = f'{self.path.name}: joint {name!r}'
        parent, child = elem.find('parent'), elem.find('child')
        if not name or parent is None or child is None:
            raise ConfigError(f'{where}: needs a name, <parent link> and <child link>')
        jtype = elem.get('type', '')
        try:
            origin = elem.find('origin')
            xyz = _floats(origin.get('xyz') if origin is not None else None, 3, (0, 0, 0))
            rpy = _floats(origin.get('rpy') if origin is not None else None, 3, (0, 0, 0))
            axis_el = elem.find('axis')
            axis = _floats(axis_el.get('xyz') if axis_el is not None else None, 3, (1, 0, 0))
            mimic = elem.find('mimic')
            multiplier = float(mimic.get('multiplier', 1.0)) if mimic is not None else 1.0
            offset = float(mimic.get('offset', 0.0)) if mimic is not None else 0.0
            limit = elem.find('limit')
            lower = upper = velocity = None
            if limit is not None:
                if limit.get('lower') is not None or limit.get('upper') is not None:
                    lower = float(limit.get('lower', 0.0))
                    upper = float(limit.get('upper', 0.0))
                velocity_text = limit.get('velocity')
                if velocity_text is not None:
                    velocity = float(velocity_text)
        except ValueError as exc:
            raise ConfigError(f'{where}: {exc}') from exc
        if jtype == 'continuous':
            lower, upper = -math.inf, math.inf
        # None only for a <parent>/<child> without a link attribute (not a valid URDF)
        parent_link, child_link = cast(str, parent.get('link')), cast(str, child.get('link'))
        return UrdfJoint(
            name=name,
            type=jtype,
            parent=parent_link,
            child=child_link,
            xyz=xyz,
            rpy=rpy,
            axis=axis,
            lower=lower,
            upper=upper,
            velocity=velocity,
            mimic=mimic.get('joint') if mimic is not None else None,
            mimic_multiplier=multiplier,
            mimic_offset=offset,
        )

    # ------------------------------------------------------------------ structure
    def require_link(self, name: str, role: str) -> None:
        """Raise a ConfigError naming ``role`` unless ``name`` is a link of the URDF."""
        if name not in self.links:
            raise ConfigError(
                f'{self.path.name}: {role} link {name!r} not found (links: {", ".join(sorted(self.links))})'
            )

    def joint(self, name: str, role: str = 'joint') -> UrdfJoint:
        """The joint ``name``; a ConfigError naming ``role`` if the URDF has none."""
        try:
            return self.joints[name]
        except KeyError:
            raise ConfigError(f'{self.path.name}: {role} {name!r} not found in the URDF') from None

    def chain(self, root: str, tip: str, roles: tuple[str, str] = ('arm root', 'tool')) -> list[UrdfJoint]:
        """Every joint from link ``root`` down to link ``tip``, fixed ones included, root first.

        Raises:
            ConfigError: a link is missing, or ``tip`` does not descend from ``root`` (the
                message names the links by their ``roles``).
        """
        self.require_link(root, roles[0])
        self.require_link(tip, roles[1])
        joints, link = [], tip
        while link != root:
            joint = self._by_child.get(link)
            if joint is None:
                raise ConfigError(
                    f'{self.path.name}: chain broken: {roles[1]} link {tip!r} does not '
                    f'descend from {roles[0]} link {root!r}'
                )
            joints.append(joint)
            link = joint.parent
        return joints[::-1]

    def arm_chain(self, root: str, tool: str) -> list[UrdfJoint]:
        """The moving joints of the chain from link ``root`` to link ``tool``, root first: every one
        revolute, continuous or prismatic, and actuated on its own (no mimic joint).

        Raises:
            ConfigError: a link is missing, the chain is broken, or a joint is a mimic joint or of
                another type.
        """
        chain = [j for j in self.chain(root, tool) if j.type != 'fixed']
        for j in chain:
            if j.mimic is not None:
                raise ConfigError(
                    f'{self.path.name}: arm joint {j.name!r} is a mimic joint (of {j.mimic!r}): '
                    'an arm joint must be actuated on its own'
                )
            if j.type not in MOVING_TYPES:
                raise ConfigError(
                    f'{self.path.name}: arm joint {j.name!r} has type {j.type!r}: '
                    f'an arm joint must be one of {MOVING_TYPES}'
                )
        return chain

    def ancestors(self, link: str) -> list[UrdfJoint]:
        """The joints from the root link down to ``link``, root first."""
        joints = []
        while link in self._by_child:
            joint = self._by_child[link]
            joints.append(joint)
            link = joint.parent
        return joints[::-1]

    def children(self, link: str) -> list[UrdfJoint]:
        """The joints whose parent is ``link``, in file order."""
        return [j for j in self.joints.values() if j.parent == link]

    def placement(self, link: str, base: str) -> tuple[np.ndarray, np.ndarray]:
        """Pose of ``link``'s frame in ``base``'s frame with every joint at zero: (R (3, 3), p (3,)).

        Raises:
            ConfigError: ``link`` does not descend from ``base``.
        """
        rot, pos = np.eye(3), np.zeros(3)
        for joint in self.chain(base, link, ('base', 'wheel')):
            r = matrix_from_rpy(joint.rpy)
            pos = pos + rot @ joint.xyz
            rot = rot @ r
        return rot, pos

    def axis_in(self, joint: UrdfJoint, frame: str) -> np.ndarray:
        """The unit axis of ``joint`` expressed in link ``frame``'s axes, every joint at zero
        (a URDF gives it in the joint's own frame, which its origin may turn).

        Raises:
            ConfigError: ``joint`` does not descend from ``frame``.
        """
        rot = self.placement(joint.child, frame)[0] if joint.child != frame else np.eye(3)
        axis = rot @ joint.axis
        return axis / max(float(np.linalg.norm(axis)), 1e-12)

    def require_wheel_axis(self, joint: UrdfJoint, role: str = 'wheel joint') -> None:
        """Raise a ConfigError naming ``role`` unless ``joint`` turns about the root link's y axis
        (either way; its own frame may be turned), as a wheel rolls."""
        if self.root_link is None:
            return
        axis = self.axis_in(joint, self.root_link)
        if abs(abs(axis[1]) - 1.0) > 1e-6:
            raise ConfigError(
                f'{self.path.name}: {role} {joint.name!r} turns about {np.round(axis, 4).tolist()} in '
                f'{self.root_link}, not about its y axis: a wheel rolls about y'
            )

    def require_masses(self) -> None:
        """Raise a ConfigError naming the first link that a joint moves (a revolute, continuous or
        prismatic joint's child) without a mass > 0 in its ``<inertial>``: a simulator's dynamics
        divide by it."""
        for joint in self.joints.values():
            if joint.type not in MOVING_TYPES:
                continue
            link = self.links.get(joint.child)
            mass = link.find('inertial/mass') if link is not None else None
            try:
                value = float(mass.get('value', 'nan')) if mass is not None else 0.0
            except ValueError:
                value = math.nan
            if not value > 0.0:
                raise ConfigError(
                    f'{self.path.name}: link {joint.child!r} (moved by joint {joint.name!r}) has no mass > 0: '
                    'give it an <inertial> with <mass value> > 0 and its inertia'
                )

    # ------------------------------------------------------------------ wheels
    def wheel_radius(self, link: str) -> float | None:
        """Radius [m] of the collision cylinder (or sphere) of ``link``, None if it has none."""
        elem = self.links.get(link)
        if elem is None:
            return None
        for coll in elem.findall('collision'):
            geom = coll.find('geometry')
            if geom is None:
                continue
            shape = geom.find('cylinder')
            if shape is None:
                shape = geom.find('sphere')
            radius = shape.get('radius') if shape is not None else None
            if radius is not None:
                try:
                    return float(radius)
                except ValueError:
                    return None
        return None
