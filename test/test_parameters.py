"""Every node's parameters as a ROS user meets them: ranges and descriptions, `ros2 param dump` and
`--params-file`, changes at run time (they take effect, or are refused with a reason), and one
home for every default."""

import dataclasses
import math
import time

import numpy as np
import pytest
import rclpy
import yaml
from std_msgs.msg import Float64MultiArray
from geometry_msgs.msg import TwistStamped
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from sensor_msgs.msg import JointState

from ros_helpers import RosHarness, overrides
from sim_bridge.node import SimNode
from wmm_control.base import WheelParams, SwmrParams
from wmm_control.nodes import (
    goal_planner,
    goal_sequencer,
    mecanum_controller,
    redundancy_resolver,
    swmr_controller,
    viewer,
)
from wmm_control.nodes.goal_planner import GoalPlannerNode
from wmm_control.nodes.parameters import robot_method, robot_period
from wmm_control.nodes.goal_sequencer import GoalSequencerNode
from wmm_control.nodes.viewer import ViewerNode
from wmm_control.nodes.mecanum_controller import MecanumControllerNode
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.paths import config_path
from wmm_control.resolvers import METHODS
from wmm_control.robot_config import load_robot
from wmm_control.errors import ConfigError
import sim_bridge.node as sim_node

# Each node with a few non-default values (read-only ones included), so that a reload that
# ignored the file would show.
NODES = {
    'wmm_sim': (SimNode, sim_node.PARAMS, dict(diagnostics_period=0.5, seed=7, start_base_pose=[0.1, -0.2, 0.3])),
    'wmm_sim_b': (SimNode, sim_node.PARAMS, dict(robot='mecanum', slip_noise=[0.001, 0.002, 0.003])),
    'swmr_controller': (SwmrControllerNode, swmr_controller.PARAMS, dict(kp=3.0, reference_timeout=0.3)),
    'mecanum_controller': (MecanumControllerNode, mecanum_controller.PARAMS, dict(reference_timeout=0.4)),
    'redundancy_resolver': (
        RedundancyResolverNode,
        redundancy_resolver.PARAMS,
        dict(method='amp', goal_tolerance=[0.02, 0.03], lambda_p=2.5),
    ),
    'goal_sequencer': (GoalSequencerNode, goal_sequencer.PARAMS, dict(republish_period=2.0)),
    'goal_planner': (
        GoalPlannerNode,
        goal_planner.PARAMS,
        dict(obstacles='table_pillar', max_replans=5, travel_margin=0.15, stall_time=4.0),
    ),
    'wmm_viewer': (
        ViewerNode,
        viewer.PARAMS,
        dict(host='127.0.0.1', port=18300, robot='mecanum', drag_publish_period=1.5),
    ),
}


# ---------------------------------------------------------------- the parameter services, as ros2cli calls them


def call(ros, client, request, timeout=10.0):
    assert client.wait_for_service(timeout_sec=timeout), client.srv_name
    future = client.call_async(request)
    assert ros.spin_until(future.done, timeout=timeout), client.srv_name
    return future.result()


def dump(ros, caller, node_name):
    """What ``ros2 param dump <node_name>`` prints, as a dict (ListParameters + GetParameters)."""
    listed = call(
        ros,
        caller.create_client(ListParameters, f'{node_name}/list_parameters'),
        ListParameters.Request(depth=ListParameters.Request.DEPTH_RECURSIVE),
    )
    names = sorted(listed.result.names)
    got = call(
        ros, caller.create_client(GetParameters, f'{node_name}/get_parameters'), GetParameters.Request(names=names)
    )
    assert len(got.values) == len(names), f'{node_name}: get_parameters answered {len(got.values)} of {len(names)}'
    params = {}
    for name, value in zip(names, got.values):
        assert value.type != ParameterType.PARAMETER_NOT_SET, f'{node_name}: {name} not set'
        section = params
        *path, leaf = name.split('.')
        for key in path:
            section = section.setdefault(key, {})
        section[leaf] = parameter_value_to_python(value)
    return {node_name: {'ros__parameters': params}}


