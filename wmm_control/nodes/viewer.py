"""``wmm_viewer``: a live 3D view of the robot in the browser, with a goal handle to drag.

Serves a scene (viser) at ``http://<host>:<port>``, logged once it is up: the robot drawn from
its URDF's visual shapes (any URDF pinocchio loads, :mod:`wmm_control.viewer.scene`), moved
by the joint states and the base pose; the end effector's path and the base's path; the goal
in force and the trajectory reference; the base velocity the resolver asks for; and a panel
with what ``/diagnostics`` says (:mod:`wmm_control.viewer.status`).

Subscribes:
  ``/joint_states`` (``sensor_msgs/JointState``): every joint of the URDF by name (arm, steer,
  drive, wheels); names the URDF lacks are ignored;
  ``/ground_truth/odom`` (``nav_msgs/Odometry``): the base link's pose while it is fresher than
  ``ground_truth_timeout`` (the simulator publishes it); else ``/odom``;
  ``/goal_pose`` (``geometry_msgs/PoseStamped``): the goal drawn (from any publisher);
  ``/ee_reference`` (``trajectory_msgs/MultiDOFJointTrajectory``): its first point, drawn;
  ``/base/reference`` (``geometry_msgs/TwistStamped``): the resolver's base twist, drawn as
  the base's course over the next second;
  ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``): the status panel;
  ``/obstacles`` (``visualization_msgs/MarkerArray``): obstacles drawn live, beside those of the
  ``obstacles`` file; bad input (an empty message, more than ``max_obstacles`` markers, a bad
  marker) refused with a warning (:mod:`wmm_control.nodes.obstacle_topic`);
  ``goal_planner/path`` (``nav_msgs/Path``, latched): the base path ``goal_planner`` plans, drawn
  on the floor while it is in force (an empty path hides it).
Publishes:
  ``/goal_pose`` (``geometry_msgs/PoseStamped``, frame ``world_frame``) when the goal handle is
  released (and at most every ``drag_publish_period`` during a drag), and the end effector's
  current pose when "Hold here" is pressed. Never a non-finite pose.

Commands: the page drives the robot (the goal handle, "Hold here") only when it is served to
this machine alone (``host`` a loopback address, the default ``127.0.0.1``) or
``allow_remote_commands`` is true; served beyond it (``0.0.0.0``, a LAN address), it shows the
robot and publishes nothing, as the log says at start: anyone who can reach the port would
otherwise drag the goal.

Topic names are relative (``-r __ns:=/r1`` views robot ``/r1``); ``/diagnostics`` is global.
Timers run on the steady clock, so the view moves with ``use_sim_time`` too; the goal is
stamped with the node's clock.
"""

from __future__ import annotations

import math

import numpy as np
import viser
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseStamped, Transform, TwistStamped
from nav_msgs.msg import Odometry, Path
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from wmm_control.errors import NonFiniteError
from wmm_control.checks import Freshness
from wmm_control.nodes.parameters import declare_parameters
from wmm_control.nodes.qos import COMMAND_QOS, DIAGNOSTICS_QOS, LATCHED_QOS, STATE_SUB_QOS
from wmm_control.nodes.runner import guard_clock, run_node
from wmm_control.nodes.stamps import seconds
from wmm_control.nodes.conversions import planar_twist, pose_stamped, pose_values
from wmm_control.nodes.obstacle_topic import ObstacleSet
from wmm_control.nodes.viewer_params import PARAMS, check
from wmm_control.robot_config import load_robot
from wmm_control.viewer.browser import BrowserScene, local_only
from wmm_control.viewer.drag import GoalDrag
from wmm_control.viewer.inputs import BaseCourse, BasePose, inputs_markdown
from wmm_control.viewer.scene import RobotScene, Trail, finite_pose, wxyz_from_xyzw, xyzw_from_wxyz
from wmm_control.viewer.status import NodeStatus, StatusBoard

__all__ = ['ViewerNode', 'main', 'PARAMS']


def _pose(pose: Pose | Transform) -> tuple[np.ndarray, np.ndarray] | None:
    """(position, unit wxyz) of a ``geometry_msgs/Pose`` or ``Transform``; None when not a pose."""
    values = pose_values(pose)
    return finite_pose(values[:3], wxyz_from_xyzw(values[3:]))


