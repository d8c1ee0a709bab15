"""Any mobile manipulator: robots set up from a URDF with ``wmm_robot init`` reach goals, bad robot
files fail with one line naming the file and the item, and a differential base never moves sideways."""

import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_bridge.closed_loop import ClosedLoop
from wmm_control.geometry import matrix_from_quaternion
from sim_bridge.world import SimWorld
from urdf_factory import SIX_MECANUM_WHEELS, write_urdf
from wmm_control.base import DifferentialKinematics, MecanumKinematics, WheelController, WheelParams
from wmm_control.cli import robot_setup
from wmm_control.errors import ConfigError, WmmError
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.resolvers import PoseTarget, make_resolver
from wmm_control.robot_config import load_robot


def _reach(cfg, method, offsets, seconds=40.0, tol=0.01):
    """Run ``method`` on the direct engine to each goal (start EE position + offset, start
    orientation) in turn; return the final errors [m] on the ground truth."""
    world = SimWorld(cfg)
    try:
        loop = ClosedLoop(world, make_resolver(method, cfg))
        p0, q0 = world.ee_pose()
        errors = []
        for off in offsets:
            goal = np.asarray(p0) + off
            target = PoseTarget(goal, matrix_from_quaternion(q0))
            for _ in range(int(seconds / world.dt)):
                loop.step(target)
                err = float(np.linalg.norm(np.asarray(world.ee_pose()[0]) - goal))
                if err < 0.5 * tol:
                    break
            errors.append(err)
        return errors
    finally:
        world.close()


@pytest.mark.parametrize(
    'base,kwargs',
    [
        ('steerable', dict(modules=3)),
        ('steerable', dict(modules=6)),
        ('mecanum', dict(arm_joints=8, prismatic_lift=True)),
        ('differential', dict(arm_joints=6)),
    ],
    ids=['steerable-3', 'steerable-6', 'mecanum-8-prismatic', 'differential-6'],
)
def test_a_robot_made_by_init_from_an_unseen_urdf_reaches_near_and_far_goals(tmp_path, base, kwargs):
    urdf = write_urdf(tmp_path / 'made_up.urdf', base, **kwargs)
    out = tmp_path / 'config' / 'made_up.yaml'
    robot_setup.init_robot(urdf, base, 'arm_base_link', 'tool_link', out)
    cfg = load_robot(out)  # no hand edit
    assert cfg.arm.n == kwargs.get('arm_joints', 7)
    if base == 'steerable':
        assert cfg.base.n_modules == kwargs['modules']
    if kwargs.get('prismatic_lift'):
        assert cfg.arm.types[0] == 'prismatic'
    # a goal within the arm's reach, then one that needs the base (1.5 m ahead, 1 m to the right)
    errors = _reach(cfg, 'amp', [np.array([0.1, 0.05, -0.05]), np.array([1.5, -1.0, 0.0])])
    assert max(errors) < 0.01, errors


def test_init_output_is_a_commented_file_check_accepts(tmp_path, capsys):
    urdf = write_urdf(tmp_path / 'r.urdf', 'differential', arm_joints=6)
    out = tmp_path / 'r.yaml'
    assert (
        robot_setup.main(
            [
                'init',
                str(urdf),
                '--base',
                'differential',
                '--arm-root',
                'arm_base_link',
                '--tool',
                'tool_link',
                '--out',
                str(out),
                '--home',
                '0,0.3,0.6,0,0.5,0',
            ]
        )
        == 0
    )
    text = out.read_text()
    assert text.startswith('#') and 'wheel_joints: [wheel_left_joint, wheel_right_joint]' in text
    assert yaml.safe_load(text)['robot']['arm']['dexterous'] == [0, 0.3, 0.6, 0, 0.5, 0]
    capsys.readouterr()
    assert robot_setup.main(['check', str(out)]) == 0
    summary = capsys.readouterr().out
    assert '6 arm joints' in summary and 'track 0.48 m' in summary


def test_init_chooses_a_home_posture_clear_of_the_body():
    for name in ('steerable', 'mecanum'):
        cfg = load_robot(name)
        home, sigma = robot_setup._choose_home(
            robot_setup.UrdfTree(cfg.urdf_path), cfg.arm.root, cfg.arm.tool, cfg.base_link, cfg.ground_z
        )
        assert CollisionModel(cfg.urdf_path, cfg.arm.joints).closest(home)[0] >= robot_setup.HOME_CLEARANCE
        assert sigma > 0.05


