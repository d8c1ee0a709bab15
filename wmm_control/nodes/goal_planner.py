"""``goal_planner``: between the user's ``/goal_pose`` and the resolver, a planned way round the obstacles.

The user publishes a goal on ``/goal_pose`` as without the planner; ``redundancy_resolver`` is
started with its ``goal_pose`` remapped to ``goal_planner/goal`` (``robot.launch.py
planner:=true`` does it). Each goal is planned off the executor's thread
(:class:`~wmm_control.planning.pursuit.GoalPursuit`, ROS-free; this module only wires topics to
it): a goal within reach with nothing in the way goes on to the resolver unchanged on
``~/goal``; otherwise the base path's points go to the resolver on ``/ee_reference``, one per
``period``, at the pace the base keeps, then the goal itself for the final approach: on
``/ee_reference`` as the last point, at rest, with the stance (the plan's last base pose) as its
joint ``base``, which the resolver holds once no point follows and judges as a goal (on ``~/goal``
without ``hold_base``). The planned base path is on ``~/path`` (latched), the state on ``/diagnostics`` and in
the log. A goal the planner finds no way to is reported with the reason, and the robot is held
where it is (its end effector's current pose sent as the goal). The plan is made again when
progress stalls or an obstacle on ``/obstacles`` comes onto the rest of the path.

Every topic, its type and frame, and the behaviour on bad input: ``docs/nodes.md`` (Planning
round obstacles). Timing: the period's timer runs on the steady clock; when the simulator says it
steps in lockstep (:mod:`~wmm_control.nodes.sim_timing`) each odometry message a period newer
than the last tick drives it instead, and the inputs are aged by the simulation's time.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from wmm_control.checks import PLAUSIBLE_FACTOR, Freshness
from wmm_control.nodes.conversions import (
    odometry_values,
    pose_values,
    reference_message,
    set_planar_pose,
    target_pose_stamped,
)
from wmm_control.nodes.diagnostics import DiagnosticsGate, diagnostic_array, log_lines, node_status
from wmm_control.nodes.goal_planner_params import FOLLOW_PARAMS, PARAMS, PLANNER_PARAMS
from wmm_control.nodes.inputs import JointSelector
from wmm_control.nodes.obstacle_topic import ObstacleSet, describe
from wmm_control.nodes.parameters import declare_parameters
from wmm_control.nodes.qos import COMMAND_QOS, DIAGNOSTICS_QOS, LATCHED_QOS, STATE_SUB_QOS
from wmm_control.nodes.runner import guard_clock, run_node
from wmm_control.nodes.sim_timing import SimTiming
from wmm_control.nodes.stamps import seconds
from wmm_control.planning.base_path import ATTEMPTS
from wmm_control.planning.follow import FollowParams
from wmm_control.planning.pursuit import GoalPursuit, PursuitLog, PursuitState
from wmm_control.resolvers.inputs import MeasuredInputs
from wmm_control.robot_config import load_robot

__all__ = ['PARAMS', 'PLAN_WAIT', 'GoalPlannerNode', 'main']

#: [s] how long Ctrl-C waits for a plan under way (about 1 s on an idle machine); the process
#: leaves without it after that and a second (the teardown's limit, ``run_node``), before
#: ``ros2 launch`` escalates to SIGKILL 15 s after Ctrl-C.
PLAN_WAIT = 10.0


class GoalPlannerNode(Node):
    """Wires ``/goal_pose``, ``/obstacles``, ``odom`` and ``joint_states`` to a
    :class:`~wmm_control.planning.pursuit.GoalPursuit`, and its steps to the resolver's topics."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('goal_planner', **kwargs)
        guard_clock(self)
        p = self.p = declare_parameters(
            self,
            'goal_planner.yaml',
            PARAMS,
            on_change={
                'state_timeout': self._set_state_timeout,
                'max_goal_distance': self._set_max_goal_distance,
                'max_replans': lambda v: setattr(self.pursuit, 'max_replans', int(v)),
            },
        )
        self.robot = load_robot(p.robot)
        self.obstacles = ObstacleSet(p.obstacles, p.world_frame)
        self.pursuit = GoalPursuit(
            self.robot,
            self.obstacles.obstacles,
            p.world_frame,
            p.max_goal_distance,
            FollowParams(**{name: getattr(p, name) for name in FOLLOW_PARAMS}),
            p.max_replans,
            {name: getattr(p, name) for name in PLANNER_PARAMS},
        )
        #: the odometry's checks, the resolver's own
        self.inputs = MeasuredInputs(p.world_frame, p.max_goal_distance, self.robot.base.velocity, PLAUSIBLE_FACTOR)
        self.arm = JointSelector(self.robot.arm.joints)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        #: the simulator's timing; a change starts the periods afresh on the clock now followed
        self.timing = SimTiming(self, lambda _timeout: setattr(self, '_last_tick', None))
        self.odom_fresh = Freshness(p.state_timeout)
        self.joints_fresh = Freshness(p.state_timeout)
        self._base: np.ndarray | None = None
        self._q_arm: np.ndarray | None = None
        self._sim_time = 0.0  # [s] the latest odometry's stamp: the time in lockstep
        self._last_tick: float | None = None
        self._last_robot = 0.0  # [s] the latest odometry's stamp at the last period
        self._goal_msg: PoseStamped | None = None
        #: the goal (or hold) for the resolver not yet sent: it waits until the resolver listens
        self._goal_out: PoseStamped | None = None
        self._log_throttle = PursuitLog()
        self._diagnostics_gate = DiagnosticsGate()
        self.pub_reference = self.create_publisher(MultiDOFJointTrajectory, 'ee_reference', COMMAND_QOS)
        self.pub_goal = self.create_publisher(PoseStamped, '~/goal', COMMAND_QOS)
        self.pub_path = self.create_publisher(Path, '~/path', LATCHED_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.create_subscription(PoseStamped, 'goal_pose', self._on_goal, COMMAND_QOS)
        self.create_subscription(MarkerArray, '/obstacles', self._on_obstacles, COMMAND_QOS)
        self.create_subscription(Odometry, 'odom', self._on_odom, STATE_SUB_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        self.create_timer(p.period, self._on_timer, clock=self._steady)
        self._publish_path(np.zeros((0, 3)))
        self.get_logger().info(
            f'planner of robot {self.robot.name}: {describe(self.obstacles.obstacles)}; trajectory points every '
            f'{p.period:g} s on {self.pub_reference.topic_name}, goals on {self.pub_goal.topic_name}; waiting for '
            f'/goal_pose (frame {p.world_frame!r})'
        )

    @property
    def teardown_limit(self) -> float:
        """[s] the teardown may take (:func:`~wmm_control.nodes.runner.run_node`): a plan under
        way is finished first (:meth:`destroy_node`)."""
        return self._close_timeout + 1.0

    @property
    def _close_timeout(self) -> float:
        # a plan under way: about 1 s on an idle machine; ``budget`` caps each of its searches
        return min(PLAN_WAIT, 2 * self.p.budget * ATTEMPTS * self.p.stances_tried + 5.0)

    def destroy_node(self) -> bool:
        """Stop the planner's thread (a plan under way is finished, waited for up to
        :data:`PLAN_WAIT`), then destroy the node."""
        self.pursuit.close(timeout=self._close_timeout)
        return super().destroy_node()

    def _set_max_goal_distance(self, distance: float) -> None:
        self.pursuit.max_goal_distance = self.inputs.max_distance = float(distance)

    def _set_state_timeout(self, timeout: float) -> None:
        self.odom_fresh.timeout = self.joints_fresh.timeout = float(timeout)

    def _now(self) -> float:
        """The time [s] by which the inputs are aged: the simulation's in lockstep, else the steady clock."""
        return self._sim_time if self.timing.lockstep else seconds(self._steady)

    def _log(self, events) -> None:
        log_lines(self, self._log_throttle.lines(events, seconds(self._steady)))

    # ------------------------------------------------------------------ inputs
    def _on_goal(self, msg: PoseStamped) -> None:
        events = self.pursuit.new_goal(msg.header.frame_id, pose_values(msg.pose))
        if self.pursuit.state is PursuitState.PLANNING and self.pursuit.goal is not None:
            self._goal_msg = msg
        self._log(events)

    def _on_obstacles(self, msg: MarkerArray) -> None:
        if self.obstacles.take(msg, self.get_logger(), self.p.max_obstacles):
            self.pursuit.set_obstacles(self.obstacles.obstacles)

    def _on_odom(self, msg: Odometry) -> None:
        odom, events = self.inputs.odometry(*odometry_values(msg))
        self._log(events)
        if odom is None:
            return
        self._base = odom[0]
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self._sim_time = stamp
        self.odom_fresh.mark(self._now())
        if self.timing.lockstep and (
            self._last_tick is None or not self._last_tick <= stamp < self._last_tick + self.p.period - 1e-9
        ):
            self._tick(stamp)

    def _on_joint_states(self, msg: JointState) -> None:
        q, _, reason = self.arm.read(msg)
        if q is None:
            self.get_logger().warn(f'rejected /joint_states {reason}', throttle_duration_sec=1.0)
            return
        self._q_arm = q
        self.joints_fresh.mark(self._now())

    # ------------------------------------------------------------------ the period
    def _on_timer(self) -> None:
        if not self.timing.lockstep:
            self._tick(seconds(self._steady))

    def _tick(self, now: float) -> None:
        """One period at ``now`` [s] (the steady clock, or the simulation's time in lockstep). The
        plan's clock and its stall rule run on the robot's: the advance of the odometry's stamp
        since the last period (in lockstep ``now`` itself), so a simulation slower than real time
        is not taken for a robot that makes no progress."""
        robot = self._sim_time
        dt = self.p.period if self._last_tick is None else min(max(robot - self._last_robot, 0.0), 1.0)
        self._last_tick, self._last_robot = now, robot
        fresh = self.odom_fresh.fresh(self._now())
        base = self._base if fresh else None
        q_arm = self._q_arm if self.joints_fresh.fresh(self._now()) else None
        if not fresh and self.pursuit.needs_base:
            waits = (
                'no trajectory point (the resolver holds its last one)'
                if self.pursuit.state is PursuitState.FOLLOWING
                else 'the plan waits for it'
            )
            self.get_logger().warn(
                f'/odom older than state_timeout {self.p.state_timeout:g} s: {waits}', throttle_duration_sec=2.0
            )
        out = self.pursuit.step(dt, base, q_arm)
        self._log(out.events)
        stamp = self.get_clock().now().to_msg()
        frame = self.p.world_frame
        if out.hold is not None:
            self._goal_out = target_pose_stamped(stamp, frame, out.hold)
            position = np.round(out.hold.position, 3).tolist()
            self.get_logger().info(f'holding the end effector where it is: {position}')
        if out.forward_goal and self._goal_msg is not None:
            self._goal_out = self._goal_msg
        self._send_goal()
        if out.reference is not None:
            follower = self.pursuit.follower
            t = follower.clock if follower is not None else 0.0
            self.pub_reference.publish(reference_message(out.reference, frame, stamp, t, self.robot.arm.joints))
        if out.path is not None:
            self._publish_path(out.path)
        if self._diagnostics_gate.due(seconds(self._steady), self.p.diagnostics_period):
            level, message, values = self.pursuit.status()
            values['odometry_fresh'] = fresh
            self.pub_diag.publish(
                diagnostic_array(stamp, [node_status(self, '', self.robot.name, level, message, values)])
            )

    def _send_goal(self) -> None:
        """Send the waiting goal once the resolver subscribes to it: a goal published before the
        subscription is matched (the resolver starting, or slow discovery on a loaded machine)
        would be lost, and a goal is sent only once."""
        if self._goal_out is None:
            return
        if self.pub_goal.get_subscription_count() == 0:
            self.get_logger().warn(
                f'nobody subscribes to {self.pub_goal.topic_name} yet (is redundancy_resolver running, its '
                'goal_pose remapped there?): the goal waits',
                throttle_duration_sec=2.0,
            )
            return
        self.pub_goal.publish(self._goal_out)
        self._goal_out = None

    def _publish_path(self, poses: np.ndarray) -> None:
        """``~/path``: the planned base poses (x, y, θ), in the world frame (none: an empty path)."""
        msg = Path()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.p.world_frame
        for pose in poses:
            stamped = PoseStamped()
            stamped.header = msg.header
            set_planar_pose(stamped.pose, pose)
            msg.poses.append(stamped)
        self.pub_path.publish(msg)


def main(args: list[str] | None = None) -> int:
    return run_node(GoalPlannerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
