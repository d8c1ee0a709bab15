"""``goal_sequencer``: plays a scenario: goals on ``/goal_pose``, or a trajectory on ``/ee_reference``.

For a scenario of goals (:mod:`wmm_control.experiments.scenario`, e.g. Table II of Sorour et
al. 2019) it publishes ``/goal_pose`` (``geometry_msgs/PoseStamped``, the scenario's frame):
each goal when its time comes, and the goal in force again every ``republish_period`` so that
a resolver started later picks it up.

For a trajectory scenario (Xing et al. §4, :mod:`wmm_control.experiments.trajectories`) it
publishes ``/ee_reference`` (``trajectory_msgs/MultiDOFJointTrajectory``, frame the
scenario's): at every clock tick one point, ``transforms[0]`` the pose, ``velocities[0]`` the
twist and ``accelerations[0]`` the acceleration (linear, angular; world axes),
``time_from_start`` the time along the trajectory. The trajectory starts from the end
effector's pose at the robot's start state (its YAML), as the paper's x0.

Time: the scenario's clock starts at the first reading of this node's clock. Under
``use_sim_time`` (recommended with ``wmm_sim`` in realtime) that is the first ``/clock`` message, and the
goals follow simulated time exactly: the node checks its timeline on every ``/clock``
message; on wall time, on a steady-clock timer every 10 ms. A simulator in lockstep says so
(its latched ``sim/lockstep_timeout``, :mod:`~wmm_control.nodes.sim_timing`): the node then
follows the simulator's ``clock`` (relative: ``/r1/clock`` in ``/r1``) without
``use_sim_time``, and the scenario starts again on it. When the scenario ends (its ``duration``), the
last goal stays in force. A clock that goes back (a restarted simulator) starts the scenario
again, and one that jumps more than 10 s ahead skips to that time; both are logged.
"""

import math
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from trajectory_msgs.msg import MultiDOFJointTrajectory
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg

from wmm_control.experiments.scenario import Goal, load_scenario
from wmm_control.kinematics import KinematicModel
from wmm_control.geometry import matrix_from_rpy, quaternion_from_matrix
from wmm_control.nodes.conversions import pose_stamped, reference_message
from wmm_control.nodes.parameters import Param, declare_parameters
from wmm_control.nodes.qos import CLOCK_QOS, COMMAND_QOS
from wmm_control.nodes.runner import guard_clock, run_node
from wmm_control.nodes.sim_timing import SimTiming

__all__ = ['GoalSequencerNode', 'main']

MAX_CLOCK_STEP = 10.0  # [s] a larger step of the clock between two checks is reported

PARAMS = (
    Param('scenario', 'Scenario name (config/scenarios/<name>.yaml) or a path to a scenario file.', read_only=True),
    Param('republish_period', 'Time [s] between re-publications of the goal in force; 0 = never.', lo=0.0, hi=3600.0),
)


def goal_message(goal: Goal, frame: str, stamp: Time) -> PoseStamped:
    """A ``PoseStamped`` of a scenario goal ``[x, y, z, roll, pitch, yaw]``."""
    pose = [float(v) for v in goal.pose]
    return pose_stamped(stamp, frame, pose[:3], quaternion_from_matrix(matrix_from_rpy(pose[3:])))


class GoalSequencerNode(Node):
    """Plays one scenario's goals on ``/goal_pose``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('goal_sequencer', **kwargs)
        guard_clock(self)
        self.p = declare_parameters(self, 'goal_sequencer.yaml', PARAMS)
        self.scenario = load_scenario(self.p.scenario)
        self.pub = self.create_publisher(PoseStamped, 'goal_pose', COMMAND_QOS)
        self.pub_ref = self.create_publisher(MultiDOFJointTrajectory, 'ee_reference', COMMAND_QOS)
        self._trajectory = None
        if self.scenario.trajectory is not None:
            self._trajectory = self.scenario.reference(KinematicModel(self.scenario.robot))
        self._sim_time = self.get_parameter('use_sim_time').value
        self._restart()
        self.published = 0
        self._lockstep_clock = None  # the simulator's clock subscription while it steps in lockstep
        if self._sim_time:
            self.create_subscription(ClockMsg, '/clock', self._on_clock, CLOCK_QOS)
        else:
            self.timing = SimTiming(self, self._on_lockstep)
        self.create_timer(0.01, self._tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        what = (
            f'trajectory {self.scenario.trajectory} on /ee_reference'
            if self._trajectory is not None
            else f'{len(self.scenario.goals)} goals on /goal_pose'
        )
        self.get_logger().info(
            f'scenario {self.scenario.name}: {what} over {self.scenario.duration} s '
            f'({"sim" if self._sim_time else "wall"} time)'
        )

    def _restart(self):
        """The scenario starts again at the next reading of the clock."""
        self._t0 = self._last_t = None
        self._index = -1
        self._last_pub = -math.inf

    def _on_lockstep(self, timeout):
        """The simulator's timing changed: in lockstep follow its clock, else the wall clock;
        either way the scenario starts again on the clock it now follows."""
        lockstep = timeout > 0.0
        if lockstep == (self._lockstep_clock is not None):
            return
        if lockstep:
            # relative, as the simulator publishes it: /r1/clock for the robot in /r1
            self._lockstep_clock = self.create_subscription(ClockMsg, 'clock', self._on_clock, CLOCK_QOS)
        else:
            self.destroy_subscription(self._lockstep_clock)
            self._lockstep_clock = None
        self._restart()
        source = "the simulator's" if lockstep else 'wall'
        self.get_logger().info(f'the scenario starts again on {source} time')

    def _on_clock(self, msg):
        if msg.clock.sec < 0:
            return  # not a time: dropped and logged (guard_clock)
        self._check(msg.clock.sec + msg.clock.nanosec * 1e-9, msg.clock)

    def _tick(self):
        if self._sim_time or self._lockstep_clock is not None:
            return  # on sim time every clock message drives the timeline
        now = self.get_clock().now()
        self._check(now.nanoseconds * 1e-9, now.to_msg())

    def _check(self, t, stamp):
        if self._last_t is not None and t < self._last_t:
            self.get_logger().warn(
                f'clock went back from {self._last_t:.6g} s to {t:.6g} s (simulator restarted?): '
                'the scenario starts again',
                throttle_duration_sec=1.0,
            )
            self._restart()
        elif self._last_t is not None and t - self._last_t > MAX_CLOCK_STEP:
            self.get_logger().warn(
                f'clock jumped {t - self._last_t:.6g} s ahead in one step: the scenario skips to that time',
                throttle_duration_sec=1.0,
            )
        self._last_t = t
        if self._t0 is None:
            self._t0 = t
        elapsed = t - self._t0
        if self._trajectory is not None:
            self.pub_ref.publish(
                reference_message(
                    self._trajectory(min(elapsed, self.scenario.duration)), self.scenario.frame, stamp, elapsed
                )
            )
            self.published += 1
            return
        index = self.scenario.goal_index(elapsed)
        period = self.p.republish_period
        if index != self._index or (period > 0 and t - self._last_pub >= period):
            if index != self._index:
                self.get_logger().info(
                    f'goal {index + 1}/{len(self.scenario.goals)} at t = {elapsed:.3f} s: '
                    f'{self.scenario.goals[index].pose.round(4).tolist()}'
                )
            self._index = index
            self._last_pub = t
            self.pub.publish(goal_message(self.scenario.goals[index], self.scenario.frame, stamp))
            self.published += 1


def main(args: list[str] | None = None) -> int:
    return run_node(GoalSequencerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
