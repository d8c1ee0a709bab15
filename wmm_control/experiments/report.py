"""The results page of a ``wmm_experiment`` run (``--report PATH``): Markdown, from its summaries.

The page is a preamble copied verbatim (the prose that explains the experiments,
``docs/results_intro.md`` for the main job), a line saying where the numbers come from
(commit, date, machine), then one section per scenario with its settings, its tables, the
papers' values beside ours where :data:`PAPER` has them, and its figures, and last the table
over both robots when the run has :data:`MATRIX`'s scenarios. Every number on the page is
from the run's summaries (the ``metrics.json`` content), so it is written, never edited.
"""

import datetime
import math
import os
import platform
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from wmm_control.experiments.metrics import METRIC_KEYS, TRAJECTORY_METRIC_KEYS

__all__ = ['PAPER', 'provenance', 'render_report', 'write_report']

#: The papers' values of a run, ``{scenario: {run: values}}``, in the units of the metrics
#: (``table`` names the source). Xing et al., Tables 2 and 3, and §4.3's base integral error.
PAPER = {
    'xing_circle_0.10': {
        'amp': {'table': 'Xing Table 2', 'base_active_any_s': 0.0, 'max_error_xy_m': 4.5e-3},
        'traditional': {
            'table': 'Xing Table 2',
            'base_active_any_s': 80.0,
            'max_error_x_m': 9.1e-3,
            'max_error_y_m': 18.9e-3,
            'max_error_xy_m': 19.1e-3,
        },
    },
    'xing_circle_0.25': {
        'amp': {
            'table': 'Xing Table 2',
            'base_active_any_s': 12.08,
            'first_base_activation_s': 6.40,
            'max_error_x_m': 24.4e-3,
            'max_error_y_m': 18.2e-3,
            'max_error_xy_m': 27.8e-3,
            'base_integral_error_m': [0.81e-2, 0.37e-2],
        },
        'traditional': {
            'table': 'Xing Table 2',
            'base_active_any_s': 80.0,
            'max_error_x_m': 66.5e-3,
            'max_error_y_m': 27.2e-3,
            'max_error_xy_m': 69.7e-3,
            'base_integral_error_m': [2.81e-2, 1.12e-2],
        },
    },
    'xing_pose': {
        'amp': {
            'table': 'Xing Table 3',
            'base_active_any_s': 18.48,
            'first_base_activation_s': 3.1,
            'base_rms': [0.67e-2, 0.044e-2, math.radians(0.08)],
            'max_error_x_m': 15.8e-3,
            'max_rotation_error_y_rad': math.radians(2.32),
        },
        'traditional': {
            'table': 'Xing Table 3',
            'base_active_any_s': 40.0,
            'base_rms': [1.18e-2, 0.082e-2, math.radians(0.13)],
            'max_error_x_m': 23.1e-3,
            'max_rotation_error_y_rad': math.radians(4.58),
        },
    },
}

#: The scenarios of the table over both robots and every method (:func:`render_report`).
MATRIX = ('matrix_circle_0.25_a', 'matrix_circle_0.25_b')


def provenance(root: str | Path | None = None) -> tuple[str, str, str]:
    """``(commit, date, machine)``: ``git rev-parse --short HEAD`` of ``root`` (default: this
    source tree) or 'unknown', today's date (UTC), and the platform with its CPU count."""
    root = Path(root) if root is not None else Path(__file__).resolve().parents[2]
    try:
        commit = (
            subprocess.run(
                ['git', 'rev-parse', '--short', 'HEAD'],
                cwd=root,
                capture_output=True,
                text=True,
                timeout=10,
                check=True,
            ).stdout.strip()
            or 'unknown'
        )
    except (OSError, subprocess.SubprocessError):
        commit = 'unknown'
    date = datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d')
    machine = f'{platform.platform()}, Python {platform.python_version()}, {os.cpu_count()} CPUs'
    return commit, date, machine


def _f(value, fmt, scale=1.0):
    return '—' if value is None else format(value * scale, fmt)


def _limits(run):
    passed = {k: v for k, v in run['limits_exceeded'].items() if v}
    return 'none' if not passed else ', '.join(f'{k} {v:.3g}' for k, v in passed.items())


def _rms(rms):
    return f'{rms[0] * 100:.2f} / {rms[1] * 100:.2f} / {math.degrees(rms[2]):.3f}'


def _settings(summary):
    sim = summary.get('simulator') or {}
    slip = (
        f'slip gain {sim.get("slip_gain", 0.0)}, drift {sim.get("slip_drift", [0, 0, 0])}, '
        f'noise {sim.get("slip_noise", [0, 0, 0])}, seed {sim.get("seed", 0)}'
    )
    wall = summary.get('experiment_wall_time_s')
    timing = 'no ROS' if summary['engine'] == 'direct' else summary['timing']
    return (
        f'Robot `{summary["robot"]}`; engine `{summary["engine"]}` ({timing}); '
        f'{sim.get("base_mode", "kinematic")} base, {slip}'
        + (f'; {wall:.0f} s wall with {summary.get("jobs", 1)} job(s)' if wall is not None else '')
        + '.'
    )


