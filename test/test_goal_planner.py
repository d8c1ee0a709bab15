"""The ``goal_planner`` node between the user's /goal_pose and the resolver, in-process with the
simulator, the base controller and the resolver (its goal_pose remapped to goal_planner/goal),
the simulator in lockstep: a goal behind the table is reached by driving round it, a goal within
reach goes to the resolver unchanged, bad input is rejected with the robot held, a goal inside
the table gets "no way", and a box put onto the rest of the path makes it plan again; alone,
the planner refuses bad odometry as the resolver does and plans from none of it."""

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from ros_helpers import ROSOUT_QOS, RosHarness, pose2d, stamp_s
from sim_bridge.node import SimNode
from wmm_control.geometry import matrix_from_quaternion, quaternion_from_matrix, rotation_angle, rotation_z
from wmm_control.kinematics import KinematicModel
from wmm_control.nodes.conversions import planned_base_values, pose_values, set_planar_pose, twist_values
from wmm_control.nodes.goal_planner import GoalPlannerNode
from wmm_control.nodes.qos import LATCHED_QOS
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.robot_config import load_robot

ROBOT = 'steerable'
OBSTACLES = 'table_pillar'
#: behind the table (x 1.25..1.75, y -0.8..0.4, top at z 0.5), which the robot faces at the start
BEHIND_TABLE = np.array([2.4, -0.2, 1.0])
#: [rad] the goal's tool turned from its start orientation about the world z axis: pointing along y
BEHIND_TABLE_YAW = 0.5 * np.pi


def _start_ee():
    robot = load_robot(ROBOT)
    model = KinematicModel(ROBOT)
    model.update(np.asarray(robot.start.base_pose, dtype=float), np.asarray(robot.start.arm, dtype=float))
    return model.ee_placement_world()


def goal_rotation(yaw=0.0):
    """The start orientation of the end effector turned by ``yaw`` about the world z axis."""
    return rotation_z(yaw) @ _start_ee()[1]


def goal_msg(position, quat=None, frame='world', yaw=0.0):
    msg = PoseStamped()
    msg.header.frame_id = frame
    if quat is None:
        quat = quaternion_from_matrix(goal_rotation(yaw))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in position)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in quat)
    return msg


class Probe:
    """The user's side: publishes goals and obstacles; records what the planner sends, the truth,
    the simulator's contacts and the log."""

    def __init__(self, ros):
        node = self.node = ros.probe('planner_probe')
        self.goal_pub = node.create_publisher(PoseStamped, '/goal_pose', 10)
        self.obstacle_pub = node.create_publisher(MarkerArray, '/obstacles', 10)
        self.forwarded, self.references, self.paths, self.truth, self.ee, self.logs = [], [], [], [], [], []
        self.diagnostics = []
        node.create_subscription(PoseStamped, '/goal_planner/goal', self.forwarded.append, 10)
        node.create_subscription(MultiDOFJointTrajectory, '/ee_reference', self.references.append, 100)
        node.create_subscription(Path, '/goal_planner/path', self.paths.append, LATCHED_QOS)
        node.create_subscription(Odometry, '/ground_truth/odom', self.truth.append, 10)
        node.create_subscription(PoseStamped, '/ee_pose', self.ee.append, 10)
        node.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)
        node.create_subscription(Log, '/rosout', self.logs.append, ROSOUT_QOS)

    def lines(self, name='goal_planner'):
        return [m.msg for m in self.logs if m.name == name]

    def ee_position(self):
        p = self.ee[-1].pose.position
        return np.array([p.x, p.y, p.z])

    def ee_rotation(self):
        o = self.ee[-1].pose.orientation
        return matrix_from_quaternion((o.x, o.y, o.z, o.w))


@pytest.fixture
def system():
    """The four nodes as ``robot.launch.py planner:=true obstacles:=table_pillar`` starts them (the
    resolver's goal_pose remapped to goal_planner/goal), the simulator in lockstep; the planner has
    the odometry and joint states when it is handed over."""
    ros = RosHarness()
    probe = Probe(ros)
    common = [Parameter('robot', value=ROBOT), Parameter('obstacles', value=OBSTACLES)]
    planner = ros.add(GoalPlannerNode(context=ros.context, parameter_overrides=common))
    resolver = ros.add(
        RedundancyResolverNode(
            context=ros.context,
            parameter_overrides=common,
            cli_args=['--ros-args', '-r', 'goal_pose:=goal_planner/goal'],
        )
    )
    ros.add(SwmrControllerNode(context=ros.context, parameter_overrides=common[:1]))
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=[*common, Parameter('timing', value='lockstep')]))
    assert ros.spin_until(
        lambda: probe.truth and probe.ee and planner._base is not None and planner._q_arm is not None, timeout=30.0
    )
    yield ros, probe, planner, resolver, sim
    ros.close()


