"""wmm_sim node, in-process: lockstep stepping, commands, safety, and what it publishes."""

import math

import numpy as np
import pytest

from ros_helpers import RosHarness, ScriptedController, overrides, pose2d, stamp_s
from same_runs import assert_same
from sim_bridge.node import SimNode
from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import load_robot

ARM = [f'arm_joint_{i}' for i in range(1, 8)]


def start(ros, script, groups=('arm', 'steer', 'drive'), **params):
    params.setdefault('timing', 'lockstep')
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(**params)))
    ctrl = ros.add(ScriptedController(ros.context, groups, script))
    return sim, ctrl


def steps(ctrl, n):
    return lambda: len(ctrl.joint_states) >= n


def test_constant_arm_velocity_moves_the_joints_by_v_times_t(ros):
    v = np.array([0.1, -0.2, 0.05, 0.15, -0.3, 0.25, 0.4])
    sim, ctrl = start(ros, lambda t, js: {'arm': v, 'steer': np.zeros(4), 'drive': np.zeros(4)})
    assert ros.spin_until(steps(ctrl, 81))
    q0 = np.array([ctrl.positions(0)[n] for n in ARM])
    q80 = np.array([ctrl.positions(80)[n] for n in ARM])
    elapsed = stamp_s(ctrl.joint_states[80]) - stamp_s(ctrl.joint_states[0])
    assert elapsed == pytest.approx(80 * 0.025)
    np.testing.assert_allclose(q80 - q0, v * elapsed, rtol=0.01)


def test_steer_and_drive_commands_move_the_base_and_odometry_equals_truth_without_slip(ros):
    # Wheels at β = 0, drive 2 rad/s: the base goes straight along x at r_w·φ̇ = 0.18 m/s.
    sim, ctrl = start(ros, lambda t, js: {'arm': np.zeros(7), 'steer': np.zeros(4), 'drive': np.full(4, 2.0)})
    assert ros.spin_until(lambda: len(ctrl.truth) >= 41 and len(ctrl.odom) >= 41)
    truth, odom = pose2d(ctrl.truth[40]), pose2d(ctrl.odom[40])
    np.testing.assert_allclose(truth, [0.18 * 40 * 0.025, 0.0, 0.0], atol=1e-9)
    np.testing.assert_array_equal(odom, truth)


def test_with_slip_drift_odometry_and_truth_drift_apart_at_the_configured_rate(ros):
    sim, ctrl = start(
        ros,
        lambda t, js: {'arm': np.zeros(7), 'steer': np.zeros(4), 'drive': np.full(4, 2.0)},
        slip_drift=[0.0, 0.02, 0.0],
    )
    assert ros.spin_until(lambda: len(ctrl.truth) >= 41 and len(ctrl.odom) >= 41)
    gap = pose2d(ctrl.truth[40]) - pose2d(ctrl.odom[40])
    np.testing.assert_allclose(gap, [0.0, 0.02 * 40 * 0.025, 0.0], atol=1e-9)


def test_command_timeout_zeroes_a_group_that_stops_sending(ros):
    # The arm controller answers only the first 10 states; lockstep waits for 'steer'
    # only, so the simulation goes on and the arm command must time out (0.1 s = 4 periods).
    def script(t, js):
        cmds = {'steer': np.zeros(4), 'drive': np.zeros(4)}
        if t < 10 * 0.025 - 1e-9:
            cmds['arm'] = np.full(7, 0.2)
        return cmds

    sim, ctrl = start(ros, script, lockstep_groups='steer')
    assert ros.spin_until(steps(ctrl, 40))
    vel = np.array([[ctrl.velocities(i)[n] for n in ARM] for i in range(40)])
    moving = np.flatnonzero(np.abs(vel).max(axis=1) > 0)
    assert moving.size > 0
    last_moving = moving.max()
    # Last command received at t = 0.225 s. The step from t = 0.35 s (age 0.125 s > 0.1 s) is
    # taken with zero velocity, so the state at 0.35 s is the last that moved at the latest;
    # at t = 0.325 s the age is 0.1 s, the timeout itself, so round-off may zero it one step early.
    assert 0.325 - 1e-9 <= stamp_s(ctrl.joint_states[last_moving]) <= 0.35 + 1e-9
    q_a, q_b = ctrl.positions(last_moving + 1), ctrl.positions(39)
    assert all(q_a[n] == q_b[n] for n in ARM)