class ViewerNode(Node):
    """Wires ROS topics to the browser scene; the page, the geometry, the choice of inputs and
    the panel text live in :mod:`wmm_control.viewer`."""

    def __init__(self, **kwargs) -> None:
        super().__init__('wmm_viewer', **kwargs)
        guard_clock(self)
        self.browser: BrowserScene | None = None
        p = self.p = declare_parameters(
            self,
            'wmm_viewer.yaml',
            PARAMS,
            check=check,
            on_change={
                'drag_publish_period': self._set_drag_period,
                'ground_truth_timeout': self._set_ground_truth_timeout,
            },
        )
        self.robot = load_robot(p.robot)
        robot = self.robot
        self.scene = RobotScene(robot.urdf_path, robot.base_link, robot.ee_frame, robot.package_dirs, robot.held_joints)
        if self.scene.skipped:
            self.get_logger().warn(f'not drawn (no drawing for their kind): {list(self.scene.skipped)}')
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.drag = GoalDrag(p.drag_publish_period)
        self.board = StatusBoard()
        self.base = BasePose(p.ground_truth_timeout)
        self.course = BaseCourse()
        self.joint_fresh = Freshness(math.inf)
        self._ee: tuple[np.ndarray, np.ndarray] | None = None  # (position, wxyz) last drawn
        self._dirty = True
        self._status_due = 0.0
        self.counters = {'joint_states_rejected': 0, 'unknown_joints': 0, 'goals_sent': 0}
        self.obstacles = ObstacleSet(p.obstacles, p.world_frame)
        trails = (Trail(p.trail_length, p.trail_step), Trail(p.trail_length, p.trail_step))
        start = self.robot.start.base_pose
        #: the page may command the robot: served to this machine alone, or allowed elsewhere
        self.commands = local_only(p.host) or p.allow_remote_commands
        self.browser = browser = BrowserScene(
            p.host,
            p.port,
            self.scene.shapes,
            self.robot.ground_z,
            start[:2],
            trails,
            on_handle=self._on_handle,
            panel=self.board.markdown(0.0),
            commands=self.commands,
        )
        browser.draw_obstacles(self.obstacles.obstacles)
        self.pub_goal = self.create_publisher(PoseStamped, 'goal_pose', COMMAND_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        self.create_subscription(
            Odometry, 'ground_truth/odom', lambda m: self._on_base(m, 'ground_truth'), STATE_SUB_QOS
        )
        self.create_subscription(Odometry, 'odom', lambda m: self._on_base(m, 'odom'), STATE_SUB_QOS)
        self.create_subscription(PoseStamped, 'goal_pose', self._on_goal, COMMAND_QOS)
        self.create_subscription(MultiDOFJointTrajectory, 'ee_reference', self._on_reference, COMMAND_QOS)
        self.create_subscription(TwistStamped, 'base/reference', self._on_base_reference, COMMAND_QOS)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, DIAGNOSTICS_QOS)
        self.create_subscription(MarkerArray, '/obstacles', self._on_obstacles, COMMAND_QOS)
        self.create_subscription(Path, 'goal_planner/path', self._on_planned_path, LATCHED_QOS)
        self.timer = self.create_timer(p.update_period, self._tick, clock=self._steady)
        self.url = f'http://{p.host}:{browser.port}'
        served = (
            f'viewer of robot {self.robot.name} at {self.url} ({len(self.scene.shapes)} shapes from '
            f'{self.robot.urdf_path.name})'
        )
        if not self.commands:
            self.get_logger().info(
                f'{served}; served beyond this machine (host {p.host}), the page shows the robot and commands '
                'nothing: allow_remote_commands:=true lets anyone who can reach the port send it goals'
            )
        elif local_only(p.host):
            self.get_logger().info(f'{served}; drag the goal handle to publish /goal_pose')
        else:
            self.get_logger().warn(
                f'{served}; allow_remote_commands is true: anyone who can reach port {browser.port} on this '
                'machine\'s network can drag the goal and move the robot'
            )

    def destroy_node(self) -> bool:
        """Stop the HTTP server, then destroy the node."""
        if self.browser is not None:
            self.browser.stop()
        return super().destroy_node()

    # ------------------------------------------------------------------ inputs
    def _now(self) -> float:
        return seconds(self._steady)

    def _set_drag_period(self, period: float) -> None:
        self.drag.period = float(period)

    def _set_ground_truth_timeout(self, timeout: float) -> None:
        self.base.set_timeout(timeout)

    def _on_obstacles(self, msg: MarkerArray) -> None:
        if self.obstacles.take(msg, self.get_logger(), self.p.max_obstacles) and self.browser is not None:
            self.browser.draw_obstacles(self.obstacles.obstacles)

    def _on_planned_path(self, msg: Path) -> None:
        if msg.header.frame_id != self.p.world_frame:
            self.get_logger().warn(
                f'goal_planner/path in frame {msg.header.frame_id!r}, not {self.p.world_frame!r}: not drawn',
                throttle_duration_sec=5.0,
            )
            return
        xy = np.array([(s.pose.position.x, s.pose.position.y) for s in msg.poses], dtype=float).reshape(-1, 2)
        if not np.all(np.isfinite(xy)):
            self.get_logger().warn('goal_planner/path with non-finite positions: not drawn', throttle_duration_sec=5.0)
            return
        if self.browser is not None:
            self.browser.draw_planned_path(xy)

    def _on_joint_states(self, msg: JointState) -> None:
        if len(msg.position) != len(msg.name):
            self.counters['joint_states_rejected'] += 1
            self.get_logger().warn(
                f'rejected /joint_states: {len(msg.position)} positions for {len(msg.name)} names',
                throttle_duration_sec=5.0,
            )
            return
        try:
            unknown = self.scene.set_joints(msg.name, msg.position)
        except NonFiniteError as exc:
            self.counters['joint_states_rejected'] += 1
            self.get_logger().warn(f'rejected /joint_states: {exc}', throttle_duration_sec=5.0)
            return
        if unknown:
            self.counters['unknown_joints'] = len(unknown)
            self.get_logger().warn(
                f'/joint_states names joints the URDF lacks (ignored): {unknown}', throttle_duration_sec=30.0
            )
        self.joint_fresh.mark(self._now())
        self._dirty = True

    def _on_base(self, msg: Odometry, source: str) -> None:
        pose = _pose(msg.pose.pose)
        if pose is None:
            self.get_logger().warn(
                f'rejected a base pose from {source}: not finite, or a zero quaternion', throttle_duration_sec=5.0
            )
            return
        self.base.take(source, *pose, self._now())
        self._dirty = True

    def base_source(self) -> str:
        """Where the base pose drawn comes from: 'ground_truth', 'odom' or 'none'."""
        return self.base.source(self._now())

    def _on_goal(self, msg: PoseStamped) -> None:
        if msg.header.frame_id not in ('', self.p.world_frame):
            self.get_logger().warn(
                f'/goal_pose in frame {msg.header.frame_id!r}, not {self.p.world_frame!r}: not drawn',
                throttle_duration_sec=5.0,
            )
            return
        pose = _pose(msg.pose)
        if pose is not None and self.browser is not None:  # else the resolver rejects it too
            self.browser.show_goal(*pose, move_handle=not self.drag.dragging)

    def _on_reference(self, msg: MultiDOFJointTrajectory) -> None:
        if not msg.points or not msg.points[0].transforms:
            return
        pose = _pose(msg.points[0].transforms[0])
        if pose is not None and self.browser is not None:
            self.browser.show_reference(*pose)

    def _on_base_reference(self, msg: TwistStamped) -> None:
        self.course.take(planar_twist(msg.twist), self._now())

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        now = self._now()
        for status in msg.status:
            self.board.update(NodeStatus.of(status, now))

    # ------------------------------------------------------------------ the goal handle
    def _on_handle(self, event: viser.TransformControlsEvent) -> None:
        """viser's callback (a worker thread): note the pose; :meth:`_tick` publishes (nothing
        when the page may not command the robot)."""
        if self.commands:
            self.drag.event(event.phase, event.target.position, event.target.wxyz, self._now())

    def publish_goal(self, position, wxyz) -> bool:
        """Publish a goal in ``world_frame`` for the page; False (nothing sent) for a non-finite
        pose, or when the page may not command the robot (:attr:`commands`)."""
        if not self.commands:
            self.get_logger().warn(
                f'goal not sent: the page is served on {self.p.host}, beyond this machine, and '
                'allow_remote_commands is false',
                throttle_duration_sec=5.0,
            )
            return False
        pose = finite_pose(position, wxyz)
        if pose is None:
            self.get_logger().warn(
                f'goal not sent: not a pose ({np.asarray(position, dtype=float).tolist()}, {np.asarray(wxyz).tolist()})'
            )
            return False
        pos, quat = pose[0], xyzw_from_wxyz(pose[1])
        self.pub_goal.publish(pose_stamped(self.get_clock().now().to_msg(), self.p.world_frame, pos, quat))
        self.counters['goals_sent'] += 1
        self.get_logger().info(
            f'goal sent: ({pos[0]:.3f}, {pos[1]:.3f}, {pos[2]:.3f}) m, quaternion (x, y, z, w) {np.round(quat, 4).tolist()}'
        )
        return True

    # ------------------------------------------------------------------ the update
    def _tick(self) -> None:
        browser = self.browser
        assert browser is not None  # None only once destroyed, and then no timer fires
        now = self._now()
        goal = self.drag.due(now)
        if goal is not None:
            self.publish_goal(*goal)
        if browser.hold_pressed() and self._ee is not None and self.publish_goal(*self._ee):
            browser.move_handle(*self._ee)
        base_position, base_wxyz = self.base.pose(now)
        if self._dirty:
            self._dirty = False
            poses = self.scene.poses(base_position, base_wxyz)
            self._ee = (poses.ee_position, poses.ee_wxyz)
            browser.draw_robot(poses, base_position, joints_known=self.joint_fresh.age(now) < math.inf)
        browser.draw_course(base_position, self.course.velocity(base_wxyz, now))
        if now >= self._status_due:
            self._status_due = now + 0.5
            browser.status_text.content = self.board.markdown(now)
            source, rejected = self.base.source(now), self.counters['joint_states_rejected']
            browser.inputs_text.content = inputs_markdown(
                self.joint_fresh.age(now), source, rejected, self.counters['goals_sent']
            )


def main(args: list[str] | None = None) -> int:
    return run_node(ViewerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
