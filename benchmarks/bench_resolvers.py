"""Cost of redundancy resolution and of the Table II experiment. Prints figures, asserts nothing.

1. Resolver cycle time (median, p99, µs) of ``pinv``, ``task_sharing`` and task sharing with
   compensation (``step`` + ``compensate``, as the node runs them), replayed on the states and
   targets of a closed-loop Table II run; each median also as a ratio to one pink IK step
   (robot A, same run, see ``shared.py``). Targets: task sharing <= 0.5x pink's median,
   p99 <= 3x its own median. Then ``amp`` and ``traditional`` on robot B, replayed on the
   R = 0.25 m circle of Xing §4.3, against one pink step on robot B. Target: AMP <= 1.0x pink's.
2. Simulated-to-wall time ratio of the whole Table II experiment, all ROS nodes in one process
   (``engine='nodes'``) and with no ROS (``engine='direct'``), with per-run ratios. Target >= 40x.
3. Peak RSS of the experiment process (run in a subprocess, so pink is not counted). Target <= 400 MB.
4. A profile of one ROS-pipeline run: the top functions by cumulative and by own time.

    python benchmarks/bench_resolvers.py [--top 15] [--skip-experiment] [--skip-profile]
"""

import argparse
import cProfile
import json
import pstats
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))  # the benchmarks' shared code

from wmm_control.experiments.scenario import load_scenario  # noqa: E402
from wmm_control.resolvers import make_resolver  # noqa: E402

SCENARIO = 'sorour_table2'
PROFILED_RUN = 'task_sharing_compensation'
RESULT_TAG = 'RESULT '
METHODS = (
    ('pinv', 'pinv', {}),
    ('task_sharing', 'task_sharing', {'compensation': False}),
    ('task_sharing + compensate', 'task_sharing', {'compensation': True}),
)


def record_cycles(scenario):
    """(state, target, feasible twist) of every period of a closed-loop task-sharing run."""
    from sim_bridge.closed_loop import ClosedLoop
    from sim_bridge.world import SimWorld

    cycles = []
    with SimWorld(scenario.robot) as world:
        loop = ClosedLoop(world, make_resolver('task_sharing', scenario.robot))
        targets = [g.target for g in scenario.goals]
        for _ in range(int(round(scenario.duration / world.dt))):
            target = targets[scenario.goal_index(world.time)]
            state = loop.state()
            rec = loop.step(target)
            cycles.append((state, target, rec.feasible_twist))
    return cycles


def time_resolver(resolver, cycles, warmup=50):
    """Wall time [µs] of ``step`` (+ ``compensate`` when the resolver uses it) per cycle."""
    compensating = resolver.uses_compensation
    for state, target, feasible in cycles[:warmup]:
        resolver.compensate(resolver.step(state, target), feasible)
    resolver.reset()
    times = np.empty(len(cycles))
    for k, (state, target, feasible) in enumerate(cycles):
        t0 = time.perf_counter_ns()
        command = resolver.step(state, target)
        if compensating:
            resolver.compensate(command, feasible)
        times[k] = time.perf_counter_ns() - t0
    return times / 1e3


#: Xing's circles track the position (r = 3, §4.2–4.3).
CIRCLE = {'rows': 'position'}


def record_circle(radius=0.25, seconds=40.0):
    """(state, target, None) of every period of AMP tracking Xing's circle on robot B."""
    from sim_bridge.closed_loop import ClosedLoop
    from sim_bridge.world import SimWorld
    from wmm_control.resolvers import PoseTarget

    cycles, w = [], np.pi / 20.0
    with SimWorld('mecanum') as world:
        loop = ClosedLoop(world, make_resolver('amp', 'mecanum', **CIRCLE))
        x0, r0 = loop.state().ee_position.copy(), loop.state().ee_rotation.copy()
        for k in range(int(round(seconds / world.dt))):
            t = k * world.dt
            target = PoseTarget(
                x0 + radius * np.array([1 - np.cos(w * t), -np.sin(w * t), 0.0]),
                r0,
                velocity=radius * w * np.array([np.sin(w * t), -np.cos(w * t), 0, 0, 0, 0]),
                acceleration=radius * w * w * np.array([np.cos(w * t), np.sin(w * t), 0, 0, 0, 0]),
            )
            state = loop.state()
            loop.step(target)
            cycles.append((state, target, None))
    return cycles


