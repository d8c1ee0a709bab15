"""``wmm_robot``: set a robot up from its URDF, and check a robot description.

Usage::

    wmm_robot init URDF --base {steerable,mecanum,differential} --arm-root LINK --tool LINK \\
        --out ROBOT.yaml [--home q1,...,qn] [--wheel-joints a,b,...] [--steer-joints ...] \\
        [--drive-joints ...] [--base-link LINK] [--name NAME] [--method METHOD] [--period S] \\
        [--package-dir DIR ...] [--srdf FILE]
    wmm_robot check ROBOT.yaml

``init`` writes a complete, commented robot YAML beside nothing but the URDF it names (its
``urdf`` path is relative to the YAML). The arm joints and their position and velocity limits
stay in the URDF (the YAML may override them); the YAML gets what a URDF cannot give, each
value commented with the rule that chose it:

* ``package_dirs``: the folders given with ``--package-dir``, where ``package://`` mesh paths
  are looked up first (:mod:`wmm_control.resources`);
* the base frame: the URDF's root link (``--base-link`` may only name it): the frame the
  base's planar pose and odometry describe, which the simulator moves and TF hangs every other
  link from (on TIAGo, ``base_footprint``, on the floor under ``base_link``);
* wheel and steer joints, found from the URDF unless named: joints outside the arm that turn
  about the base frame's y axis (wheels) or z axis (steer joints), whatever the rotation of the
  joint's own frame, whose link has a collision cylinder; Mecanum wheels (three or more) are
  ordered by their position from front to rear, left to right (front-left, front-right,
  rear-left, rear-right for four), differential ones left
  then right;
* base twist limits from the wheel rate limits: half the wheel rate budget each to the
  linear and the angular part (so both at once stay within it); base accelerations reach
  those in one second;
* the positions of the joints outside the arm and the base (``held_joints``: head, fingers, a
  second arm), each one's URDF zero clipped into its limits, where every model, the simulator
  and ``/joint_states`` hold them (a mimic joint follows its leader);
* the collision pairs (``collision.pairs``), chosen as MoveIt's set-up assistant does
  (:func:`~wmm_control.kinematics.collision.choose_pairs`): adjacent links, links no arm joint
  moves apart, pairs always in contact or never within the influence distance over
  :data:`PAIR_SAMPLES` random postures, and an SRDF's ``disable_collisions`` (``--srdf``)
  left out;
* a dexterous posture and start state: ``--home``, or else the best of 400 seeded random
  postures within the limits — the one with the largest σ_min of the arm Jacobian among
  those whose collision shapes keep 3 cm apart over the pairs above (2 cm for shapes never
  3 cm apart, none for shapes within 2 cm in 95 % of the draws: those rest close by design),
  with the tool at least 10 cm above the floor;
* the control period (``--period``, default 0.025 s) and the default method (``--method``,
  default per base family: ``amp`` on a differential base, the method that reaches goals to
  its side; ``task_sharing`` otherwise).

``init`` and ``check`` print the number of checked collision pairs and the measured cost of
one distance check (the median over random postures), with a warning above
:data:`CHECK_BUDGET`. ``check`` loads a description, prints the robot summary and exits 0, or
prints one line saying what is wrong (file and item) and exits 2.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np

import yaml

from wmm_control.cli.model_info import describe
from wmm_control.errors import WmmError
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.tasks import ManipulabilityTask
from wmm_control.kinematics.collision import (
    ALWAYS_FRACTION,
    CollisionModel,
    PairChoice,
    choose_pairs,
    median_check_time,
)
from wmm_control.resolvers import METHODS
from wmm_control.base.mecanum import MecanumKinematics
from wmm_control.resolvers.safety import SafetyParams
from wmm_control.resources import check_resources
from wmm_control.robot_config import (
    BASE_FAMILIES,
    MIN_ARM_JOINTS,
    RobotConfig,
    held_joint_positions,
    load_robot,
    usual_roller_angles,
)
from wmm_control.urdf import UrdfJoint, UrdfTree

__all__ = ['main', 'init_robot', 'detect_wheels', 'collision_summary', 'DEFAULT_METHODS']

HOME_DRAWS = 400
HOME_CLEARANCE = 0.03  # [m] from the body and between arm links
TOOL_ABOVE_FLOOR = 0.10  # [m]
DEFAULT_PERIOD = 0.025
#: The default method of each base family: on a differential base only AMP reaches goals to
#: the side (docs/robots.md).
DEFAULT_METHODS = {'steerable': 'task_sharing', 'mecanum': 'task_sharing', 'differential': 'amp'}
#: Random arm postures over which the collision pairs are chosen.
PAIR_SAMPLES = 1000
#: [m] the safety stage's default influence distance: a pair never this close is left out.
INFLUENCE = SafetyParams().collision_influence
#: [m] the safety stage's default safety distance, the distance it keeps: a pair never farther
#: apart is in contact by design and left out.
SAFETY = SafetyParams().collision_safety
#: [s] one distance check above this gets a warning (a tenth of the 25 ms period, and more
#: than the rest of a cycle takes).
CHECK_BUDGET = 0.002
#: Random arm postures over which the cost of one distance check is measured.
COST_POSTURES = 100


def _axis_is(tree, joint, base_link, k):
    """Whether ``joint`` turns about axis ``k`` (0 x, 1 y, 2 z) of ``base_link``, either way."""
    try:
        axis = tree.axis_in(joint, base_link)
    except WmmError:  # not below the base
        return False
    return abs(abs(axis[k]) - 1.0) < 1e-6


def detect_wheels(tree: UrdfTree, family: str, base_link: str, arm_joints: Iterable[str]) -> dict[str, list[str]]:
    """Wheel-side joints of ``family`` found by the conventions above.

    Returns:
        ``{'steer_joints': [...], 'drive_joints': [...]}`` or ``{'wheel_joints': [...]}``.

    Raises:
        WmmError: the URDF does not hold what the family needs.
    """
    arm = set(arm_joints)
    spinning = [
        j
        for j in tree.joints.values()
        if j.name not in arm and j.type in ('continuous', 'revolute') and j.mimic is None
    ]

    def position(joint: UrdfJoint) -> np.ndarray:
        return tree.placement(joint.child, base_link)[1]

    def about(joint: UrdfJoint, k: int) -> bool:
        return _axis_is(tree, joint, base_link, k)

    if family == 'steerable':
        steer = [
            j
            for j in spinning
            if about(j, 2) and any(c.type == 'continuous' and about(c, 1) for c in tree.children(j.child))
        ]
        drive = [next(c for c in tree.children(j.child) if c.type == 'continuous' and about(c, 1)) for j in steer]
        if len(steer) < 2:
            raise WmmError(
                f'{tree.path.name}: found {len(steer)} steer + drive modules (a joint about z '
                'with a continuous joint about y below it); a steerable base needs 2 or more: '
                'name them with --steer-joints and --drive-joints'
            )
        return {'steer_joints': [j.name for j in steer], 'drive_joints': [j.name for j in drive]}
    wheels = [
        j
        for j in spinning
        if j.type == 'continuous'
        and about(j, 1)
        and tree.wheel_radius(j.child) is not None
        and not any(about(a, 2) for a in tree.ancestors(j.child) if a.type != 'fixed')
    ]
    mecanum = family == 'mecanum'
    if (len(wheels) < 3) if mecanum else (len(wheels) != 2):
        raise WmmError(
            f'{tree.path.name}: found {len(wheels)} wheel joints (continuous, about the y axis of {base_link}, a '
            f'collision cylinder on the link) {[j.name for j in wheels]}; a {family} base needs '
            f'{"3 or more" if mecanum else "2"}: name them with --wheel-joints'
        )
    if mecanum:  # front to rear, left to right: fl, fr, rl, rr for four
        wheels.sort(key=lambda j: (-round(position(j)[0], 6), -round(position(j)[1], 6)))
    else:
        wheels.sort(key=lambda j: -position(j)[1])
    return {'wheel_joints': [j.name for j in wheels]}


def _base_limits(cfg_wheels, family, tree, base_link):
    """Base twist velocity limits (vx, vy, ω) from the wheel rates and geometry (module docstring)."""
    if family == 'steerable':
        drive = [tree.joint(n) for n in cfg_wheels['drive_joints']]
        steer = [tree.joint(n) for n in cfg_wheels['steer_joints']]
        rate = min(j.velocity or 0.0 for j in drive)
        radius = tree.wheel_radius(drive[0].child) or 0.0
        reach = max(np.hypot(*tree.placement(j.child, base_link)[1][:2]) for j in steer)
        v = 0.5 * rate * radius
        return [v, v, v / max(reach, 1e-3)]
    joints = [tree.joint(n) for n in cfg_wheels['wheel_joints']]
    rate = min(j.velocity or 0.0 for j in joints)
    radius = tree.wheel_radius(joints[0].child) or 0.0
    pos = np.array([tree.placement(j.child, base_link)[1][:2] for j in joints])
    if family == 'mecanum':
        on_axis = [n for n, (x, y) in zip(cfg_wheels['wheel_joints'], pos) if x * y == 0.0]
        if on_axis:
            raise WmmError(
                f'{tree.path.name}: Mecanum wheels {on_axis} sit on an axis of {base_link}, where the usual '
                'roller pattern places none: write the robot YAML with mecanum.roller_angles'
            )
        # the rows of the wheel map with the usual rollers: (|vx| + |vy|) takes up to half of each
        # wheel's rate budget, |ω| a quarter (for four wheels at (±d1, ±d2): R rate / 4 and that / (d1 + d2))
        rows = np.abs(MecanumKinematics(radius, pos, usual_roller_angles(pos)).inverse)
        v = 0.5 * rate / float(np.max(rows[:, 0] + rows[:, 1]))
        return [v, v, 0.25 * rate / float(np.max(rows[:, 2]))]
    track = float(pos[0, 1] - pos[1, 1])
    return [0.5 * rate * radius, 0.0, rate * radius / max(track, 1e-3)]


def _floor_height(tree, wheels, base_link):
    """z of the floor in ``base_link`` [m]: the lowest wheel's centre less its radius."""
    names = wheels.get('drive_joints') or wheels['wheel_joints']
    return min(
        tree.placement(tree.joint(n).child, base_link)[1][2] - (tree.wheel_radius(tree.joint(n).child) or 0.0)
        for n in names
    )


