"""Every executable's main(): start-up errors from the command line, and Ctrl-C."""

import importlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import rclpy
from std_msgs.msg import String

from wmm_control.experiments.ros_run import private_domain_id
from wmm_control.nodes.runner import run_node


@pytest.mark.parametrize(
    'module',
    [
        'sim_bridge.node',
        'wmm_control.nodes.swmr_controller',
        'wmm_control.nodes.mecanum_controller',
        'wmm_control.nodes.redundancy_resolver',
        'wmm_control.nodes.goal_sequencer',
        'wmm_control.nodes.goal_planner',
    ],
)
def test_a_params_file_that_cannot_be_read_is_a_clear_error_not_a_traceback(module, tmp_path, capfd):
    main = importlib.import_module(module).main
    assert main(['node', '--ros-args', '--params-file', str(tmp_path / 'missing.yaml')]) == 2
    err = capfd.readouterr().err
    assert 'cannot start' in err and 'missing.yaml' in err and 'Traceback' not in err


def test_ctrl_c_in_the_middle_of_a_callback_lets_it_finish_and_exits_cleanly():
    """rclpy's own SIGINT handler shuts the context down at once: a callback interrupted
    half-way then fails on its next publish ("publisher's context is invalid") and the process
    leaves with a traceback (seen in 1 of 6 Ctrl-Cs of a running simulator). The stop is taken
    between callbacks instead."""
    published = []

    def factory():
        node = rclpy.create_node('sigint_probe')
        pub = node.create_publisher(String, 'sigint_probe', 10)

        def tick():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # Ctrl-C arrives while the callback runs
            pub.publish(String(data='after'))
            published.append(rclpy.ok())

        node.create_timer(0.01, tick)
        return node

    before = signal.getsignal(signal.SIGINT)
    assert run_node(factory, args=['sigint_probe']) == 0
    assert published == [True]  # it finished, the context alive; no second cycle
    assert signal.getsignal(signal.SIGINT) is before


@pytest.mark.parametrize(
    'first, second, gap',
    [(signal.SIGINT, signal.SIGINT, 0.05), (signal.SIGINT, signal.SIGINT, 0.2), (signal.SIGTERM, signal.SIGINT, 0.1)],
    ids=['SIGINT twice 0.05 s apart', 'SIGINT twice 0.2 s apart', 'SIGTERM then SIGINT'],
)
def test_a_second_signal_during_teardown_neither_aborts_nor_prints_a_traceback(first, second, gap):
    """``ros2 launch`` answers Ctrl-C with SIGINT to every process, and a second one shortly
    after: the node is then being destroyed, or the interpreter is finalizing. Either used to
    end the process by the second signal (KeyboardInterrupt inside rclpy: an abort; or killed
    by SIGINT: exit -2) although the node had stopped cleanly."""
    exe = Path(sys.executable).with_name('redundancy_resolver')
    if not exe.is_file():
        pytest.fail(f'{exe} is not installed: run the README set-up (bash scripts/dev.sh test)')
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    proc = subprocess.Popen([str(exe)], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    try:
        end = time.monotonic() + 60.0
        while (
            time.monotonic() < end and proc.poll() is None and not any('waiting for /goal_pose' in ln for ln in lines)
        ):
            time.sleep(0.05)
        assert proc.poll() is None, ''.join(lines)
        time.sleep(0.5)  # spinning
        proc.send_signal(first)
        time.sleep(gap)
        if proc.poll() is None:
            proc.send_signal(second)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=5)
    out = ''.join(lines)
    assert proc.returncode == 0, f'exit {proc.returncode}:\n{out}'
    assert 'Traceback' not in out and 'terminate called' not in out, out


_STUCK = """
import atexit, os, signal, sys, time
import rclpy
from wmm_control.nodes.runner import run_node

if sys.argv[1] == 'exit':
    atexit.register(time.sleep, 60.0)  # runs after run_node's own exit handler: the exit is stuck

class Stuck(rclpy.node.Node):
    def destroy_node(self):
        if sys.argv[1] == 'teardown':
            time.sleep(60.0)  # the teardown is stuck
        if sys.argv[1] == 'locked':  # stuck in C with the interpreter lock held, as Fast DDS once was
            import ctypes
            ctypes.PyDLL(None).sleep(60)
        return super().destroy_node()

def factory():
    node = Stuck('stuck_probe')
    node.create_timer(0.2, lambda: os.kill(os.getpid(), signal.SIGINT))
    return node

raise SystemExit(run_node(factory))
"""


@pytest.mark.parametrize(
    'where, code, within',
    [
        ('teardown', 0, ('TEARDOWN_LIMIT',)),
        ('locked', 1, ('TEARDOWN_LIMIT', 'TEARDOWN_BACKSTOP')),
        ('exit', 1, ('EXIT_LIMIT',)),
    ],
    ids=['teardown', 'teardown holding the interpreter lock', 'exit'],
)
def test_a_stop_stuck_in_the_teardown_or_the_exit_ends_with_every_stack_written(where, code, within):
    """A node whose teardown (or the interpreter's exit after it) does not finish, as a middleware
    stuck on a lock does, leaves within its limit after Ctrl-C, telling where each thread was,
    instead of waiting for ``ros2 launch``'s SIGKILL. A stuck teardown still exits 0: the node
    stopped; one stuck holding the interpreter lock (no Python thread runs) leaves a little later
    with 1, as does a stuck exit."""
    from wmm_control.nodes import runner

    limit = sum(getattr(runner, name) for name in within)
    env = dict(os.environ, ROS_DOMAIN_ID=str(private_domain_id()))
    began = time.monotonic()
    proc = subprocess.run(
        [sys.executable, '-c', _STUCK, where], env=env, capture_output=True, text=True, timeout=limit + 40.0
    )
    took = time.monotonic() - began
    assert proc.returncode == code, proc.stderr
    assert took >= limit, took  # (a stop that never ends fails at subprocess.run's timeout)
    assert ('destroy_node' if where == 'teardown' else 'most recent call first') in proc.stderr, proc.stderr