def state(planner):
    return planner.pursuit.state.value


def finite_output(probe):
    """Every goal and trajectory point the planner sent is finite."""
    values = [pose_values(m.pose) for m in probe.forwarded]
    values += [pose_values(m.points[0].transforms[0]) for m in probe.references]
    return all(np.all(np.isfinite(v)) for v in values)


def reach(ros, probe, planner, resolver, position, rotation, timeout=400.0):
    """Spin until the simulator's end effector (ground truth) is within the resolver's tolerance of
    the goal, the goal handed to the resolver (directly or after the plan); True when it is."""
    tolerance = resolver.p.goal_tolerance

    def there():
        return (
            state(planner) in ('approach', 'direct')
            and resolver.target is not None
            and not resolver.targets.tracking
            and np.linalg.norm(probe.ee_position() - position) < tolerance[0]
            and rotation_angle(rotation, probe.ee_rotation()) < tolerance[1]
        )

    return ros.spin_until(there, timeout=timeout)


def test_a_goal_behind_the_table_is_reached_round_it_without_contact(system):
    ros, probe, planner, resolver, sim = system
    start = pose2d(probe.truth[-1])
    sent = goal_msg(BEHIND_TABLE, yaw=BEHIND_TABLE_YAW)
    probe.goal_pub.publish(sent)
    assert ros.spin_until(lambda: state(planner) == 'following', timeout=60.0), probe.lines()
    # the planned path, latched on ~/path in the world frame, goes from the base round the table
    assert ros.spin_until(lambda: probe.paths and len(probe.paths[-1].poses) > 10, timeout=5.0)
    path = np.array([(s.pose.position.x, s.pose.position.y) for s in probe.paths[-1].poses])
    assert probe.paths[-1].header.frame_id == 'world'
    assert np.linalg.norm(path[0] - start[:2]) < 0.05 and path[-1, 0] > 1.75  # beyond the table's far side
    reached = reach(ros, probe, planner, resolver, BEHIND_TABLE, goal_rotation(BEHIND_TABLE_YAW))
    assert reached, (
        planner.pursuit.status(),
        np.linalg.norm(probe.ee_position() - BEHIND_TABLE),
        rotation_angle(goal_rotation(BEHIND_TABLE_YAW), probe.ee_rotation()),
        pose2d(probe.truth[-1]),
        planner._base,
    )
    # the way there was the plan's points, then the user's goal itself as the last point, at rest,
    # with the stance (the plan's last base pose) and the stance's arm posture as its base, which
    # the resolver holds and judges as a goal: the base is held at the stance in the final
    # approach, and the arrival is reported
    assert len(probe.references) > 50 and finite_output(probe)
    # each point carries the plan's arm posture (the travel posture, then the arm's motion to the
    # stance's), joint by joint, which the resolver takes
    arm = list(load_robot(ROBOT).arm.joints)
    travel = [planned_base_values(m, arm) for m in probe.references[:-1]]
    assert all(list(m.joint_names) == ['end_effector', 'base', *arm] for m in probe.references[:-1])
    assert all(len(t) == 4 and np.all(np.isfinite(t[3])) for t in travel)
    last = probe.references[-1]
    assert last.header.frame_id == 'world' and list(last.joint_names) == ['end_effector', 'base', *arm]
    posture = planned_base_values(last, arm)[3]
    assert np.allclose(posture, planner.pursuit.follower.handoff.stance_arm, atol=1e-9)
    values = pose_values(last.points[0].transforms[0])
    assert values[:3] == pytest.approx(BEHIND_TABLE, abs=1e-9)
    assert rotation_angle(matrix_from_quaternion(values[3:]), goal_rotation(BEHIND_TABLE_YAW)) < 1e-6
    assert twist_values(last.points[0].velocities[0]) == pytest.approx(np.zeros(6))
    stance = np.array([(s.pose.position.x, s.pose.position.y) for s in probe.paths[-1].poses])[-1]
    assert resolver.target.base is not None and resolver.target.base.pose[:2] == pytest.approx(stance, abs=1e-6)
    assert resolver.target.base.rates == pytest.approx(np.zeros(3))
    assert resolver.target.base.stance and np.allclose(resolver.target.base.arm, posture)
    assert ros.spin_until(lambda: any('goal reached' in line for line in probe.lines('redundancy_resolver')), 5.0)
    # the base drove round the table, never into it (the simulator's own check)
    assert pose2d(probe.truth[-1])[0] > 1.75
    assert sim.contact.values['contact_periods'] == 0, sim.contact.values
    assert any('planned in' in line for line in probe.lines())
    # /diagnostics tells the final approach (published every diagnostics_period: the approach,
    # after the arm's motion to the stance's posture, may end before the next message)
    assert ros.spin_until(
        lambda: any(
            v.value == 'approach'
            for d in probe.diagnostics
            for s in d.status
            if s.name == '/goal_planner'
            for v in s.values
        ),
        5.0,
    )


