"""The launch files, started with the real ``ros2 launch`` as a user would: each system comes up and
takes the end effector to a goal published on /goal_pose, and Ctrl-C (SIGINT to the process
group, as a terminal sends it) ends every node cleanly. ``ros2`` and ``ros2 launch`` are not on
PyPI: where they are not installed next to this interpreter, these tests are skipped."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROS2 = Path(sys.executable).with_name('ros2')


def _launch_available():
    if not ROS2.exists():
        return False
    try:
        import launch_ros  # noqa: F401
    except ImportError:
        return False
    return True


pytestmark = pytest.mark.skipif(
    not _launch_available(), reason='the ros2 command line and ros2 launch are not installed in this venv'
)

from test_packaging import installed_env  # noqa: E402
from wmm_control.experiments.ros_run import private_domain_id  # noqa: E402


def _goal(robot):
    """A goal 10 cm ahead of the robot's start end-effector pose (forward kinematics of its start
    state), same orientation."""
    from wmm_control.kinematics import KinematicModel
    from wmm_control.kinematics.frames import quaternion_from_matrix

    model = KinematicModel(robot)
    start = model.config.start
    model.update(np.asarray(start.base_pose, dtype=float), np.asarray(start.arm, dtype=float))
    position, rotation = model.ee_placement_world()
    return position + [0.1, 0.0, 0.0], quaternion_from_matrix(rotation)


def _launch(install, domain, args):
    env = dict(installed_env(install), ROS_DOMAIN_ID=str(domain))
    env['PATH'] = os.pathsep.join([str(ROS2.parent), env.get('PATH', '')])
    return subprocess.Popen(
        [str(ROS2), 'launch', 'wmm_control', *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )


def _interrupt(proc):
    """Ctrl-C in the terminal: SIGINT to the whole process group; the exit code and the output."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    return proc.returncode, out


def _reach(domain, goals, use_sim_time, timeout=150.0):
    """Publish each namespace's goal until its /ee_pose is within 1 cm; which were reached."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.parameter import Parameter

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node(
        'launch_test', context=context, parameter_overrides=[Parameter('use_sim_time', value=False)]
    )
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    ee, pubs, msgs = {}, {}, {}
    for ns, (position, quat) in goals.items():
        node.create_subscription(
            PoseStamped,
            f'{ns}/ee_pose',
            lambda m, ns=ns: ee.__setitem__(ns, np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])),
            10,
        )
        pubs[ns] = node.create_publisher(PoseStamped, f'{ns}/goal_pose', 10)
        msg = PoseStamped()
        msg.header.frame_id = 'world'
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in position)
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in quat)
        msgs[ns] = msg
    reached = set()
    try:
        end = time.monotonic() + timeout
        while time.monotonic() < end and len(reached) < len(goals):
            executor.spin_once(timeout_sec=0.05)
            for ns, pub in pubs.items():
                if node.count_subscribers(f'{ns}/goal_pose') and int(time.monotonic() * 2) % 2 == 0:
                    pub.publish(msgs[ns])  # again and again: the resolver may join late
                if ns in ee and np.linalg.norm(ee[ns] - goals[ns][0]) < 0.01:
                    reached.add(ns)
    finally:
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return reached, ee


CASES = [
    ('robot_a.launch.py', [], {'': 'steerable'}, 3),
    ('robot_b.launch.py', ['use_sim_time:=true'], {'': 'mecanum'}, 3),
    ('robot.launch.py', ['robot:=panda_diff'], {'': 'panda_diff'}, 3),
    # the resolver takes its goals from goal_planner: reaching one says the planner forwarded it
    ('robot.launch.py', ['planner:=true', 'obstacles:=table_pillar'], {'': 'steerable'}, 4),
    ('two_robots.launch.py', ['use_sim_time:=true'], {'/r1': 'steerable', '/r2': 'mecanum'}, 6),
]


@pytest.mark.parametrize('launch_file, args, robots, nodes', CASES, ids=[c[0] + ' ' + ' '.join(c[1]) for c in CASES])
def test_the_launch_file_brings_up_a_system_that_reaches_a_goal_and_stops_cleanly_on_ctrl_c(
    install_tree,
    launch_file,
    args,
    robots,
    nodes,
):
    assert (install_tree / 'share' / 'wmm_control' / 'launch' / launch_file).is_file()
    # a domain of each case's own: a case's nodes still leaving cannot meet the next case's
    domain = private_domain_id(10 + CASES.index((launch_file, args, robots, nodes)))
    proc = _launch(install_tree, domain, [launch_file, *args, 'viewer:=false'])
    try:
        reached, ee = _reach(domain, {ns: _goal(robot) for ns, robot in robots.items()}, 'use_sim_time:=true' in args)
    finally:
        code, out = _interrupt(proc)
    assert reached == set(robots), f'reached {reached}; end effectors at {ee}\n{out[-4000:]}'
    assert code == 0, f'ros2 launch exit {code}\n{out[-4000:]}'
    assert 'Traceback' not in out and 'terminate called' not in out, out[-4000:]
    assert out.count('process has finished cleanly') == nodes, out[-4000:]
