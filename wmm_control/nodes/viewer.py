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
  ``obstacles`` file (:mod:`wmm_control.nodes.obstacle_topic`).
Publishes:
  ``/goal_pose`` (``geometry_msgs/PoseStamped``, frame ``world_frame``) when the goal handle is
  released (and at most every ``drag_publish_period`` during a drag), and the end effector's
  current pose when "Hold here" is pressed. Never a non-finite pose.

Topic names are relative (``-r __ns:=/r1`` views robot ``/r1``); ``/diagnostics`` is global.
Timers run on the steady clock, so the view moves with ``use_sim_time`` too; the goal is
stamped with the node's clock.
"""

from __future__ import annotations

import contextlib
import io
import math
import threading
from types import SimpleNamespace
from typing import cast

import numpy as np
import viser
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseStamped, Transform, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from wmm_control.errors import ConfigError, NonFiniteError
from wmm_control.checks import Freshness
from wmm_control.nodes.parameters import Param, declare_parameters, robot_param
from wmm_control.nodes.qos import COMMAND_QOS, DIAGNOSTICS_QOS, STATE_SUB_QOS
from wmm_control.nodes.runner import guard_clock, run_node
from wmm_control.nodes.stamps import seconds
from wmm_control.kinematics.orientation import quaternion_from_matrix, yaw_from_quaternion
from wmm_control.nodes.conversions import planar_twist, pose_values, set_pose
from wmm_control.nodes.obstacle_topic import OBSTACLE_PARAM_HELP, ObstacleSet
from wmm_control.robot_config import load_robot
from wmm_control.viewer.drag import GoalDrag
from wmm_control.viewer.scene import RobotScene, Shape, Trail, unit_wxyz, wxyz_from_xyzw, xyzw_from_wxyz
from wmm_control.viewer.status import NodeStatus, StatusBoard

__all__ = ['ViewerNode', 'main', 'PARAMS']

PARAMS = (
    robot_param('The robot drawn (its URDF, base link, end-effector frame and floor height).'),
    Param('host', 'Address the HTTP server listens on (0.0.0.0: every interface).', read_only=True),
    Param(
        'port', 'HTTP port of the viewer; when it is taken, the next free one (logged).', lo=1, hi=65535, read_only=True
    ),
    Param('world_frame', 'Frame of /goal_pose, /ee_reference and /obstacles.', read_only=True),
    Param('obstacles', OBSTACLE_PARAM_HELP, read_only=True),
    Param(
        'update_period',
        'Steady time [s] between two scene updates sent to the browser.',
        lo=0.01,
        hi=1.0,
        read_only=True,
    ),
    Param(
        'drag_publish_period',
        'While the goal handle is dragged, /goal_pose goes out at most this often [s]; once more at release.',
        lo=0.05,
        hi=60.0,
    ),
    Param(
        'ground_truth_timeout',
        'The base pose comes from /ground_truth/odom while its last message is younger '
        'than this [s] (steady clock, at receipt), else from /odom.',
        lo=0.01,
        hi=60.0,
    ),
    Param('trail_length', 'Points kept on the end-effector and base paths.', lo=2, hi=1_000_000, read_only=True),
    Param('trail_step', 'Distance [m] between two points of a path.', lo=1e-4, hi=10.0, read_only=True),
)

_OBSTACLE_COLOR = (217, 140, 64)
#: The camera the page opens with (and "Reset View" returns to), relative to the start base position.
CAMERA_LOOK_AT = np.array([0.8, 0.3, 0.6])
CAMERA_POSITION = np.array([0.8, -2.8, 1.9])
_EE_TRAIL_COLOR = (30, 110, 230)
_BASE_TRAIL_COLOR = (40, 160, 60)
_GOAL_COLOR = (220, 30, 120)
_REFERENCE_COLOR = (130, 60, 200)
_BASE_REFERENCE_COLOR = (240, 170, 0)


def _check(values: SimpleNamespace) -> str:
    if not str(values.host).strip():
        return 'parameter host: empty; give an address, e.g. 0.0.0.0 or 127.0.0.1'
    return ''


def _pose_arrays(pose: Pose | Transform) -> tuple[np.ndarray, np.ndarray | None]:
    """(position, unit wxyz or None) of a ``geometry_msgs/Pose`` or ``Transform``."""
    values = pose_values(pose)
    pos = values[:3]
    quat = unit_wxyz(wxyz_from_xyzw(values[3:]))
    if not np.all(np.isfinite(pos)):
        return pos, None
    return pos, quat


class ViewerNode(Node):
    """Wires ROS topics to the browser scene; the geometry and the panel text live in
    :mod:`wmm_control.viewer`."""

    def __init__(self, **kwargs) -> None:
        super().__init__('wmm_viewer', **kwargs)
        guard_clock(self)
        self.server: viser.ViserServer | None = None
        p = self.p = declare_parameters(
            self,
            'wmm_viewer.yaml',
            PARAMS,
            check=_check,
            on_change={
                'drag_publish_period': self._set_drag_period,
                'ground_truth_timeout': self._set_ground_truth_timeout,
            },
        )
        self.robot = load_robot(p.robot)
        self.scene = RobotScene(self.robot.urdf_path, self.robot.base_link, self.robot.ee_frame)
        if self.scene.skipped:
            self.get_logger().warn(f'not drawn (no drawing for their kind): {list(self.scene.skipped)}')
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.drag = GoalDrag(p.drag_publish_period)
        self.ee_trail = Trail(p.trail_length, p.trail_step)
        self.base_trail = Trail(p.trail_length, p.trail_step)
        self.board = StatusBoard()
        self.fresh = {k: Freshness(p.ground_truth_timeout) for k in ('ground_truth', 'odom')}
        self.joint_fresh = Freshness(math.inf)
        # (position, wxyz) per source
        self._base: dict[str, tuple[np.ndarray, np.ndarray] | None] = {'ground_truth': None, 'odom': None}
        self._base_twist: np.ndarray | None = None  # (vx, vy, ω) of /base/reference
        self._base_twist_fresh = Freshness(1.0)
        self._ee: tuple[np.ndarray, np.ndarray] | None = None  # (position, wxyz) last drawn
        self._goal: tuple[np.ndarray, np.ndarray] | None = None  # (position, wxyz) in force
        self._handle_placed = False
        self._hold = threading.Event()
        self._dirty = True
        self._status_due = 0.0
        self.counters = {'joint_states_rejected': 0, 'unknown_joints': 0, 'goals_sent': 0}
        self.obstacles = ObstacleSet(p.obstacles, p.world_frame)
        self.obstacle_handles: list[viser.SceneNodeHandle] = []
        server = self._start_server()
        self._draw_obstacles()
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
        self.timer = self.create_timer(p.update_period, self._tick, clock=self._steady)
        self.url = f'http://{p.host}:{server.get_port()}'
        self.get_logger().info(
            f'viewer of robot {self.robot.name} at {self.url} ({len(self.scene.shapes)} shapes '
            f'from {self.robot.urdf_path.name}); drag the goal handle to publish /goal_pose'
        )

    # ------------------------------------------------------------------ the browser scene
    def _start_server(self) -> viser.ViserServer:
        p = self.p
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: the node logs the URL
                self.server = viser.ViserServer(host=p.host, port=p.port, verbose=False)
        except OSError as exc:
            raise ConfigError(f'cannot serve on {p.host}:{p.port}: {exc}') from exc
        server = self.server
        server.gui.configure_theme(control_width='large')
        server.scene.set_up_direction('+z')
        start = self.robot.start.base_pose
        # From the side (−y), the start pose left of the centre: room for a goal ahead (+x).
        server.initial_camera.look_at = CAMERA_LOOK_AT + np.array([start[0], start[1], 0.0])
        server.initial_camera.position = CAMERA_POSITION + np.array([start[0], start[1], 0.0])
        server.scene.add_grid(
            '/ground',
            width=20.0,
            height=20.0,
            cell_size=0.5,
            section_size=1.0,
            position=(0.0, 0.0, self.robot.ground_z),
        )
        self.shape_handles = [self._add_shape(f'/robot/{shape.name}', shape) for shape in self.scene.shapes]
        empty = np.zeros((0, 2, 3))
        self.ee_path = server.scene.add_line_segments(
            '/paths/end_effector', empty, _EE_TRAIL_COLOR, thickness=4.0, thickness_units='screen'
        )
        self.base_path = server.scene.add_line_segments(
            '/paths/base', empty, _BASE_TRAIL_COLOR, thickness=4.0, thickness_units='screen'
        )
        self.base_course = server.scene.add_line_segments(
            '/base_reference', empty, _BASE_REFERENCE_COLOR, thickness=6.0, thickness_units='screen', visible=False
        )
        self.goal_frame = server.scene.add_frame(
            '/goal', axes_length=0.15, axes_radius=0.008, origin_radius=0.03, origin_color=_GOAL_COLOR, visible=False
        )
        self.reference_frame = server.scene.add_frame(
            '/reference',
            axes_length=0.1,
            axes_radius=0.006,
            origin_radius=0.02,
            origin_color=_REFERENCE_COLOR,
            visible=False,
        )
        self.goal_handle = server.scene.add_transform_controls(
            '/goal_handle', scale=0.35, depth_test=False, position=(0.0, 0.0, 0.0)
        )
        self.goal_handle.on_update(self._on_handle)
        with server.gui.add_folder('Goal'):
            self.hold_button = server.gui.add_button(
                'Hold here', hint='Publish the end effector\'s current pose as the goal: the robot stops where it is.'
            )
            self.hold_button.on_click(lambda _event: self._hold.set())
            self.goal_text = server.gui.add_markdown('Drag the handle to send a goal.')
        with server.gui.add_folder('Inputs'):
            self.inputs_text = server.gui.add_markdown('*Waiting for /joint_states.*')
        with server.gui.add_folder('Diagnostics'):
            self.status_text = server.gui.add_markdown(self.board.markdown(0.0))
        return server

    def _add_shape(self, name: str, shape: Shape) -> viser.SceneNodeHandle:
        assert self.server is not None  # started in __init__, None only once destroyed
        scene = self.server.scene
        opacity = None if shape.opacity >= 1.0 else shape.opacity
        if shape.kind == 'box':  # size (x, y, z)
            return scene.add_box(
                name, color=shape.color, dimensions=cast(tuple[float, float, float], shape.size), opacity=opacity
            )
        if shape.kind == 'cylinder':
            return scene.add_cylinder(
                name, radius=shape.size[0], height=shape.size[1], color=shape.color, opacity=opacity
            )
        if shape.kind == 'sphere':
            return scene.add_icosphere(name, radius=shape.size[0], color=shape.color, opacity=opacity)
        return scene.add_mesh_simple(name, shape.vertices, shape.faces, color=shape.color, opacity=opacity)

    def _draw_obstacles(self) -> None:
        """The obstacles, drawn anew."""
        for handle in self.obstacle_handles:
            handle.remove()
        self.obstacle_handles = []
        for obstacle in self.obstacles.obstacles:
            handle = self._add_shape(
                f'/obstacles/{obstacle.name}', Shape(obstacle.name, obstacle.shape, obstacle.size, _OBSTACLE_COLOR, 1.0)
            )
            handle.position = obstacle.position
            handle.wxyz = wxyz_from_xyzw(quaternion_from_matrix(obstacle.rotation))
            self.obstacle_handles.append(handle)

    def _on_obstacles(self, msg: MarkerArray) -> None:
        if self.obstacles.take(msg, self.get_logger()):
            self._draw_obstacles()

    def destroy_node(self) -> bool:
        """Stop the HTTP server, then destroy the node."""
        if self.server is not None:
            with contextlib.redirect_stdout(io.StringIO()):  # viser's "Server stopped"
                self.server.stop()
            self.server = None
        return super().destroy_node()

    # ------------------------------------------------------------------ inputs
    def _now(self) -> float:
        return seconds(self._steady)

    def _set_drag_period(self, period: float) -> None:
        self.drag.period = float(period)

    def _set_ground_truth_timeout(self, timeout: float) -> None:
        for fresh in self.fresh.values():
            fresh.timeout = float(timeout)

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
        pos, quat = _pose_arrays(msg.pose.pose)
        if quat is None:
            self.get_logger().warn(
                f'rejected a base pose from {source}: not finite, or a zero quaternion', throttle_duration_sec=5.0
            )
            return
        self._base[source] = (pos, quat)
        self.fresh[source].mark(self._now())
        self._dirty = True

    def base_source(self) -> str:
        """Where the base pose drawn comes from: 'ground_truth', 'odom' or 'none'."""
        now = self._now()
        if self._base['ground_truth'] is not None and self.fresh['ground_truth'].fresh(now):
            return 'ground_truth'
        if self._base['odom'] is not None:
            return 'odom'
        return 'ground_truth' if self._base['ground_truth'] is not None else 'none'

    def _on_goal(self, msg: PoseStamped) -> None:
        if msg.header.frame_id not in ('', self.p.world_frame):
            self.get_logger().warn(
                f'/goal_pose in frame {msg.header.frame_id!r}, not {self.p.world_frame!r}: not drawn',
                throttle_duration_sec=5.0,
            )
            return
        pos, quat = _pose_arrays(msg.pose)
        if quat is None:
            return  # the resolver rejects it too; nothing to draw
        self._goal = (pos, quat)
        self.goal_frame.position, self.goal_frame.wxyz = pos, quat
        self.goal_frame.visible = True
        if not self.drag.dragging:
            self.goal_handle.position, self.goal_handle.wxyz = pos, quat
            self._handle_placed = True
        self.goal_text.content = f'Goal in force: ({pos[0]:.3f}, {pos[1]:.3f}, {pos[2]:.3f}) m'

    def _on_reference(self, msg: MultiDOFJointTrajectory) -> None:
        if not msg.points or not msg.points[0].transforms:
            return
        pos, quat = _pose_arrays(msg.points[0].transforms[0])
        if quat is None:
            return
        self.reference_frame.position, self.reference_frame.wxyz = pos, quat
        self.reference_frame.visible = True

    def _on_base_reference(self, msg: TwistStamped) -> None:
        twist = planar_twist(msg.twist)
        if np.all(np.isfinite(twist)):
            self._base_twist = twist
            self._base_twist_fresh.mark(self._now())

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        now = self._now()
        for status in msg.status:
            self.board.update(
                NodeStatus(
                    status.name,
                    int.from_bytes(status.level, 'little') if isinstance(status.level, bytes) else int(status.level),
                    status.message,
                    {kv.key: kv.value for kv in status.values},
                    now,
                )
            )

    # ------------------------------------------------------------------ the goal handle
    def _on_handle(self, event: viser.TransformControlsEvent) -> None:
        """viser's callback (a worker thread): note the pose; :meth:`_tick` publishes."""
        target = event.target
        if event.phase == 'start':
            self.drag.start()
        elif event.phase == 'end':
            self.drag.end(target.position, target.wxyz, self._now())
        else:
            self.drag.update(target.position, target.wxyz, self._now())

    def publish_goal(self, position, wxyz) -> bool:
        """Publish a goal in ``world_frame``; False (nothing sent) for a non-finite pose."""
        pos = np.asarray(position, dtype=float)
        quat = unit_wxyz(wxyz)
        if quat is None or pos.shape != (3,) or not np.all(np.isfinite(pos)):
            self.get_logger().warn(f'goal not sent: not a pose ({pos.tolist()}, {np.asarray(wxyz).tolist()})')
            return False
        msg = PoseStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.p.world_frame
        set_pose(msg.pose, pos, xyzw_from_wxyz(quat))
        self.pub_goal.publish(msg)
        self.counters['goals_sent'] += 1
        self.get_logger().info(
            f'goal sent: ({pos[0]:.3f}, {pos[1]:.3f}, {pos[2]:.3f}) m, '
            f'quaternion (x, y, z, w) {np.round(xyzw_from_wxyz(quat), 4).tolist()}'
        )
        return True

    # ------------------------------------------------------------------ the update
    def _tick(self) -> None:
        now = self._now()
        goal = self.drag.due(now)
        if goal is not None:
            self.publish_goal(*goal)
        if self._hold.is_set():
            self._hold.clear()
            if self._ee is not None and self.publish_goal(*self._ee):
                self.goal_handle.position, self.goal_handle.wxyz = self._ee
        if self._dirty:
            self._dirty = False
            self._draw_robot()
        self._draw_base_course(now)
        if now >= self._status_due:
            self._status_due = now + 0.5
            self.status_text.content = self.board.markdown(now)
            self.inputs_text.content = self._inputs_markdown(now)

    def _base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        source = self.base_source()
        if source == 'none':
            return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        pose = self._base[source]
        assert pose is not None  # base_source() names a source with a pose
        return pose

    def _draw_robot(self) -> None:
        base_pos, base_quat = self._base_pose()
        poses = self.scene.poses(base_pos, base_quat)
        self._ee = (poses.ee_position, poses.ee_wxyz)
        ee_moved = self.ee_trail.add(poses.ee_position)
        base_moved = self.base_trail.add((base_pos[0], base_pos[1], self.robot.ground_z + 0.005))
        assert self.server is not None
        with self.server.atomic():
            for handle, position, wxyz in zip(self.shape_handles, poses.positions, poses.wxyz):
                handle.position, handle.wxyz = position, wxyz
            if ee_moved:
                self.ee_path.points = self.ee_trail.segments()
            if base_moved:
                self.base_path.points = self.base_trail.segments()
            if not self._handle_placed and self.joint_fresh.age(self._now()) < math.inf:
                # Until a goal is known the handle waits at the end effector.
                self.goal_handle.position, self.goal_handle.wxyz = self._ee
                self._handle_placed = True

    def _draw_base_course(self, now: float) -> None:
        twist = self._base_twist
        if twist is None or not self._base_twist_fresh.fresh(now) or not np.any(twist[:2]):
            self.base_course.visible = False
            return
        pos, quat = self._base_pose()
        yaw = yaw_from_quaternion(xyzw_from_wxyz(quat))
        c, s = math.cos(yaw), math.sin(yaw)
        velocity = np.array([c * twist[0] - s * twist[1], s * twist[0] + c * twist[1], 0.0])
        start = np.array([pos[0], pos[1], self.robot.ground_z + 0.01])
        self.base_course.points = np.stack((start, start + velocity))[None]  # where it heads in 1 s
        self.base_course.visible = True

    def _inputs_markdown(self, now: float) -> str:
        def age(fresh: Freshness) -> str:
            a = fresh.age(now)
            return 'never' if a == math.inf else f'{a:.2f} s ago'

        source = {
            'ground_truth': 'the simulator\'s ground truth (/ground_truth/odom)',
            'odom': 'odometry (/odom)',
            'none': 'none yet (drawn at the origin)',
        }[self.base_source()]
        return '\n'.join(
            [
                f'- joint states: {age(self.joint_fresh)}',
                f'- base pose from {source}',
                f'- joint states rejected: {self.counters["joint_states_rejected"]}',
                f'- goals sent: {self.counters["goals_sent"]}',
            ]
        )


def main(args=None):
    return run_node(ViewerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