def test_bad_commands_are_rejected_and_nothing_moves(ros):
    bad = {'arm': [0.1] * 6, 'steer': [np.nan, 0, 0, 0], 'drive': [np.inf, 1.0, 1.0, 1.0]}
    sim, ctrl = start(ros, lambda t, js: bad, lockstep_timeout=0.02)
    assert ros.spin_until(steps(ctrl, 12))
    first, last = ctrl.positions(0), ctrl.positions(11)
    assert first == last
    assert pose2d(ctrl.truth[-1]).tolist() == [0.0, 0.0, 0.0]
    counts = sim.world.counters
    assert counts['arm']['rejected'] >= 10 and counts['steer']['rejected'] >= 10
    assert counts['drive']['rejected'] >= 10


def test_commands_beyond_the_velocity_limit_are_clamped_and_reported(ros):
    limit = load_robot('steerable').arm.velocity
    sim, ctrl = start(
        ros, lambda t, js: {'arm': np.full(7, 50.0), 'steer': np.zeros(4), 'drive': np.zeros(4)}, diagnostics_period=0.1
    )
    assert ros.spin_until(lambda: len(ctrl.joint_states) >= 10 and len(ctrl.diagnostics) >= 2)
    np.testing.assert_allclose([ctrl.velocities(5)[n] for n in ARM], limit)
    arm_status = [s for s in ctrl.diagnostics[-1].status if s.name == '/wmm_sim: arm commands'][0]
    clamped = int({kv.key: kv.value for kv in arm_status.values}['clamped'])
    assert clamped >= 7 and arm_status.level == arm_status.WARN


def test_ee_pose_equals_forward_kinematics_of_published_joint_states_and_true_base(ros):
    model = KinematicModel('steerable')
    rng = np.random.default_rng(3)
    arm_v = rng.uniform(-0.4, 0.4, 7)
    sim, ctrl = start(
        ros, lambda t, js: {'arm': arm_v * np.cos(3 * t), 'steer': np.full(4, 0.3), 'drive': np.full(4, 3.0)}
    )
    assert ros.spin_until(lambda: len(ctrl.ee_poses) >= 60 and len(ctrl.truth) >= 60 and len(ctrl.joint_states) >= 60)
    worst = 0.0
    for i in range(0, 60, 5):
        q = np.array([ctrl.positions(i)[n] for n in ARM])
        assert stamp_s(ctrl.truth[i]) == stamp_s(ctrl.joint_states[i]) == stamp_s(ctrl.ee_poses[i])
        model.update(pose2d(ctrl.truth[i]), q)
        pos, _ = model.ee_placement_world()
        p = ctrl.ee_poses[i].pose.position
        worst = max(worst, np.linalg.norm(pos - [p.x, p.y, p.z]))
    assert worst <= 1e-3


def _record_run(seed):
    ros = RosHarness()
    try:

        def script(t, js):
            return {'arm': np.full(7, 0.1) * np.sin(t), 'steer': np.full(4, 0.2), 'drive': np.full(4, 4.0)}

        sim, ctrl = start(ros, script, slip_gain=0.05, slip_noise=[0.01, 0.01, 0.02], seed=seed)
        assert ros.spin_until(lambda: len(ctrl.odom) >= 50 and len(ctrl.truth) >= 50 and len(ctrl.joint_states) >= 50)
        return (
            [tuple(m.position) for m in ctrl.joint_states[:50]],
            [tuple(pose2d(m)) for m in ctrl.truth[:50]],
            [tuple(pose2d(m)) for m in ctrl.odom[:50]],
        )
    finally:
        ros.close()


def test_lockstep_runs_are_identical_for_the_same_seed():
    a, b, c = _record_run(7), _record_run(7), _record_run(8)
    assert_same(a, b)
    # the noise really depends on the seed: far beyond round-off
    assert np.abs(np.array(a[1]) - np.array(c[1])).max() > 1e-6


