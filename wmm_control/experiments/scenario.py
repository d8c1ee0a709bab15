"""Scenario files: a timeline of end-effector goals (``config/scenarios/*.yaml``).

Schema::

    scenario:
      name: sorour_table2
      description: ...
      robot: steerable            # required: robot name, alias or YAML path
      frame: world                # frame of every goal pose
      duration: 65.0              # [s]
      obstacles: table_pillar     # optional: an obstacle file (config/obstacles/<name>.yaml, or a
                                  # path, relative to this file's folder)
      goals:                      # each holds from t until the next goal's t
        - {t: 0.0, pose: [x, y, z, roll, pitch, yaw]}     # [m, rad], RPY = ZYX Euler
      # or, instead of goals, a reference trajectory from the start pose (Xing et al. §4):
      # trajectory: {kind: circle, radius: 0.1}   or   {kind: pose}

      experiment:                 # optional: how wmm_experiment runs it (defaults below)
        sim: {base_mode: kinematic, slip_gain: 0.05, slip_drift: [...], slip_noise: [...], seed: 0}
        runs:                     # one run per entry; keys other than name/method/feedback/plot
          - {name: pinv, method: pinv, feedback: ground_truth}          # are resolver parameters;
          # plot: false keeps a run out of the figures
          - {name: task_sharing, method: task_sharing, compensation: false}

An angle may be written as an expression of ``pi`` (``pi/2``, ``-pi/2``, ``3*pi/4``).
"""

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from wmm_control.errors import ConfigError
from wmm_control.paths import config_path
from wmm_control.robot_config import read_yaml_section
from wmm_control.experiments.trajectories import make_trajectory
from wmm_control.kinematics.obstacles import load_obstacles
from wmm_control.resolvers.interface import PoseTarget

if TYPE_CHECKING:
    from wmm_control.kinematics import KinematicModel

__all__ = ['Goal', 'Scenario', 'load_scenario', 'resolver_parameters', 'DEFAULT_RUNS', 'SIM_KEYS', 'RUN_KEYS']

#: Simulator settings a scenario may give (``wmm_sim`` parameters).
SIM_KEYS = ('base_mode', 'substeps', 'slip_gain', 'slip_drift', 'slip_noise', 'seed')
#: Keys of a run besides the resolver parameters of ``redundancy_resolver``.
RUN_KEYS = ('name', 'method', 'feedback', 'plot')
#: The runs of Sorour's Table II experiment (and of a scenario that names none).
DEFAULT_RUNS = (
    {'name': 'pinv', 'method': 'pinv', 'feedback': 'ground_truth'},
    {'name': 'task_sharing', 'method': 'task_sharing', 'compensation': False, 'feedback': 'ground_truth'},
    {'name': 'task_sharing_compensation', 'method': 'task_sharing', 'compensation': True, 'feedback': 'ground_truth'},
    {
        'name': 'task_sharing_compensation_odometry',
        'method': 'task_sharing',
        'compensation': True,
        'feedback': 'odometry',
    },
)

_PI_EXPR = re.compile(r'^\s*([+-]?\d*\.?\d*)\s*\*?\s*pi\s*(?:/\s*(\d+\.?\d*))?\s*$')


def _number(value, where):
    if isinstance(value, bool):
        raise ConfigError(f'{where}: expected a number, got {value!r}')
    if isinstance(value, (int, float)):
        out = float(value)
    elif isinstance(value, str):
        m = _PI_EXPR.match(value)
        if not m:
            raise ConfigError(f'{where}: expected a number or an expression like "pi/2", got {value!r}')
        coef = m.group(1)
        coef = -1.0 if coef == '-' else 1.0 if coef in ('', '+') else float(coef)
        out = coef * math.pi / (float(m.group(2)) if m.group(2) else 1.0)
    else:
        raise ConfigError(f'{where}: expected a number, got {value!r}')
    if not math.isfinite(out):
        raise ConfigError(f'{where}: must be finite, got {value!r}')
    return out


@dataclass(frozen=True)
class Goal:
    """One goal of a scenario: the pose holds from ``t`` [s] to ``end`` [s].

    Attributes:
        t: start time [s].
        end: end time [s] (the next goal's start, or the scenario's duration).
        pose: [x, y, z, roll, pitch, yaw] in the scenario's frame [m, rad]. Shape (6,).
    """

    t: float
    end: float
    pose: np.ndarray

    @cached_property
    def target(self) -> PoseTarget:
        """The goal as a :class:`~wmm_control.resolvers.PoseTarget` set-point (built once: a
        scenario run asks for it every period)."""
        return PoseTarget.from_rpy(self.pose)