def test_a_goal_within_reach_goes_to_the_resolver_unchanged(system):
    ros, probe, planner, resolver, sim = system
    position = _start_ee()[0] + [0.1, 0.0, -0.05]
    sent = goal_msg(position)
    sent.header.stamp.sec = 12  # a stamp of the user's, kept
    probe.goal_pub.publish(sent)
    assert reach(ros, probe, planner, resolver, position, goal_rotation(), timeout=120.0), probe.lines()
    assert state(planner) == 'direct'
    assert len(probe.forwarded) == 1 and probe.forwarded[0] == sent
    assert probe.references == [] and probe.paths[-1].poses == []


def test_a_goal_waits_for_the_resolver_to_subscribe_and_is_then_sent_once():
    """A resolver that starts late (or is found late on a loaded machine) still gets the goal:
    the planner holds it, says why, and sends it as soon as someone subscribes."""
    ros = RosHarness()
    try:
        common = [Parameter('robot', value=ROBOT), Parameter('obstacles', value=OBSTACLES)]
        planner = ros.add(GoalPlannerNode(context=ros.context, parameter_overrides=common))
        ros.add(SimNode(context=ros.context, parameter_overrides=common))  # in real time: no commands needed
        user = ros.probe('late_user')
        logs, forwarded = [], []
        user.create_subscription(Log, '/rosout', logs.append, ROSOUT_QOS)
        goals = user.create_publisher(PoseStamped, '/goal_pose', 10)
        assert ros.spin_until(lambda: planner._base is not None and planner._q_arm is not None, timeout=30.0)
        sent = goal_msg(_start_ee()[0] + [0.1, 0.0, -0.05])
        goals.publish(sent)
        assert ros.spin_until(
            lambda: any('nobody subscribes to /goal_planner/goal' in m.msg for m in logs), timeout=20.0
        ), [m.msg for m in logs if m.name == 'goal_planner']
        assert state(planner) == 'direct'
        user.create_subscription(PoseStamped, '/goal_planner/goal', forwarded.append, 10)
        assert ros.spin_until(lambda: forwarded, timeout=20.0)
        ros.spin_for(0.5)
        assert forwarded == [sent]
    finally:
        ros.close()


def test_a_goal_inside_the_table_has_no_way_and_the_robot_is_held(system):
    ros, probe, planner, resolver, sim = system
    probe.goal_pub.publish(goal_msg([1.5, -0.2, 0.3]))
    assert ros.spin_until(lambda: state(planner) == 'no_way', timeout=60.0), probe.lines()
    assert "the obstacle 'table'" in planner.pursuit.reason
    assert ros.spin_until(lambda: any('no way to the goal' in line for line in probe.lines()), timeout=5.0)
    ros.spin_for(1.0)
    assert probe.forwarded == [] and probe.references == []  # nothing forwarded: the resolver has no goal
    assert resolver.target is None

    def levels():
        return [s.level for d in probe.diagnostics for s in d.status if s.name == '/goal_planner']

    # the next diagnostics after the decision say so (every diagnostics_period of the simulation's
    # clock, which a loaded machine runs slower than the wall's)
    assert ros.spin_until(lambda: levels() and levels()[-1] == DiagnosticStatus.WARN, timeout=20.0), levels()


