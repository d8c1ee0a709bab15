"""redundancy_resolver with wmm_sim and swmr_controller, in process: goals on /goal_pose."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Log
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ros_helpers import RosHarness, held_up, overrides, stamp_s
from wmm_control.cli.experiment import summarize_runs
from wmm_control.experiments.direct import run_scenario
from sim_bridge.node import SimNode
from sim_bridge.world import SimWorld
from wmm_control.experiments.ros_run import run_with_nodes
from wmm_control.experiments.scenario import load_scenario
from wmm_control.nodes.goal_sequencer import GoalSequencerNode
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.nodes.conversions import set_planar_pose
from wmm_control.resolvers import make_resolver
from wmm_control.robot_config import load_robot

GOAL_YAML = """scenario:
  name: one_goal
  robot: steerable
  frame: world
  duration: {duration}
  goals:
    - {{t: 0.0, pose: [1.2, 0.4, 1.0, pi/2, 0.0, 0.3]}}
  experiment:
    sim: {{base_mode: kinematic, slip_gain: 0.05, slip_drift: [0.005, 0.0, 0.002], slip_noise: [0.01, 0.01, 0.005], seed: 4}}
    runs:
      - {{name: ts, method: task_sharing, feedback: ground_truth}}
"""


class Driver(Node):
    """Publishes goals; records commands, references, feasible twists, diagnostics and the true EE."""

    def __init__(self, context):
        super().__init__('test_driver', context=context)
        self.pub_goal = self.create_publisher(PoseStamped, '/goal_pose', 10)
        self.arm, self.refs, self.feasible, self.diag, self.ee = [], [], [], [], []
        self.create_subscription(
            Float64MultiArray, '/arm_controller/commands', lambda m: self.arm.append(list(m.data)), 10
        )
        self.create_subscription(TwistStamped, '/base/reference', self.refs.append, 10)
        self.create_subscription(TwistStamped, '/base/feasible_twist', self.feasible.append, 10)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)
        self.create_subscription(PoseStamped, '/ee_pose', self.ee.append, 10)
        self.logs = []
        self.create_subscription(Log, '/rosout', lambda m: self.logs.append((m.name, m.level, m.msg)), 100)

    def _on_diag(self, msg):
        for s in msg.status:
            if s.name == '/redundancy_resolver':
                self.diag.append((s.level, s.message, {kv.key: kv.value for kv in s.values}))

    def goal(self, xyz, quat=(0.0, 0.0, 0.0, 1.0), frame='world'):
        msg = PoseStamped()
        msg.header.frame_id = frame
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in xyz)
        (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w) = (
            float(v) for v in quat
        )
        self.pub_goal.publish(msg)

    def ee_position(self):
        p = self.ee[-1].pose.position
        return np.array([p.x, p.y, p.z])

    def sim_time(self):
        return stamp_s(self.ee[-1]) if self.ee else 0.0


@pytest.fixture
def system():
    ros = RosHarness()
    driver = ros.add(Driver(ros.context))
    # the node's own state timeout (its waits follow the lockstep simulator's): a test here stops the joint states;
    # markers every 20 ms of wall time (the trail takes a point a tick, and the lockstep
    # simulation runs seconds of motion in about one second of wall time)
    ros.add(
        RedundancyResolverNode(
            context=ros.context,
            parameter_overrides=overrides(
                diagnostics_period=1e-9,
                markers_period=0.02,
                state_timeout=0.2,
            ),
        )
    )
    ros.add(SwmrControllerNode(context=ros.context, parameter_overrides=overrides()))
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(timing='lockstep')))
    yield ros, driver, sim
    ros.close()


def run_until(ros, driver, sim_seconds):
    end = driver.sim_time() + sim_seconds
    assert ros.spin_until(lambda: driver.sim_time() >= end, timeout=60.0), 'the simulation stalled'


def test_a_goal_on_the_topic_is_reached_and_held(system):
    ros, driver, _ = system
    run_until(ros, driver, 0.2)
    assert np.allclose(driver.arm[-1], 0.0), 'no goal yet: zero commands'
    goal = np.array([1.8, 0.6, 1.0])
    driver.goal(goal, (0.0, 0.0, 0.0, 1.0))
    run_until(ros, driver, 10.0)
    assert np.linalg.norm(driver.ee_position() - goal) < 0.01
    run_until(ros, driver, 20.0)  # the null-space pull settles the posture
    held = np.array(driver.arm[-40:])
    assert np.all(np.isfinite(held)) and np.max(np.abs(held)) < 0.01, 'at the goal the robot holds still'
    level, message, values = driver.diag[-1]
    assert values['goal_reached'] == 'True' and message == 'goal reached'
    reached = [m for name, lvl, m in driver.logs if name == 'redundancy_resolver' and m.startswith('goal reached')]
    assert len(reached) == 1, f'the goal reached is logged once: {reached}'


@pytest.mark.parametrize(
    'frame, xyz, quat, reason',
    [
        ('map', (1.0, 0.0, 1.0), (0, 0, 0, 1), 'frame'),
        ('world', (float('nan'), 0.0, 1.0), (0, 0, 0, 1), 'non-finite'),
        ('world', (1.0, 0.0, 1.0), (0, 0, 0, 0), 'zero quaternion'),
        ('world', (1e300, 0.0, 1.0), (0, 0, 0, 1), 'max_goal_distance'),
    ],
)
def test_a_bad_goal_is_rejected_and_the_robot_holds(system, frame, xyz, quat, reason):
    ros, driver, _ = system
    driver.goal((1.5, 0.3, 1.0), (0.0, 0.0, 0.0, 1.0))
    run_until(ros, driver, 1.0)
    assert np.max(np.abs(driver.arm[-1])) > 0.0, 'pursuing the first goal'
    driver.goal(xyz, quat, frame)
    run_until(ros, driver, 1.0)
    assert np.allclose(driver.arm[-5:], 0.0) and all(np.all(np.isfinite(a)) for a in driver.arm)
    ref = driver.refs[-1].twist
    assert (ref.linear.x, ref.linear.y, ref.angular.z) == (0.0, 0.0, 0.0)
    node = next(n for n in ros.nodes if isinstance(n, RedundancyResolverNode))
    assert node.counters['goals_rejected'] == 1 and node.target is None


def test_a_non_unit_quaternion_is_normalised(system):
    ros, driver, _ = system
    q = np.array([0.0, 0.0, math.sin(0.2), math.cos(0.2)]) * 3.0
    driver.goal((1.2, 0.2, 1.0), q)
    run_until(ros, driver, 0.5)
    node = next(n for n in ros.nodes if isinstance(n, RedundancyResolverNode))
    assert node.target is not None
    np.testing.assert_allclose(np.linalg.det(node.target.rotation), 1.0, atol=1e-12)


def test_an_unreachable_goal_is_pursued_within_limits_and_reported(system):
    ros, driver, _ = system
    # 5 cm above the floor: the shoulder is 1.08 m up and the arm 0.92 m long, so the lowest the
    # end effector reaches is about 0.16 m. (A goal above the arm's height bound is rejected.)
    driver.goal((1.0, 0.0, 0.05))
    run_until(ros, driver, 8.0)
    arm = np.array(driver.arm)
    assert np.all(np.isfinite(arm)) and np.all(np.abs(arm) <= 3.6)
    level, message, values = driver.diag[-1]
    assert values['goal_stalled'] == 'True' and 'not reached' in message
    stalls = [
        m
        for name, lvl, m in driver.logs
        if name == 'redundancy_resolver' and lvl == Log.WARN and m.startswith('goal not reached')
    ]
    assert len(stalls) == 1, f'the stall is logged once: {stalls}'


def test_stale_joint_states_give_zero_commands(system):
    ros, driver, sim = system
    driver.goal((1.6, 0.4, 1.0))
    run_until(ros, driver, 1.0)
    assert np.max(np.abs(driver.arm[-1])) > 0.0
    ros.executor.remove_node(sim)  # the robot stops reporting
    n = len(driver.arm)
    # in lockstep the watchdog allows the simulator's lockstep_timeout (1 s) besides state_timeout
    assert ros.spin_until(lambda: len(driver.arm) > n and np.allclose(driver.arm[-1], 0.0), timeout=3.0)


def test_the_node_chain_equals_the_direct_loop(tmp_path):
    """Over topics in lockstep, each arm command uses the feasible twist of its own cycle: the
    run equals the ROS-free loop period for period (the goal reaches the resolver one period
    after the first state, hence the shift of one row). The two differ only by the round-off of
    the messages (poses travel as quaternions), about 1e-10 at first, which the closed loop
    amplifies to about 1e-5 by the time the goal is reached (how far depends on the numpy and
    pinocchio builds: 1.01e-5 with numpy 2.4); a resolver or base controller answering with its
    previous cycle's output would differ by about 1e-2, the change of a command in a period."""
    path = tmp_path / 'one_goal.yaml'
    path.write_text(GOAL_YAML.format(duration=3.0))
    sc = load_scenario(str(path))
    nodes = run_with_nodes(sc, sc.runs[0])
    from sim_bridge.slip import SlipParams

    sim = sc.sim
    world = SimWorld(
        'steerable',
        slip=SlipParams(sim['slip_gain'], tuple(sim['slip_drift']), tuple(sim['slip_noise'])),
        seed=sim['seed'],
    )
    direct = run_scenario(world, make_resolver('task_sharing', 'steerable'), sc)
    world.close()
    n = len(nodes)
    assert n > 100 and np.all(nodes.compensated)
    np.testing.assert_allclose(nodes.t, direct.t[:n] + 0.025)
    np.testing.assert_allclose(nodes.arm_command, direct.arm_command[:n], atol=1e-4)
    np.testing.assert_allclose(nodes.base_reference, direct.base_reference[:n], atol=1e-4)
    np.testing.assert_allclose(nodes.ee_position, direct.ee_position[:n], atol=1e-6)
    # and the robot did move: compensation was active while the base steered
    assert np.max(np.abs(direct.base_reference - direct.feasible_twist)) > 0.05


