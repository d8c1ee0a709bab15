"""Figures of the Table II experiment (Sorour et al. 2019, Figs 5–7), written headless.

* :func:`plot_error_norms` — Fig 6: the pose-error norm ‖e_p‖ of each run, the area under it
  per goal printed above the goal's window;
* :func:`plot_zoom_and_psi` — Fig 7: ‖e_p‖ zoomed in for the task-sharing runs, and ψ;
* :func:`plot_top_view` — the point of Fig 5: base and end-effector paths seen from above,
  with the robot's footprint (base rectangle and arm) every ~2 s on the way to goal 1;
* :func:`render_goal_pictures` — a PyBullet TinyRenderer picture of a run at the end of
  each goal window;
* :func:`write_figures` — all of them into one folder.

The ``*_figure`` functions return the open matplotlib Figure (the caller closes it); the
``plot_*`` functions save it as a PNG, close it and return the path.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np

from sim_bridge.render import render_rgb, write_png
from sim_bridge.world import SimWorld
from wmm_control.experiments.metrics import RunLog, pose_error_norm
from wmm_control.geometry import rotation_error, se2_transform_points

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from wmm_control.experiments.scenario import Scenario
    from wmm_control.kinematics import KinematicModel

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
from matplotlib.transforms import blended_transform_factory  # noqa: E402

__all__ = [
    'tracking_figure',
    'write_tracking_figures',
    'error_norm',
    'arm_reach',
    'error_norm_figure',
    'zoom_psi_figure',
    'top_view_figure',
    'plot_error_norms',
    'plot_zoom_and_psi',
    'plot_top_view',
    'render_goal_pictures',
    'write_figures',
    'BASE_SIZE',
    'FOOTPRINT_PERIOD_S',
    'PICTURE_SIZE',
]

#: Base rectangle drawn in the top view: length along the base x axis, width [m].
BASE_SIZE = (0.6, 0.5)
#: Time between two footprints drawn in the top view [s].
FOOTPRINT_PERIOD_S = 2.0
#: Width, height of a rendered goal picture [px].
PICTURE_SIZE = (480, 360)
_DPI = 110
_ERROR_LABEL = '‖e_p‖ [m, rad]'
_TIME_LABEL = 'time [s]'


def error_norm(log: RunLog, scenario: Scenario) -> np.ndarray:
    """‖e_p‖ (Sorour eq 12) of every row against the goal in force at that row.

    Args:
        log: a frozen :class:`~wmm_control.experiments.metrics.RunLog`.
        scenario: its :class:`~wmm_control.experiments.scenario.Scenario`.

    Returns:
        Error norm per row (position [m] and wrapped RPY [rad] together). Shape (K,).
    """
    err = np.full(len(log), np.nan)
    for gi, goal in enumerate(scenario.goals):
        rows = log.goal == gi
        if np.any(rows):
            err[rows] = pose_error_norm(goal.pose, log.ee_position[rows], log.ee_rotation[rows])
    return err


def arm_reach(log, model, rows):
    """World arm points and their horizontal distance from the base centre, at ``rows``.

    Args:
        log: a frozen RunLog.
        model: a :class:`~wmm_control.kinematics.KinematicModel` of the robot.
        rows: row indices. Shape (n,).

    Returns:
        (points, reach): arm joint origins and end effector [m], shape (n, 8, 3); the largest
        horizontal distance of those points from the base centre per row [m], shape (n,).
    """
    points = []
    for k in rows:
        model.update(log.base_pose[k], log.q_arm[k])
        points.append(model.arm_points_world())
    points = np.array(points).reshape(len(rows), -1, 3)
    offsets = points[:, :, :2] - log.base_pose[rows, None, :2]
    return points, np.max(np.linalg.norm(offsets, axis=2), axis=1, initial=0.0)


def _stacked_axes(n_panels, title):
    """A figure of ``n_panels`` stacked axes sharing the time axis."""
    fig, axes = plt.subplots(
        n_panels, 1, sharex=True, squeeze=False, figsize=(9, 1.2 + 2.1 * n_panels), layout='constrained', dpi=_DPI
    )
    fig.suptitle(title)
    axes = axes[:, 0]
    axes[-1].set_xlabel(_TIME_LABEL)
    return fig, axes


def _goal_switches(ax, scenario):
    """Dotted vertical lines at the goal switches (every goal start after the first)."""
    for i, goal in enumerate(scenario.goals[1:]):
        ax.axvline(goal.t, color='0.35', linestyle=':', linewidth=1.0, label='goal switch' if i == 0 else None)


def _error_panel(ax, log, scenario, title, ylim=None):
    """‖e_p‖ of one run against time, with the goal switches; returns the error."""
    err = error_norm(log, scenario)
    ax.plot(log.t, err, color='tab:blue', linewidth=1.2, label='‖e_p‖')
    _goal_switches(ax, scenario)
    ax.set_ylim(0.0, ylim if ylim is not None else 1.3 * max(float(np.nanmax(err, initial=0.0)), 1e-6))
    ax.set_xlim(0.0, scenario.duration)
    ax.set_ylabel(_ERROR_LABEL)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    return err


def _run_title(label, log):
    return f'{label} ({log.method})' if log.method and log.method != label else label


def error_norm_figure(
    logs: Mapping[str, RunLog], metrics: Mapping[str, Sequence[Mapping[str, Any]]], scenario: Scenario
) -> Figure:
    """Sorour Fig 6: one panel per run, ‖e_p‖ vs time [s], each goal's area above its window.

    Args:
        logs: dict label -> frozen RunLog.
        metrics: dict label -> list of per-goal dicts of
            :func:`~wmm_control.experiments.metrics.goal_metrics` (key ``area`` [m·s]).
        scenario: the :class:`~wmm_control.experiments.scenario.Scenario` of the runs.

    Returns:
        The open :class:`matplotlib.figure.Figure`.
    """
    fig, axes = _stacked_axes(len(logs), 'Pose-error norm; numbers: area under ‖e_p‖ per goal [m·s]')
    for ax, (label, log) in zip(axes, logs.items()):
        _error_panel(ax, log, scenario, _run_title(label, log))
        at_top = blended_transform_factory(ax.transData, ax.transAxes)
        for goal, goal_metrics in zip(scenario.goals, metrics.get(label, ())):
            if goal_metrics.get('area') is not None:
                ax.text(
                    0.5 * (goal.t + goal.end),
                    0.96,
                    f"{goal_metrics['area']:.2f}",
                    transform=at_top,
                    ha='center',
                    va='top',
                    fontsize=9,
                    color='tab:red',
                )
    axes[0].legend(loc='center right', fontsize=8)
    return fig


def _default_labels(logs):
    """The task-sharing runs (all runs when there is none)."""
    shared = [label for label, log in logs.items() if log.method == 'task_sharing']
    return shared or list(logs)


def zoom_psi_figure(
    logs: Mapping[str, RunLog], scenario: Scenario, labels: Iterable[str] | None = None, ylim: float = 0.05
) -> Figure:
    """Sorour Fig 7: ‖e_p‖ zoomed to ``ylim`` per run, then ψ [-] of the runs, vs time [s].

    Args:
        logs: dict label -> frozen RunLog.
        scenario: the Scenario of the runs.
        labels: runs to show; default those of method ``task_sharing`` (all when none is).
        ylim: upper limit of the zoomed error axes [m, rad].

    Returns:
        The open :class:`matplotlib.figure.Figure`.
    """
    labels = list(labels) if labels is not None else _default_labels(logs)
    fig, axes = _stacked_axes(len(labels) + 1, f'Pose-error norm zoomed to {ylim:g}, and task sharing ψ')
    for ax, label in zip(axes, labels):
        _error_panel(ax, logs[label], scenario, _run_title(label, logs[label]), ylim=ylim)
    psi_ax = axes[-1]
    for label in labels:
        psi_ax.plot(logs[label].t, logs[label].psi, linewidth=1.2, label=f'ψ {label}')
    _goal_switches(psi_ax, scenario)
    psi_ax.set_ylim(-0.05, 1.1)
    psi_ax.set_ylabel('ψ [-]')
    psi_ax.set_title('task sharing parameter ψ (1: arm only, 0: base and arm)', fontsize=10)
    psi_ax.grid(alpha=0.3)
    psi_ax.legend(loc='lower right', fontsize=8)
    axes[0].legend(loc='upper right', fontsize=8)
    return fig


def _base_outline(pose):
    """Corners (5, 2) of the base rectangle at ``pose`` (x, y, θ), closed."""
    half = 0.5 * np.array(BASE_SIZE)
    corners = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1], [1, 1]]) * half
    return se2_transform_points(pose, corners)


def _footprint_rows(log):
    """Rows of goal 1 every :data:`FOOTPRINT_PERIOD_S` (and its last row)."""
    rows = np.flatnonzero(log.goal == 0)
    if rows.size < 2:
        return rows
    step = max(1, int(round(FOOTPRINT_PERIOD_S / float(np.median(np.diff(log.t[rows]))))))
    return np.unique(np.append(rows[::step], rows[-1]))


def _goal_marks(ax, scenario):
    """Goal positions as stars, numbered (goals at the same x, y share one mark: "1,4")."""
    numbers = {}
    for i, goal in enumerate(scenario.goals, start=1):
        numbers.setdefault((round(goal.pose[0], 3), round(goal.pose[1], 3)), []).append(str(i))
    xy = np.array(list(numbers))
    ax.plot(xy[:, 0], xy[:, 1], 'r*', markersize=9, label='goals')
    for (x, y), names in numbers.items():
        ax.annotate(','.join(names), (x, y), textcoords='offset points', xytext=(5, 3), fontsize=8, color='tab:red')


def _top_view_panel(ax, label, log, scenario, model):
    """Paths, goals and footprints of one run seen from above."""
    points, reach = arm_reach(log, model, np.arange(len(log)))
    rows = _footprint_rows(log)
    for j, k in enumerate(rows):
        pts = points[k]
        alpha = 0.9 - 0.7 * j / max(1, len(rows) - 1)
        first = j == 0
        ax.plot(
            *_base_outline(log.base_pose[k]).T,
            color='tab:gray',
            alpha=alpha,
            linewidth=1.0,
            label='base (goal 1, every 2 s)' if first else None,
        )
        ax.plot(
            pts[:, 0],
            pts[:, 1],
            '-o',
            color='tab:orange',
            alpha=alpha,
            linewidth=1.2,
            markersize=2,
            label='arm (goal 1, every 2 s)' if first else None,
        )
    ax.plot(log.base_pose[:, 0], log.base_pose[:, 1], color='tab:blue', linewidth=1.3, label='base path')
    ax.plot(log.ee_position[:, 0], log.ee_position[:, 1], color='tab:green', linewidth=1.3, label='EE path')
    _goal_marks(ax, scenario)
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(
        f'{_run_title(label, log)}\nlargest arm footprint {float(np.max(reach, initial=0.0)):.2f} m', fontsize=10
    )
    ax.grid(alpha=0.3)


def top_view_figure(logs: Mapping[str, RunLog], scenario: Scenario, model: KinematicModel) -> Figure:
    """Top view (x-y [m], equal aspect) of each run: base and end-effector paths, goals, and
    the footprint (base rectangle :data:`BASE_SIZE`, arm polyline; lighter with time) every
    :data:`FOOTPRINT_PERIOD_S` of goal 1. Titles give the largest arm footprint: the largest
    horizontal distance of an arm point from the base centre over the run [m].

    Args:
        logs: dict label -> frozen RunLog.
        scenario: the Scenario of the runs.
        model: a :class:`~wmm_control.kinematics.KinematicModel` of the robot.

    Returns:
        The open :class:`matplotlib.figure.Figure`.
    """
    fig, axes = plt.subplots(
        1, len(logs), squeeze=False, figsize=(1.0 + 4.6 * len(logs), 5.2), layout='constrained', dpi=_DPI
    )
    fig.suptitle('Top view: paths and robot footprint on the way to goal 1')
    for ax, (label, log) in zip(axes[0], logs.items()):
        _top_view_panel(ax, label, log, scenario, model)
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, loc='outside lower center', ncols=len(names), fontsize=8)
    return fig


def _save(fig, path):
    """Save ``fig`` as a PNG at ``path``, close it, return the path."""
    path = Path(path)
    fig.savefig(path, format='png')
    plt.close(fig)
    return path


def plot_error_norms(
    logs: Mapping[str, RunLog], metrics: Mapping[str, Sequence[Mapping[str, Any]]], scenario: Scenario, path: str | Path
) -> Path:
    """Write :func:`error_norm_figure` (Sorour Fig 6) to the PNG ``path``; returns the path."""
    return _save(error_norm_figure(logs, metrics, scenario), path)


def plot_zoom_and_psi(
    logs: Mapping[str, RunLog],
    metrics: object,
    scenario: Scenario,
    path: str | Path,
    labels: Iterable[str] | None = None,
    ylim: float = 0.05,
) -> Path:
    """Write :func:`zoom_psi_figure` (Sorour Fig 7) to the PNG ``path``; returns the path.

    ``metrics`` is accepted for a signature like :func:`plot_error_norms`; the figure does
    not use it.
    """
    return _save(zoom_psi_figure(logs, scenario, labels=labels, ylim=ylim), path)


def plot_top_view(logs: Mapping[str, RunLog], scenario: Scenario, model: KinematicModel, path: str | Path) -> Path:
    """Write :func:`top_view_figure` (the point of Sorour Fig 5) to the PNG ``path``; returns the path."""
    return _save(top_view_figure(logs, scenario, model), path)


def render_goal_pictures(
    logs: Mapping[str, RunLog], scenario: Scenario, out_dir: str | Path, label: str, view: str = 'iso'
) -> list[Path]:
    """Render run ``label`` at the last row of each goal window with PyBullet's TinyRenderer.

    Writes ``goal_<i>.png`` (i = 1.., :data:`PICTURE_SIZE` px) for each goal the run reached
    in time, and ``goals_<label>.png``: the pictures side by side, titled "goal i, t = … s".

    Args:
        logs: dict label -> frozen RunLog.
        scenario: the Scenario of the run (its ``robot`` is placed).
        out_dir: output folder (created).
        label: the run to render.
        view: camera view of :data:`sim_bridge.render.VIEWS`.

    Returns:
        The written paths: the goal pictures, then the composite.
    """
    log = logs[label]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    shots, paths = [], []
    for gi in range(len(scenario.goals)):
        rows = np.flatnonzero(log.goal == gi)
        if rows.size == 0:
            continue
        k = rows[-1]
        with SimWorld(scenario.robot, start_base_pose=log.base_pose[k], start_arm=log.q_arm[k]) as world:
            rgb = render_rgb(world, view, *PICTURE_SIZE)
        paths.append(write_png(out_dir / f'goal_{gi + 1}.png', rgb))
        shots.append((f'goal {gi + 1}, t = {log.t[k]:.2f} s', rgb))
    fig, axes = plt.subplots(
        1, len(shots), squeeze=False, figsize=(3.2 * len(shots), 2.9), layout='constrained', dpi=_DPI
    )
    fig.suptitle(f'{_run_title(label, log)}: robot at the end of each goal window ({view} view)')
    for ax, (title, rgb) in zip(axes[0], shots):
        ax.imshow(rgb)
        ax.set_title(title, fontsize=9)
        ax.axis('off')
    return paths + [_save(fig, out_dir / f'goals_{label}.png')]


def write_figures(
    logs: Mapping[str, RunLog],
    metrics: Mapping[str, Sequence[Mapping[str, Any]]],
    scenario: Scenario,
    model: KinematicModel,
    out_dir: str | Path,
    render_label: str | None = None,
    zoom_labels: Iterable[str] | None = None,
) -> list[Path]:
    """Write ``fig6_error_norm.png``, ``fig7_zoom_psi.png``, ``top_view.png`` into ``out_dir``
    (created), plus :func:`render_goal_pictures` of ``render_label`` when given.

    Args:
        logs: dict label -> frozen RunLog.
        metrics: dict label -> list of per-goal metric dicts.
        scenario: the Scenario of the runs.
        model: a KinematicModel of the robot.
        out_dir: output folder.
        render_label: run to render at the end of each goal window, or None.
        zoom_labels: runs of the Fig 7 zoom (default: :func:`plot_zoom_and_psi`'s choice).

    Returns:
        The written paths.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [
        plot_error_norms(logs, metrics, scenario, out_dir / 'fig6_error_norm.png'),
        plot_zoom_and_psi(logs, metrics, scenario, out_dir / 'fig7_zoom_psi.png', labels=zoom_labels),
        plot_top_view(logs, scenario, model, out_dir / 'top_view.png'),
    ]
    if render_label is not None:
        paths += render_goal_pictures(logs, scenario, out_dir, render_label)
    return paths


# ---------------------------------------------------------------------- trajectory scenarios
def tracking_figure(logs, scenario, model):
    """Xing et al. Figs 7, 10, 11 (and 13–14 for the pose run): per run, the end effector's x-y error
    against the reference (ground truth), the commanded base velocity, σ_min of the arm Jacobian,
    and for the pose run the rotation error about the world y axis, vs time."""
    pose = scenario.trajectory.get('kind') == 'pose'
    fig, axes = _stacked_axes(4 if pose else 3, f'{scenario.name}: tracking, base commands, distance to singularity')
    reference = scenario.reference(model)
    for label, log in logs.items():
        targets = [reference(t) for t in log.t]
        ref = np.array([tg.position for tg in targets])
        err = np.linalg.norm(ref[:, :2] - log.ee_position[:, :2], axis=1)
        axes[0].plot(log.t, err * 1e3, label=label)
        if pose:
            rot = rotation_error([tg.rotation for tg in targets], log.ee_rotation)[:, 1]
            axes[3].plot(log.t, np.degrees(rot), label=label)
        axes[1].plot(log.t, np.linalg.norm(log.base_reference[:, :2], axis=1) * 1e2, label=f'{label}: |v| [cm/s]')
        axes[1].plot(log.t, np.degrees(log.base_reference[:, 2]), ls='--', label=f'{label}: ω [°/s]')
        axes[2].plot(log.t, log.sigma_min, label=label)
    axes[0].set_ylabel('x-y error [mm]')
    axes[1].set_ylabel('base command')
    axes[2].set_ylabel('σ_min(J_m) [-]')
    if pose:
        axes[3].set_ylabel('rotation error about y [°]')
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize='small', loc='upper right')
    return fig


def write_tracking_figures(
    logs: Mapping[str, RunLog], scenario: Scenario, model: KinematicModel, out_dir: str | Path
) -> list[Path]:
    """Write ``tracking.png`` (:func:`tracking_figure`) into ``out_dir``; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [_save(tracking_figure(logs, scenario, model), out_dir / 'tracking.png')]
