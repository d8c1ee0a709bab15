"""A resolver and a base controller closed on a :class:`SimWorld`, with no ROS in between.

Each period runs what the nodes run in lockstep, in the same order and with the same code
(:class:`wmm_control.cycle.Cycle`, Sorour Fig 4):

1. the inputs as the nodes receive them: the odometry (or the ground-truth base pose), the
   end effector's pose, the target, each checked as it comes, and the joint state (what the
   nodes would not answer is not sent: the world steps under the commands in force, as the
   simulator does when no command answers a state);
2. ``plan``: the resolver's arm command and base twist reference, or the robot held;
3. ``base``: the base controller (:func:`wmm_control.base.make_base_controller`) answers that
   reference at once, closed on the measured joints, with rates per command group and the
   feasible twist q̇_bf;
4. ``finish``: the arm command compensated for q̇_bf (Sorour eq 14);
5. each group's rates go to the world (``world.set_command(group, rates)``), and the world
   steps one period.

Use it for fast experiments and tests. The ROS nodes do the same over topics;
:func:`wmm_control.experiments.direct.run_scenario` plays a whole scenario on it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from wmm_control.base import BaseController, make_base_controller
from wmm_control.base.period import node_default
from wmm_control.cycle import Cycle
from wmm_control.errors import ConfigError
from wmm_control.geometry import matrix_from_quaternion, quaternion_from_matrix, quaternion_from_yaw
from wmm_control.resolvers import PoseTarget, Resolver, ResolverCommand, RobotState
from wmm_control.resolvers.period import ResolverSettings

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
        command: the resolver's final command (``ResolverCommand``), or None when the robot
            was held (no target, or an input refused) or the joint state rejected.
        arm_velocity: the arm rates in force (zero when held; the last ones sent when the joint
            state's arm joints were rejected). Shape (n,).
        feasible_twist: the base controller's answer q̇_bf (base frame; its last one when the
            joint state's base joints were rejected). Shape (3,).
        base_velocity: the base twist actually executed in the period (base frame). Shape (3,).
        cycle_s: wall time (``time.perf_counter``) of the period's control cycle
            (:meth:`~wmm_control.cycle.Cycle.step`: the method with its safety stage, the base
            controller, the compensation; not reading the state nor the simulator's step) [s].
        cycle_cpu_s: the same cycle's CPU time in this thread (``time.thread_time``) [s].
    """

    t: float
    base_pose: np.ndarray
    q_arm: np.ndarray
    q: np.ndarray
    ee_position: np.ndarray
    ee_rotation: np.ndarray
    command: ResolverCommand | None
    arm_velocity: np.ndarray
    feasible_twist: np.ndarray
    base_velocity: np.ndarray
    cycle_s: float
    cycle_cpu_s: float


