"""The viewer's page: a viser server and everything drawn on it (ROS-free).

:class:`BrowserScene` serves the scene and the panel and keeps a handle on each thing drawn:
the robot's shapes (:class:`~wmm_control.viewer.scene.RobotScene` gives their poses), the
end effector's and the base's paths, the planner's base path, the goal, the trajectory reference, the base's course,
the obstacles and the goal handle. The caller (the ``wmm_viewer`` node) says what to draw and
when; the handle's drags and the "Hold here" button reach it through the callbacks it gives.
Quaternions are (w, x, y, z), as viser takes them.
"""

from __future__ import annotations

import contextlib
import io
import ipaddress
import socket
import threading
from collections.abc import Callable, Iterable
from typing import cast

import numpy as np
import viser

from wmm_control.errors import ConfigError
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.geometry import quaternion_from_matrix
from wmm_control.viewer.scene import ScenePoses, Shape, Trail, segments, wxyz_from_xyzw

__all__ = ['BrowserScene', 'CAMERA_LOOK_AT', 'CAMERA_POSITION', 'local_only']

#: The camera the page opens with (and "Reset View" returns to), relative to the start base position.
CAMERA_LOOK_AT = np.array([0.8, 0.3, 0.6])
CAMERA_POSITION = np.array([0.8, -2.8, 1.9])
_OBSTACLE_COLOR = (217, 140, 64)
_EE_TRAIL_COLOR = (30, 110, 230)
_BASE_TRAIL_COLOR = (40, 160, 60)
_GOAL_COLOR = (220, 30, 120)
_REFERENCE_COLOR = (130, 60, 200)
_BASE_REFERENCE_COLOR = (240, 170, 0)
_PLANNED_PATH_COLOR = (0, 170, 190)
#: Heights [m] above the floor of the base's path and of its course (above the grid).
_PATH_LIFT, _COURSE_LIFT = 0.005, 0.01


def local_only(host: str) -> bool:
    """True when a server listening on ``host`` is reached from this machine alone: every address
    the name stands for is a loopback one (127.0.0.0/8, ::1; ``localhost``). A name that does not
    resolve counts as reachable from elsewhere."""
    try:
        found = socket.getaddrinfo(host.strip(), None, proto=socket.IPPROTO_TCP)
    except (OSError, UnicodeError):
        return False
    addresses = {str(info[4][0]).split('%')[0] for info in found}
    return bool(addresses) and all(ipaddress.ip_address(a).is_loopback for a in addresses)


