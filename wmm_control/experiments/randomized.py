"""Randomized closed-loop runs: random reachable goals, every method, both robots.

**A reachable goal** is the end-effector pose of a configuration the robot can take:

1. an arm configuration drawn uniformly within the position limits, ``ARM_MARGIN`` inside
   them (joints without limits: within (−π, π]);
2. a base pose drawn uniformly: (x, y) in a disc of radius ``base_radius`` around the start
   pose (or in the obstacle file's ``goal_region``), heading uniform in (−π, π];
3. the goal is that configuration's end-effector pose (forward kinematics);
4. the draw is rejected, and drawn again, when the arm comes within ``COLLISION_MARGIN`` of
   the robot's own body or the floor, or the robot within it of an obstacle, if any
   (:class:`~sim_bridge.collision.SelfCollisionChecker`).

So every goal is reached by at least one configuration within the limits and clear of the
robot's body and the obstacles. The path to it is checked: every period's configuration
against the robot's body, itself, the floor and the obstacles, on the simulator's own
geometry and the true base pose (:class:`~sim_bridge.collision.SelfCollisionChecker`,
independent of the controllers' distance model); a run that goes more than
``CONTACT_DEPTH`` into contact has failed.

**A recorded run** (``record``, ``wmm_randomized --record DIR``) is one
``DIR/<robot>_<method>_<goal>.npz`` (numpy's ``np.load``) with

* ``t`` [s], shape (K,): the start of each control period;
* ``base_pose``, shape (K, 3): the base's true pose (x [m], y [m], θ [rad]) in the world;
* ``joint_names``, shape (J,): every moving joint of the robot's URDF that the simulator
  drives (the arm's, then the steer and drive joints or the wheels);
* ``q``, shape (K, J): their positions [rad or m] at the start of each period;
* ``goal_pose``, shape (6,): the goal [x, y, z, roll, pitch, yaw], world frame [m, rad];
* ``obstacles``: the obstacle file's text, its ``random_boxes`` drawn as fixed obstacles
  (:func:`~wmm_control.kinematics.obstacles.obstacle_text`; '' without obstacles);
* ``cycle_s``, ``cycle_cpu_s``, shape (K,): each period's control cycle (the method with its
  safety stage, the base controller and the compensation, not the simulator's step), wall
  time (``time.perf_counter``) and CPU time of its thread (``time.thread_time``) [s]; NaN
  with the nodes engine, whose cycle runs in callbacks of two nodes and is not timed.

**A run** starts from the robot's start state (its YAML), with the goal given at t = 0 as a
set-point, in lockstep: the direct engine (:func:`wmm_control.experiments.direct.run_scenario`, the
same core objects the nodes run) or every node in this process over topics
(:func:`~wmm_control.experiments.ros_run.run_with_nodes`). Kinematic base, no slip,
ground-truth feedback: the runs test the controllers, not the odometry. Its outcome is

* *converged*: the goal is reached (the node's ``goal_tolerance``) and held until the end (a
  direct run ends once it has held for ``SETTLE_S``);
* *reported*: not converged, and ``goal_stalled`` was set on ``/diagnostics`` during the run
  (the node then logs the stall once; for the direct engine:
  :class:`~wmm_control.resolvers.progress.GoalProgress` over the resolver's diagnostics, what
  the node publishes). A goal reported stalled may make progress again later: the report is
  what the user was told, whatever the run's end;
* *failed*: neither, a limit passed, a non-finite command, or contact.
"""

import math
import tempfile
from dataclasses import dataclass
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike

from wmm_control.experiments.direct import run_scenario
from sim_bridge.collision import SelfCollisionChecker
from sim_bridge.world import SimWorld
from wmm_control.experiments.metrics import RunLog, run_limit_report
from wmm_control.experiments.method_runs import METHOD_RUNS, ROBOT_RUNS
from wmm_control.experiments.ros_run import run_with_nodes
from wmm_control.experiments.scenario import Goal, Scenario, load_scenario, resolver_parameters
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.obstacles import Obstacle, load_goal_region, load_obstacles, obstacle_file, obstacle_text
from wmm_control.geometry import matrix_from_rpy, rotation_angle, rpy_from_matrix
from wmm_control.nodes.parameters import load_defaults
from wmm_control.planning import GoalPlanner, NoWay
from wmm_control.planning.no_way_check import NoWayCheck, Verdict, confirm_no_way
from wmm_control.planning.pursuit import GoalPursuit, run_limit
from wmm_control.planning.timing import rest_to_rest
from wmm_control.resolvers import make_resolver
from wmm_control.resolvers.interface import ResolverDiagnostics
from wmm_control.resolvers.period import ResolverSettings
from wmm_control.resolvers.progress import GoalProgress
from wmm_control.robot_config import RobotConfig, load_robot

