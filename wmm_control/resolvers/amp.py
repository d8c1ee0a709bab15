"""Adaptive motion planning (AMP), Xing et al. §3: the base stays still until the arm cannot.

Each period (on top of :mod:`~wmm_control.resolvers.acceleration_level`):

1. With the base out of the active set, SNS (eq 9, :func:`~wmm_control.resolvers.sns.sns_accelerations`)
   shares the task among the arm joints, saturating the most violating one at a time. The
   base's accelerations are then those of its stop, eq (15): full braking at its
   acceleration limits until it is at rest (within |V_b|/A + one period).
2. The base is activated when the arm alone cannot do the task (SNS needs α < 1, or
   rank(J S) < r) or when the arm nears a singularity, σ_min(J_m) < σ_m,min (J_m over the
   task's rows: the position rows for r = 3, all six for r = 6). With the base active, SNS
   runs again over all ten coordinates, and the task is scaled by α ≤ 1 when even that is
   infeasible.
3. The tertiary objective, eqs (10)–(13): the manipulability gradient projected by P_A,
   scaled by β ≤ 1 to keep the bounds.

Following a plan (a :class:`~wmm_control.resolvers.interface.BaseReference` on the target; not
in the paper, and nothing changes without one): the plan has already decided that the base
moves, so while the base is out of the task its accelerations are those that track the planned
base pose (``task['base_follow']``, eq (23)'s law on the base, within its bounds) instead of
eq (15)'s stop, and the arm does the end effector's task around that motion, as it does around
the stop. With the base in the task (step 2) the same accelerations join the tertiary
objective, projected by P_A: what the task leaves free brings the base back onto the plan.
On the plan's way (not at the stance of its final approach) the singularity test of step 2
does not activate the base: the arm nears a singularity there because the base lags the plan,
and the base stays on the plan until the arm alone cannot do the task (α < 1). The plan's arm
posture (the travel posture, then the stance's) joins the tertiary objective as the traditional
planner's does (eq 23's law on the arm's joints, ``task['arm_follow']``, within the bounds and
less the arm's share of the task's solution), projected by P_A with the manipulability
gradient: the arm stays near the posture the path was checked with while the base lags, instead
of drifting towards higher manipulability until the end effector's points drew the base off the
plan (robot A in `doorway`: ten of 100 runs out of time on the way, ``docs/randomized.md``).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wmm_control.errors import ConfigError
from wmm_control.resolvers.acceleration_level import AccelerationParams, AccelerationResolver
from wmm_control.resolvers.sns import sns_accelerations
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import RobotConfig

__all__ = ['AmpParams', 'AmpResolver']


@dataclass(frozen=True)
class AmpParams(AccelerationParams):
    """Parameters of :class:`AmpResolver` (Xing §4 defaults).

    Attributes:
        sigma_min: σ_m,min, the singularity threshold that activates the base [-] (0.15 for
            r = 3; §4.4 uses 0.19 for r = 6).
        singularity_avoidance: activate the base near a singularity (§3.2); off reproduces
            the "AMP without singularity avoidance" run of §4.2.
        sigma_rows: rows of J_m for σ_m: ``'position'`` (always the three position rows, the
            default) or ``'task'`` (the task's rows: all six for r = 6). On robot B at its start
            state σ_m over all six rows is 0.162, below §4.4's 0.19 and near 0.15, so with
            ``'task'`` the base is active from t = 0 in the full-pose run and moves for a goal
            the arm alone reaches; over the position rows it is 0.245 (docs/results.md, "Full pose").
            For r = 3 both are the position rows.
        sigma_lookahead: anticipation τ [s]: the singularity test uses σ_m + τ·min(σ̇_m, 0), σ̇_m
            from the last period, so the base is switched on τ before σ_m would reach σ_m,min at
            its current rate (§3.2 switches the base on when the trajectory's current segment
            takes the arm towards a singularity). 0 tests σ_m < σ_m,min alone, as Fig 3 draws
            it. The base takes seconds to take over (its
            acceleration limit is 0.025 m/s², Table 1): with τ = 0 σ_m keeps falling for about
            2.5 s after the activation, to 0.74 σ_m,min on the R = 0.25 m circle; τ = 0.5 s keeps
            it above 0.9 σ_m,min.
    """

    sigma_min: float = 0.15
    singularity_avoidance: bool = True
    sigma_rows: str = 'position'
    sigma_lookahead: float = 0.5

    _allow_zero = AccelerationParams._allow_zero + ('sigma_lookahead',)

    def __post_init__(self):
        super().__post_init__()
        if self.sigma_rows not in ('task', 'position'):
            raise ConfigError(f"sigma_rows must be 'task' or 'position', got {self.sigma_rows!r}")


class AmpResolver(AccelerationResolver):
    """Xing et al.'s adaptive motion planner at acceleration level (eqs 6–15, 23).

    Args:
        robot: robot name, YAML path, RobotConfig or KinematicModel.
        params: :class:`AmpParams`.
    """

    name = 'amp'

    def __init__(self, robot: str | Path | RobotConfig | KinematicModel, params: AmpParams | None = None) -> None:
        super().__init__(robot, params if params is not None else AmpParams())

    def reset(self) -> None:
        super().reset()
        self._last_sigma = None  # σ_m of the last period, for the anticipation of the test

    def _anticipated_sigma(self, sigma):
        """σ_m + τ·min(σ̇_m, 0): where σ_m is heading, τ ahead (``sigma_lookahead``)."""
        last, self._last_sigma = self._last_sigma, sigma
        if last is None:
            return sigma
        return sigma + self.params.sigma_lookahead * min(sigma - last, 0.0) / self.params.dt

    def _base_out_of_task(self, task):
        """The base's accelerations while it is out of the task: eq (15)'s full braking to
        rest, or a followed plan's tracking (module docstring), within its bounds."""
        qd, lo, hi = task['qd'], task['lower'], task['upper']
        held = np.zeros(len(qd))
        nb = self.n_base
        wanted = -qd[:nb] / self.params.dt if task['base_follow'] is None else task['base_follow']
        held[:nb] = np.clip(wanted, lo[:nb], hi[:nb])
        return held

    def _accelerations(self, task):
        p = self.params
        n = len(task['qd'])
        arm_only = np.ones(n, dtype=bool)
        arm_only[: self.n_base] = False
        sigma = self._anticipated_sigma(task['sigma_position'] if p.sigma_rows == 'position' else task['sigma'])
        # on a plan's way the base joins the task only when the arm alone cannot do it (module docstring)
        singular = p.singularity_avoidance and sigma < p.sigma_min and not task['on_the_way']
        reason = 'singularity' if singular else ''
        if not singular:
            sns = sns_accelerations(
                task['jac'],
                task['xdd'],
                task['drift'],
                task['lower'],
                task['upper'],
                arm_only,
                self._base_out_of_task(task),
                p.rcond,
            )
            if sns.alpha < 1.0:
                reason = 'arm out of reach'
        if reason:
            sns = sns_accelerations(
                task['jac'],
                task['xdd'],
                task['drift'],
                task['lower'],
                task['upper'],
                np.ones(n, dtype=bool),
                np.zeros(n),
                p.rcond,
            )
        qdd, alpha, active, saturated = sns.qdd, sns.alpha, sns.active, sns.saturated
        beta = 1.0
        base_on = bool(np.any(active[: self.n_base]))
        follow = task['base_follow'] is not None and base_on
        if (p.manipulability or follow) and sns.pinv is not None:
            q_t, beta = self._tertiary(task, qdd, active, sns.pinv, follow)
            qdd = qdd + q_t
        if base_on:
            mode = f'base active ({reason})'
        elif task['base_follow'] is not None:
            mode = 'base on the plan'
        else:
            mode = 'base stopping' if np.any(task['qd'][: self.n_base]) else 'arm only'

        return qdd, {
            'mode': mode,
            'psi': 0.0 if base_on else 1.0,
            'limit_scale': alpha,
            'accel_scale': 1.0,
            'null_scale': beta,
            'limited': tuple(int(i) for i in np.flatnonzero(saturated)),
        }
