"""``goal_sequencer``: publishes a scenario's timeline of end-effector goals on ``/goal_pose``.

Publishes ``/goal_pose`` (``geometry_msgs/PoseStamped``, the scenario's frame): each goal of
the scenario file (:mod:`wmm_control.experiments.scenario`, e.g. Table II of Sorour et al.
2019) when its time comes, and the goal in force again every ``republish_period`` so that a
resolver started later picks it up.

Time: the scenario's clock starts at the first reading of this node's clock. Under
``use_sim_time`` (recommended with ``wmm_sim``) that is the first ``/clock`` message, and the
goals follow simulated time exactly: the node checks its timeline on every ``/clock``
message, and otherwise on a steady-clock timer. When the scenario ends (its ``duration``), the
last goal stays in force.
"""

import math

import pinocchio as pin
from geometry_msgs.msg import PoseStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg

from wmm_control.experiments.scenario import load_scenario
from wmm_control.nodes.common import Param, declare_parameters, run_node

__all__ = ['GoalSequencerNode', 'main']

PARAMS = (
    Param('scenario', 'Scenario name (config/scenarios/<name>.yaml) or a path to a scenario file.',
          read_only=True),
    Param('republish_period', 'Time [s] between re-publications of the goal in force; 0 = never.',
          lo=0.0, hi=3600.0, read_only=True),
)


def goal_message(goal, frame, stamp):
    """A ``PoseStamped`` of a scenario goal ``[x, y, z, roll, pitch, yaw]``."""
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    x, y, z, roll, pitch, yaw = (float(v) for v in goal.pose)
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
    q = pin.Quaternion(pin.rpy.rpyToMatrix(roll, pitch, yaw))
    msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w = (
        float(q.x), float(q.y), float(q.z), float(q.w))
    return msg


class GoalSequencerNode(Node):
    """Plays one scenario's goals on ``/goal_pose``."""

    def __init__(self, **kwargs):
        super().__init__('goal_sequencer', **kwargs)
        self.p = declare_parameters(self, 'goal_sequencer.yaml', PARAMS)
        self.scenario = load_scenario(self.p.scenario)
        self.pub = self.create_publisher(PoseStamped, '/goal_pose', 10)
        self._sim_time = self.get_parameter('use_sim_time').value
        self._t0 = None
        self._index = -1
        self._last_pub = -math.inf
        self.published = 0
        if self._sim_time:
            self.create_subscription(ClockMsg, '/clock', self._on_clock, 10)
        self.create_timer(0.01, self._tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        g = self.scenario.goals
        self.get_logger().info(f'scenario {self.scenario.name}: {len(g)} goals over {self.scenario.duration} s '
                               f'({"sim" if self._sim_time else "wall"} time) on /goal_pose')

    def _on_clock(self, msg):
        self._check(msg.clock.sec + msg.clock.nanosec * 1e-9, msg.clock)

    def _tick(self):
        if self._sim_time and self._t0 is None:
            return             # sim time has not started: wait for the first /clock
        now = self.get_clock().now()
        self._check(now.nanoseconds * 1e-9, now.to_msg())

    def _check(self, t, stamp):
        if self._t0 is None:
            self._t0 = t
        elapsed = t - self._t0
        index = self.scenario.goal_index(elapsed)
        period = self.p.republish_period
        if index != self._index or (period > 0 and t - self._last_pub >= period):
            if index != self._index:
                self.get_logger().info(f'goal {index + 1}/{len(self.scenario.goals)} at t = {elapsed:.3f} s: '
                                       f'{self.scenario.goals[index].pose.round(4).tolist()}')
            self._index = index
            self._last_pub = t
            self.pub.publish(goal_message(self.scenario.goals[index], self.scenario.frame, stamp))
            self.published += 1


def main(args=None):
    return run_node(GoalSequencerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