def report_resolvers(scenario):
    report_methods(
        f'{scenario.name} replayed (robot {scenario.robot})',
        scenario.robot,
        record_cycles(scenario),
        METHODS,
        'task sharing median <= 0.5x pink median; p99 <= 3x own median',
    )
    circle = record_circle()
    report_methods(
        "Xing's R = 0.25 m circle replayed (robot mecanum)",
        'mecanum',
        circle,
        (('amp', 'amp', CIRCLE), ('traditional', 'traditional', CIRCLE)),
        'AMP median <= 1.0x pink median',
    )
    report_amp_floor(circle)


def report_amp_floor(cycles):
    """AMP's cycle with its two heaviest parts made free: ∇H and ∇²H returned as zeros, and SNS
    answered by a stand-in that returns zero accelerations at once. What is left (kinematics,
    the PD law, the bounds of eqs 6–8, σ_m, the projection of the tertiary task, the
    integration and the limits) bounds from below what speeding up those two parts can give."""
    from unittest import mock

    from wmm_control.kinematics import KinematicModel
    from wmm_control.resolvers import amp, sns

    def free_sns(jac, xdd, drift, lower, upper, active, held, rcond=1e-6):
        act = np.asarray(active, dtype=bool)
        return sns.SnsResult(
            np.zeros(jac.shape[1]), 1.0, act, np.zeros_like(act), np.zeros((int(act.sum()), jac.shape[0]))
        )

    zeros = (np.zeros(7), np.zeros((7, 7)))
    full = np.median(time_resolver(make_resolver('amp', 'mecanum', **CIRCLE), cycles))
    with mock.patch.object(KinematicModel, '_manipulability_derivatives', lambda self, rows: zeros):
        no_h = np.median(time_resolver(make_resolver('amp', 'mecanum', **CIRCLE), cycles))
        with mock.patch.object(amp, 'sns_accelerations', free_sns):
            floor = np.median(time_resolver(make_resolver('amp', 'mecanum', **CIRCLE), cycles))
    print(
        f'  amp median {full:.1f} µs; with ∇H, ∇²H free {no_h:.1f} µs; with SNS free too {floor:.1f} µs '
        '(the rest of the cycle)'
    )


def report_methods(title, robot, cycles, methods, targets):
    print(f'Resolver cycle time, {len(cycles)} recorded cycles of {title}:')
    from shared import bench_pink

    pink_us = bench_pink(len(cycles), robot)
    pink_med = np.median(pink_us) if pink_us is not None else None
    print(f'  {"method":<28}{"median µs":>10}{"p99 µs":>9}{"p99/med":>9}{"med/pink":>10}')
    for label, method, params in methods:
        us = time_resolver(make_resolver(method, robot, **params), cycles)
        med, p99 = np.median(us), np.percentile(us, 99)
        vs_pink = f'{med / pink_med:10.2f}' if pink_med else f'{"—":>10}'
        print(f'  {label:<28}{med:>10.1f}{p99:>9.1f}{p99 / med:>9.2f}{vs_pink}')
    if pink_us is None:
        print('  pink not installed (pip install pin-pink quadprog): comparison skipped')
    else:
        print(f'  {"pink solve_ik (quadprog)":<28}{pink_med:>10.1f}{np.percentile(pink_us, 99):>9.1f}')
    print(f'  targets: {targets}')


