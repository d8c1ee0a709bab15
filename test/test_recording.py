"""Every experiment run is recorded: a rosbag2 (MCAP) of all its topics, read back with rosbags."""

import json

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from wmm_control.cli.experiment import bag_path, main as experiment_main
from wmm_control.errors import ConfigError
from wmm_control.experiments.ros_run import run_with_nodes
from wmm_control.experiments.scenario import load_scenario

SCENARIO = """scenario:
  name: recorded
  robot: steerable
  frame: world
  duration: {duration}
  goals:
    - {{t: 0.0, pose: [1.0, 0.2, 1.0, pi/2, 0.0, 0.0]}}
  experiment:
    sim: {{base_mode: kinematic}}
    runs:
      - {{name: ts, method: task_sharing, feedback: ground_truth}}
"""

TOPICS = {
    '/joint_states',
    '/ee_pose',
    '/odom',
    '/ground_truth/odom',
    '/clock',
    '/arm_controller/commands',
    '/steer_controller/commands',
    '/drive_controller/commands',
    '/base/reference',
    '/base/feasible_twist',
    '/diagnostics',
    '/goal_pose',
    '/robot_description',
    '/rosout',
    '/parameter_events',
}


def _stamp(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_a_run_is_recorded_with_every_topic_and_reads_back(tmp_path):
    duration = 2.0
    path = tmp_path / 'recorded.yaml'
    path.write_text(SCENARIO.format(duration=duration))
    scenario = load_scenario(str(path))
    bag = tmp_path / 'rosbag2_ts'
    log = run_with_nodes(scenario, scenario.runs[0], bag_path=bag)
    assert (bag / 'metadata.yaml').is_file() and list(bag.glob('*.mcap'))
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert TOPICS <= set(counts), sorted(TOPICS - set(counts))
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types['/joint_states'] == 'sensor_msgs/msg/JointState'
        joint_states, log_times, description = [], [], None
        for connection, timestamp, data in reader.messages():
            log_times.append(timestamp * 1e-9)
            if connection.topic == '/joint_states':
                joint_states.append(typestore.deserialize_cdr(data, connection.msgtype))
            elif connection.topic == '/robot_description':
                description = typestore.deserialize_cdr(data, connection.msgtype).data
    periods = round(duration / 0.025)
    # the state at 0 and after each period until the run ends (the last one may still be in flight)
    assert periods <= counts['/joint_states'] <= periods + 2
    assert (
        counts['/ee_pose'] == counts['/odom'] == counts['/clock']
        and 0 <= counts['/ee_pose'] - counts['/joint_states'] <= 1
    )  # the joint states go out last
    assert counts['/robot_description'] == 1 and '<robot' in description
    assert counts['/arm_controller/commands'] >= periods and counts['/diagnostics'] >= periods
    stamps = [_stamp(m) for m in joint_states]
    assert stamps[0] == 0.0 and stamps[-1] == pytest.approx(duration, abs=0.03)
    assert np.all(np.diff(stamps) > 0), 'in order, one per period'
    # log times: the simulator's time at receipt
    assert min(log_times) == 0.0 and max(log_times) == pytest.approx(duration, abs=0.03)
    assert len(log) > 0
    with pytest.raises(ConfigError, match='exists already'):
        run_with_nodes(scenario, scenario.runs[0], bag_path=bag)


def test_wmm_experiment_writes_a_recording_beside_metrics_json(tmp_path):
    path = tmp_path / 'recorded.yaml'
    path.write_text(SCENARIO.format(duration=0.5))
    out = tmp_path / 'out'
    for _ in range(2):  # a second run into the same folder replaces the recording
        assert experiment_main(['--scenario', str(path), '--out', str(out), '--no-figures']) == 0
    metrics = json.loads((out / 'metrics.json').read_text())
    assert metrics['runs']['ts']['recording'] == str(bag_path(out, 'ts'))
    with Reader(bag_path(out, 'ts')) as reader:
        assert {c.topic: c.msgcount for c in reader.connections}['/joint_states'] >= 20


def test_an_experiment_run_can_be_watched_live_in_the_browser(tmp_path):
    """``wmm_experiment --view``: the viewer serves its page while the run goes on, and the
    run's results are those of a run without it (the viewer only listens and draws)."""
    import socket
    import urllib.request

    path = tmp_path / 'viewed.yaml'
    path.write_text(SCENARIO.format(duration=2.0))
    scenario = load_scenario(path)
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        port = sock.getsockname()[1]
    pages = []

    def progress(_seconds):
        if not pages:
            with urllib.request.urlopen(f'http://127.0.0.1:{port}/', timeout=10) as resp:
                pages.append((resp.status, resp.read(2000).decode(errors='replace')))

    viewed = run_with_nodes(scenario, scenario.runs[0], progress=progress, view_port=port)
    plain = run_with_nodes(scenario, scenario.runs[0])
    assert pages and pages[0][0] == 200 and '<html' in pages[0][1].lower()
    np.testing.assert_allclose(viewed.q_arm, plain.q_arm, rtol=0, atol=1e-9)  # [rad]: round-off only
    with pytest.raises(SystemExit):
        experiment_main(['--scenario', str(path), '--view', '--engine', 'direct', '--out', str(tmp_path)])
