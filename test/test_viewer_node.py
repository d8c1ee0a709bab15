"""``wmm_viewer``'s wiring, in-process with the simulator: the scene follows the topics, the goal
handle and "Hold here" publish ``/goal_pose``, names are relative, parameters are checked."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.parameter import Parameter

from rcl_interfaces.msg import Log

from ros_helpers import ROSOUT_QOS, overrides
from sim_bridge.node import SimNode
from wmm_control.errors import ConfigError
from wmm_control.nodes.viewer import ViewerNode
from wmm_control.paths import config_path
from wmm_control.viewer.browser import local_only


def viewer(ros, **params):
    return ros.add(
        ViewerNode(context=ros.context, parameter_overrides=overrides(host='127.0.0.1', port=18080, **params))
    )


def goals_on(ros, topic='/goal_pose'):
    got = []
    listener = ros.add(ros_node(ros, 'goal_listener'))
    listener.create_subscription(PoseStamped, topic, got.append, 10)
    return got


def ros_node(ros, name, namespace=None):
    import rclpy

    return rclpy.create_node(name, context=ros.context, namespace=namespace)


def test_the_scene_follows_the_simulator_and_hold_here_publishes_the_end_effectors_pose(ros):
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(start_base_pose=[0.5, -0.3, 0.4])))
    view = viewer(ros)
    got = goals_on(ros)
    ee = []
    listener = ros.add(ros_node(ros, 'ee_listener'))
    listener.create_subscription(PoseStamped, '/ee_pose', ee.append, 10)
    assert ros.spin_until(lambda: view.base_source() == 'ground_truth' and view._ee is not None and len(ee) > 2)
    ros.spin_for(0.3)
    # The drawn end effector is the simulator's (ground truth), and every shape handle sits where
    # the scene puts it.
    position, _ = view._ee
    truth = ee[-1].pose.position
    assert position == pytest.approx([truth.x, truth.y, truth.z], abs=1e-6)
    poses = view.scene.poses(*view.base.pose(view._now()))
    for handle, expected in zip(view.browser.shape_handles, poses.positions):
        assert np.asarray(handle.position) == pytest.approx(expected, abs=1e-9)
    # Until a goal is known the handle waits at the end effector.
    assert np.asarray(view.browser.goal_handle.position) == pytest.approx(position, abs=1e-9)
    view.browser._hold.set()
    assert ros.spin_until(lambda: len(got) == 1, timeout=5)
    goal = got[0]
    assert goal.header.frame_id == 'world'
    assert [goal.pose.position.x, goal.pose.position.y, goal.pose.position.z] == pytest.approx(position, abs=1e-9)
    assert sim.world.robot.name == 'steerable'


def test_a_drag_publishes_once_at_release_and_never_a_non_finite_pose(ros):
    view = viewer(ros, drag_publish_period=5.0)
    got = goals_on(ros)
    ros.spin_for(0.3)

    def event(phase, position, wxyz):
        view._on_handle(SimpleNamespace(phase=phase, target=SimpleNamespace(position=position, wxyz=wxyz)))

    event('start', (0, 0, 0), (1, 0, 0, 0))
    for k in range(10):
        event('update', (1.0 + 0.01 * k, 0.5, 0.8), (1, 0, 0, 0))
        ros.spin_for(0.05)
    assert got == []  # shorter than drag_publish_period: nothing yet
    event('update', (math.nan, 0.5, 0.8), (1, 0, 0, 0))  # a broken update is dropped
    event('end', (1.2, 0.5, 0.8), (0, 0, 0, 2))
    assert ros.spin_until(lambda: got, timeout=5)
    ros.spin_for(0.5)
    assert len(got) == 1
    p, o = got[0].pose.position, got[0].pose.orientation
    assert (p.x, p.y, p.z) == pytest.approx((1.2, 0.5, 0.8)) and (o.x, o.y, o.z, o.w) == pytest.approx((0, 0, 1, 0))
    # Its own goal comes back on /goal_pose and is drawn; the handle stays there.
    assert ros.spin_until(lambda: view.browser.goal_frame.visible, timeout=5)
    assert np.asarray(view.browser.goal_frame.position) == pytest.approx((1.2, 0.5, 0.8))
    assert not view.publish_goal((0, math.inf, 0), (1, 0, 0, 0)) and not view.publish_goal((0, 0, 0), (0, 0, 0, 0))
    ros.spin_for(0.3)
    assert len(got) == 1


def test_topic_names_are_relative_to_the_namespace(ros):
    view = ros.add(
        ViewerNode(
            context=ros.context,
            namespace='/r1',
            parameter_overrides=overrides(host='127.0.0.1', port=18090, robot='mecanum'),
        )
    )
    ros.spin_for(0.2)
    topics = {name for name, _ in view.get_topic_names_and_types()}
    for name in (
        '/r1/joint_states',
        '/r1/odom',
        '/r1/ground_truth/odom',
        '/r1/goal_pose',
        '/r1/ee_reference',
        '/r1/base/reference',
        '/diagnostics',
    ):
        assert name in topics, name
    assert view.pub_goal.topic_name == '/r1/goal_pose'


def test_a_robot_yaml_path_and_use_sim_time_without_a_clock(ros):
    ros.add(SimNode(context=ros.context, parameter_overrides=overrides(robot='mecanum', publish_clock=False)))
    view = viewer(ros, robot=str(config_path('robots', 'mecanum.yaml')), use_sim_time=True)
    assert view.robot.name == 'mecanum'
    # The ROS clock stands at 0 (no /clock), the steady timers draw all the same.
    assert ros.spin_until(lambda: view._ee is not None and view.base_source() != 'none')
    assert view.get_clock().now().nanoseconds == 0


@pytest.mark.parametrize(
    'params, message',
    [
        (dict(robot='C'), "unknown robot 'C'"),
        (dict(robot='/nowhere/robot.yaml'), 'not found'),
        (dict(host=' '), 'host'),
        (dict(allow_remote_commands='yes'), 'allow_remote_commands'),
    ],
)
def test_invalid_parameters_fail_with_a_clear_error(ros, params, message):
    with pytest.raises(ConfigError, match=message):
        ViewerNode(context=ros.context, parameter_overrides=overrides(**{'port': 18100, **params}))


def test_two_robots_in_namespaces_the_viewer_of_one_draws_that_robot_only(ros):
    """Robot A in /r1 and robot B in /r2 in one domain, a viewer in /r1: it draws robot A (its
    URDF), and its base follows /r1's simulator, not /r2's."""
    r1 = ros.add(
        SimNode(context=ros.context, namespace='/r1', parameter_overrides=overrides(start_base_pose=[1.0, 2.0, 0.3]))
    )
    ros.add(
        SimNode(
            context=ros.context,
            namespace='/r2',
            parameter_overrides=overrides(robot='mecanum', start_base_pose=[-3.0, -1.0, -0.5]),
        )
    )
    view = ros.add(
        ViewerNode(context=ros.context, namespace='/r1', parameter_overrides=overrides(host='127.0.0.1', port=18081))
    )
    assert ros.spin_until(lambda: view.base_source() == 'ground_truth' and view._ee is not None)
    ros.spin_for(0.3)
    assert view.robot.name == 'steerable'
    x, y, theta = r1.world.base_pose()
    position, wxyz = view.base.pose(view._now())
    assert np.asarray(position)[:2] == pytest.approx([x, y], abs=1e-6)
    assert 2.0 * math.atan2(wxyz[3], wxyz[0]) == pytest.approx(theta, abs=1e-6)
    pos, _ = r1.world.ee_pose()
    assert view._ee[0] == pytest.approx(pos, abs=1e-6)


def test_obstacles_of_the_file_and_the_topic_are_drawn_where_they_are_and_bad_messages_change_nothing(ros):
    from visualization_msgs.msg import Marker, MarkerArray

    view = viewer(ros, obstacles='table_pillar', max_obstacles=3)
    warnings = []
    ros.add(ros_node(ros, 'log_listener')).create_subscription(
        Log, '/rosout', lambda m: warnings.append(m.msg) if m.level >= Log.WARN else None, ROSOUT_QOS
    )
    assert [h.name for h in view.browser.obstacle_handles] == ['/obstacles/table', '/obstacles/pillar']
    assert np.asarray(view.browser.obstacle_handles[0].position) == pytest.approx([1.5, -0.2, -0.1])
    publisher = ros.add(ros_node(ros, 'obstacle_publisher')).create_publisher(MarkerArray, '/obstacles', 10)
    marker = Marker()
    marker.header.frame_id = 'world'
    marker.ns, marker.id, marker.type, marker.action = 'live', 3, Marker.SPHERE, Marker.ADD
    marker.scale.x = marker.scale.y = marker.scale.z = 0.3
    marker.pose.position.x, marker.pose.orientation.w = 2.0, 1.0
    assert ros.spin_until(lambda: publisher.get_subscription_count() > 0, timeout=5)
    publisher.publish(MarkerArray(markers=[marker]))
    assert ros.spin_until(lambda: len(view.browser.obstacle_handles) == 3, timeout=5)
    assert np.asarray(view.browser.obstacle_handles[2].position) == pytest.approx([2.0, 0.0, 0.0])
    # an empty message and one of more than max_obstacles markers: refused, with warnings; nothing redrawn
    drawn, kept = list(view.browser.obstacle_handles), view.obstacles.obstacles
    publisher.publish(MarkerArray())
    moved = []
    for i in range(4):
        m = Marker()
        m.header.frame_id, m.ns, m.id, m.type, m.action = 'world', 'live', 10 + i, Marker.SPHERE, Marker.ADD
        m.scale.x = m.scale.y = m.scale.z = 0.3
        m.pose.position.x, m.pose.orientation.w = 5.0 + i, 1.0
        moved.append(m)
    publisher.publish(MarkerArray(markers=moved))
    wanted = ('empty /obstacles message', '4 markers, more than max_obstacles 3')
    assert ros.spin_until(lambda: all(any(w in line for line in warnings) for w in wanted), timeout=5), warnings
    assert view.browser.obstacle_handles == drawn and view.obstacles.obstacles == kept
    assert np.asarray(view.browser.obstacle_handles[2].position) == pytest.approx([2.0, 0.0, 0.0])
    # the limit is live: raised at run time, the same message is taken
    assert view.set_parameters([Parameter('max_obstacles', value=4)])[0].successful
    assert not view.set_parameters([Parameter('max_obstacles', value=0)])[0].successful
    publisher.publish(MarkerArray(markers=moved))
    assert ros.spin_until(lambda: len(view.browser.obstacle_handles) == 7, timeout=5)


@pytest.mark.parametrize(
    'host, local',
    [
        ('127.0.0.1', True),
        ('127.3.4.5', True),
        ('localhost', True),
        ('::1', True),
        ('0.0.0.0', False),
        ('::', False),
        ('192.0.2.7', False),
        ('no-such-host.invalid', False),
    ],
)
def test_a_host_is_local_only_when_every_address_it_names_is_a_loopback_one(host, local):
    assert local_only(host) is local


def test_the_viewer_listens_on_this_machine_alone_by_default_and_its_page_commands_the_robot(ros):
    view = ros.add(ViewerNode(context=ros.context, parameter_overrides=overrides(port=18083)))
    assert view.p.host == '127.0.0.1' and view.p.allow_remote_commands is False
    described = view.describe_parameter('allow_remote_commands')
    assert described.read_only and 'anyone who can reach the port' in described.description
    assert view.commands and view.browser.goal_handle is not None and view.browser.hold_button is not None


@pytest.mark.parametrize('allow', [False, True])
def test_a_page_served_beyond_this_machine_commands_the_robot_only_when_allowed(ros, allow):
    """On 0.0.0.0 (every interface) the page has no goal handle nor "Hold here", and what its
    handlers get publishes nothing, unless ``allow_remote_commands``; the log says which at start."""
    logs = []
    probe = ros.add(ros_node(ros, 'log_probe'))
    probe.create_subscription(Log, '/rosout', lambda m: logs.append((m.name, m.level, m.msg)), ROSOUT_QOS)
    view = ros.add(
        ViewerNode(
            context=ros.context,
            parameter_overrides=overrides(
                host='0.0.0.0', port=18084, allow_remote_commands=allow, drag_publish_period=0.05
            ),
        )
    )
    got = goals_on(ros)
    assert ros.spin_until(lambda: any(name == 'wmm_viewer' and 'viewer of robot' in m for name, _, m in logs))
    started = next((lvl, m) for name, lvl, m in logs if name == 'wmm_viewer' and 'viewer of robot' in m)
    assert view.commands is allow
    assert (view.browser.goal_handle is not None, view.browser.hold_button is not None) == (allow, allow)
    if allow:
        assert started[0] == Log.WARN and 'anyone who can reach port 18084' in started[1]
    else:
        assert started[0] == Log.INFO and 'commands nothing' in started[1]
        assert 'allow_remote_commands:=true' in started[1] and 'served on 0.0.0.0' in view.browser.goal_text.content
    ros.spin_for(0.2)
    # what the page's handlers get: a drag released at a pose, and a press of "Hold here"
    event = SimpleNamespace(phase='end', target=SimpleNamespace(position=(1.2, 0.5, 0.8), wxyz=(1, 0, 0, 0)))
    view._on_handle(event)
    view.browser._hold.set()
    ros.spin_for(0.6)
    assert len(got) == (2 if allow else 0)
    assert view.counters['goals_sent'] == len(got)


def test_the_planners_path_is_drawn_on_the_floor_and_an_empty_one_hides_it(ros):
    from nav_msgs.msg import Path

    from wmm_control.nodes.conversions import set_planar_pose
    from wmm_control.nodes.qos import LATCHED_QOS

    view = viewer(ros, obstacles='table_pillar')
    planned = view.browser.planned_path
    assert not planned.visible
    publisher = ros.add(ros_node(ros, 'planner_stand_in')).create_publisher(Path, '/goal_planner/path', LATCHED_QOS)
    path = Path()
    path.header.frame_id = 'world'
    for pose in ((0.0, 0.0, 0.0), (1.0, -1.0, 0.5), (2.4, -0.8, 1.5)):
        stamped = PoseStamped()
        set_planar_pose(stamped.pose, pose)
        path.poses.append(stamped)
    publisher.publish(path)
    assert ros.spin_until(lambda: planned.visible, timeout=5)
    segments = np.asarray(planned.points)
    assert segments.shape == (2, 2, 3)
    assert segments[0, 0, :2] == pytest.approx([0.0, 0.0]) and segments[1, 1, :2] == pytest.approx([2.4, -0.8])
    assert np.all(segments[..., 2] > view.robot.ground_z)  # on the floor, above the grid
    path.poses = []
    publisher.publish(path)
    assert ros.spin_until(lambda: not planned.visible, timeout=5)
