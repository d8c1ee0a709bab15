"""What the nodes publish for a ROS user: the /diagnostics key sets (documented in docs/nodes.md) and
the QoS of every topic."""

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy

from ros_helpers import overrides
from sim_bridge.node import SimNode
from wmm_control.experiments.ros_run import LOCKSTEP_TIMEOUT
from wmm_control.nodes.diagnostics import DiagnosticsGate
from wmm_control.nodes.mecanum_controller import MecanumControllerNode
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.robot_config import load_robot

# The /diagnostics table of docs/nodes.md: status name -> its keys (every message of that status).
SIM_GROUP = {'clamped', 'rejected', 'position_limited', 'command_age_s'}
DIAGNOSTIC_KEYS = {
    '/wmm_sim: simulation': {'sim_time_s', 'steps', 'real_time_factor'},
    '/swmr_controller': {
        'status',
        'route',
        'qp_status',
        'icr_next_xy',
        'icr_at_infinity',
        'active_constraints',
        'solve_time_us',
        'beta_ref',
        'feasible_twist',
        'reference',
        'reference_age_s',
        'references_rejected',
        'cycles',
        'joint_states_rejected',
        'stale_cycles',
        'joint_states_skipped',
        'commands_not_applied',
        'measured_period_s',
    },
    '/mecanum_controller': {
        'status',
        'velocity_scale',
        'accel_scale',
        'reference',
        'reference_dropped',
        'reference_limited',
        'feasible_twist',
        'wheel_rates',
        'wheel_rate_ratio',
        'reference_age_s',
        'references_rejected',
        'cycles',
        'joint_states_rejected',
        'stale_cycles',
        'commands_not_applied',
        'joint_states_skipped',
        'measured_period_s',
    },
}
RESOLVER_ALWAYS = {
    'cycles',
    'goals',
    'goals_rejected',
    'compensation_dropped',
    'stale_cycles',
    'joint_states_skipped',
    'measured_period_s',
    'obstacles',
    # the safety stage's counts (SafetyCounts)
    'binding_self',
    'binding_floor',
    'binding_obstacle',
    'binding_arm_stopping',
    'binding_base_along_path',
    'binding_base_between',
    'binding_base_after_turn',
    'binding_base_without_turn',
    'binding_base_turn_rate',
    'relaxed_cycles',
    'base_held_cycles',
}
RESOLVER_GOAL = {
    'method',
    'mode',
    'psi',
    'position_error_m',
    'orientation_error_rad',
    'limit_scale',
    'accel_scale',
    'null_scale',
    'compensation_scale',
    'compensated',
    'limited',
    'sigma_min',
    'cycle_time_us',
    'reference_time_left_s',
    'clearance_m',
    'closest_pair',
    'collision_constraints',
    'collision_changed',
    'goal_reached',
    'goal_stalled',
    'arm_command',
    'base_reference',
}


