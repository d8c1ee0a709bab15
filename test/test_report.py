"""``wmm_experiment --report PAGE``: the results page written from the run's tables."""

import json
import re

from test_experiment_jobs import NODES_SCENARIO
from wmm_control.cli.experiment import main as experiment_main
from wmm_control.experiments.report import PAPER, provenance, write_report


def _report(tmp_path, page, capfd, *args):
    """The page ``wmm_experiment *args --report page`` writes (direct engine, one job, no figures)."""
    out = ['--engine', 'direct', '--jobs', '1', '--no-figures', '--out', str(tmp_path / 'out'), '--report', str(page)]
    assert experiment_main([*args, *out]) == 0
    capfd.readouterr()
    return page.read_text()


def test_the_page_has_the_intro_where_it_came_from_and_every_run(tmp_path, capfd):
    scenario = tmp_path / 'two_runs.yaml'
    scenario.write_text(
        NODES_SCENARIO.replace('  robot: steerable', '  description: one goal, 1 s\n  robot: steerable')
    )
    page = tmp_path / 'docs' / 'results.md'
    page.parent.mkdir()
    intro = '# Results\n\nProse about the experiments, | kept | as written.\n'
    (page.parent / 'results_intro.md').write_text(intro)
    text = _report(tmp_path, page, capfd, '--scenario', str(scenario))
    assert text.startswith(intro)
    commit, date, machine = provenance()
    assert f'commit `{commit}` on {date}, on {machine}' in text
    assert re.search(r'CPUs\.\*$', text.splitlines()[len(intro.splitlines()) + 1])
    assert '## `two_runs`: one goal, 1 s' in text
    metrics = json.loads((tmp_path / 'out' / 'metrics.json').read_text())
    for name, run in metrics['runs'].items():
        row = next(line for line in text.splitlines() if line.startswith(f'| `{name}` | `{run["method"]}` |'))
        assert f'| {run["total_area"]:.2f} |' in row
        assert row.count('/') == len(run['goals'])  # area / final error, one cell per goal
    assert '| `area` |' in text and '| `base_rms` |' not in text


def test_a_trajectory_run_has_the_papers_values_beside_ours(tmp_path, capfd):
    page = tmp_path / 'r.md'
    text = _report(tmp_path, page, capfd, 'xing_pose', '--runs', 'amp')
    header = next(line for line in text.splitlines() if line.startswith('| run | method | base RMS'))
    assert header.endswith('| paper |')
    row = next(line for line in text.splitlines() if line.startswith('| `amp` |'))
    assert PAPER['xing_pose']['amp']['table'] in row and 'base active 18.48 s' in row
    assert row.count('|') == header.count('|')
    assert '| `base_integral_error_m` |' in text


def test_figures_outside_the_pages_folder_are_copied_beside_it(tmp_path):
    figure = tmp_path / 'out' / 'fig6_error_norm.png'
    figure.parent.mkdir()
    figure.write_bytes(b'png')
    (tmp_path / 'out' / 'goal_1.png').write_bytes(b'png')
    summary = {
        'scenario': 'two_goals',
        'description': 'd',
        'robot': 'steerable',
        'engine': 'direct',
        'timing': 'direct (no ROS)',
        'simulator': {},
        'runs': {},
        'figures': [str(figure), str(tmp_path / 'out' / 'goal_1.png')],
    }
    page = write_report(tmp_path / 'docs' / 'results.md', [summary])
    assert (tmp_path / 'docs' / 'figures' / 'two_goals' / 'fig6_error_norm.png').read_bytes() == b'png'
    text = page.read_text()
    assert '](figures/two_goals/fig6_error_norm.png)' in text
    assert 'goal_1' not in text
