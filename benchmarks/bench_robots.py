"""Cycle cost on every shipped robot, and how it grows with the arm's joints n and the modules N.
Prints figures, asserts nothing.

1. Per shipped robot: each method's cycle (``step`` + ``compensate`` when the method uses it)
   and the robot's base controller, median and p99 [µs], replayed on the states of a
   closed-loop run (direct engine) through two goals: one within the arm's reach, one that
   needs the base; and one pink IK step on the same model in the same run (``pip install
   pin-pink quadprog``; skipped when absent), as the yardstick of a QP-based whole-body IK.
2. Growth: made-up robots (the test suite's URDF factory) with n = 6, 7, 8 arm joints on a
   Mecanum base, and steerable bases with N = 2, 3, 4, 6 modules: the median cycle of
   task sharing and AMP over n, of the steerable base controller over N.

Part 1 is measured more fully by ``bench_cycle.py`` (the whole cycle with the base
controller, at free-space, self-near and obstacle-near states, against pink with and without
its self-collision barrier); it stays for the figures of ``docs/benchmarks.md`` (Every
shipped robot) and for part 2.

    python benchmarks/bench_robots.py [--cycles 400]
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a source checkout
sys.path.insert(0, str(ROOT / 'test'))  # the URDF factory of the tests
sys.path.insert(0, str(Path(__file__).resolve().parent))

from shared import bench_pink, closed_loop_states  # noqa: E402
from urdf_factory import write_urdf  # noqa: E402
from wmm_control.base import make_base_controller  # noqa: E402
from wmm_control.cli.robot_setup import init_robot  # noqa: E402
from wmm_control.resolvers import make_resolver  # noqa: E402
from wmm_control.robot_config import load_robot, robot_names  # noqa: E402

METHODS = ('pinv', 'task_sharing', 'amp', 'traditional')


def time_method(cfg, method, states):
    resolver = make_resolver(method, cfg)
    times = []
    for state, target, _ in states:
        t0 = time.perf_counter()
        cmd = resolver.step(state, target)
        if resolver.uses_compensation:
            resolver.compensate(cmd, cmd.base_twist)
        times.append((time.perf_counter() - t0) * 1e6)
    return np.array(times[20:])


def time_base(cfg, states):
    ctrl = make_base_controller(cfg, cfg.period)
    times = []
    for _, _, reference in states:
        t0 = time.perf_counter()
        ctrl.step(reference)
        times.append((time.perf_counter() - t0) * 1e6)
    return np.array(times[20:])


def _fmt(us):
    return f'{np.median(us):7.1f} / {np.percentile(us, 99):7.1f}'


def per_robot(cycles):
    print('## Cycle per shipped robot: median / p99 [µs]\n')
    print('| robot | n | base | ' + ' | '.join(METHODS) + ' | base controller | pink IK step |')
    print('|---|---|---|' + '---|' * (len(METHODS) + 2))
    for name in robot_names():
        cfg = load_robot(name)
        states = closed_loop_states(cfg, cycles)
        cells = [_fmt(time_method(cfg, m, states)) for m in METHODS]
        pink = bench_pink(cycles, name)
        pink_cell = _fmt(pink) if pink is not None else 'not installed'
        print(
            f'| {name} | {cfg.arm.n} | {cfg.base.family} | '
            + ' | '.join(cells)
            + f' | {_fmt(time_base(cfg, states))} | {pink_cell} |',
            flush=True,
        )


def made_up(tmp, base, **kwargs):
    tag = '_'.join(f'{k}{v}' for k, v in kwargs.items())
    urdf = write_urdf(Path(tmp) / f'{base}_{tag}.urdf', base, **kwargs)
    out = Path(tmp) / f'{base}_{tag}.yaml'
    init_robot(urdf, base, 'arm_base_link', 'tool_link', out)
    return load_robot(out)


def growth(cycles):
    with tempfile.TemporaryDirectory() as tmp:
        print('\n## Growth with the arm joints n (Mecanum base): median [µs]\n')
        print('| n | task_sharing | amp |')
        print('|---|---|---|')
        for n in (6, 7, 8):
            cfg = made_up(tmp, 'mecanum', arm_joints=n)
            states = closed_loop_states(cfg, cycles)
            print(
                f'| {n} | {np.median(time_method(cfg, "task_sharing", states)):.1f} | '
                f'{np.median(time_method(cfg, "amp", states)):.1f} |',
                flush=True,
            )
        print('\n## Growth with the steerable modules N: median / p99 of the base controller [µs]\n')
        print('| N | swmr_controller |')
        print('|---|---|')
        for modules in (2, 3, 4, 6):
            cfg = made_up(tmp, 'steerable', modules=modules)
            states = closed_loop_states(cfg, cycles)
            print(f'| {modules} | {_fmt(time_base(cfg, states))} |', flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cycles', type=int, default=400, help='periods replayed per robot (default: %(default)s)')
    args = parser.parse_args()
    per_robot(args.cycles)
    growth(args.cycles)


if __name__ == '__main__':
    main()