class Listener(Node):
    def __init__(self, context):
        super().__init__('diagnostics_listener', context=context)
        self.statuses = []
        self.create_subscription(DiagnosticArray, '/diagnostics', lambda m: self.statuses.extend(m.status), 100)
        self.pub_goal = self.create_publisher(PoseStamped, '/goal_pose', 10)


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_diagnostics_keys_are_the_documented_ones(ros, robot):
    config = load_robot(robot)
    listener = ros.add(Listener(ros.context))
    resolver = ros.add(
        RedundancyResolverNode(
            context=ros.context,
            parameter_overrides=overrides(
                robot=robot,
                method='task_sharing' if robot == 'steerable' else 'amp',
                diagnostics_period=0.05,
            ),
        )
    )
    if robot == 'steerable':
        ros.add(
            SwmrControllerNode(
                context=ros.context,
                parameter_overrides=overrides(diagnostics_period=0.05),
            )
        )
    else:
        ros.add(
            MecanumControllerNode(
                context=ros.context,
                parameter_overrides=overrides(robot=robot, diagnostics_period=0.05),
            )
        )
    sim = ros.add(
        SimNode(
            context=ros.context,
            parameter_overrides=overrides(
                robot=robot, timing='lockstep', diagnostics_period=0.05, lockstep_timeout=LOCKSTEP_TIMEOUT
            ),
        )
    )
    assert ros.spin_until(lambda: sim.world.time >= 0.3, timeout=30.0)  # no goal yet
    goal = PoseStamped()
    goal.header.frame_id = 'world'
    x, y, z = config.start.ee_pose[:3] + np.array([0.05, 0.0, 0.0])
    goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = x, y, z
    goal.pose.orientation.w = 1.0
    listener.pub_goal.publish(goal)
    assert ros.spin_until(lambda: resolver.counters['goals'] == 1 and sim.world.time >= 1.0, timeout=60.0)
    ros.spin_for(0.2)

    seen = {}
    for status in listener.statuses:
        seen.setdefault(status.name, []).append({kv.key for kv in status.values})
    groups = sim.world.command_groups
    expected = dict(DIAGNOSTIC_KEYS, **{f'/wmm_sim: {g} commands': SIM_GROUP for g in groups})
    base = '/swmr_controller' if robot == 'steerable' else '/mecanum_controller'
    expected = {
        k: v
        for k, v in expected.items()
        if k != ('/mecanum_controller' if base == '/swmr_controller' else '/swmr_controller')
    }
    assert set(seen) == set(expected) | {'/redundancy_resolver'}
    for name, keys in expected.items():
        assert all(k == keys for k in seen[name]), (name, [k ^ keys for k in seen[name]])
    # The resolver: the counters always; the goal keys too once a goal is pursued.
    resolver_sets = seen['/redundancy_resolver']
    assert resolver_sets[-1] == RESOLVER_ALWAYS | RESOLVER_GOAL
    assert all(k in (RESOLVER_ALWAYS, RESOLVER_ALWAYS | RESOLVER_GOAL) for k in resolver_sets)


def _reliability(node, topic, publisher):
    infos = node.get_publishers_info_by_topic(topic) if publisher else node.get_subscriptions_info_by_topic(topic)
    return {i.node_name: i.qos_profile.reliability for i in infos}


def test_qos_sensor_data_and_commands(ros):
    # The QoS table of docs/nodes.md: the sim publishes its state reliable (any subscriber matches); the
    # controllers consume it best effort; commands are reliable both ways.
    ros.add(SimNode(context=ros.context))
    ros.add(SwmrControllerNode(context=ros.context))
    ros.add(RedundancyResolverNode(context=ros.context))
    probe = ros.add(Node('qos_probe', context=ros.context))
    ros.spin_for(0.5)
    assert _reliability(probe, '/joint_states', True) == {'wmm_sim': ReliabilityPolicy.RELIABLE}
    subs = _reliability(probe, '/joint_states', False)
    assert subs == {
        'swmr_controller': ReliabilityPolicy.BEST_EFFORT,
        'redundancy_resolver': ReliabilityPolicy.BEST_EFFORT,
    }
    assert _reliability(probe, '/odom', False) == {'redundancy_resolver': ReliabilityPolicy.BEST_EFFORT}
    for topic, node in (
        ('/arm_controller/commands', 'redundancy_resolver'),
        ('/base/reference', 'redundancy_resolver'),
        ('/steer_controller/commands', 'swmr_controller'),
    ):
        assert _reliability(probe, topic, True) == {node: ReliabilityPolicy.RELIABLE}
    assert set(_reliability(probe, '/arm_controller/commands', False).values()) == {ReliabilityPolicy.RELIABLE}


def test_diagnostics_come_at_the_configured_rate_and_never_with_period_zero():
    """Every node gates its /diagnostics with one DiagnosticsGate: the first cycle reports, then
    one message per ``diagnostics_period`` of the node's clock; 0 silences it; a period changed
    at run time applies from the next message."""
    gate = DiagnosticsGate()
    times = np.arange(0.0, 1.0, 0.025)  # 40 control periods of 25 ms
    sent = [t for t in times if gate.due(t, 0.1)]
    np.testing.assert_allclose(sent, np.arange(0.0, 1.0, 0.1), atol=1e-9)
    assert not any(DiagnosticsGate().due(t, 0.0) for t in times)
    gate = DiagnosticsGate()
    assert [t for t in times if gate.due(t, 0.5 if t < 0.3 else 0.05)] == list(
        times[[0, 20, 22, 24, 26, 28, 30, 32, 34, 36, 38]]
    )