__all__ = [
    'RandomGoal',
    'sample_goals',
    'run_goal',
    'cycle_stats',
    'summarize',
    'ROBOTS',
    'METHOD_RUNS',
    'ROBOT_RUNS',
    'DURATION_FLOOR_S',
    'DURATION_DISTANCE_M',
    'DURATION_SLACK',
    'run_duration',
    'ARM_MARGIN',
    'COLLISION_MARGIN',
    'CONTACT_DEPTH',
    'SETTLE_S',
    'goal_settings',
    'run_contact',
    'write_record',
    'no_way_check',
]

#: The robots, by name.
ROBOTS = ('steerable', 'mecanum')
#: The longest run [s] of a robot (:func:`run_duration`) is at least this: long enough for the slowest
#: approach of robot A that never stalls (amp, 64 s), whose arm, not its base, sets the pace.
DURATION_FLOOR_S = 90.0
#: [m] :func:`run_duration` times the base's drive over this distance, from rest to rest
DURATION_DISTANCE_M = 5.0
#: :func:`run_duration` gives a run this many times that drive's time: robot B's base (0.25 m/s, 0.025 m/s²,
#: Xing Table 1) drives 5 m in 30 s, its slowest approach that never stalls took 128 s (amp): 180 s
DURATION_SLACK = 6.0
#: Drawn arm configurations stay this far inside the position limits [rad].
ARM_MARGIN = 0.1
#: Clearance of a drawn configuration from the robot's body and the floor [m].
COLLISION_MARGIN = 0.02
#: A run whose arm goes this far into the body, itself or the floor is in contact [m].
CONTACT_DEPTH = 0.001
#: A direct run ends once the goal has been held this long [s].
SETTLE_S = 2.0


@dataclass(frozen=True)
class RandomGoal:
    """One drawn goal.

    Attributes:
        index: its number in the draw.
        base_pose: base pose (x, y, θ) of the configuration it comes from [m, m, rad]. Shape (3,).
        q_arm: arm configuration it comes from [rad or m]. Shape (n,).
        pose: the goal [x, y, z, roll, pitch, yaw], world frame [m, rad]. Shape (6,).
        draws: configurations drawn for it (the rejected ones included).
    """

    index: int
    base_pose: np.ndarray
    q_arm: np.ndarray
    pose: np.ndarray
    draws: int


def goal_settings() -> tuple[tuple[float, ...], float, float]:
    """``(goal_tolerance, stall_time, min_progress_ratio)`` of the ``redundancy_resolver``
    node, from its defaults (``config/redundancy_resolver.yaml``): (position [m], orientation
    [rad]), [s] and [-]."""
    defaults = load_defaults('redundancy_resolver.yaml', 'redundancy_resolver')
    return (
        tuple(float(v) for v in defaults['goal_tolerance']),
        float(defaults['stall_time']),
        float(defaults['min_progress_ratio']),
    )


def _arm_box(arm):
    lo = np.where(np.isfinite(arm.position_lower), arm.position_lower + ARM_MARGIN, -math.pi)
    hi = np.where(np.isfinite(arm.position_upper), arm.position_upper - ARM_MARGIN, math.pi)
    return lo, hi