@dataclass(frozen=True)
class Scenario:
    """A timeline of goals on one robot."""

    name: str
    description: str
    robot: str
    frame: str
    duration: float
    goals: tuple
    path: Path
    sim: dict | None = None
    runs: tuple = DEFAULT_RUNS
    trajectory: dict | None = None
    #: the obstacle file ('' for none) and its obstacles
    obstacles_file: str = ''
    obstacles: tuple = ()

    def reference(self, model: 'KinematicModel') -> Callable[[float], PoseTarget]:
        """The trajectory ``t -> PoseTarget`` of a trajectory scenario, from the end effector's pose
        at the robot's start state (its YAML), through ``model`` (a KinematicModel of the robot)."""
        cfg = model.config
        model.update(cfg.start.base_pose, cfg.start.arm)
        return make_trajectory(self.trajectory, *model.ee_placement_world())

    def target(self, t, reference=None):
        """The target in force at time ``t`` [s]: the goal, or the reference trajectory's point."""
        return reference(t) if self.trajectory is not None else self.goals[self.goal_index(t)].target

    def goal_index(self, t: float) -> int:
        """Index of the goal in force at time ``t`` [s] (0 before the first start)."""
        idx = 0
        for i, goal in enumerate(self.goals):
            if t + 1e-9 >= goal.t:
                idx = i
        return idx


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load ``config/scenarios/<name>.yaml`` or a scenario file path.

    Raises:
        ConfigError: missing file or an invalid entry (the message names it).
    """
    text = str(name_or_path)
    path = Path(text) if text.endswith(('.yaml', '.yml')) else config_path('scenarios', f'{text}.yaml')
    raw = read_yaml_section(path, 'scenario', 'scenario')
    where = path.name
    robot = raw.get('robot')
    if not isinstance(robot, str) or not robot:
        raise ConfigError(f'{path}: scenario.robot is required (a robot name, alias or YAML path), got {robot!r}')
    duration = _number(raw.get('duration'), f'{where}.duration')
    if duration <= 0:
        raise ConfigError(f'{where}.duration must be > 0, got {duration}')
    sim, runs = _experiment(raw.get('experiment') or {}, where)
    obstacles_file = raw.get('obstacles') or ''
    if not isinstance(obstacles_file, str):
        raise ConfigError(f'{where}.obstacles: expected the name or path of an obstacle file, got {obstacles_file!r}')
    if obstacles_file.endswith(('.yaml', '.yml')) and not Path(obstacles_file).is_absolute():
        obstacles_file = str(path.parent / obstacles_file)
    common = dict(
        name=str(raw.get('name', path.stem)),
        description=str(raw.get('description', '')),
        robot=robot,
        frame=str(raw.get('frame', 'world')),
        duration=duration,
        path=path,
        sim=sim,
        runs=runs,
        obstacles_file=obstacles_file,
        obstacles=load_obstacles(obstacles_file),
    )
    if 'trajectory' in raw:
        if 'goals' in raw:
            raise ConfigError(f'{where}: give goals or a trajectory, not both')
        spec = raw['trajectory']
        make_trajectory(spec, np.zeros(3), np.eye(3))  # checks the entry
        return Scenario(goals=(), trajectory=dict(spec), **common)
    return Scenario(goals=_goals(raw.get('goals'), duration, where), **common)


def _goals(goals_raw, duration, where):
    if not isinstance(goals_raw, list) or not goals_raw:
        raise ConfigError(f'{where}.goals: expected a non-empty list (or a trajectory)')
    starts, poses = [], []
    for i, g in enumerate(goals_raw):
        w = f'{where}.goals[{i}]'
        if not isinstance(g, dict) or 'pose' not in g or 't' not in g:
            raise ConfigError(f'{w}: expected {{t: ..., pose: [x, y, z, roll, pitch, yaw]}}')
        pose = g['pose']
        if not isinstance(pose, list) or len(pose) != 6:
            raise ConfigError(f'{w}.pose: expected 6 values [x, y, z, roll, pitch, yaw], got {pose!r}')
        starts.append(_number(g['t'], f'{w}.t'))
        poses.append(np.array([_number(v, f'{w}.pose[{k}]') for k, v in enumerate(pose)]))
    if any(b <= a for a, b in zip(starts, starts[1:])) or starts[0] < 0 or starts[-1] >= duration:
        raise ConfigError(f'{where}.goals: start times must increase, from >= 0 to below the duration, got {starts}')
    ends = starts[1:] + [duration]
    return tuple(Goal(t, e, p) for t, e, p in zip(starts, ends, poses))


def resolver_parameters(run: Mapping[str, Any]) -> dict:
    """The resolver parameters of a run entry (every key but :data:`RUN_KEYS`)."""
    return {k: v for k, v in run.items() if k not in RUN_KEYS}


def _experiment(raw, where):
    """The ``experiment`` section: simulator settings and runs, checked by key."""
    if not isinstance(raw, dict):
        raise ConfigError(f'{where}.experiment: expected a mapping')
    sim = raw.get('sim') or {}
    if not isinstance(sim, dict) or set(sim) - set(SIM_KEYS):
        raise ConfigError(f'{where}.experiment.sim: keys must be among {list(SIM_KEYS)}, got {sim!r}')
    runs = raw.get('runs')
    if runs is None:
        return dict(sim), DEFAULT_RUNS
    if not isinstance(runs, list) or not runs:
        raise ConfigError(f'{where}.experiment.runs: expected a non-empty list')
    names = []
    for i, run in enumerate(runs):
        if not isinstance(run, dict) or not isinstance(run.get('name'), str) or 'method' not in run:
            raise ConfigError(f'{where}.experiment.runs[{i}]: expected {{name: ..., method: ..., ...}}')
        names.append(run['name'])
    if len(set(names)) != len(names):
        raise ConfigError(f'{where}.experiment.runs: names must be unique, got {names}')
    return dict(sim), tuple(dict(r) for r in runs)
