"""What a run is judged by: its log, and the per-goal metrics of the experiments.

A :class:`RunLog` holds one row per control period, recorded from the ground truth (the
end-effector pose and the base pose the simulator reports) and from the commands. Both the
ROS-free :class:`~sim_bridge.closed_loop.ClosedLoop` and the ROS experiment runner fill it.
:func:`goal_metrics` turns it into the numbers of Sorour Figs 5–7 (``metrics.json``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import rotation_angle, rotation_error, rpy_from_matrix, twist_to_world, wrap_angle

if TYPE_CHECKING:
    from wmm_control.experiments.scenario import Scenario
    from wmm_control.kinematics import KinematicModel
    from wmm_control.resolvers.interface import ResolverDiagnostics
    from wmm_control.robot_config import RobotConfig

__all__ = [
    'RunLog',
    'goal_metrics',
    'trajectory_metrics',
    'run_limit_report',
    'pose_error_norm',
    'METRIC_KEYS',
    'TRAJECTORY_METRIC_KEYS',
]

#: Per-goal keys of :func:`goal_metrics` and what they mean (documented in docs/results.md).
METRIC_KEYS = {
    'area': 'area under the pose-error norm ‖e_p‖ (eq 12, position [m] and wrapped RPY [rad]) '
    'over the goal window [m·s] (the numbers of Sorour Fig 6)',
    'final_position_error_m': 'position error at the end of the window, ground truth [m]',
    'final_orientation_error_rad': 'rotation angle between the final and the goal orientation [rad]',
    'reached': 'final errors below 1 cm and 0.02 rad',
    'time_to_rfm_s': 'time from the goal start until the position error first enters r_fm [s] '
    '(0 when it starts inside; null when it never does)',
    'base_path_m': 'length of the base path in the window [m]',
    'base_path_fine_m': 'length of the base path while ψ = 1 (fine manipulation) [m]',
    'footprint_m': 'largest horizontal distance of any arm joint or the end effector from the base centre [m]',
    'max_switch_jump_rad_s': 'largest change of an arm joint velocity command at a mode switch [rad/s] '
    '(null when the mode never switches)',
    'max_switch_jump_base': 'largest change of a base twist reference component at a mode switch [m/s or rad/s]',
    'psi_min': 'smallest ψ in the window',
    'psi_max': 'largest ψ in the window',
    'dex_deviation_psi0_rad': 'while ψ = 0: largest |q_a − q_a,dex| (any joint) once the arm has come '
    'within 0.05 rad of q_a,dex [rad] (null: no such phase)',
    'dex_deviation_psi0_start_rad': 'largest |q_a − q_a,dex| at the start of the ψ = 0 phases [rad]',
    'compensation_dropped': 'periods whose arm command went out without the eq (14) term '
    '(the base controller did not answer in time)',
}


class RunLog:
    """One row per control period of a run (append, then :meth:`freeze`).

    Columns (after :meth:`freeze`, numpy arrays of K rows): ``t`` [s], ``goal`` (index),
    ``ee_position`` (K, 3), ``ee_rotation`` (K, 3, 3), ``base_pose`` (K, 3), ``q_arm`` (K, 7),
    ``arm_command`` (K, 7), ``base_reference`` (K, 3), ``feasible_twist`` (K, 3), ``psi``,
    ``mode`` (list of str), ``limit_scale``, ``accel_scale``, ``null_scale``,
    ``compensation_scale``, ``compensated`` (bool), ``cycle_time_s``, ``sigma_min``,
    ``clearance`` [m] (the safety stage's closest pair), ``collision_changed`` (bool: the
    stage changed the command), ``cycle_s`` and ``cycle_cpu_s`` (the whole control cycle's
    wall and thread CPU time [s], :class:`~sim_bridge.closed_loop.CycleRecord`; NaN where the
    engine does not time it) and ``q`` (K, J): every joint of ``joint_names`` (the
    simulator's joints, the arm's first; NaN rows where a period's were not recorded).
    """

    COLUMNS = (
        't',
        'goal',
        'ee_position',
        'ee_rotation',
        'base_pose',
        'q_arm',
        'arm_command',
        'base_reference',
        'feasible_twist',
        'psi',
        'mode',
        'limit_scale',
        'accel_scale',
        'null_scale',
        'compensation_scale',
        'compensated',
        'cycle_time_s',
        'sigma_min',
        'clearance',
        'collision_changed',
        'cycle_s',
        'cycle_cpu_s',
        'q',
    )

    def __init__(self, method: str = '', label: str = '', joint_names: Iterable[str] = ()) -> None:
        self.method = method
        self.label = label
        self.joint_names = tuple(joint_names)
        self.rows: dict[str, Any] = {c: [] for c in self.COLUMNS}
        self.wall_time_s = 0.0
        self.sim_counters: dict | None = None  # the simulator's command counters per group (clamped, rejected, ...)
        # the resolver's safety-stage counts (SafetyCounts.values(): cycles each limit bound, ...)
        self.safety_counts: dict | None = None
        self.final_status: dict | None = None  # nodes engine: the goal's state after the resolver's last cycle
        self.first_stall_s: float | None = None  # nodes engine: when the resolver first found the goal stalled [s]
        self.planning: dict | None = None  # nodes engine with goal_planner: GoalPursuit.account()
        self.refused = ''  # direct engine: why the last target refused was (the robot held still then)
        self.frozen = False

    def append(
        self,
        t: float,
        goal: int,
        ee_position: ArrayLike,
        ee_rotation: ArrayLike,
        base_pose: ArrayLike,
        q_arm: ArrayLike,
        arm_command: ArrayLike,
        base_reference: ArrayLike,
        feasible_twist: ArrayLike | None,
        diagnostics: ResolverDiagnostics,
        q: ArrayLike | None = None,
        cycle_s: float = float('nan'),
        cycle_cpu_s: float = float('nan'),
    ) -> None:
        """Add one period: the state at its start, the commands sent, and the resolver's
        :class:`~wmm_control.resolvers.ResolverDiagnostics`. ``feasible_twist`` may be None;
        ``q`` (every joint of ``joint_names``) too; ``cycle_s``, ``cycle_cpu_s``: the control
        cycle's wall and thread CPU time [s], NaN when not timed."""
        d = diagnostics
        r = self.rows
        r['t'].append(float(t))
        r['goal'].append(int(goal))
        r['ee_position'].append(np.asarray(ee_position, dtype=float))
        r['ee_rotation'].append(np.asarray(ee_rotation, dtype=float))
        r['base_pose'].append(np.asarray(base_pose, dtype=float))
        r['q_arm'].append(np.asarray(q_arm, dtype=float))
        r['arm_command'].append(np.asarray(arm_command, dtype=float))
        r['base_reference'].append(np.asarray(base_reference, dtype=float))
        r['feasible_twist'].append(
            np.asarray(feasible_twist if feasible_twist is not None else np.full(3, np.nan), dtype=float)
        )
        r['psi'].append(d.psi)
        r['mode'].append(d.mode)
        r['limit_scale'].append(d.limit_scale)
        r['accel_scale'].append(d.accel_scale)
        r['null_scale'].append(d.null_scale)
        r['compensation_scale'].append(d.compensation_scale)
        r['compensated'].append(d.compensated)
        r['cycle_time_s'].append(d.cycle_time_s)
        r['sigma_min'].append(d.sigma_min)
        r['clearance'].append(d.clearance)
        r['collision_changed'].append(d.collision_changed)
        r['cycle_s'].append(float(cycle_s))
        r['cycle_cpu_s'].append(float(cycle_cpu_s))
        r['q'].append(np.full(len(self.joint_names), np.nan) if q is None else np.asarray(q, dtype=float))

    def freeze(self) -> Self:
        """Turn the columns into arrays; returns self."""
        if not self.frozen:
            for c in self.COLUMNS:
                if c != 'mode':
                    self.rows[c] = np.array(self.rows[c])
            self.frozen = True
        return self

    def __getattr__(self, name):
        rows = self.__dict__.get('rows')
        if rows is not None and name in rows:
            return rows[name]
        raise AttributeError(name)

    def __len__(self):
        return len(self.rows['t'])


def pose_error_norm(goal_pose: ArrayLike, ee_position: np.ndarray, ee_rotation: np.ndarray) -> np.ndarray:
    """‖e_p‖ of Sorour eq (12): position error and wrapped RPY difference, per row. Shape (K,)."""
    goal_pose = np.asarray(goal_pose, dtype=float)
    pos = goal_pose[:3] - ee_position
    rpy = np.array([rpy_from_matrix(r) for r in ee_rotation])
    ang = wrap_angle(goal_pose[3:] - rpy)
    return np.sqrt(np.sum(pos * pos, axis=1) + np.sum(ang * ang, axis=1))


def _rotation_angle(r_goal, rot):
    return rotation_angle(r_goal, rot)


def goal_metrics(
    log: RunLog, scenario: Scenario, model: KinematicModel, r_fm: float, q_dex: ArrayLike, dt: float
) -> list[dict]:
    """The per-goal metrics (:data:`METRIC_KEYS`) of a frozen :class:`RunLog`.

    Args:
        log: the run.
        scenario: its :class:`~wmm_control.experiments.scenario.Scenario`.
        model: a :class:`~wmm_control.kinematics.KinematicModel` of the robot (footprint).
        r_fm: fine manipulation range [m].
        q_dex: dexterous arm posture [rad or m]. Shape (n,).
        dt: control period [s].

    Returns:
        A list of dicts, one per goal.
    """
    log.freeze()
    out = []
    q_dex = np.asarray(q_dex, dtype=float)
    for gi, goal in enumerate(scenario.goals):
        idx = np.flatnonzero(log.goal == gi)
        if idx.size == 0:
            out.append({'goal': gi + 1, 'start_s': goal.t, 'end_s': goal.end, 'cycles': 0})
            continue
        target = goal.target
        pos_err = np.linalg.norm(target.position - log.ee_position[idx], axis=1)
        err = pose_error_norm(goal.pose, log.ee_position[idx], log.ee_rotation[idx])
        last = idx[-1]
        final_pos = float(pos_err[-1])
        final_ori = _rotation_angle(target.rotation, log.ee_rotation[last])
        inside = np.flatnonzero(pos_err <= r_fm)
        base_xy = log.base_pose[idx, :2]
        steps = np.linalg.norm(np.diff(base_xy, axis=0), axis=1)
        fine = log.psi[idx][1:] >= 1.0
        footprint = 0.0
        for k in idx:
            model.update(log.base_pose[k], log.q_arm[k])
            pts = model.arm_points_world()[:, :2] - log.base_pose[k, :2]
            footprint = max(footprint, float(np.max(np.linalg.norm(pts, axis=1))))
        modes = [log.mode[k] for k in idx]
        switches = [j for j in range(1, len(idx)) if modes[j] != modes[j - 1]]
        arm_jump = [float(np.max(np.abs(log.arm_command[idx[j]] - log.arm_command[idx[j - 1]]))) for j in switches]
        base_jump = [
            float(np.max(np.abs(log.base_reference[idx[j]] - log.base_reference[idx[j - 1]]))) for j in switches
        ]
        dev_after, dev_start = _dex_deviation(log, idx, q_dex)
        out.append(
            {
                'goal': gi + 1,
                'start_s': goal.t,
                'end_s': goal.end,
                'cycles': int(idx.size),
                'area': float(np.sum(err) * dt),
                'final_position_error_m': final_pos,
                'final_orientation_error_rad': final_ori,
                'reached': bool(final_pos < 0.01 and final_ori < 0.02),
                'time_to_rfm_s': max(0.0, float(log.t[idx[inside[0]]] - goal.t)) if inside.size else None,
                'base_path_m': float(np.sum(steps)),
                'base_path_fine_m': float(np.sum(steps[fine])),
                'footprint_m': footprint,
                'max_switch_jump_rad_s': max(arm_jump) if arm_jump else None,
                'max_switch_jump_base': max(base_jump) if base_jump else None,
                'psi_min': float(np.min(log.psi[idx])),
                'psi_max': float(np.max(log.psi[idx])),
                'dex_deviation_psi0_rad': dev_after,
                'dex_deviation_psi0_start_rad': dev_start,
                'compensation_dropped': int(np.count_nonzero(~log.compensated[idx])),
            }
        )
    return out


def _dex_deviation(log, idx, q_dex):
    """(largest deviation from q_dex once within 0.05 rad, largest deviation at a phase start) over ψ = 0."""
    dev = np.max(np.abs(log.q_arm[idx] - q_dex), axis=1)
    psi0 = log.psi[idx] == 0.0
    if not np.any(psi0):
        return None, None
    after, starts = [], []
    phase_started = False
    settled = False
    for j in range(idx.size):
        if not psi0[j]:
            phase_started = settled = False
            continue
        if not phase_started:
            starts.append(float(dev[j]))
            phase_started = True
        if dev[j] <= 0.05:
            settled = True
        if settled:
            after.append(float(dev[j]))
    return (max(after) if after else None), max(starts)


#: Keys of :func:`trajectory_metrics` (Xing et al. Tables 2–3), documented in docs/results.md.
TRAJECTORY_METRIC_KEYS = {
    'base_rms': 'RMS of the commanded base velocity (vx, vy [m/s], ω [rad/s]) over the run',
    'base_active_s': 'time during which each commanded base velocity component is not zero [s]',
    'base_active_any_s': 'time during which any commanded base velocity component is not zero [s]',
    'max_error_x_m': 'largest |x error| of the end effector against the reference, ground truth [m]',
    'max_error_y_m': 'largest |y error| [m]',
    'max_error_xy_m': 'largest distance in the x-y plane [m]',
    'max_error_m': 'largest 3-D position error [m]',
    'max_rotation_error_y_rad': 'largest |rotation error about the world y axis| [rad]',
    'max_orientation_error_rad': 'largest rotation angle between the orientation and the reference [rad]',
    'sigma_min_min': 'smallest σ_min of the arm Jacobian (the task rows) over the run',
    'first_base_activation_s': 'time of the first non-zero base command [s] (null: never)',
    'joint_limit_margin_rad': 'smallest distance of an arm joint to a position limit over the run [rad] '
    '(joints without limits left out)',
    'base_integral_error_m': "Xing's integral of the base's kinematic error, |x| and |y| [m]: the mean, "
    'over the time the base is commanded (first to last non-zero command), of the '
    'distance between the path its commands describe and its true path (null: the '
    'base never moved)',
}


def trajectory_metrics(log: RunLog, scenario: Scenario, model: KinematicModel, dt: float, skip_s: float = 1.0) -> dict:
    """Xing et al. Tables 2–3 for a run of a trajectory scenario (:data:`TRAJECTORY_METRIC_KEYS`).

    The reference starts from the end effector's pose at the robot's start state, as the
    goal_sequencer plays it. Errors are taken after ``skip_s`` seconds (the start transient).
    """
    log.freeze()
    reference = scenario.reference(model)
    targets = [reference(t) for t in log.t]
    pos_err = np.array([tg.position for tg in targets]) - log.ee_position
    rot_err = rotation_error([tg.rotation for tg in targets], log.ee_rotation)
    late = log.t >= log.t[0] + skip_s
    base = log.base_reference
    moving = np.abs(base) > 1e-9
    any_moving = np.any(moving, axis=1)
    return {
        'base_rms': np.sqrt(np.mean(base * base, axis=0)).tolist(),
        'base_active_s': (np.count_nonzero(moving, axis=0) * dt).tolist(),
        'base_active_any_s': float(np.count_nonzero(any_moving) * dt),
        'max_error_x_m': float(np.max(np.abs(pos_err[late, 0]))),
        'max_error_y_m': float(np.max(np.abs(pos_err[late, 1]))),
        'max_error_xy_m': float(np.max(np.linalg.norm(pos_err[late, :2], axis=1))),
        'max_error_m': float(np.max(np.linalg.norm(pos_err[late], axis=1))),
        'max_rotation_error_y_rad': float(np.max(np.abs(rot_err[late, 1]))),
        'max_orientation_error_rad': float(np.max(np.linalg.norm(rot_err[late], axis=1))),
        'sigma_min_min': float(np.min(log.sigma_min)),
        'first_base_activation_s': float(log.t[np.argmax(any_moving)]) if np.any(any_moving) else None,
        'joint_limit_margin_rad': _joint_limit_margin(log.q_arm, model.config.arm),
        'base_integral_error_m': _base_integral_error(log, any_moving, dt),
    }


def _base_integral_error(log, moving, dt):
    """Mean |commanded path − true path| (x, y) over the commanded window, the commands integrated
    from the true pose at its start (Xing §4.3's integral base error)."""
    idx = np.flatnonzero(moving)
    if idx.size == 0:
        return None
    first, last = idx[0], idx[-1] + 1
    pose = log.base_pose[first].astype(float).copy()
    errors = []
    for k in range(first, min(last, len(log.t) - 1)):
        vx, vy, w = log.base_reference[k]
        pose = pose + dt * twist_to_world(pose[2], (vx, vy, w))
        errors.append(np.abs(pose[:2] - log.base_pose[k + 1, :2]))
    return np.mean(errors, axis=0).tolist() if errors else None


def _joint_limit_margin(q, arm):
    margin = np.minimum(q - arm.position_lower, arm.position_upper - q)
    finite = np.isfinite(margin)
    return float(np.min(margin[finite])) if np.any(finite) else None


def run_limit_report(log: RunLog, robot: RobotConfig, dt: float, tol: float = 1e-9) -> dict:
    """Largest excess over every limit in a run (all zero when no limit was ever passed).

    The run starts at rest: the first command's change is measured from zero.

    Returns:
        dict: ``arm_position``, ``arm_velocity``, ``arm_acceleration``, ``base_velocity``,
        ``base_acceleration`` (largest excess, 0 when within) and ``non_finite`` (count).
    """
    log.freeze()
    arm = robot.arm
    q = log.q_arm
    pos = float(max(0.0, np.max(q - arm.position_upper), np.max(arm.position_lower - q)))
    vel = float(max(0.0, np.max(np.abs(log.arm_command) - arm.velocity)))
    acc = float(max(0.0, np.max(np.abs(np.diff(log.arm_command, axis=0, prepend=0.0)) - arm.acceleration * dt)))
    bvel = float(max(0.0, np.max(np.abs(log.base_reference) - robot.base.velocity)))
    bacc = float(
        max(0.0, np.max(np.abs(np.diff(log.base_reference, axis=0, prepend=0.0)) - robot.base.acceleration * dt))
    )
    bad = int(np.count_nonzero(~np.isfinite(log.arm_command)) + np.count_nonzero(~np.isfinite(log.base_reference)))
    return {
        'arm_position': pos if pos > tol else 0.0,
        'arm_velocity': vel if vel > tol else 0.0,
        'arm_acceleration': acc if acc > tol else 0.0,
        'base_velocity': bvel if bvel > tol else 0.0,
        'base_acceleration': bacc if bacc > tol else 0.0,
        'non_finite': bad,
    }
