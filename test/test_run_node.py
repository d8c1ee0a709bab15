"""Every executable's main(): start-up errors from the command line, and Ctrl-C."""

import importlib
import os
import signal
import time

import pytest
import rclpy
from std_msgs.msg import String

from wmm_control.nodes.common import run_node


@pytest.mark.parametrize('module', ['sim_bridge.node', 'wmm_control.nodes.swmr_controller',
                                    'wmm_control.nodes.mecanum_controller', 'wmm_control.nodes.redundancy_resolver',
                                    'wmm_control.nodes.goal_sequencer'])
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
            time.sleep(0.05)                   # Ctrl-C arrives while the callback runs
            pub.publish(String(data='after'))
            published.append(rclpy.ok())

        node.create_timer(0.01, tick)
        return node

    before = signal.getsignal(signal.SIGINT)
    assert run_node(factory, args=['sigint_probe']) == 0
    assert published == [True]                 # it finished, the context alive; no second cycle
    assert signal.getsignal(signal.SIGINT) is before