def test_goal_sequencer_plays_the_scenario_on_sim_time():
    ros = RosHarness()
    try:
        driver = ros.add(Driver(ros.context))
        goals = []
        driver.create_subscription(PoseStamped, '/goal_pose', goals.append, 10)
        ros.add(GoalSequencerNode(context=ros.context, parameter_overrides=overrides(use_sim_time=True)))
        sim = ros.add(
            SimNode(context=ros.context, parameter_overrides=overrides(timing='lockstep', lockstep_timeout=0.001))
        )
        assert ros.spin_until(lambda: sim.world.time >= 21.0, timeout=60.0)
        xs = [(stamp_s(g), g.pose.position.y) for g in goals]
        first_switch = next(t for t, y in xs if abs(y - 1.3) < 1e-9)
        # The simulator runs free (1 ms of wall time per 25 ms period), so the sequencer's
        # sim-time timer may fire a few periods late on a loaded machine: 4 periods allowed.
        assert xs[0][1] == pytest.approx(1.5) and first_switch == pytest.approx(20.0, abs=0.1)
    finally:
        ros.close()


def test_the_goal_is_reached_with_wheel_contact_physics():
    """base_mode physics: the base moves through PyBullet wheel contact, the steering is closed on
    the measured steer angles; with the end effector measured (as the paper's simulator does) it
    reaches the goal. (On wheel odometry alone the contact slip leaves a few cm: see docs/methods.md.)"""
    feedback = 'ground_truth'
    ros = RosHarness()
    try:
        driver = ros.add(Driver(ros.context))
        ros.add(
            RedundancyResolverNode(
                context=ros.context,
                parameter_overrides=overrides(ee_feedback=feedback),
            )
        )
        ros.add(SwmrControllerNode(context=ros.context, parameter_overrides=overrides()))
        ros.add(SimNode(context=ros.context, parameter_overrides=overrides(timing='lockstep', base_mode='physics')))
        goal = np.array([1.8, 0.6, 1.0])
        driver.goal(goal)
        # Contact physics makes the run sensitive to round-off (the base controller restarts when
        # the measured rates stray from the command): two ways of normalising the measured
        # quaternion, 1e-16 apart, reach the goal before 16 s and between 16 and 30 s.
        run_until(ros, driver, 30.0)
        error = np.linalg.norm(driver.ee_position() - goal)
        assert error < 0.01, f'{error * 1e3:.1f} mm from the goal'
    finally:
        ros.close()


