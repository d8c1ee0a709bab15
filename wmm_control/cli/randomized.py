"""``wmm_randomized``: randomized closed-loop runs, every method on every shipped robot.

Usage::

    wmm_randomized [--goals N] [--seed S] [--robots steerable,mecanum,...] [--methods pinv,...]
                   [--indices I,...] [--engine direct|nodes] [--obstacles FILE] [--record DIR]
                   [--jobs N] [--out FILE [--resume]]

Draws ``N`` reachable goals per robot (:mod:`wmm_control.experiments.randomized` says what
reachable means), runs each method to each goal from the robot's start state in lockstep, in
this process, and prints per robot and method: runs, converged, reported (stalled, on
``/diagnostics``), failed, the worst final error of the converged runs, the time to converge,
and the worst use of any velocity or acceleration limit; then the control cycle's thread CPU
and wall time per period (the largest p99 of a run and the longest cycle). ``--indices`` runs
only those goals of the draw (one run again, say). ``--obstacles`` puts an obstacle file's obstacles
(:mod:`wmm_control.kinematics.obstacles`) in the simulator and the controller, and draws the
goals clear of them (in the file's ``goal_region``, if it has one); every period's clearance
is checked on the simulator's geometry. ``--record DIR`` writes each run as
``DIR/<robot>_<method>_<goal>.npz`` (:mod:`wmm_control.experiments.randomized` documents the
arrays). ``--jobs`` runs that many runs at once, in separate processes (default: one per core; the results are the
same as one at a time). ``--out`` writes every run as JSON, rewritten as each run ends;
``--resume`` keeps the runs already in that file (from an interrupted run of the same draw,
engine, obstacles and parameters) and runs only the others.
The exit status is 1 when a run failed (a limit passed, a non-finite command, or neither
converged nor reported).
"""

import argparse
import json
import os
import sys
from collections.abc import Mapping
from functools import partial
from typing import Any

from wmm_control.errors import WmmError
from wmm_control.experiments.jobs import default_jobs, jobs_argument, run_jobs
from wmm_control.experiments.randomized import METHOD_RUNS, run_goal, sample_goals, summarize
from wmm_control.robot_config import load_robot, robot_names

__all__ = ['main', 'format_summary', 'format_cycle_times']


def _f(value, fmt):
    return '—' if value is None else format(value, fmt)


