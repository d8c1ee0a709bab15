"""Tests of the ROS-free simulator core (sim_bridge.SimWorld, slip model, renderer).

Tolerances: kinematic-mode motion is exact up to floating-point rounding, so it is checked
to 1e-9 (m, rad); physics-mode motion to the percent level stated at each test; the
ground-truth end-effector pose against the kinematics core's FK to 1 mm / 1 mrad (PyBullet
stores link poses in single precision, errors ≈ 1e-7 m).
"""

import dataclasses
import math
import struct
import zlib

import numpy as np
import pytest

from sim_bridge import SimWorld, SlipParams, render_png
from urdf_factory import SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES, write_mecanum_robot
from wmm_control.base import MecanumKinematics
from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import SteerableBase, load_robot

DT = 0.025
#: [m, rad] two runs of the same world and seed agree to this (round-off; any other draw or
#: command moves them by far more)
SAME = 1e-9
# Robot A geometry (SPEC / Sorour Table I), written out for hand computation.
HIPS = [(0.24, 0.19), (0.24, -0.19), (-0.24, 0.19), (-0.24, -0.19)]
R_W = 0.09
D_OFF = 0.045
# Robot B (mecanum.yaml): R, d1, d2.
R_B, D1, D2 = 0.076, 0.25, 0.22


@pytest.fixture
def world_a():
    w = SimWorld('A', start_base_pose=(0.0, 0.0, 0.0))
    yield w
    w.close()


@pytest.fixture
def world_b():
    w = SimWorld('B', start_base_pose=(0.0, 0.0, 0.0))
    yield w
    w.close()


def run(world, seconds):
    for _ in range(int(round(seconds / world.dt))):
        world.step()


def steer_in_place(world, targets, seconds=2.0):
    """Turn robot A's steer joints to ``targets`` [rad] while the drive wheels roll the
    offset wheel round its steer axis (φ̇ = d β̇ / r_w), so the base must stay still."""
    _, q, _ = world.joint_state()
    beta = q[7:11]
    rates = (np.asarray(targets) - beta) / seconds
    assert world.set_command('steer', rates).clamped == 0
    assert world.set_command('drive', D_OFF * rates / R_W).clamped == 0
    run(world, seconds)
    world.zero_command('steer')
    world.zero_command('drive')


def twin(beta):
    """The steer angle in [−π/2, π/2] equivalent to β (β ± π with the wheel reversed)."""
    return math.remainder(beta, math.pi)


def f_row(beta, hx, hy):
    """Sorour's inverse actuation row f(β) = [cos β, sin β, d − hy cos β + hx sin β]."""
    return np.array([math.cos(beta), math.sin(beta), D_OFF - hy * math.cos(beta) + hx * math.sin(beta)])


# ----------------------------------------------------------------------------- arm
@pytest.mark.parametrize('robot', ['A', 'B'])
def test_constant_arm_velocity_moves_joints_by_v_t(robot):
    with SimWorld(robot) as w:
        _, q0, _ = w.joint_state()
        v = np.array([0.3, -0.2, 0.25, 0.1, -0.4, 0.35, 0.5])
        assert w.set_command('arm', v).accepted
        run(w, 1.0)  # 40 steps
        names, q, qd = w.joint_state()
        assert names[:7] == w.robot.arm.joints
        np.testing.assert_allclose(q[:7] - q0[:7], v * 1.0, rtol=1e-9)
        np.testing.assert_array_equal(qd[:7], v)
        np.testing.assert_allclose(w.time, 1.0, rtol=1e-12)
        np.testing.assert_array_equal(w.base_pose(), w.robot.start.base_pose)  # base untouched


@pytest.mark.parametrize('robot', ['A', 'B'])
def test_physics_mode_arm_follows_v_t_within_one_percent(robot):
    with SimWorld(robot, base_mode='physics') as w:
        _, q0, _ = w.joint_state()
        v = np.array([0.3, -0.2, 0.25, 0.1, -0.4, 0.35, 0.5])
        w.set_command('arm', v)
        run(w, 1.0)
        _, q, _ = w.joint_state()
        np.testing.assert_allclose(q[:7] - q0[:7], v, rtol=0.01)


