"""colcon builds an installable ament_python package whose executables start.

This is the layout ``ros2 run wmm_control <exe>`` relies on: the ament index marker,
``share/wmm_control/package.xml``, the config files, and one executable per console
script under ``lib/wmm_control/``.
"""

import configparser
import math
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def console_scripts(prefix):
    """Executable names the installed package declares (its entry_points.txt)."""
    parser = configparser.ConfigParser()
    parser.read(next(prefix.glob('lib/python3*/site-packages/wmm_control*.egg-info/entry_points.txt')))
    return sorted(parser['console_scripts'])


def installed_env(prefix):
    env = dict(os.environ)
    site = next(prefix.glob('lib/python3*/site-packages'))
    env['PYTHONPATH'] = os.pathsep.join([str(site), env.get('PYTHONPATH', '')])
    env['AMENT_PREFIX_PATH'] = str(prefix)
    return env


def test_install_tree_has_the_ament_layout(install_tree):
    share = install_tree / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'wmm_control').is_file()
    assert (share / 'wmm_control' / 'package.xml').read_text() == (REPO / 'package.xml').read_text()
    for src in (REPO / 'config').rglob('*'):
        if src.is_file():
            assert (share / 'wmm_control' / src.relative_to(REPO)).is_file(), src


def test_package_xml_is_a_valid_manifest_of_an_ament_python_package():
    """package.xml is well-formed XML (a ``--`` inside a comment is not) and says ament_python:
    else colcon takes the package for a plain Python one and its install never registers the
    package with the ament index (below)."""
    import xml.etree.ElementTree as ElementTree

    root = ElementTree.parse(REPO / 'package.xml').getroot()
    assert root.tag == 'package' and root.findtext('name') == 'wmm_control'
    assert root.findtext('export/build_type') == 'ament_python'