def test_garbage_on_every_input_never_gives_a_non_finite_or_over_limit_command(system):
    """NaN, inf and finite but absurd values on every topic the resolver reads."""
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState

    ros, driver, _ = system
    pubs = {
        t: driver.create_publisher(m, t, 10)
        for t, m in (('/odom', Odometry), ('/joint_states', JointState), ('/base/feasible_twist', TwistStamped))
    }
    driver.goal((1.5, 0.3, 1.0))
    run_until(ros, driver, 0.5)
    for value in (float('nan'), float('inf'), 1e308, -1e300):
        odom = Odometry()
        odom.pose.pose.position.x = value
        odom.pose.pose.orientation.w = 1.0
        pubs['/odom'].publish(odom)
        js = JointState()
        js.name = ['arm_joint_1', 'arm_joint_2']
        js.position = [value]
        pubs['/joint_states'].publish(js)
        tw = TwistStamped()
        tw.twist.linear.x = value
        pubs['/base/feasible_twist'].publish(tw)
        driver.goal((value, 0.0, 1.0))
        driver.goal((1.5, 0.3, 1.0))
        run_until(ros, driver, 0.3)
    arm = np.array(driver.arm)
    refs = np.array([(r.twist.linear.x, r.twist.linear.y, r.twist.angular.z) for r in driver.refs])
    assert np.all(np.isfinite(arm)) and np.all(np.isfinite(refs))
    assert np.all(np.abs(arm) <= 3.6) and np.all(np.abs(refs) <= 1.0 + 1e-9)
    run_until(ros, driver, 8.0)
    assert np.linalg.norm(driver.ee_position() - np.array([1.5, 0.3, 1.0])) < 0.01, 'still reaches its goal'