def test_arm_stops_at_position_limit(world_b):
    upper = world_b.robot.arm.position_upper[1]  # joint 2: ±2.2 rad
    world_b.set_command('arm', [0, 1.5, 0, 0, 0, 0, 0])
    run(world_b, 2.0)  # would reach 0.52 + 3.0
    _, q, qd = world_b.joint_state()
    assert q[1] == upper
    assert qd[1] == 0.0
    assert world_b.counters['arm']['position_limited'] > 0


# ----------------------------------------------------------------------------- base, robot A
def test_steering_in_place_with_offset_compensation_keeps_base_still(world_a):
    targets = [0.7, -0.4, 1.2, -1.5]
    steer_in_place(world_a, targets)
    _, q, _ = world_a.joint_state()
    np.testing.assert_allclose(q[7:11], targets, atol=1e-12)
    np.testing.assert_allclose(world_a.base_pose(), [0.0, 0.0, 0.0], atol=1e-12)


def test_steer_then_drive_translates_along_the_wheel_heading(world_a):
    alpha = math.pi / 6
    steer_in_place(world_a, [alpha] * 4)
    v = 0.4  # [m/s]
    world_a.set_command('drive', [v / R_W] * 4)
    run(world_a, 2.5)
    expected = [v * 2.5 * math.cos(alpha), v * 2.5 * math.sin(alpha), 0.0]
    np.testing.assert_allclose(world_a.base_pose(), expected, atol=1e-9)
    np.testing.assert_allclose(world_a.base_twist(), [v * math.cos(alpha), v * math.sin(alpha), 0.0], atol=1e-12)


def test_steer_then_drive_follows_a_circular_arc(world_a):
    # ICR at (0, Rc): twist (v, 0, v/Rc); path x = Rc sin ωt, y = Rc (1 − cos ωt), θ = ωt.
    rc, v = 2.0, 0.5
    w = v / rc
    betas = [twin(math.atan2(rc - hy, 0.0 - hx) - math.pi / 2) for hx, hy in HIPS]
    steer_in_place(world_a, betas)
    twist = np.array([v, 0.0, w])
    rates = [f_row(b, hx, hy) @ twist / R_W for b, (hx, hy) in zip(betas, HIPS)]
    assert world_a.set_command('drive', rates).clamped == 0
    t = 3.0
    run(world_a, t)
    expected = [rc * math.sin(w * t), rc * (1 - math.cos(w * t)), w * t]
    np.testing.assert_allclose(world_a.base_pose(), expected, atol=1e-9)


def test_rotation_in_place_about_the_base_centre(world_a):
    betas = [twin(math.atan2(-hy, -hx) - math.pi / 2) for hx, hy in HIPS]
    steer_in_place(world_a, betas)
    w = 0.5
    rates = [f_row(b, hx, hy) @ np.array([0.0, 0.0, w]) / R_W for b, (hx, hy) in zip(betas, HIPS)]
    world_a.set_command('drive', rates)
    run(world_a, 2.0)
    np.testing.assert_allclose(world_a.base_pose(), [0.0, 0.0, 1.0], atol=1e-9)


# ----------------------------------------------------------------------------- base, robot B
def test_mecanum_strafe_and_arc_follow_eq16(world_b):
    # Strafe +y at 0.2 m/s: ω = (1/R)[vx − vy − kω, vx + vy + kω, vx + vy − kω, vx − vy + kω].
    k = D1 + D2
    vy = 0.2
    world_b.set_command('wheel', np.array([-vy, vy, vy, -vy]) / R_B)
    run(world_b, 2.0)
    np.testing.assert_allclose(world_b.base_pose(), [0.0, 0.4, 0.0], atol=1e-9)
    # Then an arc: vx = 0.2, ω = 0.4 for 2 s from (0, 0.4, 0).
    vx, w = 0.2, 0.4
    world_b.set_command('wheel', np.array([vx - k * w, vx + k * w, vx - k * w, vx + k * w]) / R_B)
    run(world_b, 2.0)
    expected = [vx / w * math.sin(w * 2.0), 0.4 + vx / w * (1 - math.cos(w * 2.0)), w * 2.0]
    np.testing.assert_allclose(world_b.base_pose(), expected, atol=1e-9)