# ---------------------------------------------------------------- bad robot files
def _copy_robot_a(tmp_path):
    src = load_robot('steerable')
    shutil.copy(src.urdf_path, tmp_path / 'robot.urdf')
    raw = yaml.safe_load(src.yaml_path.read_text())
    raw['robot']['urdf'] = 'robot.urdf'
    return raw


def _edit_urdf(tmp_path, old, new, count=1):
    path = tmp_path / 'robot.urdf'
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, count))


BAD_FILES = {
    'urdf unreadable': (lambda t, r: (t / 'robot.urdf').write_text('<robot><link'), 'URDF unreadable'),
    'link missing': (
        lambda t, r: r['arm'].__setitem__('root', 'no_such_link'),
        "arm root link 'no_such_link' not found",
    ),
    'chain broken': (lambda t, r: r['arm'].__setitem__('root', 'steer_fl_link'), 'chain broken'),
    'fewer than 6 arm joints': (lambda t, r: r['arm'].__setitem__('root', 'arm_link_2'), 'needs at least 6'),
    'joint without limits': (
        lambda t, r: _edit_urdf(t, '<limit lower="-2.094395" upper="2.094395" effort="176" velocity="1.919862"/>', ''),
        "joint 'arm_joint_2' has no <limit lower>",
    ),
    'wheel joint missing': (
        lambda t, r: r['steerable']['drive_joints'].__setitem__(2, 'drive_xx_joint'),
        "drive joint 'drive_xx_joint' not found",
    ),
    'zero radius': (
        lambda t, r: _edit_urdf(
            t, '<cylinder radius="0.09" length="0.05"/>', '<cylinder radius="0" length="0.05"/>', 2
        ),
        'radius must be > 0',
    ),
    'negative radius override': (
        lambda t, r: r['steerable'].__setitem__('wheel_radius', -0.1),
        'steerable.wheel_radius: must be finite and > 0',
    ),
    'NaN in the YAML': (lambda t, r: r['arm'].__setitem__('acceleration', [float('nan')] * 7), 'arm.acceleration: NaN'),
    'unknown family': (lambda t, r: r.__setitem__('base_type', 'legged'), "unknown base family 'legged'"),
    'duplicate joint names': (
        lambda t, r: r['steerable']['drive_joints'].__setitem__(1, 'drive_fl_joint'),
        "joint 'drive_fl_joint' is named twice",
    ),
    'duplicate joint in the URDF': (
        lambda t, r: _edit_urdf(t, 'name="drive_fr_joint"', 'name="drive_fl_joint"'),
        "duplicate joint name 'drive_fl_joint'",
    ),
    'mimic joint in the arm': (
        lambda t, r: _edit_urdf(
            t,
            '<joint name="arm_joint_3" type="revolute">',
            '<joint name="arm_joint_3" type="revolute"><mimic joint="arm_joint_2"/>',
        ),
        'is a mimic joint',
    ),
    'missing mesh': (
        lambda t, r: _edit_urdf(
            t,
            '<link name="arm_link_3">',
            '<link name="arm_link_3"><visual><geometry><mesh filename="meshes/nowhere.stl"/></geometry></visual>',
        ),
        'meshes/nowhere.stl (meshes/nowhere.stl)',
    ),
    'unknown package': (
        lambda t, r: _edit_urdf(
            t,
            '<link name="arm_link_3">',
            '<link name="arm_link_3"><visual><geometry><mesh filename="package://no_such_pkg/m.stl"/></geometry>'
            '</visual>',
        ),
        "package 'no_such_pkg' of package://no_such_pkg/m.stl not found",
    ),
    'wheel about x': (
        lambda t, r: _edit_urdf(
            t, '<axis xyz="0 1 0"/>\n    <limit effort="50"', '<axis xyz="1 0 0"/>\n    <limit effort="50"'
        ),
        "drive joint 'drive_fl_joint' turns about [1.0, 0.0, 0.0] in base_link, not about its y axis",
    ),
    'zero-mass link': (
        lambda t, r: _edit_urdf(t, '<mass value="2.7"/>', '<mass value="0"/>'),
        'has no mass > 0',
    ),
    'collision pair of no link': (
        lambda t, r: r.__setitem__('collision', {'pairs': [['arm_link_3', 'no_such_link']]}),
        "collision.pairs link 'no_such_link' not found",
    ),
    'start state outside the limits': (
        lambda t, r: r['start']['arm'].__setitem__(1, 3.0),
        'start.arm: outside the position limits: arm_joint_2 = 3',
    ),
    'dexterous outside the limits': (lambda t, r: r['arm'].__setitem__('dexterous', [9.0] * 7), 'dexterous: outside'),
    'urdf file missing': (lambda t, r: r.__setitem__('urdf', 'nowhere.urdf'), 'urdf: file not found'),
    'sideways limit on a differential base': (
        lambda t, r: (
            r.__setitem__('base_type', 'differential'),
            r.__setitem__('differential', {'wheel_joints': ['drive_fl_joint', 'drive_fr_joint']}),
        ),
        'wheels must sit on one axle',
    ),
}