def sample_goals(
    robot: str | Path | RobotConfig, count: int, seed: int = 0, base_radius: float = 1.0, obstacles: str | Path = ''
) -> list[RandomGoal]:
    """``count`` reachable goals for ``robot`` (see the module docstring), reproducible by
    ``seed``, clear of the obstacles of the file ``obstacles`` (name or path; '' for none).

    Returns:
        list of :class:`RandomGoal`.
    """
    cfg = load_robot(robot)
    around = load_obstacles(obstacles)
    region = load_goal_region(obstacles)
    model = KinematicModel(cfg)
    rng = np.random.default_rng(seed)
    lo, hi = _arm_box(cfg.arm)
    start = np.asarray(cfg.start.base_pose, dtype=float)
    if region is not None:
        start = np.array([region[0][0], region[0][1], 0.0])
        base_radius = region[1]
    goals: list[RandomGoal] = []
    with SelfCollisionChecker(cfg, margin=COLLISION_MARGIN, obstacles=around) as checker:
        while len(goals) < count:
            draws = 0
            while True:
                draws += 1
                q = rng.uniform(lo, hi)
                radius, bearing = base_radius * math.sqrt(rng.uniform()), rng.uniform(-math.pi, math.pi)
                base = start + np.array([radius * math.cos(bearing), radius * math.sin(bearing), 0.0])
                base[2] = rng.uniform(-math.pi, math.pi)
                if not checker.collisions(q, base):
                    break
            model.update(base, q)
            pos, rot = model.ee_placement_world()
            goals.append(RandomGoal(len(goals), base, q, np.concatenate((pos, rpy_from_matrix(rot))), draws))
    return goals


def _scenario(robot, goal, duration, obstacles):
    return Scenario(
        name=f'random_{robot.name}_{goal.index}',
        description='random reachable goal',
        robot=robot.name,
        frame='world',
        duration=duration,
        goals=(Goal(0.0, duration, goal.pose),),
        path=None,
        sim={'base_mode': 'kinematic'},
        runs=(),
        obstacles_file=obstacles,
        obstacles=load_obstacles(obstacles),
    )


def _run_direct(robot, run, goal, duration, obstacles, plan=False):
    """A direct run; with ``plan`` the goal is pursued as ``goal_planner`` pursues it
    (:class:`~wmm_control.planning.pursuit.GoalPursuit`, its plans made within the period that
    asks for them): the plan's way there first, planned again from where the robot is when it
    stalls (``MAX_REPLANS`` times at most), then the goal. (None, planning) when the first plan
    finds no way."""
    resolver = make_resolver(run['method'], robot, **resolver_parameters(run))
    tolerance, stall_time, ratio = goal_settings()
    progress = GoalProgress(tolerance, stall_time, resolver.params.dt, min_progress_ratio=ratio)
    settle = int(round(SETTLE_S / resolver.params.dt))
    held = [0]
    first_stall = []

    def done(diagnostics: ResolverDiagnostics) -> bool:
        # given the diagnostics towards the goal only: once a plan is followed to its end
        progress.update(diagnostics)
        if progress.stalled and not first_stall:
            first_stall.append(progress.cycles * resolver.params.dt)
        held[0] = held[0] + 1 if progress.reached else 0
        return held[0] >= settle

    pursuit = None
    if plan:
        settings = ResolverSettings.defaults()
        pursuit = GoalPursuit(
            robot, load_obstacles(obstacles), settings.world_frame, settings.max_goal_distance, threaded=False
        )
    with SimWorld(robot, base_mode='kinematic') as world:
        scenario = _scenario(robot, goal, duration, obstacles)
        log = run_scenario(world, resolver, scenario, until=done, pursuit=pursuit, after_plan=True)
    status = {'goal_reached': progress.reached, 'first_stall_s': first_stall[0] if first_stall else None}
    if pursuit is None:
        return log, status
    return _with_account(log, status, pursuit.account())


def _with_account(log, status: dict, planning: dict):
    """A planned run's (log, status with the pursuit's ``planning`` account), or (None,
    planning) when its first plan found no way (the run is then not counted as one)."""
    if planning['no_way'] and planning['plans'] == 1:
        return None, planning
    return log, dict(status, **planning)