def test_sourcing_the_install_registers_the_package_for_ros2_run(install_tree):
    """``source install/setup.bash`` puts the package's prefix on AMENT_PREFIX_PATH, where
    ``ros2 run`` and ``ros2 launch`` look for it (colcon's hook for an ament package: built as a
    plain Python package, the install set PYTHONPATH alone and ``ros2 run wmm_control`` found
    no package)."""
    env = {k: v for k, v in os.environ.items() if k not in ('AMENT_PREFIX_PATH', 'COLCON_PREFIX_PATH')}
    setup = install_tree.parent / 'setup.bash'
    out = subprocess.run(
        ['bash', '-c', f'source "{setup}" && echo "$AMENT_PREFIX_PATH"'],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert str(install_tree) in out.stdout.strip().split(os.pathsep), out.stdout + out.stderr


def test_every_console_script_is_installed_under_lib_and_starts(install_tree):
    names = console_scripts(install_tree)
    assert 'wmm_model' in names
    env = installed_env(install_tree)
    nodes = []
    for name in names:
        exe = install_tree / 'lib' / 'wmm_control' / name
        assert exe.is_file() and os.access(exe, os.X_OK), exe
        if name == 'wmm_experiment':
            out = subprocess.run([str(exe), '--help'], env=env, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0 and "sorour_table2" in out.stdout and "matrix_circle_0.25_b" in out.stdout, (
                out.stderr
            )
            continue
        if name == 'wmm_randomized':
            out = subprocess.run([str(exe), '--help'], env=env, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0 and '--goals' in out.stdout, out.stderr
            continue
        if name == 'wmm_robot':
            # the installed share directory holds every shipped robot: check one of each new family
            out = subprocess.run(
                [str(exe), 'check', 'panda_diff'], env=env, capture_output=True, text=True, timeout=120
            )
            assert out.returncode == 0 and 'differential wheels' in out.stdout, out.stderr
            continue
        if name == 'wmm_model':
            out = subprocess.run([str(exe), '--robot', 'B'], env=env, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stderr
            # The installed copy reads its robot files from the installed share directory.
            assert (
                f'urdf: {install_tree / "share" / "wmm_control" / "config" / "robots" / "mecanum.urdf"}' in out.stdout
            )
            continue
        nodes.append(name)
    # Every node, its executable's name: it must come up (its node on the ROS graph of a domain of
    # this test alone) and keep running until interrupted, then exit cleanly. Started together.
    assert len(nodes) >= 8, nodes
    _nodes_come_up_and_stop_cleanly(install_tree, nodes)


def _nodes_come_up_and_stop_cleanly(install_tree, names):
    import rclpy

    from wmm_control.experiments.ros_run import private_domain_id

    domain = private_domain_id(53)
    env = dict(installed_env(install_tree), ROS_DOMAIN_ID=str(domain))
    procs = {
        name: subprocess.Popen(
            [str(install_tree / 'lib' / 'wmm_control' / name)],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for name in names
    }
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    probe = rclpy.create_node('console_script_probe', context=context)
    try:
        end = time.monotonic() + 120.0
        up = set()
        while time.monotonic() < end and up != set(names):
            up = set(probe.get_node_names()) & set(names)
            if any(proc.poll() is not None for proc in procs.values()):
                break
            time.sleep(0.1)
        for pause in (0.0, 1.0):  # when all are up, and a second later (the last to come up running a while too)
            time.sleep(pause)
            for name, proc in procs.items():
                assert proc.poll() is None, f'{name} exited early:\n{proc.communicate()[0]}'
            assert up == set(names), f'not on the graph: {sorted(set(names) - up)}'
    finally:
        probe.destroy_node()
        rclpy.try_shutdown(context=context)
        for proc in procs.values():  # interrupted together, as at the end of a launch
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        results = {name: _stop(proc) for name, proc in procs.items()}
    for name, (code, out) in results.items():
        assert _stopped_cleanly(code, out), f'{name} exit code {code}:\n{out}'


def test_wmm_model_reports_a_clear_error_for_an_unknown_robot(install_tree):
    exe = install_tree / 'lib' / 'wmm_control' / 'wmm_model'
    out = subprocess.run(
        [str(exe), '--robot', 'C'], env=installed_env(install_tree), capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 2
    assert "unknown robot 'C'" in out.stderr


def _stopped_cleanly(code, out):
    """Exit code 0; or 1 from the runner's backstop on a teardown stuck with the interpreter lock
    held (Fast DDS once hung destroying a participant so, one stop in many), its stacks written."""
    return code == 0 or (code == 1 and 'Timeout (' in out and 'in destroy_node' in out)


def _stop(proc):
    """SIGINT, then the exit code and the output."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)  # its threads' stacks into the output: where it hangs
        time.sleep(1.0)
        proc.kill()
        out, _ = proc.communicate()
    return proc.returncode, out


ROBOT_A = {'wmm_sim': [], 'swmr_controller': [], 'redundancy_resolver': []}
ROBOT_B = {
    'wmm_sim': ['--ros-args', '-p', 'robot:=mecanum'],
    'mecanum_controller': [],
    'redundancy_resolver': ['--ros-args', '-p', 'robot:=mecanum'],
}  # amp: robot B's default


ROBOT_UR = {
    'wmm_sim': ['--ros-args', '-p', 'robot:=ur_mecanum'],
    'mecanum_controller': ['--ros-args', '-p', 'robot:=ur_mecanum'],
    'redundancy_resolver': ['--ros-args', '-p', 'robot:=ur_mecanum'],
}
ROBOT_PANDA = {
    'wmm_sim': ['--ros-args', '-p', 'robot:=panda_diff'],
    'differential_controller': [],
    'redundancy_resolver': ['--ros-args', '-p', 'robot:=panda_diff'],
}
NEAR, FAR = (0.1, 0.05, -0.05), (1.5, -1.0, 0.0)  # offsets from the start: in reach, and one for the base


def _run_system(install_tree, system, goals):
    """Start ``system`` (executable → arguments), each its own process as ``ros2 run`` does, on
    a private domain; publish each goal of ``goals`` from this process until the end effector is
    within 1 cm and 0.05 rad of it (ground truth, ``/ee_pose``), then the next. A goal is
    ``(position, quaternion (x, y, z, w))``, or ``(offset, None)``: the start pose moved by the
    offset. Returns the end-effector pose when each goal was reached (None: not within 90 s)."""
    import numpy as np
    import rclpy
    from geometry_msgs.msg import PoseStamped

    from wmm_control.experiments.ros_run import private_domain_id

    domain = private_domain_id(54)
    env = dict(installed_env(install_tree), ROS_DOMAIN_ID=str(domain))
    procs = {
        name: subprocess.Popen(
            [str(install_tree / 'lib' / 'wmm_control' / name)] + args,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for name, args in system.items()
    }
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('goal_test', context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    ee = []
    node.create_subscription(
        PoseStamped,
        '/ee_pose',
        lambda m: ee.append(
            np.array(
                [
                    m.pose.position.x,
                    m.pose.position.y,
                    m.pose.position.z,
                    m.pose.orientation.x,
                    m.pose.orientation.y,
                    m.pose.orientation.z,
                    m.pose.orientation.w,
                ]
            )
        ),
        10,
    )
    pub = node.create_publisher(PoseStamped, '/goal_pose', 10)
    reached_at = []
    try:
        while not ee and len(ee) < 1:
            executor.spin_once(timeout_sec=0.05)
            if any(proc.poll() is not None for proc in procs.values()):
                break
        start = ee[0] if ee else None
        for position, quat in goals:
            if start is None:
                break
            if quat is None:
                position, quat = start[:3] + np.asarray(position), start[3:]
            goal, quat = np.asarray(position, dtype=float), np.asarray(quat, dtype=float)
            msg = PoseStamped()
            msg.header.frame_id = 'world'
            msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in goal)
            o = msg.pose.orientation
            o.x, o.y, o.z, o.w = (float(v) for v in quat)
            reached = False
            end = time.monotonic() + 90.0
            while time.monotonic() < end and not reached:
                executor.spin_once(timeout_sec=0.05)
                if node.count_subscribers('/goal_pose') and int(time.monotonic() * 2) % 2 == 0:
                    pub.publish(msg)  # published again and again: the resolver may join late
                # within 1 cm, and 0.05 rad of the orientation (|<q, q_goal>| = cos(angle / 2))
                reached = (
                    bool(ee) and np.linalg.norm(ee[-1][:3] - goal) < 0.01 and abs(ee[-1][3:] @ quat) > math.cos(0.025)
                )
            reached_at.append(ee[-1] if reached else None)
            if not reached:
                break
    finally:
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        results = {name: _stop(proc) for name, proc in procs.items()}
    for name, (code, out) in results.items():
        assert _stopped_cleanly(code, out) and 'Traceback' not in out, f'{name} exit {code}:\n{out}'
    return reached_at, ee[-1] if ee else None


# Goals: position, orientation quaternion (x, y, z, w); robot B's tool keeps pointing along world x.
@pytest.mark.parametrize(
    'system, goal, quat',
    [
        (ROBOT_A, (2.0, 1.0, 1.0), (0.0, 0.0, 0.0, 1.0)),
        (ROBOT_B, (0.75, 0.1, 0.45), (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5))),
    ],
    ids=['robot A, task sharing', 'robot B, amp'],
)
def test_three_installed_executables_take_the_end_effector_to_a_published_goal(install_tree, system, goal, quat):
    """The simulator, the base controller and redundancy_resolver, each its own process started
    as ``ros2 run`` does, on a private domain: a goal published from this process is reached
    (robot A with no arguments at all; robot B with the robot parameter: its default method, amp)."""
    reached, last = _run_system(install_tree, system, [(goal, quat)])
    assert reached and reached[0] is not None, f'end effector at {last}, goal {goal}'


@pytest.mark.parametrize('system', [ROBOT_UR, ROBOT_PANDA], ids=['ur_mecanum', 'panda_diff'])
def test_the_new_robots_reach_a_goal_in_reach_and_one_that_needs_the_base_across_processes(install_tree, system):
    """``robot:=ur_mecanum`` / ``robot:=panda_diff`` (differential_controller, whose default
    robot it is) on every node: both goals reached within 1 cm on the ground truth."""
    reached, last = _run_system(install_tree, system, [(NEAR, None), (FAR, None)])
    assert len(reached) == 2 and all(r is not None for r in reached), f'reached {reached}, end effector at {last}'