def test_invalid_parameters_fail_with_a_clear_error(ros):
    with pytest.raises(ConfigError, match='lockstep_groups: unknown groups'):
        SimNode(context=ros.context, parameter_overrides=overrides(lockstep_groups='arm,wheel'))
    with pytest.raises(ConfigError, match='base_mode'):
        SimNode(context=ros.context, parameter_overrides=overrides(base_mode='teleport'))
    with pytest.raises(ConfigError, match='period'):
        SimNode(context=ros.context, parameter_overrides=overrides(period=-1.0))


@pytest.mark.parametrize('timing', ['realtime', 'lockstep'])
def test_runs_under_use_sim_time_as_the_time_source(ros, timing):
    # Under use_sim_time the ROS clock advances only with the /clock the simulator itself
    # publishes: timers on it would never fire and the simulator would freeze at t = 0.
    sim, ctrl = start(
        ros,
        lambda t, js: {'arm': np.zeros(7), 'steer': np.zeros(4), 'drive': np.full(4, 2.0)},
        timing=timing,
        use_sim_time=True,
    )
    assert ros.spin_until(lambda: len(ctrl.joint_states) >= 20 and len(ctrl.truth) >= 20, timeout=10)
    stamps = np.array([stamp_s(m) for m in ctrl.joint_states[:20]])
    np.testing.assert_allclose(np.diff(stamps), 0.025, atol=1e-9)  # simulated time, one period a step
    assert pose2d(ctrl.truth[19])[0] > 0.0  # and the commands act
    assert sim.get_clock().now().nanoseconds > 0


# ---------------------------------------------------------------- odometry covariance, PyBullet client


def _planar(cov):
    full = np.array(cov).reshape(6, 6)
    return full[np.ix_([0, 1, 5], [0, 1, 5])]


def test_odometry_covariance_is_the_slip_models_error(ros):
    # Drive straight with slip (gain, drift, noise): the reported covariances must match the
    # errors odometry actually makes against the ground truth.
    noise = [0.01, 0.01, 0.02]
    sim, ctrl = start(
        ros,
        lambda t, js: {'arm': np.zeros(7), 'steer': np.zeros(4), 'drive': np.full(4, 5.0)},
        slip_gain=0.05,
        slip_drift=[0.003, 0.0, 0.002],
        slip_noise=noise,
        seed=3,
    )
    assert ros.spin_until(lambda: len(ctrl.odom) >= 161 and len(ctrl.truth) >= 161)
    odom, truth = ctrl.odom[1:161], ctrl.truth[1:161]

    def twist(m):
        return np.array([m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z])

    err = np.array([twist(t) - twist(o) for o, t in zip(odom, truth)])
    reported = np.array([np.diag(_planar(o.twist.covariance)) for o in odom])
    # Mean squared twist error per axis vs the mean reported variance: equal within sampling error.
    np.testing.assert_allclose(np.mean(err**2, axis=0), np.mean(reported, axis=0), rtol=0.3)
    assert np.all(reported[:, :2] > 1e-5)  # not a placeholder: at least noise² + slip²
    # The pose: the dead-reckoning error after 4 s against its reported mean squared error.
    o, t = odom[-1], truth[-1]
    pose_err = np.array(
        [t.pose.pose.position.x - o.pose.pose.position.x, t.pose.pose.position.y - o.pose.pose.position.y]
    )
    cov = _planar(o.pose.covariance)
    assert cov[0, 0] > cov[1, 1] > 0  # the slip acts along x, the direction of motion
    assert 0.25 < abs(pose_err[0]) / math.sqrt(cov[0, 0]) < 2.0
    assert abs(pose_err[1]) < 3 * math.sqrt(cov[1, 1])
    np.testing.assert_array_equal(truth[-1].pose.covariance, np.zeros(36))  # ground truth is exact