def set_parameter(ros, caller, node_name, name, value):
    """The SetParameters service, as ``ros2 param set`` calls it: the one result."""
    request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    response = call(ros, caller.create_client(SetParameters, f'{node_name}/set_parameters'), request)
    return response.results[0]


def plain(value):
    return list(value) if isinstance(value, (list, tuple)) or hasattr(value, 'tolist') else value


# ---------------------------------------------------------------- declarations


@pytest.mark.parametrize('key', sorted(NODES))
def test_every_parameter_is_described_and_every_numeric_one_has_a_range(ros, key):
    cls, specs, params = NODES[key]
    node = ros.add(cls(context=ros.context, parameter_overrides=overrides(**params)))
    for spec in specs:
        desc = node.describe_parameter(spec.name)
        value = node.get_parameter(spec.name).value
        assert desc.description, spec.name
        numeric = (
            isinstance(value, (int, float))
            and not isinstance(value, bool)
            or (isinstance(value, (list, tuple)) or hasattr(value, 'tolist'))
            and not isinstance(value, str)
            and len(value)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        )
        if numeric:
            assert desc.floating_point_range or desc.integer_range, f'{key}: {spec.name} has no range'
        else:
            assert not (desc.floating_point_range or desc.integer_range), spec.name


# ---------------------------------------------------------------- ros2 param dump, then --params-file


@pytest.mark.parametrize('key', sorted(NODES))
def test_the_dump_lists_every_parameter_and_loads_back(ros, key, tmp_path):
    cls, specs, params = NODES[key]
    node = ros.add(cls(context=ros.context, parameter_overrides=overrides(**params)))
    caller = ros.add(Node('param_cli', context=ros.context))
    name = node.get_fully_qualified_name()
    dumped = dump(ros, caller, name)
    values = dumped[name]['ros__parameters']
    assert {s.name for s in specs} <= set(values)
    for pname, value in params.items():
        assert plain(values[pname]) == pytest.approx(value) if not isinstance(value, str) else values[pname] == value
    path = tmp_path / 'dump.yaml'
    path.write_text(yaml.dump(dumped, default_flow_style=False))

    # A second node of the same kind, in a fresh context, from the file alone.
    other = RosHarness()
    try:
        reloaded = other.add(cls(context=other.context, cli_args=['--ros-args', '--params-file', str(path)]))
        for spec in specs:
            got, want = reloaded.get_parameter(spec.name).value, node.get_parameter(spec.name).value
            assert plain(got) == plain(want), spec.name
    finally:
        other.close()


def test_the_sim_start_state_follows_the_robot_yaml(ros):
    # Neither start_base_pose nor start_arm is written in the node YAML: their defaults are the
    # robot's start state, and `ros2 param get` answers with it.
    for robot in ('steerable', 'mecanum'):
        sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(robot=robot)))
        start = load_robot(robot).start
        assert plain(sim.get_parameter('start_arm').value) == start.arm.tolist()
        assert plain(sim.get_parameter('start_base_pose').value) == start.base_pose.tolist()
        np.testing.assert_allclose(sim.world.joint_state()[1][:7], start.arm, atol=1e-9)


# ---------------------------------------------------------------- refused sets

REFUSED = [
    # node, parameter, value, words of the reason
    ('wmm_sim', 'command_timeout', -1.0, 'out of range'),
    ('wmm_sim', 'command_timeout', math.nan, 'out of range'),
    ('wmm_sim', 'lockstep_groups', 'arm,wheel', 'unknown groups'),
    ('wmm_sim', 'period', 0.01, 'read-only'),
    ('wmm_sim', 'slip_noise', [0.1, 0.1, 0.1], 'read-only'),
    ('swmr_controller', 'reference_timeout', 1e9, 'out of range'),
    ('swmr_controller', 'reference_timeout', '0.1', 'type'),
    ('swmr_controller', 'kp', 3.0, 'read-only'),
    ('mecanum_controller', 'joint_state_timeout', 0.0, 'out of range'),
    ('redundancy_resolver', 'goal_tolerance', [0.01], 'expected 2 values'),
    ('redundancy_resolver', 'goal_tolerance', [0.01, -1.0], 'outside'),
    ('redundancy_resolver', 'state_timeout', math.inf, 'out of range'),
    ('redundancy_resolver', 'method', 'amp', 'read-only'),
    ('goal_sequencer', 'republish_period', -0.5, 'out of range'),
    ('goal_sequencer', 'scenario', 'xing_pose', 'read-only'),
    ('wmm_viewer', 'drag_publish_period', 0.0, 'out of range'),
    ('wmm_viewer', 'port', 9000, 'read-only'),
]