def test_a_differential_base_drives_and_turns_by_its_two_wheels():
    # its rolling model comes from its base section: equal rates drive along x at r φ̇,
    # opposite ones turn on the spot at 2 r φ̇ / track
    robot = load_robot('panda_diff')
    r, track = robot.base.wheel_radius, robot.base.track
    with SimWorld(robot) as world:
        world.set_command('wheel', [2.0, 2.0])
        run(world, 1.0)
        np.testing.assert_allclose(world.base_pose(), [2.0 * r, 0.0, 0.0], atol=1e-9)
        world.set_command('wheel', [-1.0, 1.0])  # left back, right forward: counter-clockwise
        run(world, 1.0)
        np.testing.assert_allclose(world.base_pose(), [2.0 * r, 0.0, 2.0 * r / track], atol=1e-9)


# ----------------------------------------------------------------------------- odometry and slip
def drive_a_pattern(world):
    """Steer (sub-stepped path), drive along an arc, then straight."""
    steer_in_place(world, [0.3, 0.2, 0.35, 0.25], seconds=1.0)
    world.set_command('steer', [0.2, -0.1, 0.15, 0.05])
    world.set_command('drive', [4.0, 5.0, 4.5, 5.5])
    run(world, 1.0)
    world.zero_command('steer')
    world.set_command('drive', [5.0] * 4)
    run(world, 1.0)


@pytest.mark.parametrize('slip', [None, SlipParams()])
def test_odometry_equals_truth_bitwise_without_slip(slip):
    with SimWorld('A', slip=slip, start_base_pose=(0.5, -0.2, 0.4)) as w:
        drive_a_pattern(w)
        assert np.linalg.norm(w.base_pose()[:2] - [0.5, -0.2]) > 0.5  # it did move
        np.testing.assert_array_equal(w.odom_pose(), w.base_pose())
        np.testing.assert_array_equal(w.odom_twist(), w.base_twist())
    with SimWorld('B', slip=slip) as w:
        w.set_command('wheel', [3.0, -2.0, 4.0, 1.0])
        run(w, 2.0)
        np.testing.assert_array_equal(w.odom_pose(), w.base_pose())