def _goals_section(summary):
    runs = summary['runs']
    n = max((len(run['goals']) for run in runs.values()), default=0)
    lines = [
        'Area under ‖e_p‖ per goal [m·s] / final position error [mm] (ground truth, end of each goal\'s window):',
        '',
        '| run | method | feedback | '
        + ' | '.join(f'goal {i + 1}' for i in range(n))
        + ' | total area | all reached (< 1 cm, < 0.02 rad) | limits passed |',
        '|---|---|---|' + '---|' * n + '---|---|---|',
    ]
    for name, run in runs.items():
        cells = [
            f'{_f(g.get("area"), ".2f")} / {_f(g.get("final_position_error_m"), ".1f", 1e3)}' for g in run['goals']
        ]
        cells += [''] * (n - len(cells))
        lines.append(
            f'| `{name}` | `{run["method"]}` | {run["feedback"]} | '
            + ' | '.join(cells)
            + f' | {run["total_area"]:.2f} | {"yes" if run["all_goals_reached"] else "no"}'
            f' | {_limits(run)} |'
        )
    lines += [
        '',
        'Per goal (keys of `metrics.json`, below):',
        '',
        '| run | goal | footprint [m] | t → r_fm [s] | base path, ψ = 1 [m] | base path [m] | '
        'arm-rate jump at a switch [rad/s] | ψ range | q_dex distance with ψ = 0, settled / at start [rad] | '
        'final orientation error [rad] |',
        '|---|---|---|---|---|---|---|---|---|---|',
    ]
    for name, run in runs.items():
        for g in run['goals']:
            lines.append(
                f'| `{name}` | {g["goal"]} | {_f(g.get("footprint_m"), ".2f")} | '
                f'{_f(g.get("time_to_rfm_s"), ".2f")} | {_f(g.get("base_path_fine_m"), ".2f")} | '
                f'{_f(g.get("base_path_m"), ".2f")} | {_f(g.get("max_switch_jump_rad_s"), ".2f")} | '
                f'{_f(g.get("psi_min"), ".2g")}–{_f(g.get("psi_max"), ".2g")} | '
                f'{_f(g.get("dex_deviation_psi0_rad"), ".2f")} / '
                f'{_f(g.get("dex_deviation_psi0_start_rad"), ".2f")} | '
                f'{_f(g.get("final_orientation_error_rad"), ".4f")} |'
            )
    return lines


def _paper_text(values):
    """The papers' values of one run in the words and units of the tracking table."""
    if not values:
        return ''
    parts = [values['table']]
    if 'base_active_any_s' in values:
        parts.append(f'base active {values["base_active_any_s"]:.2f} s')
    if 'first_base_activation_s' in values:
        parts.append(f'from {values["first_base_activation_s"]:.2f} s')
    if 'base_rms' in values:
        parts.append(f'RMS {_rms(values["base_rms"])}')
    errors = [(axis, values[f'max_error_{axis}_m']) for axis in ('x', 'y', 'xy') if f'max_error_{axis}_m' in values]
    if errors:
        parts.append(
            'max error '
            + ' / '.join(a for a, _ in errors)
            + ' '
            + ' / '.join(f'{v * 1e3:.1f}' for _, v in errors)
            + ' mm'
        )
    if 'max_rotation_error_y_rad' in values:
        parts.append(f'rotation about y {values["max_rotation_error_y_rad"]:.3f} rad')
    if 'base_integral_error_m' in values:
        ix, iy = values['base_integral_error_m']
        parts.append(f'base integral error x / y {ix * 100:.2f} / {iy * 100:.2f} cm')
    return '; '.join(parts)


def _tracking_section(summary):
    paper = PAPER.get(summary['scenario'], {})
    lines = [
        'Commanded base velocity (RMS vx / vy [cm/s] / ω [°/s]; time any component is non-zero [s]; '
        'first non-zero command [s]), largest end-effector error against the reference (ground truth) '
        "and Xing's integral of the base's kinematic error:",
        '',
        '| run | method | base RMS | base active [s] | first base command [s] | max error x / y / xy [mm] | '
        'rotation about y [rad] | σ_min | base integral error x / y [cm] | closest joint to a limit [rad] | '
        'limits passed |' + (' paper |' if paper else ''),
        '|---|---|---|---|---|---|---|---|---|---|---|' + ('---|' if paper else ''),
    ]
    for name, run in summary['runs'].items():
        m = run['tracking']
        integral = m.get('base_integral_error_m')
        integral_text = '—' if integral is None else f'{integral[0] * 100:.2f} / {integral[1] * 100:.2f}'
        lines.append(
            f'| `{name}` | `{run["method"]}` | {_rms(m["base_rms"])} | {m["base_active_any_s"]:.2f} | '
            f'{_f(m.get("first_base_activation_s"), ".2f")} | {m["max_error_x_m"] * 1e3:.1f} / '
            f'{m["max_error_y_m"] * 1e3:.1f} / {m["max_error_xy_m"] * 1e3:.1f} | '
            f'{m["max_rotation_error_y_rad"]:.3f} | {m["sigma_min_min"]:.3f} | {integral_text} | '
            f'{_f(m.get("joint_limit_margin_rad"), ".2f")} | {_limits(run)} |'
            + (f' {_paper_text(paper.get(name))} |' if paper else '')
        )
    return lines