def experiment_only(engine):
    """Run the whole experiment in this process; print its figures as one JSON line."""
    import resource
    from wmm_control.cli.experiment import run_experiment

    start = time.perf_counter()
    logs, summary = run_experiment(load_scenario(SCENARIO), engine=engine, show_progress=False)
    wall = time.perf_counter() - start
    sim = sum(len(log) * 0.025 for log in logs.values())
    print(
        RESULT_TAG
        + json.dumps(
            {
                'engine': engine,
                'sim_s': sim,
                'wall_s': wall,
                'runs': {
                    name: [run['sim_to_wall_ratio'], run['periods'], run['resolver_cycle_median_us']]
                    for name, run in summary['runs'].items()
                },
                'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            }
        ),
        flush=True,
    )


def report_experiment():
    print(f'\nWhole {SCENARIO} experiment, each engine in a fresh process:')
    for engine in ('nodes', 'direct'):
        out = subprocess.run(
            [sys.executable, __file__, '--experiment-only', engine], capture_output=True, text=True, check=False
        )
        line = next((ln for ln in out.stdout.splitlines() if ln.startswith(RESULT_TAG)), None)
        if line is None:
            print(f'  engine {engine}: failed (exit {out.returncode})\n{out.stderr[-2000:]}')
            continue
        r = json.loads(line[len(RESULT_TAG) :])
        print(
            f'  engine {engine:<7} {r["sim_s"]:.0f} sim s in {r["wall_s"]:.1f} s wall: '
            f'{r["sim_s"] / r["wall_s"]:.1f}x (target >= 40x); peak RSS {r["peak_rss_mb"]:.0f} MB (target <= 400 MB)'
        )
        print(f'    {"run":<38}{"sim/wall":>9}{"wall ms/period":>16}{"periods":>9}{"resolver median µs":>20}')
        for name, (ratio, periods, resolver_us) in r['runs'].items():
            print(f'    {name:<38}{ratio:8.1f}x{25.0 / ratio:>16.2f}{periods:>9}{resolver_us:>20.1f}')


def _where(key):
    path, line, func = key
    return f'{Path(path).name}:{line}({func})' if line else func


def report_profile(top):
    from wmm_control.experiments.ros_run import run_with_nodes

    scenario = load_scenario(SCENARIO)
    run = next(r for r in scenario.runs if r['name'] == PROFILED_RUN)
    profiler = cProfile.Profile()
    profiler.enable()
    log = run_with_nodes(scenario, run)
    profiler.disable()
    stats = pstats.Stats(profiler).stats  # {key: (primitive calls, calls, own, cumulative, callers)}
    total = max(v[3] for v in stats.values())
    print(
        f'\nProfile of one ROS-pipeline run ({PROFILED_RUN}, {len(log)} periods, '
        f'{log.wall_time_s:.1f} s wall under the profiler):'
    )
    for title, col in (('cumulative', 3), ('own', 2)):
        print(f'  {f"top {top} by {title} time":<62}{"calls":>9}{"own s":>8}{"own %":>7}{"cum s":>8}{"cum %":>7}')
        for key, v in sorted(stats.items(), key=lambda kv: -kv[1][col])[:top]:
            print(
                f'    {_where(key)[:60]:<60}{v[1]:>9}{v[2]:>8.2f}{100 * v[2] / total:>7.1f}'
                f'{v[3]:>8.2f}{100 * v[3] / total:>7.1f}'
            )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--top', type=int, default=15, help='functions listed in the profile')
    parser.add_argument('--skip-experiment', action='store_true', help='no whole-experiment timing')
    parser.add_argument('--skip-profile', action='store_true', help='no profile')
    parser.add_argument('--experiment-only', choices=('nodes', 'direct'), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.experiment_only:
        experiment_only(args.experiment_only)
        return
    report_resolvers(load_scenario(SCENARIO))
    if not args.skip_experiment:
        report_experiment()
    if not args.skip_profile:
        report_profile(args.top)


if __name__ == '__main__':
    main()