@pytest.mark.parametrize('key,name,value,reason', REFUSED, ids=[f'{r[0]}.{r[1]}={r[2]}' for r in REFUSED])
def test_an_invalid_or_read_only_set_is_refused_with_a_reason(ros, key, name, value, reason):
    cls, _, _ = NODES[key]
    node = ros.add(cls(context=ros.context))
    caller = ros.add(Node('param_cli', context=ros.context))
    before = plain(node.get_parameter(name).value)
    result = set_parameter(ros, caller, node.get_fully_qualified_name(), name, value)
    assert not result.successful
    assert reason.lower() in result.reason.lower(), result.reason
    assert plain(node.get_parameter(name).value) == before
    assert plain(getattr(node.p, name)) == before


# ---------------------------------------------------------------- live changes take effect


class BaseDriver(Node):
    """Publishes joint states (zero positions) and base references; records the feasible twists."""

    def __init__(self, context, joints):
        super().__init__('base_driver', context=context)
        self.joints = list(joints)
        self.feasible = []
        self.pub_js = self.create_publisher(JointState, '/joint_states', 10)
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)
        self.create_subscription(TwistStamped, '/base/feasible_twist', self.feasible.append, 10)
        # Stands in for the simulator: a controller whose wheel commands nobody receives holds
        # its state at the measured one.
        for topic in ('/steer_controller/commands', '/drive_controller/commands', '/wheel_controller/commands'):
            self.create_subscription(Float64MultiArray, topic, lambda msg: None, 10)

    def reference(self, twist):
        msg = TwistStamped()
        msg.header.frame_id = 'base_link'
        msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z = twist
        self.pub_ref.publish(msg)

    def joint_state(self):
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.name = self.joints
        msg.position = [0.0] * len(self.joints)
        self.pub_js.publish(msg)

    def speed(self):
        t = self.feasible[-1].twist
        return math.hypot(t.linear.x, t.linear.y) + abs(t.angular.z)


def run_cycles(ros, driver, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        driver.joint_state()
        ros.spin_for(0.025)


@pytest.mark.parametrize(
    'cls,robot,twist',
    [(SwmrControllerNode, 'steerable', (0.3, 0.0, 0.0)), (MecanumControllerNode, 'mecanum', (0.0, 0.0, 0.3))],
    ids=['swmr_controller', 'mecanum_controller'],
)
def test_a_shorter_reference_timeout_set_at_run_time_brakes_the_base(ros, cls, robot, twist):
    node = ros.add(
        cls(
            context=ros.context,
            parameter_overrides=overrides(
                robot=robot, reference_timeout=30.0, reference_wait=0.0, joint_state_timeout=30.0
            ),
        )
    )
    driver = ros.add(BaseDriver(ros.context, load_robot(robot).base.joints))
    caller = ros.add(Node('param_cli', context=ros.context))
    ros.spin_for(0.3)
    driver.reference(twist)
    run_cycles(ros, driver, 0.6)
    run_cycles(ros, driver, 0.6)  # no new reference for 0.6 s: still fresh at 30 s
    moving = driver.speed()
    assert moving > 0.1
    result = set_parameter(ros, caller, node.get_fully_qualified_name(), 'reference_timeout', 0.1)
    assert result.successful, result.reason
    run_cycles(ros, driver, 1.0)  # now stale: braked to rest within |v|/a (0.3 s at most)
    assert driver.speed() < 1e-9
    assert node.p.reference_timeout == 0.1


def test_a_shorter_command_timeout_set_at_run_time_zeroes_a_stale_command(ros):
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(command_timeout=10.0)))
    caller = ros.add(Node('param_cli', context=ros.context))
    pub = caller.create_publisher(Float64MultiArray, '/arm_controller/commands', 10)
    ros.spin_for(0.3)
    pub.publish(Float64MultiArray(data=[0.2, 0, 0, 0, 0, 0, 0]))
    ros.spin_for(0.5)
    assert sim.world.command[0] == pytest.approx(0.2)  # held: younger than 10 s
    result = set_parameter(ros, caller, sim.get_fully_qualified_name(), 'command_timeout', 0.1)
    assert result.successful, result.reason
    ros.spin_for(0.3)
    assert sim.world.command[0] == 0.0  # older than 0.1 s: zeroed