def _choose_home(tree, arm_root, tool, base_link, ground, seed=0, pairs=None, package_dirs=()):
    """The documented posture choice (module docstring): ``(q (n,), σ_min)``, clear over the
    link ``pairs`` (default: the collision model's own rules): each shape pair
    :data:`HOME_CLEARANCE` apart, or the safety stage's safety distance for one that is that far
    apart in none of the draws (two links of a wrist); one within the safety distance in
    :data:`~wmm_control.kinematics.collision.ALWAYS_FRACTION` of the draws rests close by
    design, and the collision model leaves it out at this posture."""
    chain = tree.arm_chain(arm_root, tool)
    names = [j.name for j in chain]
    lower = np.array([max(j.lower, -math.pi) if j.lower is not None else -math.pi for j in chain])
    upper = np.array([min(j.upper, math.pi) if j.upper is not None else math.pi for j in chain])
    model = KinematicModel.from_urdf(tree.path, names, tool, base_link)
    # chosen pairs are all checked (those in contact by design are left out already); the
    # model's own rules leave out those in contact with every joint at zero
    margin = -math.inf if pairs is not None else 0.02
    clearance = CollisionModel(tree.path, names, margin=margin, pairs=pairs, package_dirs=package_dirs)
    rng = np.random.default_rng(seed)
    postures, sigmas, distances = [], [], []
    for _ in range(HOME_DRAWS):
        # away from the limits: the middle 80 % of each range
        q = lower + (upper - lower) * (0.1 + 0.8 * rng.random(len(chain)))
        model.update(np.zeros(3), q)
        pos, _ = model.ee_placement_world()
        if pos[2] < ground + TOOL_ABOVE_FLOOR:
            continue
        postures.append(q)
        sigmas.append(ManipulabilityTask(model, 'full').sigma_min())
        # exact below HOME_CLEARANCE, a lower bound above it
        distances.append(clearance._distances_within(clearance._configuration(q), HOME_CLEARANCE)[0])
    if postures:
        dist = np.array(distances).reshape(len(postures), -1)
        need = np.where(dist.max(axis=0, initial=-np.inf) >= HOME_CLEARANCE, HOME_CLEARANCE, SAFETY)
        # a shape pair within SAFETY in ALWAYS_FRACTION of the draws rests close by design (one
        # shape pair of two links that meet on another, choose_pairs): the collision model
        # leaves it out at this posture
        need[(dist < SAFETY).mean(axis=0) >= ALWAYS_FRACTION] = -np.inf
        clear = np.flatnonzero(np.all(dist >= need, axis=1))
    if not postures or not clear.size:
        raise WmmError(
            f'{tree.path.name}: no posture of {HOME_DRAWS} draws keeps the arm {HOME_CLEARANCE} m clear '
            f'of the body ({SAFETY} m for pairs never that far apart) with the tool above the floor: '
            'give one with --home'
        )
    best = int(clear[np.argmax(np.asarray(sigmas)[clear])])
    return postures[best], sigmas[best]


