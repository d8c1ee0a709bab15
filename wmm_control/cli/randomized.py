"""``wmm_randomized``: randomized closed-loop runs, every method on every shipped robot.

Usage::

    wmm_randomized [--goals N] [--seed S] [--robots steerable,mecanum,...] [--methods pinv,...]
                   [--indices I,...] [--engine direct|nodes] [--obstacles FILE] [--plan] [--record DIR]
                   [--sweep NAME=V1,V2,...] [--jobs N] [--cluster ray|ray:auto|ray:HOST:PORT|ray://HOST:PORT]
                   [--out FILE [--resume]]

Draws ``N`` reachable goals per robot (:mod:`wmm_control.experiments.randomized` says what
reachable means), runs each method to each goal from the robot's start state in lockstep, in
this process, and prints per robot and method: runs, converged, reported (stalled, on
``/diagnostics``), failed, the worst final error of the converged runs, the time to converge,
and the worst use of any velocity or acceleration limit; then the control cycle's thread CPU
and wall time per period (the largest p99 of a run and the longest cycle). ``--indices`` runs
only those goals of the draw (one run again, say). ``--obstacles`` puts an obstacle file's obstacles
(:mod:`wmm_control.kinematics.obstacles`; its ``random_boxes`` drawn by ``--seed``) in the simulator and the controller, and draws the
goals clear of them (in the file's ``goal_region``, if it has one); every period's clearance
is checked on the simulator's geometry. ``--plan`` plans the way to each
goal round the obstacles first (:mod:`wmm_control.planning`), the run follows it at the robot's
pace (planned again from where the robot stalls) and then goes to the goal; a goal the planner
finds no way to counts as "no way", with its reason, not as failed, and that verdict is checked
apart from the planner's search (:func:`~wmm_control.planning.no_way_check.confirm_no_way`):
the table counts the "no way" runs confirmed, refuted and unchecked, and a line per run gives
its reason and the check's evidence. ``--record DIR`` writes
each run as ``DIR/<robot>_<method>_<goal>.npz`` (:mod:`wmm_control.experiments.randomized`
documents the arrays). ``--sweep NAME=V1,V2,...`` (repeatable) runs the goals with every value of a resolver
parameter (every combination of several; :mod:`wmm_control.experiments.sweep`), prints one
table per value, and with ``--out`` plots the converged share and the time to converge against
the value beside it (``<out>_sweep.png``). ``--jobs`` runs that many runs at once, in separate
processes (default: one per core; the results are the same as one at a time). ``--cluster``
runs them as Ray tasks, on a Ray instance of this machine or on a cluster
(:mod:`wmm_control.experiments.cluster`), with the same results. ``--out`` writes every run as
JSON, rewritten as each run ends; ``--resume`` keeps the runs already in that file (from an
interrupted run of the same draw, engine, obstacles, parameters and sweep) and runs only the
others. A run that raises is recorded as failed, with its error.
The exit status is 1 when a run failed (a limit passed, a non-finite command, contact, an
error, or neither converged nor reported), 2 on bad input (before any run starts).
"""

import argparse
import json
import os
import sys
import shutil
import tempfile
import traceback
from collections.abc import Mapping
from contextlib import ExitStack
from functools import partial
from pathlib import Path
from typing import Any

# only what the arguments need: the study's modules (the kinematics, the simulator, ROS) are
# imported where they are used, once the arguments are parsed (--help and a bad argument answer
# at once)
from wmm_control.errors import WmmError
from wmm_control.experiments.cluster import CLUSTER_HELP, files_of, ray_session, run_tasks, write_files
from wmm_control.experiments.jobs import default_jobs, jobs_argument, run_jobs
from wmm_control.experiments.method_runs import METHOD_RUNS, ROBOT_RUNS
from wmm_control.paths import robot_names

__all__ = ['main', 'format_summary', 'format_cycle_times', 'format_no_way']


def _f(value, fmt):
    return '—' if value is None else format(value, fmt)


