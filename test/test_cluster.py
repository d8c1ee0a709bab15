"""``--cluster`` (runs as Ray tasks) and ``--sweep`` of ``wmm_randomized``, ``--cluster`` of
``wmm_experiment``: the same results as a serial run, nothing lost when a worker node dies,
bad input refused before any run.

Cheap runs only: robot A with ``pinv`` (about 0.5 s a run) and ``amp`` on a few goals.
Every Ray instance a test starts is stopped by it (``ray.shutdown``, ``ray stop``).
"""

import contextlib
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import wmm_control.experiments.randomized as study
from wmm_control.cli.experiment import main as experiment_main
from wmm_control.cli.randomized import main as randomized_main, sweep_plot_path

from same_runs import SAME, assert_same
from test_experiment_jobs import NODES_SCENARIO, _without_timing as without

pytest.importorskip('ray')

STUDY = ['--robots', 'steerable', '--methods', 'pinv', '--goals', '4', '--seed', '0']
#: run fields that measure the machine, not the run
TIMING = ('wall', 'cycle')


def _without_timing(value):
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if not any(t in k for t in TIMING)}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def _study(argv, out, code=0):
    assert randomized_main([*argv, '--out', str(out)]) == code
    return json.loads(out.read_text())


def _keys(document):
    return [
        (r['robot'], r['method'], r['goal'], json.dumps(r.get('sweep', {}), sort_keys=True)) for r in document['runs']
    ]


def test_two_documents_differ_by_a_number_beyond_round_off_or_by_any_name():
    run = {'robot': 'steerable', 'outcome': 'converged', 'goal': 0, 'final_position_error_m': 0.0012}
    document = {'runs': [run], 'summary': [{'runs': 1, 'converged': 1}]}
    assert_same(document, json.loads(json.dumps(document)))
    assert_same(document, {**document, 'runs': [{**run, 'final_position_error_m': 0.0012 + SAME / 2}]})
    for changed in (
        {**run, 'final_position_error_m': 0.0012 + 2 * SAME},
        {**run, 'outcome': 'failed'},
        {**run, 'goal': 1},
        {k: v for k, v in run.items() if k != 'goal'},
    ):
        with pytest.raises(AssertionError):
            assert_same(document, {**document, 'runs': [changed]})
    with pytest.raises(AssertionError):
        assert_same(document, {**document, 'runs': [run, run]})


def test_serial_two_jobs_and_a_local_ray_give_the_same_runs(tmp_path):
    serial = _study([*STUDY, '--jobs', '1', '--record', str(tmp_path / 'rec_serial')], tmp_path / 'serial.json')
    jobs = _study([*STUDY, '--jobs', '2'], tmp_path / 'jobs.json')
    ray = _study(
        [*STUDY, '--jobs', '2', '--cluster', 'ray', '--record', str(tmp_path / 'rec_ray')], tmp_path / 'ray.json'
    )
    assert [r['outcome'] for r in serial['runs']] == ['converged'] * 4
    assert [r['goal'] for r in serial['runs']] == [0, 1, 2, 3]
    assert_same(_without_timing(jobs), _without_timing(serial))
    assert_same(_without_timing(ray), _without_timing(serial))
    # the recordings came back through Ray and were written here
    names = sorted(p.name for p in (tmp_path / 'rec_serial').iterdir())
    assert names == [f'steerable_pinv_{i}.npz' for i in range(4)]
    assert sorted(p.name for p in (tmp_path / 'rec_ray').iterdir()) == names
    for name in names:
        a, b = np.load(tmp_path / 'rec_serial' / name), np.load(tmp_path / 'rec_ray' / name)
        assert set(a.files) == set(b.files) and len(a['t']) > 10
        for key in a.files:
            if any(word in key for word in TIMING):  # each period's cycle times differ run to run
                continue
            if np.issubdtype(a[key].dtype, np.floating):
                np.testing.assert_allclose(a[key], b[key], rtol=0, atol=SAME, err_msg=key)
            else:
                np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    import ray as ray_module

    assert not ray_module.is_initialized()  # the Ray instance of the study is gone