def _names(text):
    return [n.strip() for n in text.split(',') if n.strip()] if text else None


def _fmt_list(values):
    return '[' + ', '.join(f'{v:.6g}' for v in values) + ']'


def init_robot(
    urdf,
    family,
    arm_root,
    tool,
    out,
    home=None,
    wheel_joints=None,
    steer_joints=None,
    drive_joints=None,
    base_link=None,
    name=None,
    method=None,
    period=DEFAULT_PERIOD,
    package_dirs=(),
    srdf=None,
    pair_samples=PAIR_SAMPLES,
):
    """Write a robot YAML for ``urdf`` at ``out`` (see the module docstring); returns its text.

    Raises:
        WmmError (ConfigError among them): what the URDF lacks, or an invalid option.
    """
    urdf, out = Path(urdf).resolve(), Path(out).resolve()
    tree = UrdfTree(urdf)
    if family not in BASE_FAMILIES:
        raise WmmError(f'--base: unknown base family {family!r}; expected one of {list(BASE_FAMILIES)}')
    method = method or DEFAULT_METHODS[family]
    if method not in METHODS:
        raise WmmError(f'--method: unknown method {method!r}; expected one of {sorted(METHODS)}')
    if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0.0):
        raise WmmError(f'--period: must be a number of seconds > 0, got {period!r}')
    package_dirs = [Path(d).expanduser().resolve() for d in package_dirs]
    for folder in package_dirs:
        if not folder.is_dir():
            raise WmmError(f'--package-dir: folder not found: {folder}')
    if srdf is not None and not Path(srdf).is_file():
        raise WmmError(f'--srdf: file not found: {srdf}')
    check_resources(urdf, package_dirs)
    tree.require_masses()
    root = tree.root_link
    if root is None:
        raise WmmError(f'{urdf.name}: the URDF has no single root link')
    if base_link not in (None, root):
        raise WmmError(
            f'--base-link {base_link}: the base frame must be the URDF\'s root link {root!r}, the frame '
            'the simulator moves and odometry and TF describe'
        )
    base_link = root
    chain = tree.arm_chain(arm_root, tool)
    if len(chain) < MIN_ARM_JOINTS:
        raise WmmError(
            f'{urdf.name}: the chain {arm_root!r} → {tool!r} has {len(chain)} joints; '
            f'an arm needs at least {MIN_ARM_JOINTS}'
        )
    arm_names = [j.name for j in chain]
    if wheel_joints or steer_joints:
        wheels = (
            {'steer_joints': steer_joints, 'drive_joints': drive_joints}
            if family == 'steerable'
            else {'wheel_joints': wheel_joints}
        )
        if family == 'steerable' and not (steer_joints and drive_joints):
            raise WmmError('a steerable base needs both --steer-joints and --drive-joints')
    else:
        wheels = detect_wheels(tree, family, base_link, arm_names)
    role = 'drive joint' if family == 'steerable' else 'wheel joint'
    for wheel in wheels.get('drive_joints') or wheels['wheel_joints']:
        tree.require_wheel_axis(tree.joint(wheel, role), role)
    velocity = _base_limits(wheels, family, tree, base_link)
    ground = _floor_height(tree, wheels, base_link)
    choice = choose_pairs(urdf, arm_names, ground, INFLUENCE, pair_samples, srdf, package_dirs, contact=SAFETY)
    if home is not None:
        q_home = np.asarray(home, dtype=float)
        if q_home.shape != (len(chain),):
            raise WmmError(f'--home: expected {len(chain)} joint values, got {len(q_home)}')
        home_rule = 'given with --home'
    else:
        q_home, sigma = _choose_home(
            tree, arm_root, tool, base_link, ground, pairs=choice.checked, package_dirs=package_dirs
        )
        home_rule = (
            f'the best of {HOME_DRAWS} seeded draws (σ_min {sigma:.3f}): arm {HOME_CLEARANCE} m clear '
            f'over the collision pairs ({SAFETY} m for those never that far apart), tool ≥ {TOOL_ABOVE_FLOOR} m '
            'above the floor'
        )
    rel = Path(_relative(urdf, out.parent))
    lines = [
        f'# Robot description of {urdf.name}, written by `wmm_robot init` (check it with `wmm_robot check`).',
        '# The URDF holds the arm chain, joint limits and base geometry; this file names them and adds',
        '# what a URDF cannot give. Every value may be edited.',
        'robot:',
        f'  name: {name or out.stem}',
        f'  description: {urdf.stem} with a {family} base',
        f'  urdf: {rel.as_posix()}',
    ]
    if package_dirs:
        dirs = ', '.join(_flow(Path(_relative(d, out.parent)).as_posix()) for d in package_dirs)
        lines.append(f'  package_dirs: [{dirs}]   # where package:// paths are looked up first')
    lines += [
        f'  base_type: {family}',
        f'  base_link: {base_link}   # the URDF\'s root link: the frame odometry and TF move',
        f'  ground_z: {ground:.6g}          # floor height in {base_link} at rest [m]',
        f'  period: {period}       # control period [s]: the default of every node',
        f'  method: {method}  # the redundancy_resolver default'
        + (' (on a differential base, the one that reaches goals to the side)' if family == 'differential' else ''),
        '  arm:',
        f'    root: {arm_root}',
        f'    tool: {tool}    # the end-effector frame',
        f'    # {len(chain)} joints from the URDF: {", ".join(arm_names)};',
        '    # their position and velocity limits are the URDF\'s <limit> unless given here;',
        '    # acceleration limits: 2 × the velocity limit (full speed in 0.5 s) unless given here',
        f'    dexterous: {_fmt_list(q_home)}   # {home_rule}',
        '  base:',
        f'    velocity: {_fmt_list(velocity)}   # [m/s, m/s, rad/s]: half the wheel rate budget to v, half to ω',
        f'    acceleration: {_fmt_list(velocity)}   # [m/s², m/s², rad/s²]: the velocity limits in one second',
        '  start:',
        '    base_pose: [0.0, 0.0, 0.0]',
        f'    arm: {_fmt_list(q_home)}   # = dexterous',
        f'  {family}:',
    ]
    for key, names in wheels.items():
        lines.append(f'    {key}: [{", ".join(names)}]')
    lines.append('    # geometry (wheel radius, hips / d1, d2 / track) and wheel rate limits from the URDF')
    lines += _held_lines(tree, arm_names, [n for names in wheels.values() for n in names])
    lines += _pair_lines(choice)
    text = '\n'.join(lines) + '\n'
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    try:
        load_robot(out)
    except WmmError:
        out.unlink()
        raise
    return text


