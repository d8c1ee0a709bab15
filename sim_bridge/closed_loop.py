"""A resolver and a base controller closed on a :class:`SimWorld`, with no ROS in between.

Each period runs what the nodes run in lockstep, in the same order (the phases of
:class:`wmm_control.cycle.Cycle`, Sorour Fig 4):

1. read the state (joint states, odometry or ground-truth base pose, end-effector pose);
2. ``plan``: ``resolver.step(state, target)``, the arm command and the base twist reference;
3. ``base``: the base controller (:func:`wmm_control.base.make_base_controller`) answers that
   reference at once, closed on the measured joints, with rates per command group and the
   feasible twist q̇_bf;
4. ``finish``: ``resolver.compensate(command, q̇_bf)`` (Sorour eq 14) finishes the arm command;
5. each group's rates go to the world (``world.set_command(group, rates)``), and the world
   steps one period.

Use it for fast experiments and tests. The ROS nodes do the same over topics;
:func:`wmm_control.experiments.direct.run_scenario` plays a whole scenario on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from wmm_control.base import BaseController, make_base_controller
from wmm_control.cycle import Cycle
from wmm_control.errors import ConfigError
from wmm_control.geometry import matrix_from_quaternion
from wmm_control.resolvers import PoseTarget, Resolver, ResolverCommand, RobotState

if TYPE_CHECKING:
    from sim_bridge.world import SimWorld

__all__ = ['ClosedLoop', 'CycleRecord', 'FEEDBACKS']

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
    command: ResolverCommand
    feasible_twist: np.ndarray
    base_velocity: np.ndarray


class ClosedLoop:
    """Run ``resolver`` and the robot's base controller on ``world``: a
    :class:`~wmm_control.cycle.Cycle` (``cycle``) and the world's input and output.

    Args:
        world: a :class:`~sim_bridge.world.SimWorld`.
        resolver: a :class:`~wmm_control.resolvers.Resolver` for the same robot.
        feedback: ``'ground_truth'`` (true base pose and end effector, as the paper's
            simulator) or ``'odometry'`` (wheel odometry and forward kinematics, what a robot
            without external sensing has).
        base_controller: a :class:`~wmm_control.base.BaseController`; default
            :func:`~wmm_control.base.make_base_controller`. It starts from the world's joints.
    """

    def __init__(
        self,
        world: SimWorld,
        resolver: Resolver,
        feedback: str = 'ground_truth',
        base_controller: BaseController | None = None,
    ) -> None:
        if feedback not in FEEDBACKS:
            raise ConfigError(f'feedback must be one of {FEEDBACKS}, got {feedback!r}')
        self.world = world
        self.resolver = resolver
        self.feedback = feedback
        self.robot = world.robot
        self.base = base_controller if base_controller is not None else make_base_controller(self.robot, world.dt)
        self.cycle = Cycle(resolver, self.base)
        index = {n: i for i, n in enumerate(world.joint_names)}
        self._arm = [index[n] for n in self.robot.arm.joints]
        self._groups = {g: [index[n] for n in names] for g, names in self.base.command_groups.items()}
        _, q, _ = world.joint_state()
        self.base.reset(self._positions(q))

    def _positions(self, q):
        """The positions of each base command group in ``q`` (``world.joint_names`` order)."""
        return {g: q[idx] for g, idx in self._groups.items()}

    def state(self) -> RobotState:
        """The :class:`RobotState` the resolver sees now."""
        w = self.world
        _, q, qd = w.joint_state()
        if self.feedback == 'ground_truth':
            pos, quat = w.ee_pose()
            return RobotState(
                w.base_pose(),
                w.base_twist(),
                q[self._arm],
                qd[self._arm],
                ee_position=pos,
                ee_rotation=matrix_from_quaternion(quat),
            )
        return RobotState(w.odom_pose(), w.odom_twist(), q[self._arm], qd[self._arm])

    def step(self, target: PoseTarget) -> CycleRecord:
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
        result = self.cycle.step(state, target, self._positions(q_all))
        for group, rates in result.base.rates.items():
            w.set_command(group, rates)
        w.set_command('arm', result.command.arm_velocity)
        w.step()
        return CycleRecord(
            t=t,
            base_pose=pose,
            q_arm=state.q_arm,
            q=q_all.copy(),
            ee_position=ee_pos,
            ee_rotation=matrix_from_quaternion(ee_quat),
            command=result.command,
            feasible_twist=np.asarray(result.base.feasible_twist, dtype=float),
            base_velocity=w.base_twist(),
        )