def test_amp_tracks_a_trajectory_on_ee_reference_with_the_base_still():
    """Robot B, Xing's R = 0.1 m circle played by goal_sequencer on /ee_reference (sim time):
    over topics AMP tracks it with the arm alone (the base reference stays exactly zero)."""
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from wmm_control.experiments.trajectories import make_trajectory

    ros = RosHarness()
    try:
        driver = ros.add(Driver(ros.context))
        refs = []
        driver.create_subscription(MultiDOFJointTrajectory, '/ee_reference', refs.append, 10)
        ros.add(
            GoalSequencerNode(
                context=ros.context, parameter_overrides=overrides(scenario='xing_circle_0.10', use_sim_time=True)
            )
        )
        ros.add(
            RedundancyResolverNode(
                context=ros.context,
                parameter_overrides=overrides(
                    robot='mecanum',
                    method='amp',
                    ee_feedback='ground_truth',
                ),
            )
        )
        ros.add(
            SimNode(
                context=ros.context,
                parameter_overrides=overrides(robot='mecanum', timing='lockstep', lockstep_groups='arm'),
            )
        )
        run_until(ros, driver, 8.0)
        # /clock is keep-last 1: on a loaded machine the sequencer may skip a period's reference
        assert len(refs) > 250
        bases = np.array([(r.twist.linear.x, r.twist.linear.y, r.twist.angular.z) for r in driver.refs])
        assert len(bases) > 300 and not np.any(bases)
        start = driver.ee[0]
        p, q = start.pose.position, start.pose.orientation
        import pinocchio as pin

        circle = make_trajectory(
            {'kind': 'circle', 'radius': 0.1},
            np.array([p.x, p.y, p.z]),
            pin.Quaternion(q.w, q.x, q.y, q.z).toRotationMatrix(),
        )
        errors = [
            np.linalg.norm(
                circle(stamp_s(m) - 0.025).position
                - np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])
            )
            for m in driver.ee[40:]
        ]
        assert max(errors) < 2e-3 and np.linalg.norm(driver.ee_position() - np.array([p.x, p.y, p.z])) > 0.05
    finally:
        ros.close()