def _box(name_id, x, y, size, frame='world'):
    marker = Marker()
    marker.header.frame_id = frame
    marker.ns, marker.id, marker.type, marker.action = 'test', name_id, Marker.CUBE, Marker.ADD
    marker.scale.x, marker.scale.y, marker.scale.z = size
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = x, y, 0.3
    marker.pose.orientation.w = 1.0
    return marker


def test_bad_goals_and_obstacles_are_rejected_with_a_reason_and_the_robot_held(system):
    ros, probe, planner, resolver, sim = system
    near = _start_ee()[0] + [0.1, 0.0, 0.0]
    bad_goals = {
        'non-finite': goal_msg([np.nan, 0.0, 1.0]),
        "frame 'map'": goal_msg(near, frame='map'),
        'beyond max_goal_distance': goal_msg([80.0, 0.0, 1.0]),
        'below the floor': goal_msg([1.0, 0.0, -2.0]),
        'zero quaternion': goal_msg(near, quat=(0.0, 0.0, 0.0, 0.0)),
    }
    for msg in bad_goals.values():  # a second apart: a reason of the same kind is logged once a second
        probe.goal_pub.publish(msg)
        assert ros.spin_until(lambda: state(planner) == 'rejected', timeout=5.0)
        ros.spin_for(1.05)
    assert ros.spin_until(lambda: all(any(k in line for line in probe.lines()) for k in bad_goals), timeout=5.0), (
        probe.lines()
    )
    assert probe.forwarded == [] and probe.references == [] and planner.pursuit.counters.goals_rejected == 5
    # obstacles: NaN and negative sizes, another frame, an empty message, a huge one
    obstacles = planner.obstacles.obstacles
    for marker in (
        _box(1, 1.0, 1.0, (np.nan, 0.3, 0.3)),
        _box(2, 1.0, 1.0, (-0.3, 0.3, 0.3)),
        _box(3, 1.0, 1.0, (0.3, 0.3, 0.3), frame='map'),
    ):
        probe.obstacle_pub.publish(MarkerArray(markers=[marker]))
        ros.spin_for(1.05)
    probe.obstacle_pub.publish(MarkerArray())
    probe.obstacle_pub.publish(MarkerArray(markers=[_box(i, 5.0 + i, 5.0, (0.1, 0.1, 0.1)) for i in range(1000)]))
    wanted = (
        'marker test/1: scale [nan',
        'marker test/2: scale [-0.3',
        "marker test/3: frame 'map'",
        'empty /obstacles',
        '1000 markers, more than max_obstacles 200',
    )
    assert ros.spin_until(lambda: all(any(k in line for line in probe.lines()) for k in wanted), timeout=10.0), (
        probe.lines()
    )
    assert planner.obstacles.obstacles == obstacles
    # a goal within reach still goes through; a bad one then holds the robot where it is
    probe.goal_pub.publish(goal_msg(near))
    assert ros.spin_until(lambda: state(planner) == 'direct' and len(probe.forwarded) == 1, timeout=30.0)
    before = probe.ee_position()
    assert ros.spin_until(lambda: np.linalg.norm(probe.ee_position() - before) > 0.02, timeout=10.0)  # on its way
    probe.goal_pub.publish(goal_msg([np.inf, 0.0, 1.0]))
    assert ros.spin_until(lambda: len(probe.forwarded) == 2, timeout=10.0)
    assert finite_output(probe)
    hold = pose_values(probe.forwarded[-1].pose)[:3]
    assert np.linalg.norm(hold - probe.ee_position()) < 0.02  # held where the end effector is

    # held on its way to the goal 0.1 m ahead: the base brakes (about 1 cm past the hold), the end
    # effector comes back to the hold, and both come to rest there within 3 s of simulated time
    def spin_simulated(seconds):
        until = stamp_s(probe.truth[-1]) + seconds
        assert ros.spin_until(lambda: stamp_s(probe.truth[-1]) >= until, timeout=10.0 * seconds)

    spin_simulated(3.0)
    base = pose2d(probe.truth[-1])
    spin_simulated(0.5)
    assert np.linalg.norm(hold - probe.ee_position()) < 0.01
    assert pose2d(probe.truth[-1])[:2] == pytest.approx(base[:2], abs=0.002)
    assert np.linalg.norm(probe.ee_position() - near) > 0.03