def _run_nodes(robot, run, goal, duration, obstacles, plan=False):
    """A run with every node in this process; with ``plan`` ``goal_planner`` between the goal and
    the resolver (:func:`~wmm_control.experiments.ros_run.run_with_nodes`). (None, planning)
    when the first plan finds no way."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'goal.yaml'
        path.write_text(
            yaml.safe_dump(
                {
                    'scenario': {
                        'name': f'random_{robot.name}_{goal.index}',
                        'robot': robot.name,
                        'frame': 'world',
                        'duration': duration,
                        'goals': [{'t': 0.0, 'pose': [float(v) for v in goal.pose]}],
                        'obstacles': str(obstacle_file(obstacles).resolve()) if obstacles else '',
                    }
                }
            )
        )
        scenario = load_scenario(path)
        entry = dict(run, name=run['method'], feedback='ground_truth')
        log = run_with_nodes(scenario, entry, planner=plan, after_plan=True)
    final = log.final_status or {}
    status = {'goal_reached': final.get('goal_reached', False), 'first_stall_s': log.first_stall_s}
    if not plan:
        return log, status
    return _with_account(log, status, log.planning)


def _limit_use(log, robot, dt):
    """How much of each limit the run used: the largest |value| / limit (<= 1 within) and the
    smallest distance of an arm joint to a position limit [rad]."""
    arm, base, axes = robot.arm, robot.base, list(robot.base.axes)
    # (a differential base's vy has a zero limit: any vy at all is a limit passed, which
    # run_limit_report counts; the use is taken over the axes the base follows)
    arm_cmd, base_ref = log.arm_command, log.base_reference[:, axes]
    use = {
        'arm_velocity': float(np.max(np.abs(arm_cmd) / arm.velocity)),
        'arm_acceleration': float(np.max(np.abs(np.diff(arm_cmd, axis=0, prepend=0.0)) / (arm.acceleration * dt))),
        'base_velocity': float(np.max(np.abs(base_ref) / base.velocity[axes])),
        'base_acceleration': float(
            np.max(np.abs(np.diff(base_ref, axis=0, prepend=0.0)) / (base.acceleration[axes] * dt))
        ),
    }
    margin = np.minimum(log.q_arm - arm.position_lower, arm.position_upper - log.q_arm)
    finite = np.isfinite(margin)
    use['arm_position_margin_rad'] = float(np.min(margin[finite])) if np.any(finite) else math.inf
    return use


def run_contact(
    robot: str | Path | RobotConfig,
    q_arm: Sequence[np.ndarray] | np.ndarray,
    base_pose: Sequence[np.ndarray] | np.ndarray | None = None,
    obstacles: Iterable[Obstacle] = (),
) -> tuple[float, str]:
    """The deepest contact of a run's configurations (arm ``q_arm``, true base pose
    ``base_pose``, one row per period) with the robot's body, itself, the floor or an
    obstacle, on the simulator's geometry: ``(depth [m], 'a/b')``, ``(0.0, '')`` when every
    period is clear."""
    depth, pair = 0.0, ''
    poses = [None] * len(q_arm) if base_pose is None else base_pose
    with SelfCollisionChecker(robot, margin=0.0, obstacles=obstacles) as checker:
        for q, pose in zip(q_arm, poses):
            for a, b, d in checker.collisions(q, pose):
                if -d > depth:
                    depth, pair = -d, f'{a}/{b}'
    return depth, pair


def run_duration(robot: RobotConfig) -> float:
    """The longest run [s] of ``robot`` (a planned run counts it from when its first plan's base path
    is planned to end, :func:`run_goal`): :data:`DURATION_SLACK` times the time its base needs to drive
    :data:`DURATION_DISTANCE_M` from rest to rest along its slowest axis of translation, within that axis'
    velocity and acceleration limits (:func:`~wmm_control.planning.timing.rest_to_rest`), and at least
    :data:`DURATION_FLOOR_S`. Robot B (``mecanum``): 6 × 30 s = 180 s; the other shipped robots' bases
    drive it in 6–15 s: 90 s."""
    base = robot.base
    drive = max(
        rest_to_rest(DURATION_DISTANCE_M, float(base.velocity[k]), float(base.acceleration[k]))
        for k in (0, 1)
        if k in base.axes
    )
    return max(DURATION_FLOOR_S, DURATION_SLACK * drive)


def run_goal(
    robot: str | Path | RobotConfig,
    method: str,
    goal: RandomGoal,
    engine: str = 'direct',
    duration: float | None = None,
    params: Mapping[str, Any] | None = None,
    obstacles: str | Path = '',
    record: str | Path | None = None,
    plan: bool = False,
) -> dict:
    """One closed-loop run of ``method`` to ``goal`` from the robot's start state.

    ``params`` (resolver parameters) override those of :data:`METHOD_RUNS` and :data:`ROBOT_RUNS`.
    ``duration``: the run's limit [s] (default :func:`run_duration`); with ``plan`` it counts from
    when the base path of the goal's first plan is planned to end
    (:func:`~wmm_control.planning.pursuit.run_limit`): a goal the base drives far to is given
    the time of its drive on top.
    ``obstacles``: an obstacle file (name or path; '' for none), in the simulator and the
    controller. ``record``: a folder to write the run to (the module docstring says how).
    ``plan``: the planner plans the way to the goal first (as ``goal_planner`` does,
    :class:`~wmm_control.planning.pursuit.GoalPursuit`; with the nodes engine the node itself,
    planning in its thread while the robot is held), the run follows its hand-off at the robot's pace
    (:class:`~wmm_control.planning.follow.PlanFollower`), then goes to the goal; when the robot
    stalls on the way it is planned again from where the robot is. A goal the planner finds no
    way to is not run (or the run ends where a plan again finds none): ``no_way``, unless the
    run went into contact or past a limit (``failed``).

    Returns:
        dict: ``robot``, ``method``, ``goal`` (index), ``outcome`` (``converged`` | ``reported`` |
        ``failed``, or ``no_way`` with ``plan``: the planner's reason in ``no_way_reason``, the
        robot held still, or stopped where a plan from where it stalled found none), ``time_s`` (simulated),
        ``time_limit_s`` (the run's limit, ``duration`` with the plan's path on top), ``time_to_reach_s`` (first entry into the
        tolerance, null: never), ``final_position_error_m``, ``final_orientation_error_rad``,
        ``first_stall_s`` (when the goal was first reported stalled, null: never),
        ``limits_exceeded`` (:func:`~wmm_control.experiments.metrics.run_limit_report`),
        ``contact_depth_m`` and ``contact_pair`` (:func:`run_contact`),
        ``limit_use`` (largest fraction of each velocity and acceleration limit, smallest
        distance to an arm position limit), ``sim_clamped`` (command entries the simulator had
        to clamp), ``cycle_s`` and ``cycle_cpu_s`` (the control cycle's wall and thread CPU
        time over the run's periods, :func:`cycle_stats`), ``why`` (the reason of a failure,
        else empty) and ``refused`` (why the resolver refused the goal and held the robot
        still, else empty); with ``plan`` also ``planning_time_s`` (of every plan of the run),
        ``replans`` (the plans from where the robot stalled, at most :data:`MAX_REPLANS`),
        ``no_way`` (its kind, else None), ``no_way_reason``, ``no_way_from`` (the base pose the
        plan that found no way was made from), ``planned_end_s`` (when the first plan's base path
        is planned to end, None without a path to follow) and, for a ``no_way`` run, ``no_way_check``
        (:func:`no_way_check`: ``verdict`` confirmed | refuted | unchecked, ``evidence``, the
        stance that refutes it, ...).
    """
    cfg = load_robot(robot)
    duration = run_duration(cfg) if duration is None else duration
    run = {**METHOD_RUNS[method], **ROBOT_RUNS.get(cfg.name, {}).get(method, {}), **(params or {})}
    log, status = (_run_direct if engine == 'direct' else _run_nodes)(cfg, run, goal, duration, obstacles, plan=plan)
    planning: dict = {}
    limit = duration
    if plan:
        keys = ('planning_time_s', 'no_way', 'no_way_reason', 'no_way_from', 'replans', 'planned_end_s')
        planning = {k: status.pop(k) for k in keys}
        limit = run_limit(duration, planning['planned_end_s'])
        if log is None:
            log, status = _held(cfg, method, goal, '')
    if not len(log):  # the goal was refused: the robot held still
        log, status = _held(cfg, method, goal, log.refused or 'goal refused by the resolver')
    if record is not None:
        write_record(Path(record) / f'{cfg.name}_{method}_{goal.index}.npz', log, goal.pose, obstacles)
    dt = float(np.median(np.diff(log.t))) if len(log) > 1 else cfg.period
    target = Goal(0.0, duration, goal.pose).target
    pos_err = np.linalg.norm(log.ee_position - target.position, axis=1)
    ori_err = np.array([rotation_angle(target.rotation, r) for r in log.ee_rotation])
    tolerance = goal_settings()[0]
    inside = np.flatnonzero((pos_err <= tolerance[0]) & (ori_err <= tolerance[1]))
    exceeded = run_limit_report(log, cfg, dt, tol=1e-9)
    clamped = sum(c['clamped'] + c['rejected'] for c in (log.sim_counters or {}).values())
    why = []
    if exceeded['non_finite']:
        why.append(f'{exceeded["non_finite"]} non-finite commands')
    why += [f'{k} limit passed by {v:.3g}' for k, v in exceeded.items() if k != 'non_finite' and v > 0]
    if clamped:
        why.append(f'{clamped} command entries clamped by the simulator')
    depth, pair = run_contact(cfg, log.q_arm, log.base_pose, load_obstacles(obstacles))
    if depth > CONTACT_DEPTH:
        why.append(f'{pair} {depth * 100:.1f} cm into contact')
    if planning.get('no_way'):  # the planner found no way (at the start or from where the robot stalled)
        outcome = 'no_way'
    elif status['goal_reached']:
        outcome = 'converged'
    elif status['first_stall_s'] is not None:
        outcome = 'reported'
    else:
        outcome = 'failed'
        why.append(f'neither reached nor ever reported stalled in {limit:g} s')
    if why:
        outcome = 'failed'
    if outcome == 'no_way':
        planning['no_way_check'] = no_way_check(cfg, goal, obstacles, planning)
    return {
        'robot': cfg.name,
        'method': method,
        'goal': goal.index,
        'outcome': outcome,
        'time_s': float(log.t[-1] + dt),
        'time_limit_s': limit,
        'time_to_reach_s': float(log.t[inside[0]]) if inside.size else None,
        'final_position_error_m': float(pos_err[-1]),
        'final_orientation_error_rad': float(ori_err[-1]),
        'first_stall_s': status['first_stall_s'],
        'limits_exceeded': exceeded,
        'contact_depth_m': depth,
        'contact_pair': pair,
        'limit_use': _limit_use(log, cfg, dt),
        'sim_clamped': int(clamped),
        'cycle_s': cycle_stats(log.cycle_s),
        'cycle_cpu_s': cycle_stats(log.cycle_cpu_s),
        'why': '; '.join(why),
        'refused': status.get('refused', ''),
        **planning,
    }


def no_way_check(cfg: RobotConfig, goal: RandomGoal, obstacles: str | Path, planning: Mapping[str, Any]) -> dict:
    """The check of a run's "no way" (:func:`~wmm_control.planning.no_way_check.confirm_no_way`,
    with the planner's defaults, as the runs plan) for the goal ``goal`` among the obstacles of
    the file ``obstacles``, the robot where the plan that found none was made
    (``planning['no_way_from']``): its :meth:`~wmm_control.planning.no_way_check.NoWayCheck.as_dict`.
    Unchecked when the planner gave no kind (it failed)."""
    kind, where = planning.get('no_way'), planning.get('no_way_from')
    if kind not in {k.value for k in NoWay} or where is None:
        return NoWayCheck(Verdict.UNCHECKED, f'the planner gave no reason to check ({kind})').as_dict()
    planner = GoalPlanner(cfg, load_obstacles(obstacles))
    return confirm_no_way(planner, goal.pose[:3], matrix_from_rpy(goal.pose[3:]), kind, where).as_dict()


def _held(cfg: RobotConfig, method: str, goal: RandomGoal, refused: str) -> tuple[RunLog, dict]:
    """The log of a run whose goal the resolver refused (no motion reaches it, or it lies inside
    an obstacle): one period of the robot held still at its start state, and the goal reported
    (refusing it is what the resolver must do), with the reason."""
    model = KinematicModel(cfg)
    model.update(cfg.start.base_pose, cfg.start.arm)
    position, rotation = model.ee_placement_world()
    target = Goal(0.0, 0.0, goal.pose).target
    error = float(np.linalg.norm(np.asarray(position) - target.position))
    held = ResolverDiagnostics(
        method,
        'held',
        1.0,
        error,
        rotation_angle(target.rotation, np.asarray(rotation)),
        1.0,
        1.0,
        1.0,
        1.0,
        (),
        math.nan,
        False,
        0.0,
    )
    log = RunLog(method=method, label='held')
    n = cfg.arm.n
    log.append(0.0, 0, position, rotation, cfg.start.base_pose, cfg.start.arm, np.zeros(n), np.zeros(3), None, held)
    return log.freeze(), {'goal_reached': False, 'first_stall_s': 0.0, 'refused': refused}


def cycle_stats(seconds: ArrayLike) -> dict[str, float] | None:
    """``{'p50', 'p99', 'max'}`` of a run's cycle times ``seconds`` [s] (the median, the 99th
    percentile and the largest, over the timed periods); None when no period was timed."""
    timed = np.asarray(seconds, dtype=float)
    timed = timed[np.isfinite(timed)]
    if not timed.size:
        return None
    return {
        'p50': float(np.median(timed)),
        'p99': float(np.percentile(timed, 99)),
        'max': float(timed.max()),
    }


def write_record(path: Path, log: RunLog, goal_pose: ArrayLike, obstacles: str | Path = '') -> None:
    """Write the run ``log`` to ``path`` (``.npz``, the module docstring says what it holds)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    text = obstacle_text(obstacles) if obstacles else ''
    np.savez_compressed(
        path,
        t=log.t,
        base_pose=log.base_pose,
        joint_names=np.array(log.joint_names, dtype=str),
        q=log.q,
        goal_pose=np.asarray(goal_pose, dtype=float),
        obstacles=np.array(text),
        cycle_s=log.cycle_s,
        cycle_cpu_s=log.cycle_cpu_s,
    )