def _matrix_section(summaries):
    lines = [
        '## The R = 0.25 m circle on both robots with all four methods',
        '',
        '| robot | method | base active [s] | base RMS vx / vy [cm/s], ω [°/s] | max x-y error [mm] | '
        'closest joint to a limit [rad] | resolver cycle, median [µs] |',
        '|---|---|---|---|---|---|---|',
    ]
    for summary in summaries:
        for i, (name, run) in enumerate(summary['runs'].items()):
            m = run['tracking']
            robot = f'`{summary["robot"]}`' if i == 0 else ''
            lines.append(
                f'| {robot} | `{name}` | {m["base_active_any_s"]:.1f} | '
                f'{_rms(m["base_rms"])} | {m["max_error_xy_m"] * 1e3:.1f} | '
                f'{_f(m.get("joint_limit_margin_rad"), ".2f")} | {run["resolver_cycle_median_us"]:.0f} |'
            )
    return lines


def _figures(summary, figure_links):
    return [
        f'![{summary["scenario"]}: {Path(link).stem}]({link})' for link in figure_links.get(summary['scenario'], ())
    ]


def _keys_section(keys, title):
    return [f'**{title}**', '', '| key | meaning |', '|---|---|'] + [
        f'| `{key}` | {text.replace("|", chr(92) + "|")} |' for key, text in keys.items()
    ]


def render_report(
    summaries: Sequence[Mapping[str, Any]],
    preamble: str = '',
    provenance_line: str | None = None,
    figure_links: Mapping[str, Sequence[str]] | None = None,
) -> str:
    """The Markdown page of ``summaries`` (one ``metrics.json`` content per scenario).

    Args:
        summaries: the run's summaries, in the order of the page.
        preamble: text copied first, verbatim.
        provenance_line: the line that says where the numbers come from (default: from
            :func:`provenance`).
        figure_links: ``{scenario: [link, ...]}``, the figures to show (relative to the page).
    """
    if provenance_line is None:
        commit, date, machine = provenance()
        provenance_line = f'Generated by `wmm_experiment --report` from commit `{commit}` on {date}, on {machine}.'
    figure_links = figure_links or {}
    lines = [preamble.rstrip('\n'), ''] if preamble.strip() else []
    lines += [f'*{provenance_line}*', '']
    goal_keys = trajectory_keys = False
    for summary in summaries:
        lines += [f'## `{summary["scenario"]}`: {summary["description"]}', '', _settings(summary), '']
        if any('tracking' in run for run in summary['runs'].values()):
            trajectory_keys = True
            lines += _tracking_section(summary)
        else:
            goal_keys = True
            lines += _goals_section(summary)
        lines += ['']
        for figure in _figures(summary, figure_links):
            lines += [figure, '']
    matrix = [s for s in summaries if s['scenario'] in MATRIX]
    if len(matrix) == len(MATRIX):
        lines += _matrix_section(matrix) + ['']
    if goal_keys or trajectory_keys:
        lines += ['## The keys of `metrics.json`', '']
    if goal_keys:
        lines += _keys_section(METRIC_KEYS, 'Per goal') + ['']
    if trajectory_keys:
        lines += _keys_section(TRAJECTORY_METRIC_KEYS, 'Per run of a trajectory (`tracking`)') + ['']
    return '\n'.join(lines).rstrip('\n') + '\n'


#: Figures a report leaves out: one picture per goal (the side-by-side ``goals_<run>.png`` has them).
_SKIPPED_FIGURE = 'goal_'


def _figure_links(summaries, page):
    """``{scenario: [link]}``: each summary's figures, relative to ``page``; a figure outside the
    page's folder is copied into ``<folder>/figures/<scenario>/`` first, so that the page's
    links work wherever it is read."""
    folder = page.resolve().parent
    links = {}
    for summary in summaries:
        for path in map(Path, summary.get('figures', ())):
            if path.name.startswith(_SKIPPED_FIGURE) or not path.is_file():
                continue
            path = path.resolve()
            if folder not in path.parents:
                target = folder / 'figures' / summary['scenario'] / path.name
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(path, target)
                path = target
            links.setdefault(summary['scenario'], []).append(path.relative_to(folder).as_posix())
    return links


def write_report(
    page: str | Path, summaries: Sequence[Mapping[str, Any]], preamble_path: str | Path | None = None
) -> Path:
    """Write :func:`render_report` of ``summaries`` to ``page``, with the text of
    ``preamble_path`` (if given and present) first; returns ``page``."""
    page = Path(page)
    preamble = Path(preamble_path).read_text() if preamble_path and Path(preamble_path).is_file() else ''
    page.parent.mkdir(parents=True, exist_ok=True)
    text = render_report(summaries, preamble, figure_links=_figure_links(summaries, page))
    page.write_text(text)
    return page
