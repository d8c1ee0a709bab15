"""The nodes learn that the simulator steps in lockstep, with no parameter but the simulator's
``timing:=lockstep`` (:mod:`wmm_control.nodes.sim_timing`): they age their inputs by the
simulation's time, answer every state however long they took, wait for each other as long as
the simulator waits, and still stop the robot when the joint states truly stop."""

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, Float64MultiArray

from ros_helpers import ROSOUT_QOS, RosHarness, held_up, pose2d, stamp_s
from sim_bridge.node import SimNode
from wmm_control.kinematics import KinematicModel
from wmm_control.nodes.goal_sequencer import GoalSequencerNode
from wmm_control.nodes.qos import LATCHED_QOS
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.sim_timing import LOCKSTEP_TOPIC
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.robot_config import load_robot

#: what a node logs when it takes its inputs for stale, or drops a state for its wait
STALE_WARNINGS = ('no /joint_states', 'max_state_wait', 'usual delivery', 'no /base/feasible_twist', 'older than')
SWITCH_AT = 1.0  # [s] of simulated time: the second goal
REACH = np.array([0.35, 0.0, 0.0])  # [m] the second goal from the start: the base moves too

SCENARIO = """scenario:
  name: lockstep_goals
  robot: steerable
  frame: world
  duration: 30.0
  goals:
    - {{t: 0.0, pose: {start}}}
    - {{t: {switch}, pose: {goal}}}
"""


def _start_pose():
    robot = load_robot('steerable')
    model = KinematicModel('steerable')
    model.update(robot.start.base_pose, robot.start.arm)
    return model.ee_pose_world()


class Probe:
    """Records the goals, the true end effector, every command and the warnings of the nodes."""

    def __init__(self, ros):
        node = ros.probe('lockstep_probe')
        self.goals, self.ee, self.truth, self.warnings, self.timing = [], [], [], [], []
        self.commands = {g: [] for g in ('arm', 'steer', 'drive')}
        node.create_subscription(PoseStamped, '/goal_pose', self.goals.append, 10)
        node.create_subscription(PoseStamped, '/ee_pose', self.ee.append, 10)
        node.create_subscription(Odometry, '/ground_truth/odom', self.truth.append, 10)
        node.create_subscription(Float64, LOCKSTEP_TOPIC, lambda m: self.timing.append(m.data), LATCHED_QOS)
        for group, kept in self.commands.items():
            node.create_subscription(
                Float64MultiArray, f'/{group}_controller/commands', lambda m, kept=kept: kept.append(list(m.data)), 50
            )
        node.create_subscription(Log, '/rosout', self._on_log, ROSOUT_QOS)

    def _on_log(self, msg):
        if msg.level >= Log.WARN:
            self.warnings.append((msg.name, msg.msg))

    def stale(self):
        """The warnings that say an input went stale or a state was dropped."""
        return [(name, m) for name, m in self.warnings if any(w in m for w in STALE_WARNINGS)]

    def sim_time(self):
        return stamp_s(self.ee[-1]) if self.ee else 0.0

    def ee_position(self):
        p = self.ee[-1].pose.position
        return np.array([p.x, p.y, p.z])


@pytest.fixture
def lockstep(tmp_path):
    """The scenario player, robot A's resolver and base controller with their defaults, and the
    simulator with ``timing:=lockstep`` alone, as three commands would start them."""
    start = _start_pose()
    goal = start.copy()
    goal[:3] += REACH
    path = tmp_path / 'lockstep_goals.yaml'
    path.write_text(SCENARIO.format(start=start.tolist(), goal=goal.tolist(), switch=SWITCH_AT))
    ros = RosHarness()
    probe = Probe(ros)
    ros.add(GoalSequencerNode(context=ros.context, parameter_overrides=[Parameter('scenario', value=str(path))]))
    resolver = ros.add(RedundancyResolverNode(context=ros.context))
    base = ros.add(SwmrControllerNode(context=ros.context))
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=[Parameter('timing', value='lockstep')]))
    yield ros, probe, resolver, base, sim, goal[:3]
    ros.close()


def test_a_held_up_resolver_in_lockstep_reaches_the_goal_with_no_stale_data(lockstep):
    """The resolver is held up 0.3 s every 8th cycle (a heavy cycle on a busy machine): three
    times the realtime ``max_state_wait`` and past every node's 0.2 s joint-state timeout. In
    lockstep the world waits for it: no answer is dropped, no input goes stale, the scenario
    plays on the simulation's time, and the robot, base and arm, reaches the goal."""
    ros, probe, resolver, base, sim, goal = lockstep
    with held_up(resolver.resolver, 'step', 0.3, every=8):
        reached = ros.spin_until(
            lambda: probe.sim_time() > SWITCH_AT + 0.5 and resolver.progress.reached, timeout=120.0
        )
    assert probe.timing and probe.timing[-1] == pytest.approx(sim.p.lockstep_timeout)
    assert resolver.watchdog.timing.lockstep and base.watchdog.timing.lockstep
    assert reached, f'goal not reached by {probe.sim_time():.2f} s of simulated time'
    assert np.linalg.norm(probe.ee_position() - goal) < 0.011
    # the scenario follows the simulation's time without use_sim_time: from its start on the
    # simulator's clock, the second goal is sent (and stamped) at its time in the scenario,
    # whatever the wall clock did meanwhile
    on_sim_time = [g for g in probe.goals if stamp_s(g) < 1e6]  # not a wall-clock stamp
    second = [g for g in on_sim_time if abs(g.pose.position.x - goal[0]) < 1e-9]
    assert second and stamp_s(second[0]) - stamp_s(on_sim_time[0]) == pytest.approx(SWITCH_AT, abs=0.03)
    assert probe.stale() == [], probe.stale()
    assert resolver.watchdog.skipped == 0 and base.watchdog.skipped == 0
    assert resolver.counters['compensation_dropped'] == 0
    assert resolver.counters['stale_cycles'] <= 1 and base.counters['stale_cycles'] <= 1  # the first state
    assert not [m for name, m in probe.warnings if name == 'wmm_sim'], 'the simulator never stepped without answers'
    assert pose2d(probe.truth[-1])[0] - pose2d(probe.truth[0])[0] > 0.05, 'the base drove its share'


def test_the_watchdogs_still_zero_the_commands_when_the_simulator_stops(lockstep):
    ros, probe, resolver, base, sim, goal = lockstep
    assert ros.spin_until(lambda: probe.sim_time() > SWITCH_AT + 0.5, timeout=60.0)
    moving = {g: np.max(np.abs(c[-1])) for g, c in probe.commands.items()}
    assert moving['arm'] > 0.0 and moving['drive'] > 0.0, moving
    ros.executor.remove_node(sim)  # the simulator stops publishing
    counts = {g: len(c) for g, c in probe.commands.items()}
    timeout = resolver.p.state_timeout + sim.p.lockstep_timeout
    assert ros.spin_until(
        lambda: all(len(c) > counts[g] and not np.any(c[-1]) for g, c in probe.commands.items()), timeout=3 * timeout
    ), {g: c[-1] for g, c in probe.commands.items()}
    # each watchdog says why (its line reaches /rosout a moment later)
    stops = {}
    assert ros.spin_until(
        lambda: (
            stops.update((n, m) for n, m in probe.warnings if m.startswith('no /joint_states'))
            or set(stops) == {'redundancy_resolver', 'swmr_controller'}
        ),
        timeout=5.0,
    ), stops
    assert all(f'for {timeout:g} s' in m for m in stops.values()), stops
