"""``wmm_experiment --jobs N``: the runs in worker processes give the numbers of a serial run."""

import json
import re

import pytest

from same_runs import assert_same
from wmm_control.cli.experiment import main as experiment_main

#: metrics.json keys that measure the machine, not the run
TIMING = {
    'wall_time_s',
    'sim_to_wall_ratio',
    'resolver_cycle_median_us',
    'experiment_wall_time_s',
    'experiment_sim_to_wall_ratio',
    'peak_memory_mb',
    'jobs',
    'recording',
}

NODES_SCENARIO = """scenario:
  name: two_runs
  robot: steerable
  frame: world
  duration: 1.0
  goals:
    - {t: 0.0, pose: [1.0, 0.2, 1.0, pi/2, 0.0, 0.0]}
  experiment:
    sim: {base_mode: kinematic}
    runs:
      - {name: pinv, method: pinv, feedback: ground_truth}
      - {name: ts, method: task_sharing, feedback: ground_truth}
"""


def _without_timing(value):
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if k not in TIMING}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def _table(stdout):
    """The printed tables, without the wall-time figures."""
    lines = [re.sub(r'; sim/wall [0-9.]+x', '', line) for line in stdout.splitlines()]
    return [line for line in lines if 'simulated s in' not in line]


def _run(capfd, argv, out):
    assert experiment_main([*argv, '--out', str(out), '--no-figures']) == 0
    return _without_timing(json.loads((out / 'metrics.json').read_text())), _table(capfd.readouterr().out)


def test_two_jobs_give_the_tables_and_metrics_of_a_serial_run(tmp_path, capfd):
    """The cheapest of the papers' experiments, two of its runs, on the direct engine."""
    argv = ['xing_singularity', '--engine', 'direct', '--runs', 'amp_no_avoidance,amp_avoidance_as_printed']
    serial = _run(capfd, [*argv, '--jobs', '1'], tmp_path / 'serial')
    parallel = _run(capfd, [*argv, '--jobs', '2'], tmp_path / 'jobs')
    assert list(serial[0]['runs']) == ['amp_avoidance_as_printed', 'amp_no_avoidance']
    assert_same(parallel[0], serial[0])
    assert parallel[1] == serial[1]  # the printed tables


def test_two_jobs_of_the_nodes_engine_do_not_hear_each_other(tmp_path, capfd):
    """Each worker's nodes run on a ROS domain of their own: the results are the serial ones."""
    path = tmp_path / 'two_runs.yaml'
    path.write_text(NODES_SCENARIO)
    serial = _run(capfd, ['--scenario', str(path), '--jobs', '1'], tmp_path / 'serial')
    parallel = _run(capfd, ['--scenario', str(path), '--jobs', '2'], tmp_path / 'jobs')
    assert list(serial[0]['runs']) == ['pinv', 'ts']
    assert_same(parallel[0], serial[0])
    assert parallel[1] == serial[1]  # the printed tables


@pytest.mark.parametrize('value', ['0', '-2', 'two', '1.5'])
def test_jobs_must_be_a_positive_whole_number(value, capfd):
    with pytest.raises(SystemExit) as exc:
        experiment_main(['xing_singularity', '--jobs', value])
    assert exc.value.code == 2
    assert f'--jobs: expected a positive whole number of worker processes, got {value!r}' in capfd.readouterr().err


def test_view_shows_one_run_at_a_time(capfd):
    with pytest.raises(SystemExit) as exc:
        experiment_main(['xing_singularity', '--view', '--jobs', '2'])
    assert exc.value.code == 2
    assert '--view shows one run at a time' in capfd.readouterr().err