def test_a_shorter_lockstep_timeout_set_at_run_time_steps_the_sim(ros):
    # No controller: lockstep waits lockstep_timeout (60 s) before it starts; 0.01 s steps at once.
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(timing='lockstep', lockstep_timeout=60.0)))
    caller = ros.add(Node('param_cli', context=ros.context))
    ros.spin_for(0.5)
    assert sim.world.time == 0.0
    result = set_parameter(ros, caller, sim.get_fully_qualified_name(), 'lockstep_timeout', 0.01)
    assert result.successful, result.reason
    assert ros.spin_until(lambda: sim.world.time >= 0.25, timeout=5.0)


def test_lockstep_groups_set_at_run_time_change_what_the_sim_waits_for(ros):
    sim = ros.add(
        SimNode(
            context=ros.context,
            parameter_overrides=overrides(timing='lockstep', lockstep_timeout=60.0, lockstep_groups='arm'),
        )
    )
    caller = ros.add(Node('param_cli', context=ros.context))
    pub = caller.create_publisher(Float64MultiArray, '/arm_controller/commands', 10)
    # a controller answers the joint states: the simulator starts once it listens to them too,
    # not when its command publisher alone is seen (the first state would go unanswered)
    ros.spin_for(0.5)
    assert not sim.wait.started
    caller.create_subscription(JointState, '/joint_states', lambda msg: None, 10)
    assert ros.spin_until(lambda: sim.wait.started, timeout=5.0)
    ros.spin_for(0.2)
    t0 = sim.world.time
    pub.publish(Float64MultiArray(data=[0.0] * 7))
    assert ros.spin_until(lambda: sim.world.time > t0, timeout=5.0)  # the arm alone steps it
    result = set_parameter(ros, caller, sim.get_fully_qualified_name(), 'lockstep_groups', 'arm,steer')
    assert result.successful, result.reason
    t1 = sim.world.time
    pub.publish(Float64MultiArray(data=[0.0] * 7))
    ros.spin_for(0.5)
    assert sim.world.time == t1  # now it waits for steer too


# ---------------------------------------------------------------- one home for every default


def _leaves(tree, prefix=''):
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from _leaves(value, f'{prefix}{key}.')
    else:
        yield prefix[:-1], tree


NODE_YAMLS = {
    'wmm_sim.yaml': sim_node.PARAMS,
    'swmr_controller.yaml': swmr_controller.PARAMS,
    'mecanum_controller.yaml': mecanum_controller.PARAMS,
    'redundancy_resolver.yaml': redundancy_resolver.PARAMS,
    'goal_sequencer.yaml': goal_sequencer.PARAMS,
    'goal_planner.yaml': goal_planner.PARAMS,
    'wmm_viewer.yaml': viewer.PARAMS,
}