def _flow(name: str) -> str:
    """``name`` as a YAML flow scalar (quoted where YAML needs it)."""
    return yaml.safe_dump(name, default_flow_style=True, width=1 << 20).splitlines()[0]


def _held_lines(tree: UrdfTree, arm: list[str], base: list[str]) -> list[str]:
    """The ``held_joints:`` section of the YAML: every movable joint outside the ``arm`` and
    ``base`` joints at its default position, a mimic joint as a comment (it follows its leader)."""
    held = held_joint_positions(tree, arm, base)
    lines = [
        '  # the joints outside the arm and the base (head, fingers), held at these positions [rad or m] by',
        '  # every model, the simulator and /joint_states: the URDF\'s zero clipped into each joint\'s limits.',
        '  # A mimic joint follows its leader (the URDF\'s <mimic>) and is not listed. Edit freely.',
        '  held_joints:',
    ]
    for name, value in held.items():
        joint = tree.joint(name)
        if joint.mimic is not None:
            lines.append(f'    # {name}: {value:.6g}   follows {joint.mimic} (mimic)')
            continue
        bounded = joint.type != 'continuous' and joint.lower is not None and joint.upper is not None
        limits = f' in [{joint.lower:.6g}, {joint.upper:.6g}]' if bounded else ''
        lines.append(f'    {_flow(name)}: {value:.6g}   # {joint.type}{limits}')
    if not held:
        lines[-1] = '  held_joints: {}   # none: every movable joint is the arm\'s or the base\'s'
    return lines