def test_experiment_on_a_local_ray_gives_the_serial_metrics_and_recordings(tmp_path, capfd):
    """Each run's log and rosbag2 recording come back from its task and are written here."""
    path = tmp_path / 'two_runs.yaml'
    path.write_text(NODES_SCENARIO)
    metrics = {}
    for mode, extra in (('serial', ['--jobs', '1']), ('ray', ['--cluster', 'ray', '--jobs', '2'])):
        out = tmp_path / mode
        assert experiment_main(['--scenario', str(path), '--no-figures', '--out', str(out), *extra]) == 0
        metrics[mode] = without(json.loads((out / 'metrics.json').read_text()))
        for run in ('pinv', 'ts'):
            bag = out / f'rosbag2_{run}'
            assert (bag / 'metadata.yaml').is_file() and (bag / f'rosbag2_{run}.mcap').stat().st_size > 1000
    assert list(metrics['serial']['runs']) == ['pinv', 'ts']
    assert_same(metrics['ray'], metrics['serial'])


def _free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _procs():
    """``{pid: (parent pid, command line)}`` of every process."""
    out = {}
    for d in Path('/proc').iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / 'cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
                ppid = int((d / 'stat').read_text().rsplit(')', 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            out[int(d.name)] = (ppid, cmd)
    return out


@pytest.fixture
def two_nodes(tmp_path):
    """A Ray cluster of two nodes on this machine, one CPU each, as two ``ray start``: the GCS
    port and the second node's raylet port. Stopped after the test (``ray stop``)."""
    ray_cli = str(Path(sys.executable).with_name('ray'))
    env = dict(
        os.environ,
        RAY_AUTH_MODE='token',
        RAY_health_check_period_ms='500',
        RAY_health_check_failure_threshold='3',
        RAY_health_check_initial_delay_ms='0',
    )
    gcs, raylet = _free_port(), _free_port()
    common = ['--num-cpus', '1', '--disable-usage-stats']
    try:
        subprocess.run(
            [ray_cli, 'start', '--head', '--port', str(gcs), '--include-dashboard=false', *common],
            env=env,
            check=True,
            capture_output=True,
            timeout=120,
        )
        subprocess.run(
            [ray_cli, 'start', '--address', f'127.0.0.1:{gcs}', '--node-manager-port', str(raylet), *common],
            env=env,
            check=True,
            capture_output=True,
            timeout=120,
        )
        yield env, gcs, raylet
    finally:
        subprocess.run([ray_cli, 'stop', '--force'], env=env, capture_output=True, timeout=120)


#: [s] a worker of the second node has run a task this long when that node is killed
BUSY_BEFORE_KILL_S = 5.0


def test_a_worker_node_killed_mid_study_loses_no_run(two_nodes, tmp_path):
    """The second node dies (its raylet and its workers, SIGKILL, as when a machine goes down)
    while one of its workers runs a task: the task runs again on the head node; every run is in
    --out once, as in a serial run. (A worker left alive without its raylet may finish its task
    and hand the small result straight to the driver: then nothing is run again.)"""
    env, gcs, raylet = two_nodes
    argv = ['--robots', 'steerable', '--methods', 'amp', '--goals', '8', '--indices', '3,5,6,7']
    out = tmp_path / 'killed.json'
    driver = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'wmm_control.cli.randomized',
            *argv,
            '--cluster',
            f'ray:127.0.0.1:{gcs}',
            '--out',
            str(out),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    killed = None
    seen: dict[int, float] = {}  # busy worker: when first seen busy
    try:
        deadline = time.monotonic() + 90.0
        while killed is None and time.monotonic() < deadline and driver.poll() is None:
            procs = _procs()
            node = [p for p, (_, cmd) in procs.items() if 'raylet' in cmd and f'node_manager_port={raylet}' in cmd]
            busy = [p for p, (pp, cmd) in procs.items() if node and pp == node[0] and cmd.startswith('ray::_task')]
            now = time.monotonic()
            for pid in busy:
                seen.setdefault(pid, now)
            # Killed mid-run: a worker's first task spends its first seconds importing the study's
            # modules, and a run takes several seconds more.
            if any(now - seen[pid] >= BUSY_BEFORE_KILL_S for pid in busy):
                workers = [p for p, (pp, _) in procs.items() if pp == node[0]]
                for pid in (node[0], *workers):
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(pid, 9)
                killed = node[0]
            time.sleep(0.1)
        stdout, stderr = driver.communicate(timeout=180)
    finally:
        if driver.poll() is None:
            driver.kill()
    assert killed is not None, 'the second node never ran a task'
    assert driver.returncode == 0, stderr[-2000:]
    assert 'retried=1' in stderr or 'retried=2' in stderr, stderr[-2000:]
    assert '| steerable | amp | 4 | 4 |' in stdout
    serial = _study([*argv, '--jobs', '1'], tmp_path / 'serial.json')
    document = json.loads(out.read_text())
    assert sorted(_keys(document)) == sorted(_keys(serial)) and len(set(_keys(document))) == 4
    assert_same(_without_timing(document), _without_timing(serial))


SWEEP = ['--robots', 'steerable', '--methods', 'pinv', '--goals', '2', '--jobs', '1']


def test_a_sweep_runs_the_grid_and_resumes_only_what_is_missing(tmp_path, capfd, monkeypatch):
    out = tmp_path / 'sweep.json'
    argv = [*SWEEP, '--sweep', 'lambda_p=1.0,3.0', '--sweep', 'collision_influence=0.15']
    document = _study(argv, out)
    printed = capfd.readouterr().out
    points = [{'lambda_p': 1.0, 'collision_influence': 0.15}, {'lambda_p': 3.0, 'collision_influence': 0.15}]
    assert document['sweep'] == {'lambda_p': [1.0, 3.0], 'collision_influence': [0.15]}
    assert [(r['sweep'], r['goal']) for r in document['runs']] == [(p, g) for p in points for g in (0, 1)]
    assert [(row['sweep'], row['robot'], row['method'], row['runs']) for row in document['summary']] == [
        (p, 'steerable', 'pinv', 2) for p in points
    ]
    for label in ('lambda_p=1.0,collision_influence=0.15:', 'lambda_p=3.0,collision_influence=0.15:'):
        table = printed.split(label)[1].splitlines()
        assert table[1].startswith('| robot | method |') and table[3].startswith('| steerable | pinv | 2 |')
    plot = sweep_plot_path(out)
    assert plot == tmp_path / 'sweep_sweep.png' and plot.read_bytes()[:4] == b'\x89PNG'
    # the parameter reaches the runs: with the pose controller's gain three times higher, they differ
    first, second = document['runs'][:2], document['runs'][2:]
    assert all(abs(a['final_position_error_m'] - b['final_position_error_m']) > SAME for a, b in zip(first, second))

    # an interrupted sweep: --resume runs only the runs missing from --out
    partial = dict(document, runs=document['runs'][:3])
    out.write_text(json.dumps(partial))
    calls = []
    run_goal = study.run_goal
    monkeypatch.setattr(study, 'run_goal', lambda *a, **k: calls.append((a[2].index, k['params'])) or run_goal(*a, **k))
    resumed = _study([*argv, '--resume'], out)
    assert calls == [(1, points[1])]
    assert_same(_without_timing(resumed), _without_timing(document))


def test_a_run_that_raises_is_recorded_failed_with_its_error(tmp_path, monkeypatch):
    run_goal = study.run_goal

    def broken(robot, method, goal, **kw):
        if goal.index == 1:
            raise FloatingPointError('a fault of this run alone')
        return run_goal(robot, method, goal, **kw)

    monkeypatch.setattr(study, 'run_goal', broken)
    document = _study(SWEEP, tmp_path / 'raised.json', code=1)
    ok, raised = document['runs']
    assert ok['outcome'] == 'converged' and raised['outcome'] == 'failed'
    assert raised['why'] == 'raised FloatingPointError: a fault of this run alone'
    assert 'FloatingPointError' in raised['error']
    (row,) = document['summary']
    assert (row['runs'], row['converged'], row['failed']) == (2, 1, 1)


@pytest.mark.parametrize(
    'argv, line',
    [
        (['--sweep', 'collision_reach=0.1'], "--sweep: unknown parameter 'collision_reach'; one of "),
        (
            ['--sweep', 'collision_influence=0.05,2.0'],
            '--sweep collision_influence: 2.0 is outside its range [0.001, 1]',
        ),
        (['--sweep', 'rows=full,some'], "--sweep rows: 'some' is not one of "),
        (['--sweep', 'collision_influence=0.01'], '--sweep collision_influence=0.01: method pinv: collision_safety'),
        (['--cluster', 'spark'], "--cluster: expected ray, ray:auto, ray:HOST:PORT or ray://HOST:PORT, got 'spark'"),
        (
            ['--cluster', 'ray://127.0.0.1:{port}'],
            '--cluster ray://127.0.0.1:{port}: nothing answers at 127.0.0.1:{port}',
        ),
        (['--cluster', 'ray:127.0.0.1:{port}'], '--cluster ray:127.0.0.1:{port}: nothing answers at 127.0.0.1:{port}'),
    ],
)
def test_bad_input_is_one_line_and_exit_2_before_any_run(argv, line, capfd, monkeypatch):
    monkeypatch.setattr(study, 'run_goal', lambda *a, **k: pytest.fail('a run started'))
    port = _free_port()
    argv = [a.format(port=port) for a in argv]
    assert randomized_main([*SWEEP, *argv]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert err[-1].startswith('wmm_randomized: ' + line.format(port=port)), err
    assert len([e for e in err if 'wmm_randomized' in e]) == 1


def test_ray_not_installed_is_one_line_and_exit_2(capfd, monkeypatch):
    monkeypatch.setattr(study, 'run_goal', lambda *a, **k: pytest.fail('a run started'))
    monkeypatch.setitem(sys.modules, 'ray', None)  # import ray raises ImportError
    assert randomized_main([*SWEEP, '--cluster', 'ray']) == 2
    assert capfd.readouterr().err.strip().splitlines()[-1] == (
        'wmm_randomized: --cluster ray: Ray is not installed; pip install ".[cluster]" '
        '(or pip install -r scripts/requirements-cluster.txt)'
    )
    assert experiment_main(['xing_singularity', '--engine', 'direct', '--cluster', 'ray']) == 2
    assert 'Ray is not installed' in capfd.readouterr().err


def test_ray_auto_without_a_cluster_is_one_line_and_exit_2(capfd, monkeypatch, tmp_path):
    """``RAY_ADDRESS`` names a port nothing listens on; then, unset, no Ray runs on this machine
    (Ray's ``auto`` would find any that does)."""
    monkeypatch.setattr(study, 'run_goal', lambda *a, **k: pytest.fail('a run started'))
    port = _free_port()
    monkeypatch.setenv('RAY_ADDRESS', f'127.0.0.1:{port}')
    assert randomized_main([*SWEEP, '--cluster', 'ray:auto']) == 2
    assert capfd.readouterr().err.strip().splitlines()[-1] == (
        f'wmm_randomized: --cluster ray:auto: nothing answers at 127.0.0.1:{port} (Connection refused)'
    )
    if any('gcs_server' in cmd for _, cmd in _procs().values()):
        return  # a Ray of other work runs here: ray:auto would join it
    monkeypatch.delenv('RAY_ADDRESS')
    monkeypatch.setenv('RAY_TMPDIR', str(tmp_path))
    assert randomized_main([*SWEEP, '--cluster', 'ray:auto']) == 2
    assert (
        capfd.readouterr()
        .err.strip()
        .splitlines()[-1]
        .startswith('wmm_randomized: --cluster ray:auto: no Ray cluster answers')
    )
