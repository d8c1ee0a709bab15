"""Benchmark of sim_bridge.SimWorld: microseconds per simulation step.

For each robot and base mode: the time of ``step()`` alone, and of one full cycle as the
node will run it (set the commands, ``step()``, then read joint states, base pose and twist,
odometry and the EE pose). Median and 99th percentile over N steps after a warm-up, and the
real-time factor of the full cycle at dt = 25 ms.

Run:  python benchmarks/bench_sim.py [--steps N]
"""

import argparse
import time

import numpy as np

from sim_bridge import SimWorld, SlipParams


def _commands(robot, k):
    """Time-varying commands: the arm sways, the base drives (and steers, robot A)."""
    s = np.sin(0.05 * k)
    arm = 0.3 * s * np.array([1.0, -0.8, 0.6, 0.5, -1.0, 0.7, 0.9])
    if robot == 'A':
        steer = np.full(4, 0.2 * s) if (k // 40) % 2 else np.zeros(4)  # steer half of the time
        return {'arm': arm, 'steer': steer, 'drive': np.array([4.0, 4.5, 4.0, 4.5]) + s}
    return {'arm': arm, 'wheel': np.array([3.0, -2.0, 2.5, -1.5]) * (1.0 + 0.2 * s)}


def bench(robot, mode, steps, slip=None):
    """Return (median, p99) µs of step() and of a full cycle, for one configuration."""
    with SimWorld(robot, base_mode=mode, slip=slip) as w:
        t_step, t_cycle = [], []
        for k in range(steps + 50):
            t0 = time.perf_counter()
            for group, values in _commands(robot, k).items():
                w.set_command(group, values)
            t1 = time.perf_counter()
            w.step()
            t2 = time.perf_counter()
            w.joint_state()
            w.base_pose()
            w.base_twist()
            w.odom_pose()
            w.odom_twist()
            w.ee_pose()
            t3 = time.perf_counter()
            if k >= 50:
                t_step.append(t2 - t1)
                t_cycle.append(t3 - t0)
        dt = w.dt
    st = np.array(t_step) * 1e6
    cy = np.array(t_cycle) * 1e6
    return np.median(st), np.percentile(st, 99), np.median(cy), np.percentile(cy, 99), dt


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--steps', type=int, default=2000, help='timed steps per configuration')
    args = parser.parse_args()
    configs = [
        ('A', 'kinematic', None, args.steps),
        ('A', 'kinematic', SlipParams(gain=0.05, drift=(0.001, 0.0, 0.002), noise_std=0.005), args.steps),
        ('B', 'kinematic', None, args.steps),
        ('B', 'kinematic', SlipParams(gain=0.05, drift=(0.001, 0.0, 0.002), noise_std=0.005), args.steps),
        ('A', 'physics', None, max(args.steps // 5, 100)),
        ('B', 'physics', None, max(args.steps // 5, 100)),
    ]
    print('SimWorld step cost, dt = 25 ms, substeps = 10 (µs; cycle = commands + step + all reads)')
    print(
        f'{"robot":5} {"mode":9} {"slip":4} {"steps":>5} {"step med":>9} {"step p99":>9} '
        f'{"cycle med":>9} {"cycle p99":>9} {"x realtime":>10}'
    )
    for robot, mode, slip, steps in configs:
        sm, sp, cm, cp, dt = bench(robot, mode, steps, slip)
        print(
            f'{robot:5} {mode:9} {"on" if slip else "off":4} {steps:5d} {sm:9.1f} {sp:9.1f} '
            f'{cm:9.1f} {cp:9.1f} {dt * 1e6 / cm:10.0f}'
        )


if __name__ == '__main__':
    main()