def test_a_box_put_onto_the_rest_of_the_path_makes_it_plan_again_round_it(system):
    ros, probe, planner, resolver, sim = system
    probe.goal_pub.publish(goal_msg(BEHIND_TABLE, yaw=BEHIND_TABLE_YAW))
    assert ros.spin_until(lambda: state(planner) == 'following' and planner.pursuit.progress > 0.1, timeout=120.0)
    rest = planner.pursuit.follower.remaining_poses()
    x, y = rest[len(rest) * 2 // 3, :2]  # on the path, well ahead of the base
    probe.obstacle_pub.publish(MarkerArray(markers=[_box(7, float(x), float(y), (0.3, 0.3, 0.6))]))
    assert ros.spin_until(lambda: any('planning again' in line for line in probe.lines()), timeout=60.0), probe.lines()
    assert any('from the planned path' in line for line in probe.lines())
    assert ros.spin_until(lambda: state(planner) == 'following' and probe.paths[-1].poses, timeout=60.0), probe.lines()
    path = np.array([(s.pose.position.x, s.pose.position.y) for s in probe.paths[-1].poses])
    assert np.min(np.hypot(path[:, 0] - x, path[:, 1] - y)) > 0.2  # the new path keeps off the box
    reached = reach(ros, probe, planner, resolver, BEHIND_TABLE, goal_rotation(BEHIND_TABLE_YAW))
    assert reached, (planner.pursuit.status(), probe.lines())
    assert sim.contact.values['contact_periods'] == 0, sim.contact.values


def test_bad_odometry_is_rejected_as_the_resolver_rejects_it_and_no_plan_starts_from_it():
    """/odom with NaN, beyond max_goal_distance, with a twist beyond ten times the base limits or
    a zero quaternion is refused with the resolver's reason in the log; a goal then waits for good
    odometry and is planned from that pose, never from a refused one."""
    ros = RosHarness()
    try:
        common = [Parameter('robot', value=ROBOT), Parameter('obstacles', value=OBSTACLES)]
        planner = ros.add(GoalPlannerNode(context=ros.context, parameter_overrides=common))
        user = ros.probe('odom_user')
        logs = []
        user.create_subscription(Log, '/rosout', logs.append, ROSOUT_QOS)
        odom_pub = user.create_publisher(Odometry, '/odom', 10)
        goals = user.create_publisher(PoseStamped, '/goal_pose', 10)

        def lines():
            return [m.msg for m in logs if m.name == 'goal_planner']

        def odometry(x, y, yaw=0.0, quat=None, vx=0.0):
            msg = Odometry()
            msg.header.frame_id = 'world'
            set_planar_pose(msg.pose.pose, (x, y, yaw))
            if quat is not None:
                o = msg.pose.pose.orientation
                o.x, o.y, o.z, o.w = quat
            msg.twist.twist.linear.x = vx
            return msg

        bad = {
            'rejected /odom with non-finite values': odometry(np.nan, 0.0),
            'rejected /odom at (80, 0): beyond max_goal_distance 50.0 m': odometry(80.0, 0.0),
            'rejected /odom with twist [100.0, 0.0, 0.0] beyond 10 times the base velocity limits': odometry(
                0.0, 0.0, vx=100.0
            ),
            'rejected /odom with a zero quaternion': odometry(0.0, 0.0, quat=(0.0, 0.0, 0.0, 0.0)),
        }
        sending = [None]
        user.create_timer(0.02, lambda: sending[0] is not None and odom_pub.publish(sending[0]))
        assert ros.spin_until(lambda: odom_pub.get_subscription_count() > 0, timeout=10.0)
        goals.publish(goal_msg(_start_ee()[0] + [0.1, 0.0, -0.05]))
        for msg in bad.values():
            sending[0] = msg
            ros.spin_for(0.3)
        assert ros.spin_until(lambda: all(any(k in line for line in lines()) for k in bad), timeout=5.0), lines()
        assert planner._base is None and state(planner) == 'planning' and planner.pursuit.counters.plans == 0
        assert any('the plan waits for it' in line for line in lines()), lines()
        # good odometry: the plan starts from its pose
        sending[0] = odometry(0.4, -0.3, 0.5)
        assert ros.spin_until(lambda: planner.pursuit.counters.plans == 1, timeout=10.0), lines()
        assert planner._base == pytest.approx([0.4, -0.3, 0.5])
        assert ros.spin_until(
            lambda: any('planning (new goal) from the base at [0.4, -0.3, 0.5]' in line for line in lines()),
            timeout=5.0,
        ), lines()
    finally:
        ros.close()
