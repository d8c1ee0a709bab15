"""``wmm_experiment``: run a paper's experiment end to end and write its numbers and figures.

Usage::

    wmm_experiment [SCENARIO|all] [--scenario PATH] [--out DIR] [--runs NAME,...] [--engine nodes|direct]
                   [--seed N] [--no-figures] [--jobs N] [--cluster ray|ray:auto|ray:HOST:PORT|ray://HOST:PORT]
                   [--report PAGE]

``SCENARIO`` names ``config/scenarios/<SCENARIO>.yaml``; ``all`` (the default) runs both papers'
experiments (:data:`MAIN_JOB`: Table II of Sorour et al. 2019 and Xing et al. §4), each into
``DIR/<scenario>``; ``--scenario PATH`` takes any file of that form. Each run of the
scenario's ``experiment`` section is simulated with every node in this process over real
topics (``--engine nodes``, the default: ``wmm_sim`` in lockstep, ``swmr_controller``,
``redundancy_resolver``, ``goal_sequencer``), or with the same objects and no ROS in between
(``--engine direct``, for quick sweeps). DIR receives ``metrics.json``, the figures and, with
``--engine nodes``, one rosbag2 (MCAP) of all the topics of each run, ``rosbag2_<run>/``.
``--jobs N`` runs that many runs at once, each in a process of its own (default: one per core;
1: one after the other in this process); every run is deterministic, so the numbers are those
of a serial run, and this process writes the tables and figures. ``--cluster`` runs them as Ray
tasks instead, on a Ray instance of this machine or on a cluster
(:mod:`wmm_control.experiments.cluster`): each run's log and recording come back to this
process, which writes them, with the numbers of a serial run. ``--report PAGE`` also writes
a Markdown page of every table the run produced (:mod:`wmm_control.experiments.report`), with
the text of ``<PAGE stem>_intro.md`` beside it, if there is one, first (``bash scripts/dev.sh
run`` writes docs/results.md so, after docs/results_intro.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import resource
import shutil
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

# only what the arguments need: the simulator, ROS, the kinematics and the resolvers are
# imported where they are used, once the arguments are parsed (--help and a bad argument answer
# at once)
from wmm_control.errors import WmmError
from wmm_control.experiments.cluster import CLUSTER_HELP, files_of, in_order, ray_session, run_tasks, write_files
from wmm_control.experiments.jobs import default_jobs, jobs_argument, run_jobs

if TYPE_CHECKING:
    from wmm_control.experiments.metrics import RunLog
    from wmm_control.experiments.scenario import Scenario

__all__ = [
    'main',
    'run_experiment',
    'simulate',
    'summarize_runs',
    'RunJob',
    'format_table',
    'format_matrix',
    'MAIN_JOB',
    'MATRIX',
]

#: The scenarios of ``wmm_experiment all``, the main job (docs/results.md): both papers' experiments.
MAIN_JOB = (
    'sorour_table2',
    'xing_circle_0.10',
    'xing_circle_0.25',
    'xing_pose',
    'xing_singularity',
    'matrix_circle_0.25_a',
    'matrix_circle_0.25_b',
)
#: The scenarios of the one table no paper has: one circle, both robots, all four methods.
MATRIX = ('matrix_circle_0.25_a', 'matrix_circle_0.25_b')
#: The control period of the runs [s].
DT = 0.025


def _run_direct(scenario, run, progress):
    from sim_bridge.slip import SlipParams
    from sim_bridge.world import SimWorld
    from wmm_control.experiments.direct import run_scenario
    from wmm_control.experiments.scenario import resolver_parameters
    from wmm_control.resolvers import make_resolver

    sim = dict(scenario.sim or {})
    slip = SlipParams(
        gain=float(sim.get('slip_gain', 0.0)),
        drift=tuple(sim.get('slip_drift', (0.0,) * 3)),
        noise_std=tuple(sim.get('slip_noise', (0.0,) * 3)),
    )
    params = resolver_parameters(run)
    resolver = make_resolver(run['method'], scenario.robot, **params)
    with SimWorld(
        scenario.robot,
        base_mode=sim.get('base_mode', 'kinematic'),
        substeps=sim.get('substeps', 10),
        slip=slip,
        seed=int(sim.get('seed', 0)),
    ) as world:
        return run_scenario(
            world,
            resolver,
            scenario,
            feedback=run.get('feedback', 'ground_truth'),
            label=run['name'],
            progress=lambda n: progress(n * world.dt),
        )


def bag_path(out: str | Path, run_name: str) -> Path:
    """The rosbag2 folder of run ``run_name`` in the output folder ``out``."""
    return Path(out) / f'rosbag2_{run_name}'


@dataclass(frozen=True)
class RunJob:
    """One run of a scenario, as handed to a worker process (:func:`simulate`)."""

    scenario: object
    run: dict
    engine: str = 'nodes'
    bag_dir: Path | None = None
    view_port: int | None = None
    #: 'bar': a progress bar; 'line': a line when the run is done (a worker's); 'none'
    progress: str = 'bar'
    #: ROS domain of a nodes run; None: the process's own (:func:`private_domain_id`)
    domain_id: int | None = None


def simulate(job):
    """Simulate one run: ``(its frozen RunLog, the peak memory of this process [MB])``."""
    scenario, run = job.scenario, job.run
    with tqdm(
        total=scenario.duration,
        desc=run['name'],
        unit='sim s',
        disable=job.progress != 'bar',
        bar_format='{desc:<36} {percentage:3.0f}%|{bar}| {n:.1f}/{total:.0f} sim s [{elapsed}]',
    ) as bar:

        def advance(dt: float) -> None:  # a run can end a period past its duration: the bar stops at 100 %
            bar.update(min(dt, max(bar.total - bar.n, 0.0)))

        if job.engine == 'nodes':
            from wmm_control.experiments.ros_run import run_with_nodes

            log = run_with_nodes(
                scenario,
                run,
                progress=advance,
                domain_id=job.domain_id,
                bag_path=None if job.bag_dir is None else bag_path(job.bag_dir, run['name']),
                view_port=job.view_port,
            )
        else:
            log = _run_direct(scenario, run, advance)
    if job.progress == 'line':
        print(
            f'  {scenario.name} / {run["name"]}: {len(log) * DT:.0f} sim s in {log.wall_time_s:.0f} s',
            file=sys.stderr,
            flush=True,
        )
    return log, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def simulate_shipped(job):
    """:func:`simulate` on another machine: its recording is written to a folder of that machine
    and comes back as bytes: ``(RunLog, peak memory [MB], {path under the job's bag_dir: bytes})``."""
    with tempfile.TemporaryDirectory() as tmp:
        bag_dir = None if job.bag_dir is None else tmp
        log, peak_mb = simulate(dataclasses.replace(job, bag_dir=bag_dir))
        return log, peak_mb, files_of(tmp)


def _lost(job, why):
    raise WmmError(f'{job.scenario.name} / {job.run["name"]}: {why}')


def _on_cluster(todo, session):
    """The ``(RunLog, peak memory)`` of every job of ``todo`` in their order, run as Ray tasks of
    ``session`` (:func:`ray_session`); each recording written here as it comes back."""
    bar = tqdm(total=len(todo), unit='run', file=sys.stderr, smoothing=0.0)
    try:
        tasks = run_tasks(session, simulate_shipped, todo, _lost, lambda n: bar.set_postfix(retried=n, refresh=False))
        for job, (log, peak_mb, files) in zip(todo, in_order(_counted(tasks, bar))):
            if job.bag_dir is not None:
                write_files(job.bag_dir, files)
            yield log, peak_mb
    finally:
        bar.close()


def _counted(results, bar):
    for item in results:
        bar.update(1)
        yield item


def _selected(scenario, runs):
    selected = [r for r in scenario.runs if runs is None or r['name'] in runs]
    if not selected:
        raise WmmError(f'no run named {sorted(runs)}; the scenario has {[r["name"] for r in scenario.runs]}')
    return selected


def run_experiment(
    scenario: Scenario,
    runs: Iterable[str] | None = None,
    engine: str = 'nodes',
    show_progress: bool = True,
    bag_dir: str | Path | None = None,
    view_port: int | None = None,
    jobs: int = 1,
) -> tuple[dict[str, RunLog], dict]:
    """Simulate the runs of ``scenario``, ``jobs`` at once (separate processes; 1: in this
    process); with ``bag_dir`` (engine ``nodes``), each run is recorded there as a rosbag2
    (MCAP) of all its topics, :func:`bag_path`.

    Returns:
        (logs, summary): ``logs`` maps a run name to its RunLog; ``summary`` is the
        ``metrics.json`` content (see docs/results.md for its keys).
    """
    selected = _selected(scenario, runs)
    todo = _jobs_of(scenario, selected, engine, bag_dir, view_port, 'bar' if show_progress else 'none', jobs)
    logs = {run['name']: log for run, (log, _) in zip(selected, run_jobs(simulate, todo, jobs))}
    return logs, summarize_runs(scenario, selected, logs, engine, bag_dir)


def _jobs_of(scenario, selected, engine, bag_dir, view_port, progress, workers, first=0):
    """The :class:`RunJob` of each selected run. With several workers, each run reports a line
    when done instead of a bar, and each nodes run gets a ROS domain of its own (``first``
    numbers the jobs across scenarios)."""
    if workers == 1:
        return [RunJob(scenario, run, engine, bag_dir, view_port, progress) for run in selected]
    from wmm_control.experiments.ros_run import private_domain_id

    return [
        RunJob(
            scenario,
            run,
            engine,
            bag_dir,
            view_port,
            'line' if progress != 'none' else 'none',
            private_domain_id(offset=1 + first + i),
        )
        for i, run in enumerate(selected)
    ]


def summarize_runs(
    scenario: Scenario,
    selected: Iterable[Mapping[str, Any]],
    logs: Mapping[str, RunLog],
    engine: str = 'nodes',
    bag_dir: str | Path | None = None,
) -> dict:
    """The ``metrics.json`` content of the runs ``selected`` of ``scenario``, simulated into
    ``logs`` (run name -> RunLog)."""
    from wmm_control.experiments.metrics import (
        METRIC_KEYS,
        TRAJECTORY_METRIC_KEYS,
        run_limit_report,
        trajectory_metrics,
    )
    from wmm_control.experiments.scenario import resolver_parameters
    from wmm_control.kinematics import KinematicModel

    model = KinematicModel(scenario.robot)
    robot = model.config
    summary_runs = {}
    dt = DT
    for run in selected:
        log = logs[run['name']]
        entry = {
            'method': run['method'],
            'feedback': run.get('feedback', 'ground_truth'),
            'parameters': resolver_parameters(run),
            'periods': len(log),
            'wall_time_s': log.wall_time_s,
            'sim_to_wall_ratio': float(log.t[-1] + dt) / log.wall_time_s if log.wall_time_s > 0 else None,
            'resolver_cycle_median_us': float(np.median(log.cycle_time_s) * 1e6),
            'limits_exceeded': run_limit_report(log, robot, dt, tol=1e-6),
            'simulator_counters': log.sim_counters,
            # the safety stage: the closest it saw the arm come to the body, itself or the floor,
            # and the periods in which it changed the method's arm command
            'clearance_min_m': float(np.min(log.clearance)),
            'collision_changed_periods': int(np.count_nonzero(log.collision_changed)),
            # the cycles in which each of its limits bound, as the resolver's /diagnostics reports them
            'safety_counts': log.safety_counts,
        }
        if bag_dir is not None and engine == 'nodes':
            entry['recording'] = str(bag_path(bag_dir, run['name']))
        if scenario.trajectory is not None:
            entry['tracking'] = trajectory_metrics(log, scenario, model, dt)
        else:
            entry.update(_goal_summary(log, scenario, model, run, dt))
        summary_runs[run['name']] = entry
    summary = {
        'scenario': scenario.name,
        'description': scenario.description,
        'robot': robot.name,
        'engine': engine,
        'timing': 'lockstep' if engine == 'nodes' else 'direct (no ROS)',
        'simulator': dict(scenario.sim or {}, base_mode=(scenario.sim or {}).get('base_mode', 'kinematic')),
        'goal_windows_s': [[g.t, g.end] for g in scenario.goals],
        'trajectory': scenario.trajectory,
        'runs': summary_runs,
        'metric_keys': TRAJECTORY_METRIC_KEYS if scenario.trajectory is not None else METRIC_KEYS,
    }
    return summary


def _goal_summary(log, scenario, model, run, dt):
    """Per-goal metrics of a run of a goals scenario, with its totals."""
    from wmm_control.experiments.metrics import goal_metrics
    from wmm_control.resolvers import TaskSharingParams

    goals = goal_metrics(
        log, scenario, model, run.get('r_fm', TaskSharingParams().r_fm), model.config.arm.dexterous, dt
    )
    if not (run['method'] == 'task_sharing' and run.get('compensation', True)):
        for g in goals:
            g['compensation_dropped'] = None
    return {
        'total_area': float(sum(g.get('area', 0.0) for g in goals)),
        'all_goals_reached': all(g.get('reached', False) for g in goals),
        'goals': goals,
    }


def _f(value, fmt):
    return '—' if value is None else format(value, fmt)


def format_tracking_table(summary: Mapping[str, Any]) -> str:
    """Xing et al. Tables 2–3 style: commanded base velocity RMS and active time, end-effector errors."""
    head = (
        f'{"run":<34}{"base RMS vx, vy [cm/s], ω [°/s]":>32}{"base active [s]":>17}{"max err x, y, xy [mm]":>24}'
        f'{"rot y [rad]":>12}{"σ_min":>7}'
    )
    lines = [head, '-' * len(head)]
    for name, run in summary['runs'].items():
        m = run['tracking']
        rms = m['base_rms']
        lim = run['limits_exceeded']
        lines.append(
            f'{name:<34}{rms[0] * 100:>12.2f}{rms[1] * 100:>9.2f}{np.degrees(rms[2]):>11.3f}'
            f'{m["base_active_any_s"]:>17.2f}{m["max_error_x_m"] * 1e3:>10.2f}{m["max_error_y_m"] * 1e3:>7.2f}'
            f'{m["max_error_xy_m"] * 1e3:>7.2f}{m["max_rotation_error_y_rad"]:>12.4f}{m["sigma_min_min"]:>7.3f}'
        )
        lines.append(
            f'{"":<5}{"no limit passed" if not any(lim.values()) else f"LIMITS PASSED: {lim}"}; '
            f'first base command at {_f(m["first_base_activation_s"], ".2f")} s; '
            f'sim/wall {run["sim_to_wall_ratio"]:.1f}x'
        )
    return '\n'.join(lines)


def format_matrix(summaries: Iterable[Mapping[str, Any]]) -> str:
    """One table over scenarios of trajectories: per robot and method, base active time and RMS,
    largest end-effector error, joint-limit margin, resolver cycle time."""
    head = (
        f'{"robot":<11}{"method":<14}{"base active [s]":>16}{"base RMS vx, vy [cm/s], ω [°/s]":>33}'
        f'{"max err xy [mm]":>16}{"joint margin [rad]":>19}{"cycle [µs]":>11}'
    )
    lines = [head, '-' * len(head)]
    for summary in summaries:
        for name, run in summary['runs'].items():
            m = run['tracking']
            rms = m['base_rms']
            lines.append(
                f'{summary["robot"]:<11}{name:<14}{m["base_active_any_s"]:>16.2f}{rms[0] * 100:>13.2f}'
                f'{rms[1] * 100:>9.2f}{np.degrees(rms[2]):>11.3f}{m["max_error_xy_m"] * 1e3:>16.1f}'
                f'{_f(m["joint_limit_margin_rad"], ".3f"):>19}{run["resolver_cycle_median_us"]:>11.0f}'
            )
    return '\n'.join(lines)


def format_table(summary: Mapping[str, Any]) -> str:
    """A plain-text table of the summary: per run and goal, area, final errors, entry time, footprint."""
    if any('tracking' in run for run in summary['runs'].values()):
        return format_tracking_table(summary)
    lines = []
    head = f'{"run":<36}{"goal":>5}{"area":>8}{"pos err":>10}{"ori err":>9}{"t→r_fm":>8}{"footpr.":>8}{"base":>7}'
    units = f'{"":<36}{"":>5}{"[m·s]":>8}{"[mm]":>10}{"[rad]":>9}{"[s]":>8}{"[m]":>8}{"[m]":>7}'
    lines += [head, units, '-' * len(head)]
    for name, run in summary['runs'].items():
        for g in run['goals']:
            lines.append(
                f'{name if g["goal"] == 1 else "":<36}{g["goal"]:>5}{_f(g.get("area"), "8.3f")}'
                f'{_f(g.get("final_position_error_m", 0) * 1e3, "10.2f")}'
                f'{_f(g.get("final_orientation_error_rad"), "9.4f")}{_f(g.get("time_to_rfm_s"), "8.2f")}'
                f'{_f(g.get("footprint_m"), "8.3f")}{_f(g.get("base_path_m"), "7.2f")}'
            )
        lim = run['limits_exceeded']
        within = 'no limit passed' if not any(lim.values()) else f'LIMITS PASSED: {lim}'
        lines.append(
            f'{"":<5}total area {run["total_area"]:.3f} m·s; all goals reached (<1 cm, <0.02 rad): '
            f'{"yes" if run["all_goals_reached"] else "no"}; {within}; '
            f'sim/wall {run["sim_to_wall_ratio"]:.1f}x'
        )
    return '\n'.join(lines)


def _figures(scenario, logs, summary, out):
    """The figures of a run: Sorour's Figs 5–7 for goals, Xing's for a trajectory."""
    # matplotlib is paid for only when figures are written (not by --help nor --no-figures)
    from wmm_control.experiments.figures import write_figures, write_tracking_figures
    from wmm_control.kinematics import KinematicModel

    plotted = {r['name']: logs[r['name']] for r in scenario.runs if r['name'] in logs and r.get('plot', True)}
    if not plotted:
        return []
    model = KinematicModel(scenario.robot)
    if scenario.trajectory is not None:
        return write_tracking_figures(plotted, scenario, model, out)
    render = next((n for n in plotted if 'compensation' in n), next(iter(plotted)))
    metrics = {n: summary['runs'][n]['goals'] for n in plotted}
    zoom = [
        r['name']
        for r in scenario.runs
        if r['name'] in plotted
        and r['method'] == 'task_sharing'
        and r.get('feedback', 'ground_truth') == 'ground_truth'
    ] or None
    return write_figures(plotted, metrics, scenario, model, out, render_label=render, zoom_labels=zoom)


def _prepare(scenario, args, out):
    """The scenario with ``--seed`` applied and its selected runs; ``out`` made, without the
    recordings of an earlier run."""
    if args.seed is not None:
        scenario = dataclasses.replace(scenario, sim=dict(scenario.sim or {}, seed=args.seed))
    selected = _selected(scenario, set(args.runs.split(',')) if args.runs else None)
    out.mkdir(parents=True, exist_ok=True)
    for run in scenario.runs:
        old = bag_path(out, run['name'])
        if (old / 'metadata.yaml').is_file():
            shutil.rmtree(old)
    return scenario, selected, out


def _header(scenario, args):
    sim = scenario.sim or {}
    engine = (
        'all nodes in one process over topics, wmm_sim in lockstep' if args.engine == 'nodes' else 'no ROS (direct)'
    )
    print(
        f'\n{scenario.name}: {scenario.description}\n'
        f'robot {scenario.robot}; {engine}; {sim.get("base_mode", "kinematic")} base; slip gain '
        f'{sim.get("slip_gain", 0.0)}, drift {sim.get("slip_drift", [0, 0, 0])}, noise '
        f'{sim.get("slip_noise", [0, 0, 0])}, seed {sim.get("seed", 0)}; end-effector error measured on the '
        'ground truth',
        flush=True,
    )


def _write(scenario, selected, logs, args, out, elapsed, peak_mb):
    """Write ``metrics.json`` and the figures of one scenario's runs into ``out``; print its table."""
    summary = summarize_runs(scenario, selected, logs, engine=args.engine, bag_dir=out)
    total_sim = sum(len(log) * DT for log in logs.values())
    summary['jobs'] = args.jobs
    summary['experiment_wall_time_s'] = elapsed
    summary['experiment_sim_to_wall_ratio'] = total_sim / elapsed
    summary['peak_memory_mb'] = peak_mb
    if not args.no_figures:
        summary['figures'] = [str(p) for p in _figures(scenario, logs, summary, out)]
    (out / 'metrics.json').write_text(json.dumps(summary, indent=2, default=float) + '\n')
    print(format_table(summary))
    print(
        f'{total_sim:.0f} simulated s in {elapsed:.1f} s wall ({total_sim / elapsed:.1f}x), peak memory '
        f'{summary["peak_memory_mb"]:.0f} MB; wrote {out / "metrics.json"}'
    )
    return summary


def _run_all(plans, args):
    """Simulate the runs of every ``(scenario, selected runs, out)`` of ``plans``, ``args.jobs``
    at once, and write each scenario's results in the order of ``plans``; its summaries."""
    todo = []
    for scenario, selected, out in plans:
        todo += _jobs_of(
            scenario,
            selected,
            args.engine,
            out,
            args.view_port if args.view else None,
            'none' if args.cluster else 'bar',
            2 if args.cluster else args.jobs,  # on a cluster: a ROS domain per run, as with workers
            first=len(todo),
        )
    stack = ExitStack()
    if args.cluster:
        results = _on_cluster(todo, stack.enter_context(ray_session(args.cluster, args.jobs)))
    else:
        results = run_jobs(simulate, todo, args.jobs)
    summaries = []
    start = time.perf_counter()
    try:
        for scenario, selected, out in plans:
            _header(scenario, args)
            if args.jobs == 1 and not args.cluster:  # one after the other: the scenario's own time
                start = time.perf_counter()
            logs, peak_mb = {}, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
            for run in selected:
                logs[run['name']], worker_mb = next(results)
                peak_mb = max(peak_mb, worker_mb)
            summaries.append(_write(scenario, selected, logs, args, out, time.perf_counter() - start, peak_mb))
            del logs
            gc.collect()  # the runs' logs and figures are done with: keep the peak memory down
    finally:
        results.close()
        stack.close()
    return summaries


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='wmm_experiment', description=__doc__.split('\n\n')[0])
    parser.add_argument(
        'name',
        nargs='?',
        default='all',
        help='scenario name in config/scenarios, or "all": ' + ', '.join(MAIN_JOB) + ' (default: %(default)s)',
    )
    parser.add_argument('--scenario', help='path to a scenario file (instead of a name)')
    parser.add_argument('--out', default='experiment_output', help='output directory (default: %(default)s)')
    parser.add_argument('--runs', help='comma-separated run names (default: all of the scenario)')
    parser.add_argument(
        '--engine',
        choices=('nodes', 'direct'),
        default='nodes',
        help='nodes: every node in one process over topics; direct: no ROS (default: nodes)',
    )
    parser.add_argument('--seed', type=int, help="seed of the simulator's slip noise (default: the scenario's)")
    parser.add_argument('--no-figures', action='store_true', help='skip the plots and renders')
    parser.add_argument(
        '--jobs',
        type=jobs_argument,
        metavar='N',
        help='runs at once, each in a process of its own; 1: one after the other in this process '
        f'(or the CPUs of --cluster ray; default: one per core, {default_jobs()} here; 1 with --view)',
    )
    parser.add_argument('--cluster', metavar='ray|ray:auto|ray:HOST:PORT|ray://HOST:PORT', help=CLUSTER_HELP)
    parser.add_argument(
        '--view',
        action='store_true',
        help='show each run live in the browser (wmm_viewer; engine nodes): open the URL it logs',
    )
    parser.add_argument('--view-port', type=int, default=8080, help='HTTP port of --view (default: %(default)s)')
    parser.add_argument(
        '--report',
        metavar='PAGE',
        help='also write the tables of the run as a Markdown page, after the text of '
        '<PAGE stem>_intro.md if that file exists (figures outside its folder are copied '
        'to <folder>/figures/<scenario>/)',
    )
    args = parser.parse_args(argv)
    if args.view and args.engine != 'nodes':
        parser.error('--view shows the nodes engine: drop --engine direct')
    if args.view and args.cluster:
        parser.error('--view shows one run at a time in this process: drop --cluster')
    if args.view and args.jobs not in (None, 1):
        parser.error('--view shows one run at a time: drop --jobs or give --jobs 1')
    if args.jobs is None:
        args.jobs = 1 if args.view else default_jobs()
    from wmm_control.experiments.report import write_report
    from wmm_control.experiments.scenario import load_scenario

    try:
        names = [args.scenario] if args.scenario else (list(MAIN_JOB) if args.name == 'all' else [args.name])
        plans = []
        for name in names:
            scenario = load_scenario(name)
            if len(names) > 1 and args.runs and not set(args.runs.split(',')) & {r['name'] for r in scenario.runs}:
                print(f'\n{scenario.name}: no run named {args.runs}; skipped')
                continue
            plans.append(_prepare(scenario, args, Path(args.out) / scenario.name if len(names) > 1 else Path(args.out)))
        summaries = _run_all(plans, args)
        matrix = [s for s in summaries if s['scenario'] in MATRIX]
        if len(matrix) == len(MATRIX):
            print(f'\nThe R = 0.25 m circle on both robots with all four methods:\n{format_matrix(matrix)}')
        if args.report:
            page = Path(args.report)
            print(f'wrote {write_report(page, summaries, page.with_name(page.stem + "_intro.md"))}')
    except WmmError as exc:
        print(f'wmm_experiment: {type(exc).__name__}: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('wmm_experiment: interrupted', file=sys.stderr)
        return 130
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