def test_odometry_covariance_without_slip_is_the_floor(ros):
    from sim_bridge.slip import VARIANCE_FLOOR

    sim, ctrl = start(ros, lambda t, js: {'arm': np.zeros(7), 'steer': np.zeros(4), 'drive': np.full(4, 5.0)})
    assert ros.spin_until(lambda: len(ctrl.odom) >= 40)
    np.testing.assert_allclose(np.diag(_planar(ctrl.odom[-1].pose.covariance)), VARIANCE_FLOOR)
    np.testing.assert_allclose(np.diag(_planar(ctrl.odom[-1].twist.covariance)), VARIANCE_FLOOR)


def test_destroying_the_node_closes_its_pybullet_client(ros):
    import pybullet

    sim = SimNode(context=ros.context)
    cid = sim.world.client_id
    assert pybullet.isConnected(physicsClientId=cid)
    sim.destroy_node()
    assert not pybullet.isConnected(physicsClientId=cid)
    assert sim.world.client_id == -1


def test_two_simulators_in_namespaces_each_drive_their_own_clock_and_name_their_diagnostics(ros):
    """Two simulators in /r1 and /r2, one domain, on sim time: neither publishes /clock; each
    publishes <ns>/clock, and a node of each robot (remapping /clock to it) follows its own
    robot's time. /r1 steps in real time, /r2 in lockstep with nobody answering, so their times
    part at once. Their /diagnostics statuses carry their fully qualified names."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node

    sims, clocks = {}, {}
    for ns, timing in (('r1', 'realtime'), ('r2', 'lockstep')):
        args = ['--ros-args', '-r', f'__ns:=/{ns}', '-r', f'/clock:=/{ns}/clock']
        sims[ns] = ros.add(
            SimNode(
                context=ros.context,
                cli_args=args,
                parameter_overrides=overrides(
                    timing=timing, lockstep_timeout=0.2, publish_clock=True, use_sim_time=True, diagnostics_period=0.1
                ),
            )
        )
        clocks[ns] = ros.add(
            Node(
                'follower',
                namespace=f'/{ns}',
                context=ros.context,
                cli_args=args,
                parameter_overrides=overrides(use_sim_time=True),
            )
        )
    statuses = {}
    probe = ros.add(Node('probe', context=ros.context))
    probe.create_subscription(
        DiagnosticArray, '/diagnostics', lambda m: statuses.update({s.name: s.hardware_id for s in m.status}), 10
    )

    def now(ns):
        return clocks[ns].get_clock().now().nanoseconds * 1e-9

    assert ros.spin_until(lambda: now('r1') > 2.0 and now('r2') > 0.05, timeout=30.0)
    assert probe.count_publishers('/clock') == 0
    assert probe.count_publishers('/r1/clock') == 1 and probe.count_publishers('/r2/clock') == 1
    for ns, sim in sims.items():
        assert now(ns) == pytest.approx(sim.world.time, abs=0.1), ns
    assert now('r1') > 4 * now('r2'), 'each follows its own simulator, not the other one'
    assert ros.spin_until(lambda: {'/r1/wmm_sim: simulation', '/r2/wmm_sim: simulation'} <= set(statuses))
    assert statuses['/r1/wmm_sim: simulation'] == 'steerable /r1/wmm_sim'
    assert '/r2/wmm_sim: arm commands' in statuses


def _chain(transforms, parent, child):
    """The 4×4 pose of ``child`` in ``parent`` from TransformStamped messages (a tree)."""
    from wmm_control.kinematics.frames import FrameTransform

    by_child = {m.child_frame_id: m for m in transforms}
    out = np.eye(4)
    frame = child
    while frame != parent:
        m = by_child[frame]
        t, q = m.transform.translation, m.transform.rotation
        out = (
            FrameTransform(m.header.frame_id, frame, np.array([t.x, t.y, t.z]), np.array([q.x, q.y, q.z, q.w])).matrix()
            @ out
        )
        frame = m.header.frame_id
    return out


def _ee_matrix(msg):
    from wmm_control.kinematics.frames import FrameTransform

    p, q = msg.pose.position, msg.pose.orientation
    return FrameTransform('world', 'ee', np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w])).matrix()


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_robot_description_and_the_tf_tree_place_the_end_effector_where_ee_pose_says(ros, robot):
    """robot_description (transient local) is the URDF; the TF tree world → odom → base_link →
    … → the tool, with odometry drifting from the truth, puts the tool at the ground-truth
    /ee_pose. Frames carry frame_prefix, world none."""
    from rclpy.node import Node
    from std_msgs.msg import String
    from wmm_control.kinematics.frames import FrameTransform
    from wmm_control.nodes.robot_frames import DESCRIPTION_QOS, TFMessage

    config = load_robot(robot)
    groups = ('arm', 'steer', 'drive') if robot == 'steerable' else ('arm', 'wheel')
    sizes = {'arm': 7, 'steer': 4, 'drive': 4, 'wheel': 4}
    moving = {'arm': 0.2, 'steer': 0.3, 'drive': 4.0, 'wheel': 3.0}
    sim, ctrl = start(
        ros,
        lambda t, js: {g: np.full(sizes[g], moving[g] * (-1) ** i) for i, g in enumerate(groups)},
        groups=groups,
        robot=robot,
        frame_prefix='r1/',
        slip_drift=[0.02, -0.01, 0.03],
    )
    assert ros.spin_until(steps(ctrl, 60))
    late = ros.add(Node('late_listener', context=ros.context))
    texts = []
    late.create_subscription(String, '/robot_description', lambda m: texts.append(m.data), DESCRIPTION_QOS)
    assert ros.spin_until(lambda: texts, timeout=5.0), 'a late subscriber gets robot_description'
    assert texts[0] == config.urdf_path.read_text()
    assert sim.frames.publishing_tf == (TFMessage is not None)
    assert not np.allclose(sim.world.odom_pose(), sim.world.base_pose(), atol=1e-3), 'odometry drifted'
    names, pos, _ = sim.world.joint_state()
    stamp = ctrl.ee_poses[-1].header.stamp
    ee_position, ee_quat = sim.world.ee_pose()  # the state the transforms below are of
    ee = FrameTransform('world', 'ee', np.asarray(ee_position), np.asarray(ee_quat)).matrix()
    tfs = sim.frames.static_transforms(stamp) + sim.frames.dynamic_transforms(
        stamp, dict(zip(names, pos.tolist())), sim.world.odom_pose(), sim.world.base_pose()
    )
    assert all(m.child_frame_id.startswith('r1/') for m in tfs)
    assert {m.header.frame_id for m in tfs if not m.header.frame_id.startswith('r1/')} == {'world'}
    assert len({m.child_frame_id for m in tfs}) == len(tfs), 'each frame has one parent'
    np.testing.assert_allclose(_chain(tfs, 'world', 'r1/' + config.ee_frame), ee, atol=1e-6)
    np.testing.assert_allclose(
        _chain(tfs, 'world', 'r1/' + config.base_link)[:2, 3], sim.world.base_pose()[:2], atol=1e-9
    )
    assert ctrl.odom[-1].header.frame_id == 'r1/odom' and ctrl.odom[-1].child_frame_id == 'r1/' + config.base_link


def _key(stamp):
    return (stamp.sec, stamp.nanosec)


def _tf_listener(ros, tf2):
    """The transforms of ``/tf_static`` (a list) and of each ``/tf`` message (by stamp), as tf2's
    listener receives them."""
    from rclpy.node import Node
    from wmm_control.nodes.robot_frames import DESCRIPTION_QOS

    listener = ros.add(Node('tf_listener', context=ros.context))
    static, dynamic = [], {}
    listener.create_subscription(tf2.TFMessage, '/tf_static', lambda m: static.extend(m.transforms), DESCRIPTION_QOS)
    listener.create_subscription(
        tf2.TFMessage, '/tf', lambda m: dynamic.setdefault(_key(m.transforms[0].header.stamp), list(m.transforms)), 100
    )
    return static, dynamic


def test_tf_and_tf_static_go_out_where_tf2_msgs_can_be_imported(ros):
    """/tf_static and /tf, as received, put the tool at the ground-truth /ee_pose of the same
    stamp. The messages of one step reach the two subscribers in either order: each /tf is
    paired with the /ee_pose of its stamp once both are in, never with a later one."""
    tf2 = pytest.importorskip('tf2_msgs.msg', reason='tf2_msgs has no PyPI wheel: TF needs a ROS 2 install')
    config = load_robot('steerable')
    static, dynamic = _tf_listener(ros, tf2)
    sim, ctrl = start(ros, lambda t, js: {'arm': np.full(7, 0.2), 'steer': np.full(4, 0.3), 'drive': np.full(4, 4.0)})

    def paired():
        ee = {_key(m.header.stamp): m for m in ctrl.ee_poses}
        return {k: (tfs, ee[k]) for k, tfs in dynamic.items() if k in ee}

    assert ros.spin_until(lambda: static and len(paired()) > 20)
    pairs = paired()
    for key in sorted(pairs)[-20:]:
        tfs, ee = pairs[key]
        np.testing.assert_allclose(_chain(static + tfs, 'world', config.ee_frame), _ee_matrix(ee), atol=1e-6)


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_tf_puts_every_link_where_pinocchio_puts_it_with_the_frame_prefix(ros, robot):
    """What robot_state_publisher would publish: /tf_static and /tf, as received, place every link
    of the URDF where pinocchio's forward kinematics of the joint states puts it, on the
    ground-truth base pose of the same stamp; every frame but world carries frame_prefix."""
    tf2 = pytest.importorskip('tf2_msgs.msg', reason='tf2_msgs has no PyPI wheel: TF needs a ROS 2 install')
    import pinocchio as pin

    from wmm_control.kinematics.frames import FrameTransform

    config = load_robot(robot)
    prefix = 'r2/'
    groups = ('arm', 'steer', 'drive') if robot == 'steerable' else ('arm', 'wheel')
    sizes = {'arm': 7, 'steer': 4, 'drive': 4, 'wheel': 4}
    moving = {'arm': 0.3, 'steer': 0.4, 'drive': 4.0, 'wheel': 3.0}
    static, dynamic = _tf_listener(ros, tf2)
    sim, ctrl = start(
        ros,
        lambda t, js: {g: np.full(sizes[g], moving[g] * (-1) ** i) for i, g in enumerate(groups)},
        groups=groups,
        robot=robot,
        frame_prefix=prefix,
        slip_drift=[0.02, -0.01, 0.03],
    )

    def common():
        joints = {_key(m.header.stamp): m for m in ctrl.joint_states}
        truth = {_key(m.header.stamp): m for m in ctrl.truth}
        return sorted(k for k in dynamic if k in joints and k in truth), joints, truth

    assert ros.spin_until(lambda: static and len(common()[0]) > 40)
    keys, joints, truth = common()
    model = pin.buildModelFromUrdf(str(config.urdf_path))
    data = model.createData()
    links = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    assert len(links) > 10
    for key in keys[-3:]:  # the arm and the wheels have moved by then
        position = dict(zip(joints[key].name, joints[key].position))
        q = pin.neutral(model)
        for jid in range(1, model.njoints):
            joint, value = model.joints[jid], position[model.names[jid]]
            if joint.nq == 2:  # continuous: (cos, sin)
                q[joint.idx_q : joint.idx_q + 2] = np.cos(value), np.sin(value)
            else:
                q[joint.idx_q] = value
        pin.framesForwardKinematics(model, data, q)
        pose = truth[key].pose.pose
        world_base = FrameTransform(
            'world',
            'base',
            np.array([pose.position.x, pose.position.y, pose.position.z]),
            np.array([pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w]),
        ).matrix()
        world_root = world_base @ np.linalg.inv(data.oMf[model.getFrameId(config.base_link)].homogeneous)
        tfs = static + dynamic[key]
        assert {m.header.frame_id for m in tfs if not m.header.frame_id.startswith(prefix)} == {'world'}
        assert all(m.child_frame_id.startswith(prefix) for m in tfs)
        for link in links:
            expected = world_root @ data.oMf[model.getFrameId(link)].homogeneous
            np.testing.assert_allclose(_chain(tfs, 'world', prefix + link), expected, atol=1e-9, err_msg=link)
    assert not np.allclose(sim.world.odom_pose(), sim.world.base_pose(), atol=1e-3), 'odometry drifted'
