"""Joint-state-to-command latency across processes over DDS: sim → resolver → base controller → sim.

The simulator, the base controller and the resolver run as separate processes (the installed
console scripts, default parameters, real time), on a private ROS domain, while the robot
drives to a far goal. A probe in this process receives every ``/joint_states`` message and the
commands that answer it, and prints, per stage, the median and 99th percentile of the time
from the joint state's arrival to the answer's arrival (both by the probe's clock):

* ``/base/reference`` (the resolver's cycle, stamped as the state it answers);
* ``/base/feasible_twist`` (the base controller's answer to that reference, same stamp);
* the arm command (the resolver, after the feasible twist: eq (14)'s compensation);
* the base commands (steer + drive, or wheel), and the whole chain: the last command of the
  cycle, when the simulator has everything it needs for its next step.

The reference, timed in the same run: the same simulator answered by a trivial process that
publishes zero commands for every group as soon as each joint state arrives (one DDS hop out
and one back, and rclpy's per-message cost), so the chain's figure reads as a multiple of the
floor any ROS 2 Python controller on this machine pays.

Usage: ``python benchmarks/bench_latency.py [--robot A|B] [--seconds 20]``;
``--answer`` runs the trivial answering process (used by the script itself).
"""

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from wmm_control.nodes.conversions import float_array
from wmm_control.nodes.runner import default_executor
from wmm_control.robot_config import load_robot

BIN = Path(sys.executable).parent
SYSTEMS = {
    'A': {
        'robot': 'steerable',
        'base': 'swmr_controller',
        'groups': ('arm', 'steer', 'drive'),
        'resolver': [],
        'goal': (12.0, 3.0, 1.0),
        'quat': (0.5**0.5, 0.0, 0.0, 0.5**0.5),
    },
    'B': {
        'robot': 'mecanum',
        'base': 'mecanum_controller',
        'groups': ('arm', 'wheel'),
        'resolver': [],
        'goal': (3.0, 1.0, 0.45),
        'quat': (0.0, 0.5**0.5, 0.0, 0.5**0.5),
    },  # amp: B's default
}


