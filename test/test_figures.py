"""The Table II figures (Sorour Figs 5–7) drawn from a short real run."""

import struct

import numpy as np
import pytest

from wmm_control.experiments.direct import run_scenario
from sim_bridge.world import SimWorld
from wmm_control.experiments import figures
from wmm_control.experiments.metrics import goal_metrics, pose_error_norm
from wmm_control.experiments.scenario import load_scenario
from wmm_control.resolvers import make_resolver

SCENARIO = """\
scenario:
  name: two_goals
  robot: steerable
  frame: world
  duration: 4.0
  goals:
    - {t: 0.0, pose: [1.0, 0.3, 1.0, 0.0, 0.0, 0.0]}
    - {t: 2.0, pose: [1.1, 0.1, 1.0, pi/2, 0.0, 0.0]}
"""
RUNS = {'pinv': ('pinv', {}), 'task_sharing': ('task_sharing', {'compensation': True})}


@pytest.fixture(scope='module')
def experiment(tmp_path_factory, steerable_model):
    """(logs, metrics, scenario) of two 4 s runs."""
    path = tmp_path_factory.mktemp('scenario') / 'two_goals.yaml'
    path.write_text(SCENARIO)
    scenario = load_scenario(path)
    logs, metrics = {}, {}
    for label, (method, params) in RUNS.items():
        with SimWorld('steerable') as world:
            logs[label] = run_scenario(world, make_resolver(method, 'steerable', **params), scenario, label=label)
        metrics[label] = goal_metrics(
            logs[label], scenario, steerable_model, 0.25, steerable_model.config.arm.dexterous, world.dt
        )
    return logs, metrics, scenario


def png_size(path):
    """(width, height) [px] from the PNG header."""
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n' and data[12:16] == b'IHDR'
    return struct.unpack('>II', data[16:24])


def texts_of(fig):
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def test_error_norm_follows_the_goal_in_force(experiment):
    logs, _, scenario = experiment
    log = logs['pinv']
    err = figures.error_norm(log, scenario)
    for gi, goal in enumerate(scenario.goals):
        rows = log.goal == gi
        assert np.any(rows)
        np.testing.assert_allclose(err[rows], pose_error_norm(goal.pose, log.ee_position[rows], log.ee_rotation[rows]))


def test_fig6_prints_the_areas_it_is_given(experiment):
    logs, metrics, scenario = experiment
    patched = {label: [dict(m) for m in goals] for label, goals in metrics.items()}
    patched['task_sharing'][1]['area'] = 123.456
    patched['pinv'][0]['area'] = None
    fig = figures.error_norm_figure(logs, patched, scenario)
    try:
        texts = texts_of(fig)
        assert '123.46' in texts
        assert f"{metrics['pinv'][1]['area']:.2f}" in texts
        assert len(texts) == 2 * len(scenario.goals) - 1  # the None area is left out
        assert [ax.get_xlabel() for ax in fig.axes] == ['', 'time [s]']
    finally:
        figures.plt.close(fig)


def test_stacked_figures_grow_with_the_runs(experiment, tmp_path):
    logs, metrics, scenario = experiment
    one = figures.plot_error_norms({'pinv': logs['pinv']}, metrics, scenario, tmp_path / 'one.png')
    two = figures.plot_error_norms(logs, metrics, scenario, tmp_path / 'two.png')
    zoom = figures.plot_zoom_and_psi(logs, metrics, scenario, tmp_path / 'zoom.png')
    (w1, h1), (w2, h2), (wz, hz) = png_size(one), png_size(two), png_size(zoom)
    assert w1 == w2 == wz and h2 > h1
    assert hz == h2  # one task-sharing run + the ψ panel


def test_zoom_defaults_to_the_task_sharing_runs(experiment):
    logs, _, scenario = experiment
    fig = figures.zoom_psi_figure(logs, scenario, ylim=0.02)
    try:
        titles = [ax.get_title() for ax in fig.axes]
        assert len(fig.axes) == 2 and titles[0] == 'task_sharing'
        assert fig.axes[0].get_ylim() == (0.0, 0.02)
        assert fig.axes[1].get_ylabel() == 'ψ [-]'
    finally:
        figures.plt.close(fig)


def test_top_view_titles_give_the_largest_arm_footprint(experiment, steerable_model, tmp_path):
    logs, metrics, scenario = experiment
    fig = figures.top_view_figure(logs, scenario, steerable_model)
    try:
        for ax, label in zip(fig.axes, logs):
            largest = max(m['footprint_m'] for m in metrics[label])
            assert ax.get_title() == f'{label}\nlargest arm footprint {largest:.2f} m'
            assert ax.get_aspect() == 1.0
    finally:
        figures.plt.close(fig)
    width, height = png_size(figures.plot_top_view(logs, scenario, steerable_model, tmp_path / 'top.png'))
    assert width > height


def test_base_outline_turns_with_the_base():
    corners = figures._base_outline(np.array([2.0, 1.0, np.pi / 2]))
    np.testing.assert_allclose(np.ptp(corners, axis=0), [0.5, 0.6], atol=1e-12)
    np.testing.assert_allclose(corners[:4].mean(axis=0), [2.0, 1.0])
    np.testing.assert_allclose(corners[0], corners[-1])


def test_write_figures_and_goal_pictures(experiment, steerable_model, tmp_path):
    logs, metrics, scenario = experiment
    paths = figures.write_figures(logs, metrics, scenario, steerable_model, tmp_path, render_label='task_sharing')
    names = [p.name for p in paths]
    assert names == [
        'fig6_error_norm.png',
        'fig7_zoom_psi.png',
        'top_view.png',
        'goal_1.png',
        'goal_2.png',
        'goals_task_sharing.png',
    ]
    assert all(p.stat().st_size > 1000 for p in paths)
    assert png_size(paths[3]) == png_size(paths[4]) == figures.PICTURE_SIZE
    width, height = png_size(paths[5])
    assert width > 2 * height