def test_two_robots_side_by_side_in_their_own_namespaces():
    """Every node in namespaces /r1 and /r2 in one domain: each robot reaches its own goal, and a
    goal for one never moves the other (topic names are relative; the node names repeat)."""
    ros = RosHarness()
    try:
        drivers, goals = {}, {'r1': (1.6, 0.4, 1.0), 'r2': (0.7, -0.8, 1.1)}
        for ns in goals:
            args = ['--ros-args', '-r', f'__ns:=/{ns}']
            drivers[ns] = ros.add(NamespacedDriver(ros.context, ns))
            ros.add(
                RedundancyResolverNode(
                    context=ros.context,
                    cli_args=args,
                    parameter_overrides=overrides(),
                )
            )
            ros.add(
                SwmrControllerNode(
                    context=ros.context,
                    cli_args=args,
                    parameter_overrides=overrides(),
                )
            )
            ros.add(SimNode(context=ros.context, cli_args=args, parameter_overrides=overrides(timing='lockstep')))
        drivers['r1'].goal(goals['r1'])
        assert ros.spin_until(lambda: all(d.sim_time() >= 10.0 for d in drivers.values()), timeout=90.0)
        assert np.linalg.norm(drivers['r1'].ee_position() - goals['r1']) < 0.01
        start = np.array([0.708, 0.004, 1.08])
        assert np.linalg.norm(drivers['r2'].ee_position() - start) < 1e-6, 'r2 had no goal: it must not move'
        drivers['r2'].goal(goals['r2'])
        t2 = drivers['r2'].sim_time()
        assert ros.spin_until(lambda: drivers['r2'].sim_time() >= t2 + 10.0, timeout=90.0)
        assert np.linalg.norm(drivers['r2'].ee_position() - goals['r2']) < 0.01
    finally:
        ros.close()


class NamespacedDriver(Driver):
    """The test driver inside a namespace (relative topic names resolve there)."""

    def __init__(self, context, ns):
        Node.__init__(self, 'test_driver', namespace=ns, context=context)
        self.pub_goal = self.create_publisher(PoseStamped, 'goal_pose', 10)
        self.arm, self.refs, self.feasible, self.diag, self.ee = [], [], [], [], []
        self.create_subscription(PoseStamped, 'ee_pose', self.ee.append, 10)


def test_a_renamed_node_keeps_its_defaults():
    ros = RosHarness()
    try:
        node = ros.add(RedundancyResolverNode(context=ros.context, cli_args=['--ros-args', '-r', '__node:=left_arm']))
        assert node.get_name() == 'left_arm' and node.p.lambda_p == 1.7
    finally:
        ros.close()


@pytest.mark.parametrize('scale', [1.0, 1e200, 1e-3])
def test_a_measured_quaternion_of_any_scale_is_the_rotation_it_names(scale):
    """/ee_pose with the quaternion of a rotation by π/2 about y, times 1e200 (its squared norm
    overflows) or 1e-3: the same rotation, never the identity that an overflowed norm gave."""
    ros = RosHarness()
    try:
        node = ros.add(
            RedundancyResolverNode(context=ros.context, parameter_overrides=overrides(ee_feedback='ground_truth'))
        )
        pub = ros.add(Node('ee_source', context=ros.context)).create_publisher(PoseStamped, '/ee_pose', 10)
        msg = PoseStamped()
        msg.header.frame_id = 'world'
        msg.pose.position.x = 0.5
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = 0.0, scale * math.sqrt(0.5), 0.0, scale * math.sqrt(0.5)
        assert ros.spin_until(lambda: (pub.publish(msg), node.latest.ee is not None)[1], timeout=10.0)
        np.testing.assert_allclose(node.latest.ee[1], [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]], atol=1e-12)
    finally:
        ros.close()


def test_a_new_goal_is_judged_on_its_own_cycles_only(tmp_path):
    """A goal that replaces a reached one (robot A, task sharing, which holds each arm command
    for the base's feasible twist): the command computed for the old goal, still waiting when
    the new one comes, must not count for it. Counted, the old goal's near-zero error became the
    new goal's best error, and a stall was reported 3 s later while the error fell fast."""
    path = tmp_path / 'two_goals.yaml'
    path.write_text("""\
scenario:
  name: two_goals
  robot: steerable
  frame: world
  duration: 24.0
  goals:
    - {t: 0.0, pose: [2.0, 1.0, 1.0, 0.0, 0.0, 0.0]}
    - {t: 12.0, pose: [3.0, -2.0, 0.8, 0.0, 0.0, 0.0]}
""")
    log = run_with_nodes(load_scenario(path), {'name': 'ts', 'method': 'task_sharing', 'feedback': 'odometry'})
    assert log.first_stall_s is None
    assert log.final_status['goal_reached'] is True