@pytest.mark.parametrize('kind', sorted(BAD_FILES))
def test_a_bad_robot_file_is_one_line_naming_the_file_and_the_item_and_exit_code_2(tmp_path, capsys, kind):
    raw = _copy_robot_a(tmp_path)
    mutate, message = BAD_FILES[kind]
    mutate(tmp_path, raw['robot'])
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_robot(path)
    assert robot_setup.main(['check', str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and str(path) in err and message in err, err


def test_check_as_a_process_prints_one_line_and_no_traceback(tmp_path):
    raw = _copy_robot_a(tmp_path)
    raw['robot']['arm']['dexterous'] = [9.0] * 7
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(raw))
    proc = subprocess.run(
        [sys.executable, '-m', 'wmm_control.cli.robot_setup', 'check', str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert 'Traceback' not in proc.stderr and proc.stderr.strip().count('\n') == 0


def test_init_names_what_the_urdf_lacks(tmp_path, capsys):
    urdf = write_urdf(tmp_path / 'r.urdf', 'mecanum')
    code = robot_setup.main(
        [
            'init',
            str(urdf),
            '--base',
            'differential',
            '--arm-root',
            'arm_base_link',
            '--tool',
            'tool_link',
            '--out',
            str(tmp_path / 'r.yaml'),
        ]
    )
    assert code == 2
    assert 'found 4 wheel joints' in capsys.readouterr().err
    assert not (tmp_path / 'r.yaml').exists()


def test_init_sets_up_a_mecanum_base_of_six_wheels_and_names_one_it_cannot(tmp_path):
    wheels = [(tag, x if x else 0.1, y) for tag, x, y in SIX_MECANUM_WHEELS]  # the middle pair off the y axis
    urdf = write_urdf(tmp_path / 'six.urdf', 'mecanum', arm_joints=6, wheels=wheels[::-1])
    robot_setup.init_robot(urdf, 'mecanum', 'arm_base_link', 'tool_link', tmp_path / 'six.yaml')
    base = load_robot(tmp_path / 'six.yaml').base
    assert base.wheel_joints == tuple(f'wheel_{tag}_joint' for tag, _, _ in wheels)  # front to rear, left to right
    # the linear limits take half of the wheels' rate budget at a corner of the box, turning a quarter
    kin = MecanumKinematics.from_config(base)
    vx, vy, w = base.velocity
    corners = [np.max(np.abs(kin.wheel_rates([vx, sy * vy, 0.0]))) for sy in (-1.0, 1.0)]
    assert max(corners) == pytest.approx(0.5 * base.wheel_rate_limit)
    assert np.max(np.abs(kin.wheel_rates([0.0, 0.0, w]))) == pytest.approx(0.25 * base.wheel_rate_limit)
    urdf = write_urdf(tmp_path / 'axis.urdf', 'mecanum', arm_joints=6, wheels=SIX_MECANUM_WHEELS)
    with pytest.raises(WmmError, match=r"\['wheel_ml_joint', 'wheel_mr_joint'\] sit on an axis.*roller_angles"):
        robot_setup.init_robot(urdf, 'mecanum', 'arm_base_link', 'tool_link', tmp_path / 'axis.yaml')


def _factory_edit(old, new):
    def edit(urdf):
        text = urdf.read_text()
        assert old in text
        urdf.write_text(text.replace(old, new))

    return edit


_LEFT_WHEEL = '<child link="wheel_left_link"/><origin xyz="0 0.24 0.08" rpy="0 0 0"/><axis xyz="0 1 0"/>'
INIT_BAD = {
    'missing mesh': (_factory_edit('<box size="0.6 0.45 0.2"/>', '<mesh filename="nowhere.stl"/>'), [], 'file missing'),
    'unknown package': (
        _factory_edit('<box size="0.6 0.45 0.2"/>', '<mesh filename="package://no_such_pkg/box.stl"/>'),
        [],
        "package 'no_such_pkg' of package://no_such_pkg/box.stl not found",
    ),
    'arm chain that does not exist': (
        lambda urdf: None,
        ['--arm-root', 'wheel_left_link'],
        "chain broken: tool link 'tool_link' does not descend from arm root link 'wheel_left_link'",
    ),
    'wheel about x': (
        _factory_edit(_LEFT_WHEEL, _LEFT_WHEEL.replace('<axis xyz="0 1 0"/>', '<axis xyz="1 0 0"/>')),
        ['--wheel-joints', 'wheel_left_joint,wheel_right_joint'],
        "wheel joint 'wheel_left_joint' turns about [1.0, 0.0, 0.0] in base_link, not about its y axis",
    ),
    'mimic joint in the arm chain': (
        _factory_edit(
            '<joint name="arm_joint_3" type="revolute">',
            '<joint name="arm_joint_3" type="revolute"><mimic joint="arm_joint_2"/>',
        ),
        [],
        "arm joint 'arm_joint_3' is a mimic joint (of 'arm_joint_2')",
    ),
    'zero-mass link': (
        _factory_edit(
            '<link name="arm_link_2"><inertial><mass value="1.0"/>',
            '<link name="arm_link_2"><inertial><mass value="0"/>',
        ),
        [],
        "link 'arm_link_2' (moved by joint 'arm_joint_2') has no mass > 0",
    ),
}


@pytest.mark.parametrize('kind', sorted(INIT_BAD))
def test_init_on_a_bad_description_is_one_line_and_exit_code_2(tmp_path, capsys, kind):
    edit, extra, message = INIT_BAD[kind]
    urdf = write_urdf(tmp_path / 'r.urdf', 'differential', arm_joints=6)
    edit(urdf)
    out = tmp_path / 'r.yaml'
    args = ['init', str(urdf), '--base', 'differential', '--arm-root', 'arm_base_link', '--tool', 'tool_link']
    args += ['--out', str(out), '--home', '0,0.3,0.6,0,0.5,0']
    if '--arm-root' in extra:
        args[args.index('--arm-root') + 1] = extra[1]
    else:
        args += extra
    assert robot_setup.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and message in err, err
    assert not out.exists()


def test_init_finds_wheels_whose_joint_frame_is_turned_and_picks_amp_for_a_differential_base(tmp_path, capsys):
    """TIAGo's wheel joints turn about z in a joint frame turned by −π/2 about x: about the base's y."""
    urdf = write_urdf(tmp_path / 'r.urdf', 'differential', arm_joints=6)
    for y in ('0.24', '-0.24'):
        _factory_edit(
            f'<origin xyz="0 {y} 0.08" rpy="0 0 0"/><axis xyz="0 1 0"/>',
            f'<origin xyz="0 {y} 0.08" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>',
        )(urdf)
    tree = robot_setup.UrdfTree(urdf)
    arm = [f'arm_joint_{k}' for k in range(1, 7)]
    assert robot_setup.detect_wheels(tree, 'differential', 'base_link', arm) == {
        'wheel_joints': ['wheel_left_joint', 'wheel_right_joint']
    }
    out = tmp_path / 'r.yaml'
    args = ['init', str(urdf), '--base', 'differential', '--arm-root', 'arm_base_link', '--tool', 'tool_link']
    assert robot_setup.main(args + ['--out', str(out), '--period', '0.02', '--home', '0,0.3,0.6,0,0.5,0']) == 0
    cfg = load_robot(out)
    assert cfg.method == 'amp' and cfg.period == 0.02 and cfg.base_link == 'base_link'
    assert cfg.base.wheel_joints == ('wheel_left_joint', 'wheel_right_joint')
    assert cfg.base.track == pytest.approx(0.48)
    # only the root may be the base frame
    capsys.readouterr()
    assert robot_setup.main(args + ['--out', str(tmp_path / 's.yaml'), '--base-link', 'chassis_link']) == 2
    assert "the base frame must be the URDF's root link 'base_link'" in capsys.readouterr().err


def test_check_prints_a_prismatic_joint_in_metres(tmp_path, capsys):
    urdf = write_urdf(tmp_path / 'lift.urdf', 'mecanum', arm_joints=8, prismatic_lift=True)
    robot_setup.init_robot(urdf, 'mecanum', 'arm_base_link', 'tool_link', tmp_path / 'lift.yaml', pair_samples=50)
    assert load_robot(tmp_path / 'lift.yaml').method == 'task_sharing'
    capsys.readouterr()
    assert robot_setup.main(['check', str(tmp_path / 'lift.yaml')]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith('arm_joint_')}
    assert rows['arm_joint_1'].split()[1:3] == ['0.000', '0.400'] and rows['arm_joint_1'].endswith('m, m/s, m/s²')
    assert rows['arm_joint_2'].endswith('rad, rad/s, rad/s²')


# ---------------------------------------------------------------- differential base
_twist = st.tuples(*(st.floats(-3.0, 3.0, allow_nan=False) for _ in range(3)))


@settings(max_examples=60, deadline=None)
@given(st.lists(_twist, min_size=1, max_size=40))
def test_differential_wheel_rates_never_imply_a_sideways_velocity_and_keep_their_limits(references):
    kin = DifferentialKinematics(wheel_radius=0.1, track=0.5)
    params = WheelParams(dt=0.025, velocity_limit=(0.6, 0.0, 2.4), accel_limit=(0.6, 0.0, 2.4), wheel_rate_limit=12.0)
    ctrl = WheelController(kin, params)
    prev = np.zeros(3)
    for ref in references:
        out = ctrl.step(ref)
        realised = kin.twist_from_wheels(out.wheel_rates)
        assert realised[1] == 0.0 and out.twist[1] == 0.0
        np.testing.assert_allclose(realised, out.twist, atol=1e-12)
        assert np.all(np.abs(out.wheel_rates) <= 12.0 + 1e-9)
        assert abs(out.twist[0]) <= 0.6 + 1e-12 and abs(out.twist[2]) <= 2.4 + 1e-12
        assert np.all(np.abs(out.twist - prev)[[0, 2]] <= np.array([0.6, 2.4]) * 0.025 * (1 + 1e-9))
        assert out.dropped[1] == pytest.approx(ref[1])
        prev = out.twist


def test_differential_controller_follows_the_forward_and_turning_part_of_a_reference():
    kin = DifferentialKinematics(wheel_radius=0.1, track=0.5)
    ctrl = WheelController(
        kin, WheelParams(dt=0.025, velocity_limit=(0.6, 0.0, 2.4), accel_limit=(0.6, 0.0, 2.4), wheel_rate_limit=12.0)
    )
    for _ in range(200):
        out = ctrl.step([0.3, 0.2, -0.5])
    np.testing.assert_allclose(out.twist, [0.3, 0.0, -0.5], atol=1e-12)
    # left wheel faster than the right when turning right (ω < 0)
    assert out.wheel_rates[0] > out.wheel_rates[1]
    assert out.wheel_rates == pytest.approx([(0.3 + 0.5 * 0.25) / 0.1, (0.3 - 0.5 * 0.25) / 0.1])


def test_amp_commands_a_differential_base_along_its_heading_only(tmp_path):
    urdf = write_urdf(tmp_path / 'd.urdf', 'differential', arm_joints=6)
    robot_setup.init_robot(urdf, 'differential', 'arm_base_link', 'tool_link', tmp_path / 'd.yaml')
    cfg = load_robot(tmp_path / 'd.yaml')
    world = SimWorld(cfg)
    try:
        loop = ClosedLoop(world, make_resolver('amp', cfg))
        p0, q0 = world.ee_pose()
        target = PoseTarget(np.asarray(p0) + [0.0, 1.5, 0.0], matrix_from_quaternion(q0))  # straight to the left
        lateral = []
        for _ in range(1600):
            rec = loop.step(target)
            lateral.append(abs(rec.command.base_twist[1]))
        assert max(lateral) == 0.0
        assert np.linalg.norm(np.asarray(world.ee_pose()[0]) - target.position) < 0.01
        assert abs(world.base_pose()[2]) > 0.2  # it turned to get there
    finally:
        world.close()


@pytest.mark.parametrize('method', ['pinv', 'task_sharing', 'amp', 'traditional'])
@pytest.mark.parametrize('robot', ['ur_mecanum', 'panda_diff'])
def test_the_shipped_robots_reach_a_goal_in_reach_and_one_that_needs_the_base(robot, method):
    errors = _reach(load_robot(robot), method, [np.array([0.1, 0.05, -0.05]), np.array([1.5, -1.0, 0.0])])
    assert max(errors) < 0.01, errors


def test_manipulability_derivatives_hold_for_a_prismatic_joint_and_a_square_singular_arm(tmp_path):
    """The closed-form ∇H and ∇²H (Xing appendices A–B) against central differences on an arm
    with a prismatic lift; and a six-joint arm (J_m square) at a wrist singularity gives finite
    derivatives instead of an error (AMP's tertiary objective runs there)."""
    from wmm_control.kinematics import KinematicModel
    from wmm_control.kinematics.tasks import ManipulabilityTask

    urdf = write_urdf(tmp_path / 'lift.urdf', 'mecanum', arm_joints=8, prismatic_lift=True)
    robot_setup.init_robot(urdf, 'mecanum', 'arm_base_link', 'tool_link', tmp_path / 'lift.yaml')
    model = KinematicModel(tmp_path / 'lift.yaml')
    q = np.array([0.2, 0.3, -0.5, 0.8, 0.1, -0.7, 0.4, 0.2])
    for rows in ('position', 'full'):
        task = ManipulabilityTask(model, rows)
        model.update(np.zeros(3), q)
        grad, hess = task.gradient(), task.hessian()
        fd_g, fd_h = np.zeros(8), np.zeros((8, 8))
        for k in range(8):
            dq = np.zeros(8)
            dq[k] = 1e-6
            model.update(np.zeros(3), q + dq)
            hp, gp = task.value(), task.gradient()
            model.update(np.zeros(3), q - dq)
            hm, gm = task.value(), task.gradient()
            fd_g[k], fd_h[:, k] = (hp - hm) / 2e-6, (gp - gm) / 2e-6
        np.testing.assert_allclose(grad, fd_g, rtol=1e-6, atol=1e-7 * np.abs(fd_g).max())
        np.testing.assert_allclose(hess, fd_h, rtol=1e-5, atol=1e-6 * np.abs(fd_h).max())
    ur = KinematicModel('ur_mecanum')
    ur.update(np.zeros(3), [0.0, -1.2, 1.5, -0.3, 1.0, 0.0])
    ur.update(np.zeros(3), [0.0, -1.2, 1.5, -0.3, 0.0, 0.0])  # q5 = 0: wrist axes 4 and 6 align
    wrist = ManipulabilityTask(ur, 'full')
    assert wrist.value() < 1e-12
    assert np.all(np.isfinite(wrist.gradient()))
    assert np.all(np.isfinite(wrist.hessian()))


@pytest.mark.parametrize('robot', ['ur_mecanum', 'panda_diff'])
def test_the_new_robots_reach_a_goal_that_needs_the_base_with_wheel_contact_physics(robot):
    """base_mode physics: the Mecanum roller tyre model for ur_mecanum, plain wheels with
    friction and frictionless casters for panda_diff."""
    cfg = load_robot(robot)
    with SimWorld(cfg, base_mode='physics') as world:
        loop = ClosedLoop(world, make_resolver('amp', cfg))
        p0, q0 = world.ee_pose()
        goal = np.asarray(p0) + [0.8, 0.3, 0.0]
        target = PoseTarget(goal, matrix_from_quaternion(q0))
        for _ in range(1200):
            loop.step(target)
        assert np.linalg.norm(np.asarray(world.ee_pose()[0]) - goal) < 0.01
        assert np.hypot(*world.base_pose()[:2]) > 0.3  # the base carried it


# ---------------------------------------------------------------- TIAGo (example-robot-data)
def test_tiago_is_set_up_from_its_urdf_as_it_comes(tiago_robots, tmp_path, capsys, monkeypatch):
    """TIAGo with its hand, with the commands of docs/robots.md: the wheels found, the base frame
    its root, amp by default, the hand's rigid pairs left out, a start posture found."""
    monkeypatch.delenv('ROS_PACKAGE_PATH', raising=False)
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    share, urdf = tiago_robots.parents[3], tiago_robots / 'tiago.urdf'
    out = tmp_path / 'tiago.yaml'
    args = ['init', str(urdf), '--base', 'differential', '--arm-root', 'torso_fixed_link', '--tool', 'arm_tool_link']
    assert robot_setup.main(args + ['--out', str(out)]) == 2  # the meshes' package is not known yet
    assert "package 'example-robot-data'" in capsys.readouterr().err
    assert robot_setup.main(args + ['--out', str(out), '--package-dir', str(share)]) == 0
    printed = capsys.readouterr().out
    cfg = load_robot(out)
    assert cfg.base.wheel_joints == ('wheel_left_joint', 'wheel_right_joint')
    assert cfg.base_link == 'base_footprint' and cfg.method == 'amp'
    assert cfg.arm.joints[0] == 'torso_lift_joint' and cfg.arm.n == 8
    hand = {name for name in robot_setup.UrdfTree(urdf).links if name.startswith('hand_')}
    assert not any(set(pair) <= hand for pair in cfg.collision_pairs)
    collision = CollisionModel.from_robot(cfg)
    default = CollisionModel(cfg.urdf_path, cfg.arm.joints, cfg.ground_z, cfg.start.arm, package_dirs=cfg.package_dirs)
    assert sum(set(pair) <= hand for pair in default.pairs) > 500  # the default rules check the hand with itself
    assert 0 < len(collision.pairs) < 0.5 * len(default.pairs), (len(collision.pairs), len(default.pairs))
    # the start posture keeps every checked shape pair 0.02 m apart (0.03 m for most) but those
    # that rest closer by design, within 0.02 m at nearly every posture (the telescoping torso's
    # column and lift, the lift's top and the upper arm), which the controller leaves out there
    every = CollisionModel(
        cfg.urdf_path, cfg.arm.joints, margin=-np.inf, pairs=cfg.collision_pairs, package_dirs=cfg.package_dirs
    )
    close = every._distances(every._configuration(cfg.start.arm)) < robot_setup.SAFETY
    assert 0 < close.sum() <= 4
    lower = np.maximum(cfg.arm.position_lower, -np.pi)
    upper = np.minimum(cfg.arm.position_upper, np.pi)
    rng = np.random.default_rng(3)
    drawn = [every._distances(every._configuration(rng.uniform(lower, upper)))[close] for _ in range(100)]
    assert np.all((np.array(drawn) < robot_setup.SAFETY).mean(axis=0) >= 0.9)
    assert 'shape pairs checked' in printed
    assert robot_setup.main(['check', str(out)]) == 0
    summary = capsys.readouterr().out
    assert 'torso_lift_joint' in summary and 'm, m/s, m/s²' in summary


def test_tiago_without_its_hand_reaches_a_goal_to_its_side_with_the_default_method(tiago_robots, tmp_path):
    """The documented commands only, then a goal 1.5 m to the side of the gripper: a differential
    base gets there by turning (amp, init's default for it), within 2 mm on the ground truth."""
    share, urdf = tiago_robots.parents[3], tiago_robots / 'tiago_no_hand.urdf'
    out = tmp_path / 'tiago_no_hand.yaml'
    args = ['init', str(urdf), '--base', 'differential', '--arm-root', 'torso_fixed_link', '--tool', 'arm_tool_link']
    assert robot_setup.main(args + ['--package-dir', str(share), '--out', str(out)]) == 0
    cfg = load_robot(out)
    assert cfg.method == 'amp'
    errors = _reach(cfg, cfg.method, [np.array([0.0, 1.5, 0.0])], tol=0.004)
    assert errors[0] < 0.002, errors
