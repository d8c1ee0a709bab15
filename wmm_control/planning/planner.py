"""The planner's three steps for one goal: where to stand, the way there, timed.

:class:`GoalPlanner` holds one robot among one set of obstacles; :meth:`GoalPlanner.plan` finds
the stances for an end-effector goal (:mod:`~wmm_control.planning.stance`), plans the base's
path to the best one from the robot's base pose (:mod:`~wmm_control.planning.base_path`; the
next stance when there is no path to one, or when the path is a detour: the first path to a
stance that is not a detour is kept, else the best stance's; a stance the arm has a clear way
to comes before one it has not, whatever its path), and times it (:mod:`~wmm_control.planning.timing`).
The arm travels in the posture it is given (default: the robot's start posture;
:meth:`GoalPlanner.set_travel_posture` changes it) and takes the
stance's posture only once there, so the path is checked with the arm in the travel posture and
the stance both with it (the path's end) and with the arm at the goal.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.kinematics.model import KinematicModel
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.planning.base_path import BUDGET, NARROW_MARGIN, BasePath, BasePathPlanner
from wmm_control.planning.clearance import Clearance, Travel
from wmm_control.planning.outcome import NoWay
from wmm_control.planning.stance import Stance, StanceFinder, StanceParams, StanceSearch
from wmm_control.planning.timing import BaseTrajectory, time_path
from wmm_control.robot_config import RobotConfig

__all__ = ['GoalPlanner', 'Plan']


@dataclass(frozen=True)
class Plan:
    """A plan for one goal, or why there is none.

    Attributes:
        stance: where the base stands and the arm's posture there; None when there is no plan.
        path: the base path to it (the last one tried when none was found).
        trajectory: the path timed at the control period; None when there is no plan.
        search: the stance search.
        no_way: the kind of reason when there is no plan, else None.
        reason: a sentence for a log ('' with a plan).
        planning_time: [s] wall time of the whole plan.
    """

    stance: Stance | None
    path: BasePath | None
    trajectory: BaseTrajectory | None
    search: StanceSearch
    no_way: NoWay | None
    reason: str
    planning_time: float


def _rank(stance: Stance, path: BasePath) -> tuple[bool, bool]:
    """Lower is better: a stance the arm has a clear way to (:attr:`Stance.motion_clear`) first,
    then a path that is not a detour."""
    return not stance.motion_clear, path.detour


class GoalPlanner:
    """Plans for end-effector goals of one robot among fixed obstacles (module docstring).

    Args:
        robot: the robot.
        obstacles: world frame.
        q_travel: the arm's posture while the base drives [rad or m]; default the start posture.
        travel_margin: [m] the clearance the base path keeps from every obstacle (default: the
            safety stage's influence distance, so that the dampers leave the path alone).
        step: [m] of the path's checks (:class:`~wmm_control.planning.clearance.Travel`).
        stance: :class:`~wmm_control.planning.stance.StanceParams`.
        budget: [s] the safety cap on the wall time of each base path search
            (:class:`~wmm_control.planning.base_path.BasePathPlanner`).
        seed: OMPL's seed (> 0).
        stances_tried: the most stances a plan tries a path to (the next one is tried when there
            is no path to a stance or its path is a detour).
        fraction: of the base's limits the trajectory uses.
        narrow_margin: [m] the clearance a base path may keep instead of ``travel_margin`` where
            one that keeps that is a detour and one that keeps this is shorter (through a doorway
            the travel margin leaves too narrow to find;
            :class:`~wmm_control.planning.base_path.BasePathPlanner`); 0: ``travel_margin`` only.
    """

    def __init__(
        self,
        robot: RobotConfig,
        obstacles: Iterable[Obstacle],
        q_travel: ArrayLike | None = None,
        travel_margin: float = 0.10,
        step: float = 0.01,
        stance: StanceParams | None = None,
        budget: float = BUDGET,
        seed: int = 1,
        stances_tried: int = 4,
        fraction: float = 0.95,
        narrow_margin: float = NARROW_MARGIN,
    ) -> None:
        self.robot = robot
        self.model = KinematicModel(robot)
        obstacles = tuple(obstacles)
        self.clearance = Clearance.of_robot(robot, obstacles)
        travel_posture = robot.start.arm if q_travel is None else q_travel
        self.travel = Travel(
            Clearance.of_robot(robot, obstacles, body=False), self.model, travel_posture, travel_margin, step
        )
        self.stances = StanceFinder(self.model, self.clearance, self.travel, stance)
        self.paths = BasePathPlanner(robot.base, self.travel, budget, seed, narrow_margin=narrow_margin)
        self.stances_tried = int(stances_tried)
        self.fraction = float(fraction)

    def set_travel_posture(self, q_arm: ArrayLike) -> None:
        """Plan with the arm held at ``q_arm`` [rad or m] while the base drives, from now on (the
        stances' inverse kinematics start from it too)."""
        travel = self.travel.with_posture(q_arm)
        self.travel = self.stances.travel = self.paths.travel = travel

    def plan(self, goal_position: ArrayLike, goal_rotation: ArrayLike, base_pose: Sequence[float] | np.ndarray) -> Plan:
        """A plan for the end effector to reach ``goal_position`` [m] with ``goal_rotation`` (3, 3)
        in the world, the base now at ``base_pose`` (x, y, θ)."""
        began = time.perf_counter()
        base_pose = np.asarray(base_pose, dtype=float)
        search = self.stances.find(goal_position, goal_rotation, base_pose)
        if not search.stances:
            return Plan(None, None, None, search, search.no_way, search.reason, time.perf_counter() - began)
        path = None
        chosen: tuple[Stance, BasePath] | None = None  # the best stance with a path, and that path
        for stance in search.stances[: self.stances_tried]:
            path = self.paths.plan(base_pose, stance.base_pose)
            if path.found:
                if chosen is None or _rank(stance, path) < _rank(*chosen):
                    chosen = (stance, path)
                if not path.detour:  # the stances after it have no clearer way for the arm
                    break
            elif path.no_way in (NoWay.START_BLOCKED, NoWay.TIMED_OUT):
                break
        if chosen is not None:
            stance, path = chosen
            trajectory = time_path(path.pieces, self.robot.base, self.robot.period, self.fraction)
            return Plan(stance, path, trajectory, search, None, '', time.perf_counter() - began)
        assert path is not None
        return Plan(None, path, None, search, path.no_way, path.reason, time.perf_counter() - began)

    def plan_in_posture(
        self,
        goal_position: ArrayLike,
        goal_rotation: ArrayLike,
        base_pose: Sequence[float] | np.ndarray,
        q_travel: ArrayLike | None = None,
    ) -> tuple[Plan, np.ndarray]:
        """:meth:`plan` with the arm travelling in ``q_travel`` [rad or m] (None: the planner's own
        travel posture), and in the planner's own when that finds no way (the planning times
        added); the planner's own posture stays in force. Returns (the plan, the travel posture
        it is for)."""
        own = self.travel.q_arm
        if q_travel is None:
            return self.plan(goal_position, goal_rotation, base_pose), own
        self.set_travel_posture(q_travel)
        try:
            plan = self.plan(goal_position, goal_rotation, base_pose)
        finally:
            self.set_travel_posture(own)
        if plan.trajectory is not None:
            return plan, np.asarray(q_travel, dtype=float)
        second = self.plan(goal_position, goal_rotation, base_pose)
        return dataclasses.replace(second, planning_time=plan.planning_time + second.planning_time), own
