"""A resolver and a base controller closed on a :class:`SimWorld`, with no ROS in between.

Each period runs what the nodes run in lockstep, in the same order:

1. read the state (joint states, odometry or ground-truth base pose, end-effector pose);
2. ``resolver.step(state, target)``: the arm command and the base twist reference;
3. the base controller answers that reference at once (robot A: :class:`SwmrController`,
   closed on the measured steer angles; robot B: :class:`WheelController`), giving wheel
   commands and the feasible twist q̇_bf;
4. ``resolver.compensate(command, q̇_bf)`` (Sorour eq 14) finishes the arm command;
5. the world steps one period.

Use it for fast experiments and tests. The ROS nodes do the same over topics.
"""

from dataclasses import dataclass

import numpy as np

from wmm_control.base import WheelController, SteerableGeometry, SwmrController, SwmrParams
from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.orientation import matrix_from_quaternion
from wmm_control.resolvers import RobotState

__all__ = ['ClosedLoop', 'CycleRecord', 'FEEDBACKS', 'make_base_controller']

FEEDBACKS = ('ground_truth', 'odometry')


@dataclass(frozen=True)
class CycleRecord:
    """One period of a closed-loop run (all world frame unless said otherwise).

    Attributes:
        t: simulated time at the start of the period [s].
        base_pose: true base pose (x, y, θ). Shape (3,).
        q_arm: arm joint positions [rad or m]. Shape (n,).
        q: every simulated joint's position (``world.joint_names``) [rad or m]. Shape (J,).
        ee_position: true end-effector position [m]. Shape (3,).
        ee_rotation: true end-effector orientation. Shape (3, 3).
        command: the resolver's final command (``ResolverCommand``).
        feasible_twist: the base controller's answer q̇_bf (base frame). Shape (3,).
        base_velocity: the base twist actually executed in the period (base frame). Shape (3,).
    """

    t: float
    base_pose: np.ndarray
    q_arm: np.ndarray
    q: np.ndarray
    ee_position: np.ndarray
    ee_rotation: np.ndarray
    command: object
    feasible_twist: np.ndarray
    base_velocity: np.ndarray


def make_base_controller(robot, dt):
    """The base controller of a robot: a :class:`SwmrController` (A) or a :class:`WheelController` (B)."""
    if robot.steerable is not None:
        return SwmrController(SteerableGeometry.from_config(robot.steerable),
                              SwmrParams.from_robot_config(robot, dt=dt))
    return WheelController.from_robot_config(robot, dt)


class ClosedLoop:
    """Run ``resolver`` and the robot's base controller on ``world``.

    Args:
        world: a :class:`~sim_bridge.world.SimWorld`.
        resolver: a :class:`~wmm_control.resolvers.Resolver` for the same robot.
        feedback: ``'ground_truth'`` (true base pose and end effector, as the paper's
            simulator) or ``'odometry'`` (wheel odometry and forward kinematics, what a robot
            without external sensing has).
        base_controller: default :func:`make_base_controller`.
    """

    def __init__(self, world, resolver, feedback='ground_truth', base_controller=None):
        if feedback not in FEEDBACKS:
            raise ConfigError(f'feedback must be one of {FEEDBACKS}, got {feedback!r}')
        self.world = world
        self.resolver = resolver
        self.feedback = feedback
        self.robot = world.robot
        self.base = base_controller if base_controller is not None else make_base_controller(self.robot, world.dt)
        names = world.joint_names
        index = {n: i for i, n in enumerate(names)}
        self._arm = [index[n] for n in self.robot.arm.joints]
        if self.robot.steerable is not None:
            self._steer = [index[n] for n in self.robot.steerable.steer_joints]
            _, q, _ = world.joint_state()
            self.base.reset(q[self._steer])

    def state(self):
        """The :class:`RobotState` the resolver sees now."""
        w = self.world
        _, q, qd = w.joint_state()
        if self.feedback == 'ground_truth':
            pos, quat = w.ee_pose()
            return RobotState(w.base_pose(), w.base_twist(), q[self._arm], qd[self._arm],
                              ee_position=pos, ee_rotation=matrix_from_quaternion(quat))
        return RobotState(w.odom_pose(), w.odom_twist(), q[self._arm], qd[self._arm])

    def _base_answer(self, reference):
        """Wheel commands for ``reference`` and the feasible twist q̇_bf."""
        w = self.world
        if self.robot.steerable is not None:
            _, q, _ = w.joint_state()
            out = self.base.step(reference, beta_meas=q[self._steer])
            w.set_command('steer', out.beta_dot_ref)
            w.set_command('drive', out.phi_dot_ref)
            return out.twist_executed
        out = self.base.step(reference)
        w.set_command('wheel', out.wheel_rates)
        return out.twist

    def step(self, target):
        """One period towards ``target`` (:class:`~wmm_control.resolvers.PoseTarget`).

        Returns:
            :class:`CycleRecord` of the period.
        """
        w = self.world
        t = w.time
        pose = w.base_pose()
        ee_pos, ee_quat = w.ee_pose()
        _, q_all, _ = w.joint_state()
        state = self.state()
        command = self.resolver.step(state, target)
        feasible = self._base_answer(command.base_twist)
        command = self.resolver.compensate(command, feasible)
        w.set_command('arm', command.arm_velocity)
        w.step()
        return CycleRecord(t=t, base_pose=pose, q_arm=state.q_arm, q=q_all.copy(), ee_position=ee_pos,
                           ee_rotation=matrix_from_quaternion(ee_quat), command=command,
                           feasible_twist=np.asarray(feasible, dtype=float), base_velocity=w.base_twist())


def run_scenario(world, resolver, scenario, feedback='ground_truth', label='', progress=None, until=None):
    """Run a whole scenario (goals or a trajectory) on ``world`` with no ROS in between.

    Args:
        world: a fresh :class:`~sim_bridge.world.SimWorld` of the scenario's robot.
        resolver: the method under test.
        scenario: a :class:`~wmm_control.experiments.scenario.Scenario`.
        feedback: see :class:`ClosedLoop`.
        label: name of the run in the log.
        progress: optional callable ``progress(n_periods)`` called after each period.
        until: optional callable ``until(diagnostics)``, given each period's
            :class:`~wmm_control.resolvers.ResolverDiagnostics`: the run ends early when it
            returns True.

    Returns:
        The frozen :class:`~wmm_control.experiments.metrics.RunLog`.
    """
    import time
    from wmm_control.experiments.metrics import RunLog

    # the scenario's obstacles, in the world and in the controller's collision model
    world.set_obstacles(scenario.obstacles)
    resolver.set_obstacles(scenario.obstacles)
    loop = ClosedLoop(world, resolver, feedback=feedback)
    log = RunLog(method=resolver.name, label=label, joint_names=world.joint_names)
    reference = scenario.reference(KinematicModel(world.robot)) if scenario.trajectory is not None else None
    n = int(round(scenario.duration / world.dt))
    t0 = time.perf_counter()
    for _ in range(n):
        gi = scenario.goal_index(world.time)
        rec = loop.step(scenario.target(world.time, reference))
        cmd = rec.command
        log.append(rec.t, gi, rec.ee_position, rec.ee_rotation, rec.base_pose, rec.q_arm, cmd.arm_velocity,
                   cmd.base_twist, rec.feasible_twist, cmd.diagnostics, q=rec.q)
        if progress is not None:
            progress(1)
        if until is not None and until(cmd.diagnostics):
            break
    log.wall_time_s = time.perf_counter() - t0
    log.sim_counters = {g: dict(c) for g, c in world.counters.items()}
    return log.freeze()