def _pair_lines(choice: PairChoice) -> list[str]:
    """The ``collision:`` section of the YAML: the pairs ``choice`` keeps, with how it chose them."""
    out = {reason: len(pairs) for reason, pairs in choice.left_out.items()}
    lines = [
        '  collision:',
        f'    # the link pairs the controller\'s collision model checks ("floor": the floor): of {choice.candidates}',
        f'    # pairs of links with shapes, left out: {out["adjacent"]} adjacent, {out["rigid"]} with no arm joint',
        f'    # between them, {out["srdf"]} disabled by the SRDF, {out["always"]} within {choice.contact:g} m at'
        f' {ALWAYS_FRACTION:.0%} or more',
        f'    # and {out["never"]} never within {choice.influence:g} m of {choice.samples} random postures. Edit freely.',
        '    pairs:',
    ]
    lines += [f'      - [{_flow(a)}, {_flow(b)}]' for a, b in choice.checked]
    if not choice.checked:
        lines[-1] = '    pairs: []'
    return lines


def collision_summary(cfg: RobotConfig, postures: int = COST_POSTURES, seed: int = 1) -> tuple[str, str]:
    """``(line, warning)``: the number of collision pairs ``cfg``'s collision model checks and the
    median cost of one distance check over ``postures`` seeded random arm postures; the warning
    is '' within :data:`CHECK_BUDGET`."""
    model = CollisionModel.from_robot(cfg)
    arm = cfg.arm
    lower = np.maximum(arm.position_lower, -math.pi)
    upper = np.minimum(arm.position_upper, math.pi)
    rng = np.random.default_rng(seed)
    cost = median_check_time(model, lower + (upper - lower) * rng.random((postures, arm.n)), INFLUENCE)
    rule = 'collision.pairs of the YAML' if cfg.collision_pairs is not None else 'the default rules'
    links = len({frozenset(pair) for pair in model.pairs})
    line = (
        f'collision: {len(model.pairs)} shape pairs checked ({links} link pairs, from {rule}); one distance '
        f'check {cost * 1e3:.2f} ms (median of {postures} random postures)'
    )
    warning = ''
    if cost > CHECK_BUDGET:
        warning = (
            f'warning: one distance check takes {cost * 1e3:.1f} ms, above the {CHECK_BUDGET * 1e3:g} ms budget: '
            'leave pairs out in collision.pairs (wmm_robot init chooses them; --srdf adds an SRDF\'s)'
        )
    return line, warning


