"""ROS-free planning for goals beyond what is in the way: where the base stands, a base path
clear of the obstacles (OMPL), timed within the base's limits (:class:`GoalPlanner` runs the
three; ``docs/methods.md``, "The planner")."""

from wmm_control.planning.base_path import BasePath, BasePathPlanner
from wmm_control.planning.clearance import Clearance, Travel
from wmm_control.planning.outcome import NoWay
from wmm_control.planning.planner import GoalPlanner, Plan
from wmm_control.planning.no_way_check import NoWayCheck, Verdict, confirm_no_way
from wmm_control.planning.stance import Stance, StanceFinder, StanceParams, StanceSearch
from wmm_control.planning.timing import BaseTrajectory, time_path

__all__ = [
    'BasePath',
    'BasePathPlanner',
    'BaseTrajectory',
    'Clearance',
    'GoalPlanner',
    'NoWay',
    'NoWayCheck',
    'Plan',
    'Stance',
    'StanceFinder',
    'StanceParams',
    'StanceSearch',
    'Travel',
    'Verdict',
    'confirm_no_way',
    'time_path',
]