def test_markers_show_the_goal_the_trail_and_the_footprint(system):
    """~/markers: the goal's arrow at the goal, the trail ending at the end effector, the base's
    footprint (closed, on the floor, around the base); every number finite."""
    from visualization_msgs.msg import Marker, MarkerArray

    ros, driver, sim = system
    arrays = []
    driver.create_subscription(MarkerArray, '/redundancy_resolver/markers', arrays.append, 10)
    run_until(ros, driver, 0.5)
    goal = np.array([1.5, 0.5, 1.0])
    driver.goal(goal, (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))
    run_until(ros, driver, 4.0)
    assert ros.spin_until(lambda: len(arrays) >= 3)
    by_ns = {m.ns: m for m in arrays[-1].markers}
    assert set(by_ns) == {'goal', 'reference', 'ee_trail', 'base_footprint'}
    assert all(m.header.frame_id == 'world' for m in by_ns.values())
    arrow = by_ns['goal']
    assert arrow.action == Marker.ADD and arrow.type == Marker.ARROW
    np.testing.assert_allclose([arrow.pose.position.x, arrow.pose.position.y, arrow.pose.position.z], goal)
    q = arrow.pose.orientation
    assert abs(abs(q.z) - math.sqrt(0.5)) < 1e-9 and abs(abs(q.w) - math.sqrt(0.5)) < 1e-9
    assert by_ns['reference'].action == Marker.DELETE, 'no /ee_reference tracked'
    trail = np.array([[p.x, p.y, p.z] for p in by_ns['ee_trail'].points])
    assert len(trail) > 10 and np.linalg.norm(trail[-1] - driver.ee_position()) < 0.1
    assert np.linalg.norm(trail[-1] - trail[0]) > 0.2, 'the trail follows the end effector'
    outline = np.array([[p.x, p.y, p.z] for p in by_ns['base_footprint'].points])
    assert len(outline) == 5 and np.allclose(outline[0], outline[-1]) and np.allclose(outline[:, 2], 0.0)
    base = sim.world.base_pose()
    centre = outline[:4, :2].mean(axis=0)
    assert np.linalg.norm(centre - base[:2]) < 0.3
    for array in arrays:
        for m in array.markers:
            values = [
                m.pose.position.x,
                m.pose.position.y,
                m.pose.position.z,
                m.pose.orientation.w,
                *(v for p in m.points for v in (p.x, p.y, p.z)),
            ]
            assert np.all(np.isfinite(values)), m.ns


class HandDriver(Driver):
    """A :class:`Driver` that is also the robot: joint states and odometry by hand, at rest at the
    start state, and (``answer_feasible``) each cycle's feasible twist: its reference, as if
    followed exactly."""

    def __init__(self, context, robot, answer_feasible=False):
        super().__init__(context)
        self.robot = robot
        self.pub_state = self.create_publisher(JointState, '/joint_states', 10)
        self.pub_odom = self.create_publisher(Odometry, '/odom', 10)
        self.pub_feasible = self.create_publisher(TwistStamped, '/base/feasible_twist', 10)
        if answer_feasible:  # looked up per message: a test may hold the answer up
            self.create_subscription(TwistStamped, '/base/reference', lambda msg: self.answer(msg), 10)

    def answer(self, msg):
        self.pub_feasible.publish(msg)

    def state(self):
        """Joint states and odometry stamped now (a robot's driver stamps its states with its clock)."""
        stamp = self.get_clock().now().to_msg()
        odom = Odometry()
        odom.header.stamp = stamp
        odom.header.frame_id = 'world'
        set_planar_pose(odom.pose.pose, self.robot.start.base_pose)
        self.pub_odom.publish(odom)
        msg = JointState()
        msg.header.stamp = stamp
        msg.name = list(self.robot.arm.joints)
        msg.position = [float(v) for v in self.robot.start.arm]
        msg.velocity = [0.0] * len(msg.name)
        self.pub_state.publish(msg)