def format_summary(table: Mapping[tuple[str, str], Mapping[str, Any]]) -> str:
    """The summary of :func:`~wmm_control.experiments.randomized.summarize` as a Markdown table."""
    lines = [
        '| robot | method | runs | converged | reported | failed | worst error [mm / rad] '
        '| time to converge, median / max [s] | largest use of a limit | closest joint to a limit [rad] '
        '| in contact | deepest contact [mm] |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for (robot, method), s in table.items():
        err = (
            f'{_f(s["worst_position_error_m"] and s["worst_position_error_m"] * 1e3, ".1f")} / '
            f'{_f(s["worst_orientation_error_rad"], ".3f")}'
        )
        lines.append(
            f'| {robot} | {method} | {s["runs"]} | {s["converged"]} | {s["reported"]} | {s["failed"]} '
            f'| {err} | {_f(s["median_time_s"], ".1f")} / {_f(s["max_time_s"], ".1f")} '
            f'| {s["limit_use_max"]:.3f} | {s["position_margin_min_rad"]:.3f} '
            f'| {s["in_contact"]} | {s["deepest_contact_m"] * 1e3:.1f} |'
        )
    return '\n'.join(lines)


def format_cycle_times(table: Mapping[tuple[str, str], Mapping[str, Any]]) -> str:
    """The control cycle's times per robot and method of :func:`~wmm_control.experiments.randomized.summarize`
    as a Markdown table [ms]: the largest p99 of a run and the longest cycle, thread CPU and wall."""

    def ms(value):
        return _f(value and value * 1e3, '.2f')

    lines = [
        '| robot | method | cycle CPU p99, worst run [ms] | cycle CPU max [ms] | cycle wall p99, worst run [ms] '
        '| cycle wall max [ms] |',
        '|---|---|---|---|---|---|',
    ]
    for (robot, method), s in table.items():
        lines.append(
            f'| {robot} | {method} | {ms(s["cycle_cpu_p99_s"])} | {ms(s["cycle_cpu_max_s"])} '
            f'| {ms(s["cycle_p99_s"])} | {ms(s["cycle_max_s"])} |'
        )
    return '\n'.join(lines)


def _param(text):
    """``NAME=VALUE`` -> (name, value), the value read as YAML (numbers, booleans, strings)."""
    import yaml

    name, sep, value = text.partition('=')
    if not sep or not name:
        raise WmmError(f'--param: expected NAME=VALUE, got {text!r}')
    return name, yaml.safe_load(value)


def _indices(text, goals):
    """``--indices``: a set of goal indices, or None for all of them."""
    if not text:
        return None
    try:
        out = {int(v) for v in text.split(',') if v.strip()}
    except ValueError as exc:
        raise WmmError(f'--indices: expected comma-separated integers, got {text!r}') from exc
    if not out or min(out) < 0 or max(out) >= goals:
        raise WmmError(f'--indices: each index must be within 0..{goals - 1}, got {text!r}')
    return out


def _run_one(job, options):
    robot, method, goal = job
    return run_goal(robot, method, goal, **options)


def _run_all(jobs, options, workers, bar, done=()):
    """Every run of ``jobs``, in their order, ``workers`` at a time (separate processes), after
    the runs ``done``; yields the runs so far as each one ends."""
    results = list(done)
    for job, result in zip(jobs, run_jobs(partial(_run_one, options=options), jobs, workers)):
        bar.set_description(f'{job[0]} {job[1]}')
        results.append(result)
        bar.update(1)
        yield results


def _write(path, header, results):
    """``header`` and the runs ``results`` with their summary as JSON at ``path``, replaced whole
    (an interrupted write leaves the previous file)."""
    table = summarize(results)
    document = dict(header, runs=results, summary=[dict(robot=r, method=m, **s) for (r, m), s in table.items()])
    tmp = f'{path}.tmp'
    with open(tmp, 'w') as fh:
        json.dump(document, fh, indent=1)
    os.replace(tmp, path)


def _resumed(path, header):
    """The runs of the earlier file ``path`` when it was written with the same ``header``."""
    try:
        with open(path) as fh:
            earlier = json.load(fh)
    except FileNotFoundError:
        return []
    except (OSError, ValueError) as exc:
        raise WmmError(f'--resume: cannot read {path}: {exc}') from exc
    differs = {k: (earlier.get(k), v) for k, v in header.items() if earlier.get(k) != v}
    if differs:
        raise WmmError(f'--resume: {path} is from other settings (earlier, now): {differs}')
    return earlier['runs']


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='wmm_randomized', description=__doc__.split('\n\n')[0])
    parser.add_argument('--goals', type=int, default=100, help='goals per robot (default: %(default)s)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the draw (default: %(default)s)')
    parser.add_argument(
        '--robots', default=','.join(robot_names()), help='comma-separated (default: every shipped robot, %(default)s)'
    )
    parser.add_argument('--methods', default=','.join(METHOD_RUNS), help='comma-separated (default: %(default)s)')
    parser.add_argument(
        '--indices', default='', help='comma-separated goal indices of the draw to run, e.g. 24,29 (default: all)'
    )
    parser.add_argument(
        '--engine',
        choices=('direct', 'nodes'),
        default='direct',
        help='direct: the core objects without ROS; nodes: every node in this process over '
        'topics (default: %(default)s)',
    )
    parser.add_argument(
        '--param',
        action='append',
        default=[],
        metavar='NAME=VALUE',
        help='a resolver parameter for every run, e.g. orientation_error=log (repeatable)',
    )
    parser.add_argument(
        '--obstacles', default='', help='obstacle file: a name in config/obstacles (e.g. table_pillar) or a YAML path'
    )
    parser.add_argument('--record', metavar='DIR', help='write each run to DIR/<robot>_<method>_<goal>.npz')
    parser.add_argument(
        '--jobs',
        type=jobs_argument,
        default=default_jobs(),
        help='runs at once, in separate processes (default: one per core, %(default)s)',
    )
    parser.add_argument('--out', help='write every run as JSON to this file (rewritten as each run ends)')
    parser.add_argument(
        '--resume', action='store_true', help='keep the runs already in --out (same settings) and run the others'
    )
    args = parser.parse_args(argv)
    from tqdm import tqdm

    robots = [r for r in args.robots.split(',') if r]
    methods = [m for m in args.methods.split(',') if m]
    try:
        unknown = sorted(set(methods) - set(METHOD_RUNS))
        if unknown or args.goals < 1:
            raise WmmError(
                f'--methods: unknown {unknown}, expected some of {list(METHOD_RUNS)}'
                if unknown
                else f'--goals must be >= 1, got {args.goals}'
            )
        if args.resume and not args.out:
            raise WmmError('--resume needs --out')
        params = dict(_param(text) for text in args.param)
        indices = _indices(args.indices, args.goals)
        header = {
            'seed': args.seed,
            'goals': args.goals,
            'engine': args.engine,
            'obstacles': args.obstacles,
            'params': params,
        }
        draws = {
            r: [
                g
                for g in sample_goals(r, args.goals, seed=args.seed, obstacles=args.obstacles)
                if indices is None or g.index in indices
            ]
            for r in robots
        }
        jobs = [(robot, method, goal) for robot in robots for method in methods for goal in draws[robot]]
        name = {r: load_robot(r).name for r in robots}  # the name a run records ('A' is 'steerable')
        keys = {(name[robot], method, goal.index) for robot, method, goal in jobs}
        done = (
            [r for r in _resumed(args.out, header) if (r['robot'], r['method'], r['goal']) in keys]
            if args.resume
            else []
        )
        finished = {(r['robot'], r['method'], r['goal']) for r in done}
        jobs = [job for job in jobs if (name[job[0]], job[1], job[2].index) not in finished]
        options = dict(engine=args.engine, params=params, obstacles=args.obstacles, record=args.record)
        results = done
        with tqdm(total=len(jobs) + len(done), initial=len(done), unit='run', file=sys.stderr) as bar:
            for results in _run_all(jobs, options, args.jobs, bar, done):
                if args.out:
                    _write(args.out, header, results)
    except WmmError as exc:
        print(f'wmm_randomized: {exc}', file=sys.stderr)
        return 2
    table = summarize(results)
    only = f', goals {sorted(indices)} of them' if indices is not None else ''
    print(f'{args.goals} random reachable goals per robot (seed {args.seed}{only}), engine {args.engine}:')
    print(format_summary(table))
    print(f'\nControl cycle per period (method, safety stage, base controller; engine {args.engine}):')
    print(format_cycle_times(table))
    failed = [r for r in results if r['outcome'] == 'failed']
    for r in failed:
        print(f'FAILED: {r["robot"]} {r["method"]} goal {r["goal"]}: {r["why"]}')
    if args.out and not jobs:
        _write(args.out, header, results)  # nothing left to run: the file as it is, summarized again
    return 1 if failed else 0


if __name__ == '__main__':
    raise SystemExit(main())