def _relative(path, start):
    try:
        return str(Path(path).relative_to(start))
    except ValueError:
        return os.path.relpath(path, start)


def _check(path):
    model = KinematicModel(load_robot(path))
    cfg = model.config
    return describe(model, cfg.start.base_pose, cfg.start.arm), *collision_summary(cfg)


def _print_summary(line, warning):
    print(line)
    if warning:
        print(warning, file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='wmm_robot', description='Set up a robot from its URDF; check a robot YAML.')
    sub = parser.add_subparsers(dest='command', required=True)
    ini = sub.add_parser('init', help='write a robot YAML from a URDF')
    ini.add_argument('urdf')
    ini.add_argument('--base', required=True, choices=BASE_FAMILIES)
    ini.add_argument('--arm-root', required=True, help='the link the arm chain starts from')
    ini.add_argument('--tool', required=True, help='the end-effector link')
    ini.add_argument('--out', required=True, help='the robot YAML to write')
    ini.add_argument('--home', help='dexterous posture and start state: q1,...,qn [rad or m]')
    ini.add_argument('--wheel-joints', help='Mecanum (fl,fr,rl,rr) or differential (left,right) wheel joints')
    ini.add_argument('--steer-joints', help='steerable base: the steer joints')
    ini.add_argument('--drive-joints', help='steerable base: the drive joints, in the order of the steer joints')
    ini.add_argument('--base-link', help='the base frame: the URDF root link, the only one allowed (the default)')
    ini.add_argument('--name', help='robot name (default: the YAML file stem)')
    ini.add_argument(
        '--method', help='default redundancy resolution method (default: amp on a differential base, else task_sharing)'
    )
    ini.add_argument('--period', type=float, default=DEFAULT_PERIOD, help='control period [s] (default 0.025)')
    ini.add_argument(
        '--package-dir',
        action='append',
        default=[],
        metavar='DIR',
        help='a folder package:// paths are looked up in (it holds PKG/...); may be repeated',
    )
    ini.add_argument('--srdf', help='an SRDF whose disable_collisions pairs are left out')
    chk = sub.add_parser('check', help='load a robot YAML and print its summary')
    chk.add_argument('robot', help='robot YAML path or shipped robot name')
    args = parser.parse_args(argv)
    try:
        if args.command == 'check':
            summary, *collision = _check(args.robot)
            print(summary)
            _print_summary(*collision)
            return 0
        home = None
        if args.home:
            try:
                home = [float(v) for v in args.home.split(',')]
            except ValueError:
                raise WmmError(f'--home: not a comma-separated list of numbers: {args.home!r}') from None
        init_robot(
            args.urdf,
            args.base,
            args.arm_root,
            args.tool,
            args.out,
            home=home,
            wheel_joints=_names(args.wheel_joints),
            steer_joints=_names(args.steer_joints),
            drive_joints=_names(args.drive_joints),
            base_link=args.base_link,
            name=args.name,
            method=args.method,
            period=args.period,
            package_dirs=args.package_dir,
            srdf=args.srdf,
        )
        _print_summary(*collision_summary(load_robot(args.out)))
        print(f'wrote {args.out}; check it with: wmm_robot check {args.out}')
        return 0
    except WmmError as exc:
        print(f'wmm_robot: error: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