@pytest.mark.parametrize('where', ['in the cycle', 'waiting for the feasible twist'])
def test_a_cycle_held_up_past_max_state_wait_publishes_no_answer(where):
    """A resolver held up between a joint state and its answer (stopped, or starved, or waiting
    for a late feasible twist) answers a state the world has left: that answer is dropped
    (logged), not applied as current, and the next state is answered as usual."""
    robot = load_robot('steerable')
    ros = RosHarness()
    try:
        in_cycle = where == 'in the cycle'
        driver = ros.add(HandDriver(ros.context, robot, answer_feasible=not in_cycle))
        node = ros.add(
            RedundancyResolverNode(
                context=ros.context,
                parameter_overrides=overrides(
                    method='pinv' if in_cycle else 'task_sharing',
                    state_timeout=10.0,
                    max_state_wait=0.1,
                    compensation_timeout=1.0,
                ),
            )
        )
        ros.spin_for(0.3)
        driver.goal((1.2, 0.3, 0.9))
        ros.spin_for(0.1)
        for k in range(5):
            driver.state()
            assert ros.spin_until(lambda k=k: len(driver.arm) > k, timeout=5.0)
        ros.spin_for(0.1)
        arm, refs = len(driver.arm), len(driver.refs)
        if in_cycle:
            hold = held_up(node.resolver, 'step', 0.3)
        else:
            hold = held_up(driver, 'answer', 0.3)  # the base controller's answer comes late
            refs += 1  # the base reference goes out at once; the arm command waits for its answer
        with hold:
            driver.state()
            assert ros.spin_until(lambda: any('answer dropped' in m for _, _, m in driver.logs), timeout=5.0)
        ros.spin_for(0.1)
        assert (len(driver.arm), len(driver.refs)) == (arm, refs), 'nothing more published for that state'
        driver.state()
        assert ros.spin_until(lambda: len(driver.arm) > arm, timeout=5.0), 'the next state is answered'
        assert np.all(np.isfinite(driver.arm[-1])) and np.any(driver.arm[-1])
    finally:
        ros.close()


WALL_YAML = """obstacles:
  - {name: wall, shape: box, size: [0.1, 1.0, 2.0], pose: [0.71, 0.0, 1.0]}
"""
WALL_GOAL_YAML = """scenario:
  name: behind_the_wall
  robot: mecanum
  frame: world
  duration: 2.0
  obstacles: wall.yaml
  goals:
    - {t: 0.0, pose: [1.3, 0.0, 0.5, 0.0, pi/2, 0.0]}
"""


def test_diagnostics_and_the_direct_run_name_the_limit_that_binds(tmp_path):
    """A wall 1 cm ahead of the arm of robot B (within the safety distance d_s = 2 cm) and a
    goal beyond it: the safety stage's obstacle rows take the arm away from the wall instead of
    towards the goal, and both engines count the cycles in which they did, under the same keys;
    no other limit shapes the command there."""
    (tmp_path / 'wall.yaml').write_text(WALL_YAML)
    path = tmp_path / 'behind_the_wall.yaml'
    path.write_text(WALL_GOAL_YAML)
    scenario = load_scenario(str(path))
    goal = scenario.goals[0].pose[:3]
    counted = ('relaxed_cycles', 'base_held_cycles')

    world = SimWorld('mecanum', obstacles=scenario.obstacles)
    try:
        direct = run_scenario(world, make_resolver('amp', 'mecanum'), scenario)
    finally:
        world.close()
    counts = direct.safety_counts
    assert counts['binding_obstacle'] > 0, counts
    assert all(v == 0 for k, v in counts.items() if k != 'binding_obstacle'), counts
    # and the run's summary (metrics.json) carries them
    summary = summarize_runs(scenario, [{'name': 'amp', 'method': 'amp'}], {'amp': direct}, engine='direct')
    assert summary['runs']['amp']['safety_counts'] == counts

    robot = load_robot('mecanum')
    ros = RosHarness()
    try:
        driver = ros.add(HandDriver(ros.context, robot))
        node = ros.add(
            RedundancyResolverNode(
                context=ros.context,
                parameter_overrides=overrides(
                    robot='mecanum',
                    method='amp',
                    obstacles=str(tmp_path / 'wall.yaml'),
                    diagnostics_period=1e-9,
                    state_timeout=10.0,
                ),
            )
        )
        ros.spin_for(0.3)
        driver.goal(goal, (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)))  # the scenario's: pitch π/2
        ros.spin_for(0.1)
        for k in range(10):
            driver.state()
            assert ros.spin_until(lambda k=k: len(driver.arm) > k, timeout=5.0)
        ros.spin_for(0.1)
        cycles = node.counters['cycles']
        assert cycles >= 5  # the first states may come before their odometry: no cycle
        values = driver.diag[-1][2]
        shown = {k: int(v) for k, v in values.items() if k.startswith('binding_') or k in counted}
        assert set(shown) == set(counts), 'the same keys on /diagnostics as in the direct run'
        assert shown['binding_obstacle'] == cycles, shown
        assert all(v == 0 for k, v in shown.items() if k != 'binding_obstacle'), shown
    finally:
        ros.close()
