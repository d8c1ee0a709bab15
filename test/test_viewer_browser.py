"""``wmm_viewer`` in a real browser: headless Chromium (software WebGL) on the page it serves.

Robot A's system (simulator, steerable-base controller, resolver, viewer), and robot B's
(its Mecanum-base controller, AMP), each runs as four processes on a private ROS domain; the test drives Chromium through the DevTools protocol and
checks, on screenshots of the canvas and on the topics, that
1. the robot is drawn where it is: the robot's orange (its URDF colour) around where its arm
   projects through the page's camera, its dark wheels around its wheels, and no orange far
   from it;
2. a mouse drag of the goal handle (``Input.dispatchMouseEvent``) makes ``/goal_pose`` arrive,
   frame ``world``, finite, published once for a short drag;
3. two screenshots taken while the arm moves to a published goal differ.

``WMM_UPDATE_FIGURES=1`` writes the last screenshot to ``docs/figures/viewer.png``.
Without Chromium the test is skipped.
"""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from browser_helpers import Browser, chromium_path

REPO = Path(__file__).resolve().parent.parent
FIGURE = REPO / 'docs' / 'figures' / 'viewer.png'
WIDTH, HEIGHT = 1280, 800

#: Per robot: its name, its base controller's module, a goal (position, quaternion x y z w) that
#: moves the arm, and the brightest channel of its wheels' dark grey once lit.
ROBOTS = {
    'A': ('steerable', 'wmm_control.nodes.swmr_controller', (2.0, 1.0, 1.0), (0.0, 0.0, 0.0, 1.0), 70),
    'B': ('mecanum', 'wmm_control.nodes.mecanum_controller', (1.1, 0.3, 0.7), (0.0, 0.5**0.5, 0.0, 0.5**0.5), 95),
}

pytestmark = pytest.mark.skipif(
    chromium_path() is None, reason='chromium is not installed (apt-get install chromium): browser test skipped'
)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