@pytest.mark.parametrize('yaml_name', sorted(NODE_YAMLS))
def test_a_node_yaml_holds_its_own_tuning_and_nothing_of_the_robot(yaml_name):
    node_values = yaml.safe_load(config_path(yaml_name).read_text())[yaml_name[:-5]]['ros__parameters']
    specs = {s.name: s for s in NODE_YAMLS[yaml_name]}
    # Every key is a declared parameter, and every parameter without another home is there.
    assert set(node_values) == {n for n, s in specs.items() if s.default_from is None}
    for robot in ('steerable', 'mecanum'):
        robot_leaves = dict(_leaves(yaml.safe_load(config_path('robots', f'{robot}.yaml').read_text())))
        names = {k.rsplit('.', 1)[-1] for k in robot_leaves}
        assert not set(node_values) & names, f'{yaml_name} repeats keys of {robot}.yaml'
        # Vectors of limits or geometry (3+ entries, not all zero; a pair or zeros can agree by chance).
        lists = [v for v in robot_leaves.values() if isinstance(v, list) and len(v) > 2 and any(v)]
        repeated = [k for k, v in node_values.items() if isinstance(v, list) and v in lists]
        assert not repeated, f'{yaml_name}: {repeated} repeat values of {robot}.yaml'


def test_the_control_period_has_one_home_the_robot_yaml(ros):
    # The simulator and the controllers must agree on it: each node's `period` defaults to its
    # robot's (a node YAML that wrote it too would repeat a robot-YAML key, above), and a node
    # still takes its own when given one.
    with_period = [yaml_name for yaml_name, specs in NODE_YAMLS.items() if any(s.name == 'period' for s in specs)]
    assert sorted(with_period) == [
        'goal_planner.yaml',
        'mecanum_controller.yaml',
        'redundancy_resolver.yaml',
        'swmr_controller.yaml',
        'wmm_sim.yaml',
    ]
    for yaml_name in with_period:
        assert next(s for s in NODE_YAMLS[yaml_name] if s.name == 'period').default_from is robot_period
    for robot in ('steerable', 'mecanum'):
        assert 'period' in yaml.safe_load(config_path('robots', f'{robot}.yaml').read_text())['robot']
    node = ros.add(MecanumControllerNode(context=ros.context))
    assert node.p.period == load_robot('mecanum').period
    node = ros.add(RedundancyResolverNode(context=ros.context, parameter_overrides=overrides(period=0.05)))
    assert node.p.period == 0.05 and node.resolver.params.dt == 0.05


def test_method_tuning_has_its_home_in_the_resolver_classes():
    # The resolver node's YAML holds the node's settings; a method's gains and thresholds are
    # declared with their parameter class's defaults (one home), and a dump shows them.
    node_values = yaml.safe_load(config_path('redundancy_resolver.yaml').read_text())
    keys = set(node_values['redundancy_resolver']['ros__parameters'])
    method_fields = {f.name for _, cls in METHODS.values() for f in dataclasses.fields(cls)}
    assert not keys & method_fields
    declared = {s.name for s in redundancy_resolver.PARAMS if s.default_from not in (None, robot_period, robot_method)}
    assert declared == method_fields & {s.name for s in redundancy_resolver.PARAMS}
    assert {'lambda_p', 'kp', 'sigma_min', 'gamma1'} <= declared


def test_no_robot_limit_has_a_default_in_code():
    # The base controllers' parameter classes take every limit from the robot YAML.
    limits = {
        'steer_rate_limit',
        'steer_accel_limit',
        'drive_rate_limit',
        'drive_accel_limit',
        'base_velocity_limit',
        'base_accel_limit',
        'velocity_limit',
        'accel_limit',
        'wheel_rate_limit',
    }
    for cls in (SwmrParams, WheelParams):
        with_default = [
            f.name
            for f in dataclasses.fields(cls)
            if f.name in limits
            and (f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING)
        ]
        assert not with_default, f'{cls.__name__}: {with_default} have defaults in code'


def test_a_default_written_twice_is_refused(ros, monkeypatch):
    # A start state in the node YAML as well as in the robot YAML would be two homes.
    original = sim_node.declare_parameters.__globals__['load_defaults']

    def with_start(yaml_name, node_name):
        return dict(original(yaml_name, node_name), start_arm=[0.0] * 7)

    monkeypatch.setitem(sim_node.declare_parameters.__globals__, 'load_defaults', with_start)
    with pytest.raises(ConfigError, match='one home'):
        SimNode(context=ros.context)
    assert rclpy.ok(context=ros.context)