def format_summary(table: Mapping[tuple[str, str], Mapping[str, Any]]) -> str:
    """The summary of :func:`~wmm_control.experiments.randomized.summarize` as a Markdown table."""
    lines = [
        '| robot | method | runs | converged | reported | failed | no way (confirmed / refuted / unchecked) '
        '| worst error [mm / rad] '
        '| time to converge, median / max [s] | largest use of a limit | closest joint to a limit [rad] '
        '| in contact | deepest contact [mm] |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for (robot, method), s in table.items():
        err = (
            f'{_f(s["worst_position_error_m"] and s["worst_position_error_m"] * 1e3, ".1f")} / '
            f'{_f(s["worst_orientation_error_rad"], ".3f")}'
        )
        lines.append(
            f'| {robot} | {method} | {s["runs"]} | {s["converged"]} | {s["reported"]} | {s["failed"]} '
            f'| {_no_way(s)} '
            f'| {err} | {_f(s["median_time_s"], ".1f")} / {_f(s["max_time_s"], ".1f")} '
            f'| {_f(s["limit_use_max"], ".3f")} | {_f(s["position_margin_min_rad"], ".3f")} '
            f'| {s["in_contact"]} | {s["deepest_contact_m"] * 1e3:.1f} |'
        )
    return '\n'.join(lines)


def _no_way(s):
    """A summary's "no way" cell: the count, and by the check's verdict when there are any."""
    count = s.get('no_way', 0)
    if not count:
        return '0'
    return f'{count} ({s.get("no_way_confirmed", 0)} / {s.get("no_way_refuted", 0)} / {s.get("no_way_unchecked", 0)})'


def format_no_way(results) -> str:
    """One line per "no way" run: its reason and what the check of it found."""
    lines = []
    for r in results:
        if r['outcome'] != 'no_way':
            continue
        check = r.get('no_way_check') or {}
        lines.append(
            f'NO WAY: {r["robot"]} {r["method"]} goal {r["goal"]}{_at(r)}: {r.get("no_way_reason")}; check '
            f'{check.get("verdict", "missing")}: {check.get("evidence", "")}'
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


def _raised(robot, method, goal, exc):
    """The record of a run that raised ``exc``: failed, with its error."""
    from wmm_control.robot_config import load_robot

    return {
        'robot': load_robot(robot).name,
        'method': method,
        'goal': goal.index,
        'outcome': 'failed',
        'why': f'raised {type(exc).__name__}: {exc}',
        'error': ''.join(traceback.format_exception(exc)),
    }


def _run_one(job, options):
    """One run, wherever it runs: ``(its record, {name: bytes} of its --record file)``. A run
    that raises is a failed record (never retried: it would raise again)."""
    from wmm_control.experiments import randomized as study

    robot, method, goal, point = job
    with tempfile.TemporaryDirectory() as tmp:
        try:
            params = {**options['params'], **point}
            result = study.run_goal(
                robot, method, goal, **dict(options, params=params, record=tmp if options['record'] else None)
            )
        except Exception as exc:
            result = _raised(robot, method, goal, exc)
        files = files_of(tmp)
    if point:
        result['sweep'] = dict(point)
    return result, files


def _lost(job, why):
    """The record of a run whose worker died on every try."""
    robot, method, goal, point = job
    return (dict(_raised(robot, method, goal, RuntimeError(why)), **({'sweep': dict(point)} if point else {})), {})


def _key(run):
    """What tells a run from the others of a study (its point of a sweep included)."""
    from wmm_control.experiments.sweep import point_label

    return run['robot'], run['method'], run['goal'], point_label(run.get('sweep', {}))


def _run_all(jobs, options, workers, session):
    """``(i, (record, files))`` for every job, as each ends: ``workers`` at a time (separate
    processes), or as Ray tasks when ``session`` holds a :func:`ray_session`."""
    fn = partial(_run_one, options=options)
    if session is None:
        yield from enumerate(run_jobs(fn, jobs, workers))
    else:
        ray, on_retry = session
        yield from run_tasks(ray, fn, jobs, _lost, on_retry)


def _summary(results, points):
    """The summary rows of ``--out``: per robot and method (and point of the sweep, if any)."""
    from wmm_control.experiments.randomized import summarize

    rows = []
    for point in points:
        runs = [r for r in results if r.get('sweep', {}) == point]
        for (robot, method), s in summarize(runs).items():
            rows.append(dict(({'sweep': point} if point else {}), robot=robot, method=method, **s))
    return rows


def _write(path, header, results, points):
    """``header`` and the runs ``results`` with their summary as JSON at ``path``, replaced whole
    (an interrupted write leaves the previous file)."""
    document = dict(header, runs=results, summary=_summary(results, points))
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
    parser.add_argument(
        '--plan',
        action='store_true',
        help='plan the way to each goal first (wmm_control.planning; the goal_planner node with --engine nodes) and track it',
    )
    parser.add_argument('--record', metavar='DIR', help='write each run to DIR/<robot>_<method>_<goal>.npz')
    parser.add_argument(
        '--jobs',
        type=jobs_argument,
        default=default_jobs(),
        help='runs at once, in separate processes, or the CPUs of --cluster ray (default: one per core, %(default)s)',
    )
    parser.add_argument(
        '--sweep',
        action='append',
        default=[],
        metavar='NAME=V1,V2,...',
        help='run the goals with each value of a resolver parameter (repeatable: every combination)',
    )
    parser.add_argument('--cluster', metavar='ray|ray:auto|ray:HOST:PORT|ray://HOST:PORT', help=CLUSTER_HELP)
    parser.add_argument('--out', help='write every run as JSON to this file (rewritten as each run ends)')
    parser.add_argument(
        '--resume', action='store_true', help='keep the runs already in --out (same settings) and run the others'
    )
    args = parser.parse_args(argv)
    robots = [r for r in args.robots.split(',') if r]
    methods = [m for m in args.methods.split(',') if m]
    cleanup: list[Path] = []
    try:
        return _main(args, robots, methods, cleanup)
    finally:
        for folder in cleanup:
            shutil.rmtree(folder, ignore_errors=True)


def _main(args, robots, methods, cleanup) -> int:
    from tqdm import tqdm

    from wmm_control.experiments.randomized import sample_goals, summarize
    from wmm_control.experiments.sweep import check_point, parse_sweeps, plot_sweep, point_label, sweep_grid
    from wmm_control.kinematics.obstacles import is_drawn, obstacle_file, obstacle_text
    from wmm_control.robot_config import load_robot

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
        sweeps = parse_sweeps(args.sweep)
        points = sweep_grid(sweeps)
        for method in methods:
            for robot in robots:
                run = {**METHOD_RUNS[method], **ROBOT_RUNS.get(load_robot(robot).name, {}).get(method, {}), **params}
                for point in points if sweeps else ():
                    check_point(method, run, point)
        indices = _indices(args.indices, args.goals)
        header = {
            'seed': args.seed,
            'goals': args.goals,
            'engine': args.engine,
            'obstacles': args.obstacles,
            **({'plan': True} if args.plan else {}),
            'params': params,
            **({'sweep': sweeps} if sweeps else {}),
        }
        if is_drawn(args.obstacles):  # the seed's draw, as a file every run (and process) reads
            drawn = Path(tempfile.mkdtemp(prefix='wmm_obstacles_'))
            cleanup.append(drawn)
            path = drawn / f'{obstacle_file(args.obstacles).stem}_seed{args.seed}.yaml'
            path.write_text(obstacle_text(args.obstacles, args.seed))
            args.obstacles = str(path)
        draws = {
            r: [
                g
                for g in sample_goals(r, args.goals, seed=args.seed, obstacles=args.obstacles)
                if indices is None or g.index in indices
            ]
            for r in robots
        }
        jobs = [(r, m, g, p) for p in points for r in robots for m in methods for g in draws[r]]
        name = {r: load_robot(r).name for r in robots}  # the name a run records ('A' is 'steerable')
        keys = {(name[r], m, g.index, point_label(p)) for r, m, g, p in jobs}
        done = [r for r in _resumed(args.out, header) if _key(r) in keys] if args.resume else []
        finished = {_key(r) for r in done}
        jobs = [job for job in jobs if (name[job[0]], job[1], job[2].index, point_label(job[3])) not in finished]
        options = dict(engine=args.engine, params=params, obstacles=args.obstacles, record=args.record, plan=args.plan)
        with ExitStack() as stack:
            bar = stack.enter_context(
                tqdm(total=len(jobs) + len(done), initial=len(done), unit='run', file=sys.stderr, smoothing=0.0)
            )
            tally = {'failed': sum(r['outcome'] == 'failed' for r in done), 'retried': 0}
            session = None
            if args.cluster:
                ray = stack.enter_context(ray_session(args.cluster, args.jobs))
                session = (ray, lambda n: _tally(bar, tally, retried=n))
            ended: dict[int, dict] = {}
            for i, (result, files) in _run_all(jobs, options, args.jobs, session):
                ended[i] = result
                robot, method, goal, point = jobs[i]
                if args.record and files:
                    write_files(Path(args.record) / point_label(point), files)
                bar.set_description(f'{robot} {method}')
                _tally(bar, tally, failed=tally['failed'] + (result['outcome'] == 'failed'))
                bar.update(1)
                if args.out:
                    _write(args.out, header, done + [ended[k] for k in sorted(ended)], points)
            results = done + [ended[k] for k in sorted(ended)]
    except WmmError as exc:
        print(f'wmm_randomized: {exc}', file=sys.stderr)
        return 2
    only = f', goals {sorted(indices)} of them' if indices is not None else ''
    print(f'{args.goals} random reachable goals per robot (seed {args.seed}{only}), engine {args.engine}:')
    for point in points:
        if point:
            print(f'\n{point_label(point)}:')
        table = summarize(r for r in results if r.get('sweep', {}) == point)
        print(format_summary(table))
        print(f'\nControl cycle per period (method, safety stage, base controller; engine {args.engine}):')
        print(format_cycle_times(table))
    no_way = format_no_way(results)
    if no_way:
        print(no_way)
    failed = [r for r in results if r['outcome'] == 'failed']
    for r in failed:
        print(f'FAILED: {r["robot"]} {r["method"]} goal {r["goal"]}{_at(r)}: {r["why"]}')
    if args.out and not jobs:
        _write(args.out, header, results, points)  # nothing left to run: the file as it is, summarized again
    if args.out and sweeps:
        with open(args.out) as fh:
            summary = json.load(fh)['summary']
        print(f'wrote {plot_sweep(summary, sweeps, sweep_plot_path(args.out))}')
    return 1 if failed else 0


def sweep_plot_path(out: str | Path) -> Path:
    """Where the plot of a sweep goes: beside ``--out``, ``<out stem>_sweep.png``."""
    return Path(out).with_name(Path(out).stem + '_sweep.png')


def _at(run):
    from wmm_control.experiments.sweep import point_label

    return f' ({point_label(run["sweep"])})' if run.get('sweep') else ''


def _tally(bar, tally, **counts):
    """Update the runs failed and retried of ``tally`` and show them on the progress bar."""
    tally.update(counts)
    bar.set_postfix(tally, refresh=False)


if __name__ == '__main__':
    raise SystemExit(main())