class ClosedLoop:
    """Run ``resolver`` and the robot's base controller on ``world``: a
    :class:`~wmm_control.cycle.Cycle` (``cycle``) and the world's input and output.

    Each period feeds the cycle what the nodes' topics would carry: the odometry (or the
    ground-truth base pose) and, with ground-truth feedback, the end effector's pose, checked as
    they come; the target given to :meth:`step` as a goal or a trajectory point, checked too (a
    goal no motion reaches, or inside an obstacle, is refused and the robot held, as
    ``redundancy_resolver`` does).

    Args:
        world: a :class:`~sim_bridge.world.SimWorld`.
        resolver: a :class:`~wmm_control.resolvers.Resolver` for the same robot.
        feedback: ``'ground_truth'`` (true base pose and end effector, as the paper's
            simulator) or ``'odometry'`` (wheel odometry and forward kinematics, what a robot
            without external sensing has).
        base_controller: a :class:`~wmm_control.base.BaseController`; default
            :func:`~wmm_control.base.make_base_controller`. It starts from the world's joints.
        settings: the resolver's input checks (default the node's,
            :meth:`~wmm_control.resolvers.period.ResolverSettings.defaults`).
    """

    def __init__(
        self,
        world: SimWorld,
        resolver: Resolver,
        feedback: str = 'ground_truth',
        base_controller: BaseController | None = None,
        settings: ResolverSettings | None = None,
    ) -> None:
        if feedback not in FEEDBACKS:
            raise ConfigError(f'feedback must be one of {FEEDBACKS}, got {feedback!r}')
        self.world = world
        self.resolver = resolver
        self.feedback = feedback
        self.robot = world.robot
        self.base = base_controller if base_controller is not None else make_base_controller(self.robot, world.dt)
        if settings is None:
            settings = ResolverSettings.defaults(ground_truth=feedback == 'ground_truth')
        self.cycle = Cycle(
            resolver, self.base, world.dt, settings, node_default(self.base.family, 'applied_rate_tolerance')
        )
        self.world_frame = settings.world_frame
        index = {n: i for i, n in enumerate(world.joint_names)}
        self._arm = [index[n] for n in self.robot.arm.joints]
        self._groups = {g: [index[n] for n in names] for g, names in self.base.command_groups.items()}
        self._resync = True  # the first period starts from the measured joints, as the nodes' first
        self._arm_sent, self._twist = np.zeros(self.robot.arm.n), np.zeros(3)  # the last answer in force
        #: the events of the inputs and periods so far (what a node would have logged)
        self.events: list = []

    def _positions(self, q):
        """The positions of each base command group in ``q`` (``world.joint_names`` order)."""
        return {g: q[idx] for g, idx in self._groups.items()}

    def set_obstacles(self, obstacles) -> None:
        """Keep the robot off ``obstacles`` (world frame) and refuse goals inside them."""
        self.cycle.resolver_period.set_obstacles(obstacles)

    def _base(self):
        """The base's (pose, twist) as the resolver receives them: the ground truth with
        ground-truth feedback, else the wheel odometry."""
        w = self.world
        if self.feedback == 'ground_truth':
            return w.base_pose(), w.base_twist()
        return w.odom_pose(), w.odom_twist()

    def state(self) -> RobotState:
        """The :class:`RobotState` the resolver sees now."""
        w = self.world
        _, q, qd = w.joint_state()
        pose, twist = self._base()
        if self.feedback == 'ground_truth':
            pos, quat = w.ee_pose()
            return RobotState(
                pose, twist, q[self._arm], qd[self._arm], ee_position=pos, ee_rotation=matrix_from_quaternion(quat)
            )
        return RobotState(pose, twist, q[self._arm], qd[self._arm])

    def _measure(self, now: float) -> None:
        """The odometry (the true base pose with ground-truth feedback) and the end effector's
        pose, as the nodes receive them."""
        w, period = self.world, self.cycle.resolver_period
        pose, twist = self._base()
        self.events += period.odometry(pose[:2], quaternion_from_yaw(float(pose[2])), twist, now)
        if self.feedback == 'ground_truth':
            pos, quat = w.ee_pose()
            self.events += period.ee_pose(self.world_frame, np.concatenate((pos, quat)), now)

    def submit(self, target: PoseTarget, tracking: bool = False) -> None:
        """Give the cycle ``target``: a goal, or with ``tracking`` a point of a trajectory (its
        velocity and acceleration the feedforward, and a followed plan's base with it), as
        ``/goal_pose`` and ``/ee_reference`` would carry it."""
        period, now = self.cycle.resolver_period, self.world.time
        pose = np.concatenate((target.position, quaternion_from_matrix(target.rotation)))
        base = target.base
        planned = None
        if base is not None:
            planned = (base.pose, base.rates, base.acceleration) + (() if base.arm is None else (base.arm,))
        if tracking:
            self.events += period.trajectory_point(
                self.world_frame, pose, target.velocity, target.acceleration, now, planned
            )
        else:
            self.events += period.goal(self.world_frame, pose, now, planned)

    def step(self, target: PoseTarget | None = None, tracking: bool | None = None) -> CycleRecord:
        """One period, towards ``target`` (:class:`~wmm_control.resolvers.PoseTarget`, given
        first with :meth:`submit`; None: the target already given). ``tracking`` None: a
        target with a velocity or an acceleration is a trajectory point, one without a goal.

        Returns:
            :class:`CycleRecord` of the period.
        """
        w = self.world
        t = w.time
        self._measure(t)
        if target is not None:
            if tracking is None:
                tracking = bool(np.any(target.velocity) or np.any(target.acceleration))
            self.submit(target, tracking)
        pose = w.base_pose()
        ee_pos, ee_quat = w.ee_pose()
        _, q_all, qd_all = w.joint_state()
        wall, cpu = time.perf_counter(), time.thread_time()
        result = self.cycle.step(
            q_all[self._arm], qd_all[self._arm], self._positions(q_all), self._positions(qd_all), t, self._resync
        )
        cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
        self.events += result.events
        if not result.rejected:
            self._resync = False
        if result.base is not None:  # else the commands in force stay
            for group, rates in result.base.rates.items():
                w.set_command(group, rates)
            self._twist = np.asarray(result.base.twist, dtype=float)
        if result.arm_velocity is not None:
            w.set_command('arm', result.arm_velocity)
            self._arm_sent = result.arm_velocity
        w.step()
        return CycleRecord(
            t=t,
            base_pose=pose,
            q_arm=q_all[self._arm].copy(),
            q=q_all.copy(),
            ee_position=ee_pos,
            ee_rotation=matrix_from_quaternion(ee_quat),
            command=result.command,
            arm_velocity=self._arm_sent,
            feasible_twist=self._twist,
            base_velocity=w.base_twist(),
            cycle_s=wall,
            cycle_cpu_s=cpu,
        )