def test_goal_tolerance_stall_time_and_min_progress_ratio_set_at_run_time_judge_the_goal(ros):
    """The reached/stalled judgement follows live changes; a position-only method (amp with
    ``rows: position``, r = 3) judges the position alone: its orientation is free, never a reason
    to report a stall."""
    from types import SimpleNamespace

    node = ros.add(
        RedundancyResolverNode(
            context=ros.context, parameter_overrides=overrides(robot='mecanum', method='amp', rows='position')
        )
    )
    caller = ros.add(Node('param_cli', context=ros.context))
    near = SimpleNamespace(position_error=0.004, orientation_error=0.5)  # 4 mm, orientation far off
    node.progress.update(near)
    assert node.progress.reached  # orientation free at r = 3
    assert set_parameter(ros, caller, node.get_fully_qualified_name(), 'goal_tolerance', [0.002, 0.02]).successful
    node.progress.start()
    node.progress.update(near)
    assert not node.progress.reached  # 4 mm > the new 2 mm
    assert set_parameter(ros, caller, node.get_fully_qualified_name(), 'stall_time', 0.1).successful
    for _ in range(6):  # 6 periods, 0.15 s, no progress
        node.progress.update(near)
    assert node.progress.stalled
    node.progress.start()  # 1.25 % closer each period:
    for k in range(12):  # 5 % per stall_time, under 10 %
        node.progress.update(SimpleNamespace(position_error=0.5 * 0.9875**k, orientation_error=0.001))
    assert node.progress.stalled
    assert set_parameter(ros, caller, node.get_fully_qualified_name(), 'min_progress_ratio', 0.02).successful
    node.progress.update(SimpleNamespace(position_error=0.5 * 0.9875**12, orientation_error=0.001))
    assert not node.progress.stalled  # 5 % is progress now
    full = ros.add(
        RedundancyResolverNode(
            context=ros.context,
            cli_args=['--ros-args', '-r', '__node:=full'],
            parameter_overrides=overrides(robot='mecanum'),
        )
    )  # amp, rows full: the defaults
    full.progress.update(near)
    assert not full.progress.reached  # r = 6: 0.5 rad is not reached


def test_an_integer_for_a_double_parameter_is_taken_as_that_double_at_start_up_and_at_run_time(ros):
    """``-p stall_time:=5`` and ``ros2 param set /redundancy_resolver stall_time 5`` (an integer):
    taken as 5.0; still checked against the range; an integer parameter stays an integer."""
    node = ros.add(
        RedundancyResolverNode(context=ros.context, parameter_overrides=overrides(stall_time=5, goal_tolerance=[1, 1]))
    )
    assert node.p.stall_time == 5.0 and isinstance(node.p.stall_time, float)
    assert node.get_parameter('stall_time').type_ == Parameter.Type.DOUBLE
    assert node.p.goal_tolerance == [1.0, 1.0] and node.progress.tolerance == (1.0, 1.0)
    caller = ros.add(Node('param_cli', context=ros.context))
    name = node.get_fully_qualified_name()
    assert set_parameter(ros, caller, name, 'stall_time', 7).successful
    assert node.p.stall_time == 7.0 and node.progress.stall_time == 7.0
    assert node.get_parameter('stall_time').type_ == Parameter.Type.DOUBLE
    refused = set_parameter(ros, caller, name, 'stall_time', 7000)
    assert not refused.successful and 'out of range' in refused.reason and node.p.stall_time == 7.0
    assert set_parameter(ros, caller, name, 'goal_tolerance', [1, 2]).successful
    assert node.p.goal_tolerance == [1.0, 2.0]
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(seed=3, command_timeout=1)))
    assert sim.p.command_timeout == 1.0 and sim.get_parameter('seed').type_ == Parameter.Type.INTEGER
    assert not set_parameter(ros, caller, sim.get_fully_qualified_name(), 'seed', 4.0).successful