def summarize(results: Iterable[Mapping[str, Any]]) -> dict:
    """Per robot and method: ``runs``, ``converged``, ``reported``, ``failed``, ``no_way`` (the
    planner found no way, ``--plan``) and of those ``no_way_confirmed``, ``no_way_refuted`` and
    ``no_way_unchecked`` (by their :func:`no_way_check`), ``replans`` (``--plan``: over the runs), the worst final
    errors of the converged runs, the median and largest time to converge, and the worst use of
    every limit over all runs (``limit_use_max``: largest fraction of a velocity or acceleration
    limit; ``position_margin_min_rad``), the runs in contact (``in_contact``) and the deepest
    contact (``deepest_contact_m``), and the control cycle's times over the runs timed
    (``cycle_p99_s`` and ``cycle_cpu_p99_s``: the largest p99 of a run, wall and thread CPU;
    ``cycle_max_s`` and ``cycle_cpu_max_s``: the longest cycle; None when no run was timed).
    A run that raised (no ``limit_use``) counts as failed and in nothing else (the limits: None
    when no run measured them).

    Returns:
        dict keyed by ``(robot, method)``.
    """
    out: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in results:
        out.setdefault((r['robot'], r['method']), []).append(r)
    table = {}
    for key, rows in out.items():
        conv = [r for r in rows if r['outcome'] == 'converged']
        times = [r['time_to_reach_s'] for r in conv]
        ran = [r for r in rows if 'limit_use' in r]  # a run that raised measured nothing
        use = [max(v for k, v in r['limit_use'].items() if k != 'arm_position_margin_rad') for r in ran]
        table[key] = {
            'runs': len(rows),
            'converged': len(conv),
            'reported': sum(r['outcome'] == 'reported' for r in rows),
            'failed': sum(r['outcome'] == 'failed' for r in rows),
            'no_way': sum(r['outcome'] == 'no_way' for r in rows),
            **{
                f'no_way_{verdict.value}': sum(
                    r['outcome'] == 'no_way' and (r.get('no_way_check') or {}).get('verdict') == verdict.value
                    for r in rows
                )
                for verdict in Verdict
            },
            'replans': sum(r.get('replans') or 0 for r in rows),
            'worst_position_error_m': max((r['final_position_error_m'] for r in conv), default=None),
            'worst_orientation_error_rad': max((r['final_orientation_error_rad'] for r in conv), default=None),
            'median_time_s': float(np.median(times)) if times else None,
            'max_time_s': max(times, default=None),
            'limit_use_max': max(use, default=None),
            'position_margin_min_rad': min((r['limit_use']['arm_position_margin_rad'] for r in ran), default=None),
            'non_finite': sum(r['limits_exceeded']['non_finite'] for r in ran),
            'in_contact': sum(r.get('contact_depth_m', 0.0) > CONTACT_DEPTH for r in rows),
            'deepest_contact_m': max(r.get('contact_depth_m', 0.0) for r in rows),
        }
        for clock in ('cycle_s', 'cycle_cpu_s'):
            timed = [r[clock] for r in rows if r.get(clock)]
            prefix = clock.removesuffix('_s')
            table[key][f'{prefix}_p99_s'] = max((t['p99'] for t in timed), default=None)
            table[key][f'{prefix}_max_s'] = max((t['max'] for t in timed), default=None)
    return table