def test_slip_drift_separates_odometry_at_the_configured_rate():
    drift = 0.02  # [m/s] along base x
    with SimWorld('A', slip=SlipParams(drift=(drift, 0.0, 0.0)), start_base_pose=(0, 0, 0)) as w:
        v = 0.45
        w.set_command('drive', [v / R_W] * 4)
        run(w, 4.0)
        np.testing.assert_allclose(w.odom_pose(), [v * 4.0, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(w.base_pose(), [(v + drift) * 4.0, 0.0, 0.0], atol=1e-9)
        # The base at rest does not creep.
        w.zero_command('drive')
        before = w.base_pose()
        run(w, 1.0)
        np.testing.assert_array_equal(w.base_pose(), before)


def test_slip_gain_grows_with_wheel_speed():
    gain = 0.1  # [1/(m/s)]
    gaps = []
    for v in (0.2, 0.4):  # rim speeds [m/s]
        with SimWorld('B', slip=SlipParams(gain=gain), start_base_pose=(0, 0, 0)) as w:
            w.set_command('wheel', [v / R_B] * 4)  # straight +x at v
            run(w, 2.0)
            gap = w.odom_pose()[0] - w.base_pose()[0]
            np.testing.assert_allclose(gap, gain * v * v * 2.0, rtol=1e-9)
            gaps.append(gap)
    assert gaps[1] > 3.9 * gaps[0]  # loss ∝ v², distance ∝ v


def test_slip_noise_mean_rate_and_seeded_reproducibility():
    params = SlipParams(drift=(0.0, 0.01, 0.0), noise_std=(0.01, 0.01, 0.002))
    results = []
    for seed in (3, 3, 4):
        with SimWorld('B', slip=params, seed=seed, start_base_pose=(0, 0, 0)) as w:
            w.set_command('wheel', [2.0] * 4)
            run(w, 10.0)  # 400 noise draws
            results.append((w.base_pose(), w.odom_pose()))
    np.testing.assert_allclose(results[0][0], results[1][0], rtol=0, atol=SAME)
    # another seed, other draws: millimetres apart (the noise's walk), far beyond round-off
    assert np.abs(results[0][0] - results[2][0]).max() > 1e-4
    # Lateral truth − odom ≈ 0.01 m/s · 10 s; the noise and the heading noise add a few mm.
    gap_y = results[0][0][1] - results[0][1][1]
    assert abs(gap_y - 0.1) < 0.03


def test_runs_are_identical_for_the_same_seed_and_worlds_do_not_interfere():
    params = SlipParams(gain=0.05, drift=(0.001, -0.002, 0.003), noise_std=0.01)
    w1 = SimWorld('A', slip=params, seed=7)
    w2 = SimWorld('A', slip=params, seed=7)
    try:
        for w in (w1, w2):
            w.set_command('arm', [0.1, -0.1, 0.2, 0.0, 0.3, -0.2, 0.1])
            w.set_command('steer', [0.1, 0.1, 0.1, 0.1])
            w.set_command('drive', [3.0, 3.0, 3.0, 3.0])
        trace1, trace2 = [], []
        for _ in range(60):  # interleaved stepping
            w1.step()
            w2.step()
            for w, tr in ((w1, trace1), (w2, trace2)):
                tr.append(np.concatenate([w.joint_state()[1], w.base_pose(), w.odom_pose(), *w.ee_pose()]))
        np.testing.assert_allclose(np.array(trace1), np.array(trace2), rtol=0, atol=SAME)
    finally:
        w1.close()
        w2.close()


def test_physics_runs_are_identical():
    poses = []
    for _ in range(2):
        with SimWorld('B', base_mode='physics') as w:
            w.set_command('wheel', [3.0, -3.0, 1.0, 2.0])
            w.set_command('arm', [0.2] * 7)
            run(w, 0.5)
            poses.append(np.concatenate([w.base_pose(), w.joint_state()[1], w.odom_pose()]))
    np.testing.assert_allclose(poses[0], poses[1], rtol=0, atol=SAME)


@pytest.mark.parametrize('mode', ['kinematic', 'physics'])
def test_the_world_drives_a_base_by_its_rolling_model_whatever_its_groups_are_called(mode):
    """Robot A's base with its command groups renamed: the world reads which joints steer (the
    positions its twist reads) from the base's rolling model, not from a group's name, and runs
    as robot A's (steering, then driving straight)."""

    @dataclasses.dataclass(frozen=True)
    class Renamed(SteerableBase):
        @property
        def command_groups(self) -> dict[str, tuple]:
            return {'turn': self.steer_joints, 'roll': self.drive_joints}

        @property
        def rate_limits(self) -> dict[str, float]:
            return {'turn': self.steer_rate_limit, 'roll': self.drive_rate_limit}

    robot = load_robot('A')
    base = Renamed(**{f.name: getattr(robot.base, f.name) for f in dataclasses.fields(robot.base)})
    traces = []
    for cfg, (steer, drive) in ((robot, ('steer', 'drive')), (dataclasses.replace(robot, base=base), ('turn', 'roll'))):
        with SimWorld(cfg, base_mode=mode, start_base_pose=(0.0, 0.0, 0.0)) as w:
            trace = []
            for steer_rates, drive_rates in (([0.2, -0.1, 0.15, 0.05], [4.0, 5.0, 4.5, 5.5]), ([0.0] * 4, [5.0] * 4)):
                assert w.set_command(steer, steer_rates).accepted and w.set_command(drive, drive_rates).accepted
                for _ in range(10):
                    w.step()
                    trace.append(np.concatenate([w.joint_state()[1], w.base_pose(), w.odom_pose(), w.odom_twist()]))
            traces.append(np.array(trace))
    assert np.linalg.norm(traces[0][-1, 15:17]) > 0.05  # the base moved
    np.testing.assert_allclose(traces[1], traces[0], rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- physics base
def test_physics_robot_a_drives_straight_by_wheel_contact():
    with SimWorld('A', base_mode='physics', start_base_pose=(0, 0, 0)) as w:
        v = 0.45
        w.set_command('drive', [v / R_W] * 4)
        run(w, 2.0)
        x, y, th = w.base_pose()
        assert abs(x - v * 2.0) < 0.05 * v * 2.0  # within 5 % of r φ̇ t
        assert abs(y) < 0.03 and abs(th) < 0.03
        assert np.linalg.norm(w.odom_pose()[:2] - [x, y]) < 0.05


def test_physics_robot_a_keeps_its_wheels_and_heading_on_a_long_straight_run():
    # 4 m at 0.4 m/s with zero steer rates. Wheels as PyBullet's default convex hulls (polygons
    # rolling on their corners) turned the steer joints by up to 0.036 rad and the base by
    # 0.053 rad (13.5 cm off the line); true cylinders: 0.001 rad, 0.0015 rad, 1.2 cm.
    with SimWorld('A', base_mode='physics', start_base_pose=(0, 0, 0)) as w:
        w.set_command('drive', [0.4 / R_W] * 4)
        run(w, 10.0)
        x, y, th = w.base_pose()
        names, q, _ = w.joint_state()
        steer = [q[names.index(n)] for n in w.command_groups['steer']]
        assert abs(x - 4.0) < 0.05
        assert np.max(np.abs(steer)) < 0.005
        assert abs(th) < 0.01 and abs(y) < 0.05


def test_physics_robot_b_strafes_with_roller_traction():
    with SimWorld('B', base_mode='physics', start_base_pose=(0, 0, 0)) as w:
        vy = 0.2
        w.set_command('wheel', np.array([-vy, vy, vy, -vy]) / R_B)
        run(w, 2.0)
        x, y, th = w.base_pose()
        assert abs(y - vy * 2.0) < 0.05 * vy * 2.0
        assert abs(x) < 0.02 and abs(th) < 0.02
        np.testing.assert_allclose(w.base_twist(), [0.0, vy, 0.0], atol=0.01)


def test_a_six_wheel_mecanum_base_follows_its_kinematics_in_both_modes(tmp_path):
    """Any number of Mecanum wheels: the kinematic base moves by the twist of their rates
    exactly, and the roller tyre model of physics mode drives on all six."""
    robot = load_robot(write_mecanum_robot(tmp_path, SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES))
    kin = MecanumKinematics.from_config(robot.base)
    vx, vy, w, t = 0.1, 0.15, 0.2, 2.0
    with SimWorld(robot, start_base_pose=(0.0, 0.0, 0.0)) as world:
        assert world.command_groups['wheel'] == robot.base.wheel_joints
        world.set_command('wheel', kin.wheel_rates([vx, vy, w]))
        run(world, t)
        s, c = math.sin(w * t), math.cos(w * t)
        expected = [(vx * s - vy * (1 - c)) / w, (vx * (1 - c) + vy * s) / w, w * t]  # the SE(2) exponential
        np.testing.assert_allclose(world.base_pose(), expected, atol=1e-9)
    with SimWorld(robot, base_mode='physics', start_base_pose=(0.0, 0.0, 0.0)) as world:
        world.set_command('wheel', kin.wheel_rates([0.0, 0.2, 0.0]))
        run(world, t)
        x, y, th = world.base_pose()
        assert abs(y - 0.2 * t) < 0.05 * 0.2 * t
        assert abs(x) < 0.02 and abs(th) < 0.02
        np.testing.assert_allclose(world.base_twist(), [0.0, 0.2, 0.0], atol=0.01)


# ----------------------------------------------------------------------------- safety
@pytest.mark.parametrize('robot', ['A', 'B'])
def test_bad_commands_are_rejected_and_nothing_moves(robot):
    with SimWorld(robot) as w:
        _, q0, _ = w.joint_state()
        pose0, ee0 = w.base_pose(), w.ee_pose()[0]
        wheel = 'drive' if robot == 'A' else 'wheel'
        bad = [
            ('arm', [0.1] * 6),
            ('arm', [0.1] * 8),
            ('arm', [0.1, math.nan, 0, 0, 0, 0, 0]),
            ('arm', [0, 0, 0, math.inf, 0, 0, 0]),
            ('arm', 'fast'),
            ('arm', [[0.1] * 7]),
            (wheel, [1.0, 2.0, -math.inf, 0.0]),
            (wheel, [1.0] * 3),
            ('gripper', [0.1]),
        ]
        for group, values in bad:
            res = w.set_command(group, values)
            assert not res.accepted and res.reason
        run(w, 0.5)
        _, q, qd = w.joint_state()
        np.testing.assert_array_equal(q, q0)
        assert not qd.any()
        np.testing.assert_array_equal(w.base_pose(), pose0)
        np.testing.assert_array_equal(w.ee_pose()[0], ee0)
        assert w.counters['arm']['rejected'] == 6
        assert w.counters[wheel]['rejected'] == 2
        # A good command stays in force through a rejected one.
        w.set_command('arm', [0.1] * 7)
        w.set_command('arm', [math.nan] * 7)
        w.step()
        np.testing.assert_allclose(w.joint_state()[2][:7], 0.1)


def test_commands_beyond_the_urdf_limits_are_clamped_and_counted(world_a):
    lim = world_a.velocity_limits
    np.testing.assert_allclose(lim[:7], world_a.robot.arm.velocity)  # = URDF <limit velocity>
    res = world_a.set_command('arm', [10.0, -10.0, 0.1, 0.1, 0.1, 0.1, 0.1])
    assert res.accepted and res.clamped == 2 and 'arm_joint_1' in res.reason
    res = world_a.set_command('drive', [100.0, 1.0, 1.0, 1.0])
    assert res.accepted and res.clamped == 1
    assert world_a.counters['arm']['clamped'] == 2 and world_a.counters['drive']['clamped'] == 1
    world_a.step()
    _, _, qd = world_a.joint_state()
    assert qd[0] == lim[0] and qd[1] == -lim[1]
    assert qd[11] == lim[11] == 12.0


def test_physics_with_slip_is_a_config_error():
    with pytest.raises(ConfigError):
        SimWorld('A', base_mode='physics', slip=SlipParams(gain=0.1))
    with pytest.raises(ConfigError):
        SimWorld('A', base_mode='dynamic')
    with pytest.raises(ConfigError):
        SimWorld('A', start_arm=[0.0] * 6)


# ----------------------------------------------------------------------------- FK
@pytest.mark.parametrize('robot', ['A', 'B'])
def test_ee_pose_matches_kinematics_core_fk(robot):
    model = KinematicModel(robot)
    rng = np.random.default_rng(11)
    with SimWorld(robot, start_base_pose=(0.3, -0.4, 2.5)) as w:
        group = 'drive' if robot == 'A' else 'wheel'
        for _ in range(6):
            w.set_command('arm', rng.uniform(-0.5, 0.5, 7))
            w.set_command(group, rng.uniform(-3.0, 3.0, 4))
            if robot == 'A':
                w.set_command('steer', rng.uniform(-0.5, 0.5, 4))
            run(w, 0.5)
            _, q, _ = w.joint_state()
            model.update(w.base_pose(), q[:7])
            pos_fk, rot_fk = model.ee_placement_world()
            pos, quat = w.ee_pose()
            x, y, z, qw = quat
            rot = np.array(
                [
                    [1 - 2 * (y * y + z * z), 2 * (x * y - z * qw), 2 * (x * z + y * qw)],
                    [2 * (x * y + z * qw), 1 - 2 * (x * x + z * z), 2 * (y * z - x * qw)],
                    [2 * (x * z - y * qw), 2 * (y * z + x * qw), 1 - 2 * (x * x + y * y)],
                ]
            )
            assert np.linalg.norm(pos - pos_fk) < 1e-3
            assert np.linalg.norm(rot.T @ rot_fk - np.eye(3)) < 1e-3


@pytest.mark.parametrize('robot', ['A', 'B'])
def test_start_state_is_the_papers(robot):
    with SimWorld(robot) as w:
        pos, _ = w.ee_pose()
        np.testing.assert_allclose(pos, w.robot.start.ee_pose[:3], atol=w.robot.start.ee_tolerance[0])
        np.testing.assert_array_equal(w.joint_state()[1][:7], w.robot.start.arm)


# ----------------------------------------------------------------------------- pictures
def _png_size_and_pixels(path):
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    i, idat = 8, b''
    while i < len(data):
        n = struct.unpack('>I', data[i : i + 4])[0]
        tag, body = data[i + 4 : i + 8], data[i + 8 : i + 8 + n]
        if tag == b'IHDR':
            w, h = struct.unpack('>II', body[:8])
        elif tag == b'IDAT':
            idat += body
        i += 12 + n
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 3 * w + 1)[:, 1:]
    return w, h, raw.reshape(h, w, 3)


@pytest.mark.parametrize('view', ['iso', 'top', 'side', 'front'])
def test_render_png_headless(tmp_path, view, world_a):
    out = render_png(world_a, tmp_path / f'{view}.png', view=view, width=160, height=120)
    w, h, px = _png_size_and_pixels(out)
    assert (w, h) == (160, 120)
    colours = np.unique(px.reshape(-1, 3), axis=0)
    assert len(colours) > 20  # floor, robot, shading
    with pytest.raises(ConfigError):
        render_png(world_a, tmp_path / 'x.png', view='fisheye')


def test_a_base_whose_inertial_frame_is_offset_is_placed_at_its_link_pose(world_b):
    """PyBullet places a body by its inertial frame; with one offset and turned from the base
    link (no shipped robot has one), the link still lands at the planar pose, the COM where
    PyBullet's own composition of the two puts it."""
    import pinocchio as pin
    import pybullet as p
    from wmm_control.geometry import quaternion_from_yaw

    local_pos, local_quat = (
        (0.05, -0.02, 0.1),
        tuple(np.array([0.1, 0.2, 0.05, 0.97]) / np.linalg.norm([0.1, 0.2, 0.05, 0.97])),
    )
    world_b._com_local = pin.XYZQUATToSE3(np.array([*local_pos, *local_quat]))
    world_b._com_inv = p.invertTransform(local_pos, local_quat)
    world_b._com_identity = False
    pose = (1.2, -0.4, 2.5)
    com_pos, com_quat = world_b._com_pose(pose)
    ref_pos, ref_quat = p.multiplyTransforms((1.2, -0.4, 0.0), quaternion_from_yaw(2.5).tolist(), local_pos, local_quat)
    np.testing.assert_allclose(com_pos, ref_pos, atol=1e-6)
    assert min(np.linalg.norm(np.subtract(com_quat, ref_quat)), np.linalg.norm(np.add(com_quat, ref_quat))) < 1e-6
    world_b._pose = pose
    world_b._place()
    link_pos, link_quat = world_b._base_link_pose()
    np.testing.assert_allclose(link_pos, [1.2, -0.4, 0.0], atol=1e-6)
    assert abs(math.remainder(p.getEulerFromQuaternion(link_quat)[2] - 2.5, 2 * math.pi)) < 1e-6