class BrowserScene:
    """The served page of one robot.

    Args:
        host, port: where the HTTP server listens (the next free port when ``port`` is taken).
        shapes: the robot's shapes, drawn in this order (the order of :class:`ScenePoses`).
        ground_z: the floor's height [m].
        start_xy: the base's start position (x, y) [m], which the camera looks at.
        trails: the end effector's and the base's paths.
        on_handle: called (from viser's worker thread) with each event of the goal handle.
        panel: the diagnostics panel's first text (Markdown).
        commands: False leaves out everything that commands the robot (the goal handle and
            "Hold here"): the page shows the robot and says why it sends nothing.

    Raises:
        ConfigError: the server cannot listen on ``host``:``port``.
    """

    def __init__(
        self,
        host: str,
        port: int,
        shapes: Iterable[Shape],
        ground_z: float,
        start_xy,
        trails: tuple[Trail, Trail],
        on_handle: Callable[[viser.TransformControlsEvent], None],
        panel: str,
        commands: bool = True,
    ) -> None:
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: the node logs the URL
                self.server: viser.ViserServer | None = viser.ViserServer(host=host, port=port, verbose=False)
        except OSError as exc:
            raise ConfigError(f'cannot serve on {host}:{port}: {exc}') from exc
        server = self.server
        self.port = server.get_port()
        self.ground_z = float(ground_z)
        self.ee_trail, self.base_trail = trails
        self._hold = threading.Event()
        self._handle_placed = False
        server.gui.configure_theme(control_width='large')
        server.scene.set_up_direction('+z')
        # From the side (−y), the start pose left of the centre: room for a goal ahead (+x).
        start = np.array([start_xy[0], start_xy[1], 0.0])
        server.initial_camera.look_at = CAMERA_LOOK_AT + start
        server.initial_camera.position = CAMERA_POSITION + start
        server.scene.add_grid(
            '/ground', width=20.0, height=20.0, cell_size=0.5, section_size=1.0, position=(0.0, 0.0, self.ground_z)
        )
        self.shape_handles = [self._add_shape(f'/robot/{shape.name}', shape) for shape in shapes]
        self.obstacle_handles: list[viser.SceneNodeHandle] = []
        empty = np.zeros((0, 2, 3))
        self.ee_path = server.scene.add_line_segments(
            '/paths/end_effector', empty, _EE_TRAIL_COLOR, thickness=4.0, thickness_units='screen'
        )
        self.base_path = server.scene.add_line_segments(
            '/paths/base', empty, _BASE_TRAIL_COLOR, thickness=4.0, thickness_units='screen'
        )
        self.planned_path = server.scene.add_line_segments(
            '/paths/planned', empty, _PLANNED_PATH_COLOR, thickness=3.0, thickness_units='screen', visible=False
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
        self.goal_handle: viser.TransformControlsHandle | None = None
        self.hold_button: viser.GuiButtonHandle | None = None
        if commands:
            self.goal_handle = server.scene.add_transform_controls(
                '/goal_handle', scale=0.35, depth_test=False, position=(0.0, 0.0, 0.0)
            )
            self.goal_handle.on_update(on_handle)
        with server.gui.add_folder('Goal'):
            if commands:
                self.hold_button = server.gui.add_button(
                    'Hold here',
                    hint='Publish the end effector\'s current pose as the goal: the robot stops where it is.',
                )
                self.hold_button.on_click(lambda _event: self._hold.set())
            #: what the page says of its commands: how to send a goal, or why it sends none
            self.commands_note = (
                'Drag the handle to send a goal.'
                if commands
                else f'This page is served on {host}, beyond this machine: it shows the robot and sends it '
                'nothing (the viewer\'s `allow_remote_commands` lets it).'
            )
            self.goal_text = server.gui.add_markdown(self.commands_note)
        with server.gui.add_folder('Inputs'):
            self.inputs_text = server.gui.add_markdown('*Waiting for /joint_states.*')
        with server.gui.add_folder('Diagnostics'):
            self.status_text = server.gui.add_markdown(panel)

    def _add_shape(self, name: str, shape: Shape) -> viser.SceneNodeHandle:
        assert self.server is not None  # None only once stopped
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

    def draw_obstacles(self, obstacles: Iterable[Obstacle]) -> None:
        """Draw ``obstacles`` in place of those drawn before."""
        for handle in self.obstacle_handles:
            handle.remove()
        self.obstacle_handles = []
        for obstacle in obstacles:
            handle = self._add_shape(
                f'/obstacles/{obstacle.name}', Shape(obstacle.name, obstacle.shape, obstacle.size, _OBSTACLE_COLOR, 1.0)
            )
            handle.position = obstacle.position
            handle.wxyz = wxyz_from_xyzw(quaternion_from_matrix(obstacle.rotation))
            self.obstacle_handles.append(handle)

    def draw_robot(self, poses: ScenePoses, base_position, joints_known: bool) -> None:
        """Move the shapes to ``poses`` and extend the paths (the base's at ``base_position`` on
        the floor), at once. Until a goal is known the handle waits at the end effector, from
        the first joint states on (``joints_known``)."""
        ee_moved = self.ee_trail.add(poses.ee_position)
        base_moved = self.base_trail.add((base_position[0], base_position[1], self.ground_z + _PATH_LIFT))
        assert self.server is not None
        with self.server.atomic():
            for handle, position, wxyz in zip(self.shape_handles, poses.positions, poses.wxyz):
                handle.position, handle.wxyz = position, wxyz
            if ee_moved:
                self.ee_path.points = self.ee_trail.segments()
            if base_moved:
                self.base_path.points = self.base_trail.segments()
            if not self._handle_placed and joints_known:
                self.move_handle(poses.ee_position, poses.ee_wxyz)

    def move_handle(self, position: np.ndarray, wxyz: np.ndarray) -> None:
        """Put the goal handle at a pose (nothing on a page without commands)."""
        if self.goal_handle is not None:
            self.goal_handle.position, self.goal_handle.wxyz = position, wxyz
        self._handle_placed = True

    def hold_pressed(self) -> bool:
        """True once after each press of "Hold here" (pressed in viser's worker thread)."""
        pressed = self._hold.is_set()
        self._hold.clear()
        return pressed

    def draw_course(self, base_position, velocity) -> None:
        """Show where the base heads in 1 s at world ``velocity`` (vx, vy) [m/s] from
        ``base_position``, on the floor; hide it when ``velocity`` is None."""
        if velocity is None:
            self.base_course.visible = False
            return
        start = np.array([base_position[0], base_position[1], self.ground_z + _COURSE_LIFT])
        self.base_course.points = np.stack((start, start + [velocity[0], velocity[1], 0.0]))[None]
        self.base_course.visible = True

    def draw_planned_path(self, xy: np.ndarray) -> None:
        """Draw the planner's base path through the points (x, y) [m] on the floor, in place of the
        one drawn before; hide it when there are fewer than two."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if len(xy) < 2:
            self.planned_path.visible = False
            return
        points = np.column_stack((xy, np.full(len(xy), self.ground_z + _PATH_LIFT)))
        self.planned_path.points = segments(points)
        self.planned_path.visible = True

    def show_goal(self, position: np.ndarray, wxyz: np.ndarray, move_handle: bool) -> None:
        """Draw the goal in force (and its text); the handle moves there when ``move_handle``."""
        self.goal_frame.position, self.goal_frame.wxyz = position, wxyz
        self.goal_frame.visible = True
        if move_handle:
            self.move_handle(position, wxyz)
        self.goal_text.content = (
            f'Goal in force: ({position[0]:.3f}, {position[1]:.3f}, {position[2]:.3f}) m\n\n{self.commands_note}'
        )

    def show_reference(self, position: np.ndarray, wxyz: np.ndarray) -> None:
        """Draw the trajectory reference."""
        self.reference_frame.position, self.reference_frame.wxyz = position, wxyz
        self.reference_frame.visible = True

    def stop(self) -> None:
        """Stop the HTTP server (nothing once stopped)."""
        if self.server is not None:
            with contextlib.redirect_stdout(io.StringIO()):  # viser's "Server stopped"
                self.server.stop()
            self.server = None