def answer(groups):
    """The trivial controller: zero commands for every group, at once, for each joint state."""
    rclpy.init()
    node = Node('latency_answer')
    sizes = {'arm': 7, 'steer': 4, 'drive': 4, 'wheel': 4}
    pubs = {g: node.create_publisher(Float64MultiArray, f'{g}_controller/commands', 10) for g in groups}
    node.create_subscription(
        JointState, 'joint_states', lambda m: [pubs[g].publish(float_array(np.zeros(sizes[g]))) for g in groups], 10
    )
    executor = default_executor()
    executor.add_node(node)
    try:
        with contextlib.suppress(KeyboardInterrupt):  # SIGINT is how the benchmark stops it
            while rclpy.ok():
                executor.spin_once(timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


class Probe(Node):
    """Arrival times of each joint state and of the messages that answer it."""

    def __init__(self, context, groups):
        super().__init__('latency_probe', context=context)
        self.states = []  # (arrival, stamp)
        self.stamped = {'base/reference': {}, 'base/feasible_twist': {}}
        self.commands = {g: [] for g in groups}
        self.moving = False
        self.create_subscription(JointState, 'joint_states', self._on_state, 50)
        for topic, arrivals in self.stamped.items():
            self.create_subscription(
                TwistStamped, topic, lambda m, a=arrivals: a.setdefault(_key(m), time.perf_counter()), 50
            )
        for group, arrivals in self.commands.items():
            self.create_subscription(
                Float64MultiArray,
                f'{group}_controller/commands',
                lambda m, a=arrivals: a.append(time.perf_counter()),
                50,
            )
        self.create_subscription(Odometry, 'ground_truth/odom', self._on_truth, 10)
        self.goal = self.create_publisher(PoseStamped, 'goal_pose', 10)

    def _on_state(self, msg):
        self.states.append((time.perf_counter(), _key(msg)))

    def _on_truth(self, msg):
        self.moving = abs(msg.twist.twist.linear.x) + abs(msg.twist.twist.linear.y) > 0.05

    def latencies(self, start):
        """Per stage, the latency [s] of every cycle whose joint state arrived after ``start``."""
        out = {
            'base/reference': [],
            'base/feasible_twist': [],
            'arm command': [],
            'base commands': [],
            'whole chain': [],
        }
        arrivals = [t for t, _ in self.states] + [np.inf]
        for i, (t0, key) in enumerate(self.states):
            if t0 < start:
                continue
            t_next = arrivals[i + 1]
            firsts = {}
            for group, times in self.commands.items():
                j = np.searchsorted(times, t0)
                firsts[group] = times[j] if j < len(times) and times[j] < t_next else None
            for topic in ('base/reference', 'base/feasible_twist'):
                t = self.stamped[topic].get(key)
                if t is not None and t >= t0:
                    out[topic].append(t - t0)
            if firsts.get('arm') is not None:
                out['arm command'].append(firsts['arm'] - t0)
            base = [t for g, t in firsts.items() if g != 'arm']
            if base and None not in base:
                out['base commands'].append(max(base) - t0)
            if None not in firsts.values():
                out['whole chain'].append(max(firsts.values()) - t0)
        return out


def _key(msg):
    return (msg.header.stamp.sec, msg.header.stamp.nanosec)


def measure(system, seconds, trivial, domain):
    """Start the processes, wait until the robot is under way (or the answers flow), measure."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    robot = ['--ros-args', '-p', f'robot:={system["robot"]}']
    if trivial:
        commands = [[str(BIN / 'wmm_sim')] + robot, [sys.executable, __file__, '--answer', ','.join(system['groups'])]]
    else:
        commands = [
            [str(BIN / 'wmm_sim')] + robot,
            [str(BIN / system['base'])],
            [str(BIN / 'redundancy_resolver')] + robot + system['resolver'],
        ]
    procs = [subprocess.Popen(c, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for c in commands]
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    probe = Probe(context, system['groups'])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    goal = PoseStamped()
    goal.header.frame_id = 'world'
    goal.pose.position.x, goal.pose.position.y, goal.pose.position.z = system['goal']
    o = goal.pose.orientation
    o.x, o.y, o.z, o.w = system['quat']
    try:
        end = time.monotonic() + 120.0
        ready = False
        while time.monotonic() < end and not ready:
            executor.spin_once(timeout_sec=0.05)
            if not trivial and probe.count_subscribers('goal_pose'):
                probe.goal.publish(goal)
            ready = all(probe.commands.values()) and (trivial or probe.moving)
        if not ready:
            raise RuntimeError('the system did not start')
        start = time.perf_counter() + 1.0
        end = time.monotonic() + 1.0 + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        return probe.latencies(start)
    finally:
        executor.remove_node(probe)
        probe.destroy_node()
        rclpy.try_shutdown(context=context)
        for p in procs:
            p.send_signal(signal.SIGINT)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def _row(name, values):
    ms = np.asarray(values) * 1e3
    return f'| {name} | {np.median(ms):.2f} ms | {np.percentile(ms, 99):.2f} ms | {len(ms)} |'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--robot', choices=sorted(SYSTEMS), default='A')
    parser.add_argument('--seconds', type=float, default=20.0)
    parser.add_argument('--answer', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.answer:
        answer(args.answer.split(','))
        return 0
    system = SYSTEMS[args.robot]
    domain = 100 + (os.getpid() + 71) % 100
    load_robot(system['robot'])
    floor = measure(system, args.seconds, trivial=True, domain=domain)
    chain = measure(system, args.seconds, trivial=False, domain=domain)
    print(f'robot {args.robot}, {args.seconds:g} s each, separate processes over DDS (arrival at a probe)')
    print('| stage (from the joint state) | median | p99 | cycles |')
    print('|---|---|---|---|')
    for stage, values in chain.items():
        print(_row(stage, values))
    print(_row('reference: trivial answer, all groups', floor['whole chain']))
    ratio = np.median(chain['whole chain']) / np.median(floor['whole chain'])
    print(f'whole chain / trivial answer: {ratio:.1f}× (median)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