class Process:
    """One node as its own process (``python -m module``), its output collected."""

    def __init__(self, module: str, args: list[str], env: dict) -> None:
        self.name = module
        self.proc = subprocess.Popen(
            [sys.executable, '-m', module, *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        self.lines: list[str] = []
        threading.Thread(target=lambda: self.lines.extend(self.proc.stdout), daemon=True).start()

    def output(self) -> str:
        return ''.join(self.lines)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(2)
        try:
            return self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait()


# ---------------------------------------------------------------- where things are on the page

FOV = math.radians(75.0)  # the vertical field of view of the page's camera


def project(points, camera_position, look_at, width, height, fov=FOV):
    """Pixel (x, y) of world ``points`` (n, 3) seen by a pinhole camera, z up (three.js' perspective
    camera: vertical field of view ``fov``, the page's aspect)."""
    c = np.asarray(camera_position, dtype=float)
    forward = np.asarray(look_at, dtype=float) - c
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.atleast_2d(points) - c
    depth = d @ forward
    f = 1.0 / math.tan(fov / 2.0)
    x_ndc = (d @ right) * f / (depth * width / height)
    y_ndc = (d @ up) * f / depth
    return np.stack(((x_ndc + 1.0) / 2.0 * width, (1.0 - y_ndc) / 2.0 * height), axis=1)


def orange(img):
    """Pixels of the robot's orange (URDF rgba 1 0.45 0 on robot A, 0.85 0.55 0.10 on B), shaded
    by the lights: red high, green well below it, blue low."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > 140) & (g > 0.25 * r) & (g < 0.75 * r) & (b < 0.35 * r)


def dark(img, brightest=70):
    """Pixels of the wheels' dark grey (URDF rgba 0.15 0.15 0.15 on robot A, 0.25 0.27 0.30 on B)."""
    return img.max(axis=2) < brightest


def gizmo_red(img):
    """Pixels of the goal handle's x-axis colour (#ff2060: red, little green, some blue)."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > 200) & (g < 90) & (b > 50) & (b < 170)


def window_count(mask, x, y, half):
    h, w = mask.shape
    x0, x1 = max(int(x) - half, 0), min(int(x) + half + 1, w)
    y0, y1 = max(int(y) - half, 0), min(int(y) + half + 1, h)
    return int(mask[y0:y1, x0:x1].sum()) if x0 < x1 and y0 < y1 else 0


def densest(mask, around, radius, half=4):
    """The pixel of ``mask`` within ``radius`` of ``around`` with the most ``mask`` pixels about it."""
    ys, xs = np.nonzero(mask)
    near = (xs - around[0]) ** 2 + (ys - around[1]) ** 2 < radius**2
    best, where = 0, None
    for x, y in zip(xs[near], ys[near]):
        n = window_count(mask, x, y, half)
        if n > best:
            best, where = n, (float(x), float(y))
    return where


# ---------------------------------------------------------------- the test

#: Close the page's notices (the client's "Software WebGL rendering detected"): number closed.
DISMISS_NOTICES = "[...document.querySelectorAll('[class*=\"Notification-root\"] button')].map(b => b.click()).length"


@pytest.fixture(params=sorted(ROBOTS), ids=lambda k: f'robot_{k}')
def system(request):
    """A robot's three nodes and the viewer, each its own process, on a private domain."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    from wmm_control.experiments.ros_run import private_domain_id

    domain = private_domain_id()
    port = free_port()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    name, controller, goal, orientation, brightest = ROBOTS[request.param]
    robot = ['--ros-args', '-p', f'robot:={name}']
    procs = [
        Process('sim_bridge.node', robot, env),
        Process(controller, [], env),
        Process('wmm_control.nodes.redundancy_resolver', robot, env),
        Process('wmm_control.nodes.viewer', [*robot, '-p', 'host:=127.0.0.1', '-p', f'port:={port}'], env),
    ]
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('viewer_test', context=context)
    goals, joints = [], []
    node.create_subscription(PoseStamped, '/goal_pose', goals.append, 10)
    node.create_subscription(JointState, '/joint_states', lambda m: joints.append(m), 10)
    publisher = node.create_publisher(PoseStamped, '/goal_pose', 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin():
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    state = {
        'node': node,
        'goals': goals,
        'joints': joints,
        'publisher': publisher,
        'procs': procs,
        'url': f'http://127.0.0.1:{port}',
        'robot': name,
        'goal': goal,
        'orientation': orientation,
        'brightest': brightest,
        'key': request.param,
    }
    try:
        yield state
    finally:
        spinning.clear()
        spinner.join(timeout=5)
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        codes = {p.name: p.stop() for p in procs}
        for p in procs:
            assert codes[p.name] == 0 and 'Traceback' not in p.output(), f'{p.name} exit {codes[p.name]}:\n{p.output()}'


def wait_for(predicate, timeout, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.1)
    raise AssertionError(f'timed out after {timeout} s waiting for {what}')


def arm_positions(msg):
    positions = dict(zip(msg.name, msg.position))
    return np.array([positions[f'arm_joint_{k}'] for k in range(1, 8)])


def save(img, path):
    from PIL import Image

    Image.fromarray(img).save(path)


def test_the_viewer_draws_the_robot_moves_it_and_its_goal_handle_publishes_a_goal(system, tmp_path):
    from geometry_msgs.msg import PoseStamped

    from wmm_control.viewer.browser import CAMERA_LOOK_AT, CAMERA_POSITION
    from wmm_control.robot_config import load_robot
    from wmm_control.viewer.scene import RobotScene

    viewer = system['procs'][-1]
    wait_for(
        lambda: f'viewer of robot {system["robot"]} at http://' in viewer.output(), 60, 'the viewer\'s URL in its log'
    )
    wait_for(lambda: len(system['joints']) > 10, 60, '/joint_states')

    # Where the robot is: its start state through the page's camera.
    robot = load_robot(system['robot'])
    scene = RobotScene(robot.urdf_path, robot.base_link, robot.ee_frame)
    scene.set_joints(robot.arm.joints, robot.start.arm)
    x0, y0, th0 = robot.start.base_pose
    poses = scene.poses((x0, y0, 0.0), (math.cos(th0 / 2), 0.0, 0.0, math.sin(th0 / 2)))
    camera = CAMERA_POSITION + np.array([x0, y0, 0.0]), CAMERA_LOOK_AT + np.array([x0, y0, 0.0])
    pixels = project(poses.positions, *camera, WIDTH, HEIGHT)
    names = [s.name for s in scene.shapes]
    arm = pixels[
        [
            i
            for i, n in enumerate(names)
            if n.startswith('arm_link_') and orange(np.array([[scene.shapes[i].color]], dtype=np.uint8))[0, 0]
        ]
    ]
    wheels = pixels[[i for i, n in enumerate(names) if n.startswith('wheel_')]]
    handle = project(poses.ee_position, *camera, WIDTH, HEIGHT)[0]

    browser = Browser(chromium_path(), WIDTH, HEIGHT)
    try:
        browser.navigate(system['url'])
        wait_for(lambda: browser.evaluate(DISMISS_NOTICES) is not None, 60, 'the page')

        # 1. The robot drawn where it is, in its colours.
        def robot_drawn():
            img = browser.screenshot()
            hits = sum(window_count(orange(img), x, y, 25) > 20 for x, y in arm)
            return (
                img
                if hits >= len(arm) - 1
                and sum(window_count(dark(img, system['brightest']), x, y, 20) > 15 for x, y in wheels) >= 3
                else None
            )

        end = time.monotonic() + 120
        img = None
        while img is None and time.monotonic() < end:
            img = robot_drawn()
        assert img is not None, 'the canvas does not show the robot\'s orange arm and dark wheels where they are'
        browser.evaluate(DISMISS_NOTICES)
        time.sleep(1.0)
        img = browser.screenshot()
        save(img, tmp_path / 'start.png')
        box = np.vstack((pixels, [handle]))
        lo, hi = box.min(axis=0) - 120, box.max(axis=0) + 120
        ys, xs = np.nonzero(orange(img[:, : WIDTH - 420]))  # the panel (right) has no orange
        far = (xs < lo[0]) | (xs > hi[0]) | (ys < lo[1]) | (ys > hi[1])
        assert far.sum() < 50, f'{far.sum()} orange pixels far from the robot (screenshot {tmp_path / "start.png"})'

        # 2. A drag of the goal handle publishes /goal_pose once, at its end.
        spot = densest(gizmo_red(img), handle, 150)
        assert spot is not None, f'no goal handle drawn near the end effector at {handle.round()}'
        before = len(system['goals'])
        began = time.monotonic()
        browser.drag(spot, (spot[0] + 40, spot[1] + 25))
        took = time.monotonic() - began
        wait_for(lambda: len(system['goals']) > before, 30, '/goal_pose after the drag')
        time.sleep(2.0)
        sent = system['goals'][before:]
        # One at the release, and at most one per drag_publish_period (0.5 s) before it; none after.
        assert 1 <= len(sent) <= 2 + took / 0.5, f'{len(sent)} goals for a drag of {took:.1f} s:\n' + ''.join(
            viewer.lines[-30:]
        )
        settled = len(system['goals'])
        time.sleep(2.0)
        assert len(system['goals']) == settled, 'goals still published after the drag ended'
        goal = sent[0]
        values = [
            goal.pose.position.x,
            goal.pose.position.y,
            goal.pose.position.z,
            goal.pose.orientation.x,
            goal.pose.orientation.y,
            goal.pose.orientation.z,
            goal.pose.orientation.w,
        ]
        assert goal.header.frame_id == 'world' and all(math.isfinite(v) for v in values), goal
        moved = (
            math.dist(values[:3], poses.ee_position) > 1e-3
            or abs(np.dot(values[3:], [*poses.ee_wxyz[1:], poses.ee_wxyz[0]])) < 1.0 - 1e-6
        )
        assert moved, f'the dragged goal {values} is the handle\'s start pose'

        # 3. Two screenshots while the arm moves to a published goal differ.
        msg = PoseStamped()
        msg.header.frame_id = 'world'
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = system['goal']
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = system['orientation']
        system['publisher'].publish(msg)
        start = arm_positions(system['joints'][-1])
        wait_for(lambda: np.abs(arm_positions(system['joints'][-1]) - start).max() > 0.05, 60, 'the arm to move')
        first = browser.screenshot()
        q_first = arm_positions(system['joints'][-1])
        time.sleep(1.5)
        second = browser.screenshot()
        q_second = arm_positions(system['joints'][-1])
        assert np.abs(q_second - q_first).max() > 0.01, 'the arm stood still between the screenshots'
        changed = np.abs(first.astype(int) - second.astype(int)).max(axis=2) > 30
        assert changed[:, : WIDTH - 420].sum() > 300, f'only {changed.sum()} pixels changed while the arm moved'
        if os.environ.get('WMM_UPDATE_FIGURES') == '1' and system['key'] == 'A':
            time.sleep(4.0)
            FIGURE.parent.mkdir(parents=True, exist_ok=True)
            save(browser.screenshot(), FIGURE)
    finally:
        browser.close()
