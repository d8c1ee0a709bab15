"""Why the planner found no way: one reason per kind, for a node's log and diagnostics."""

from __future__ import annotations

from enum import Enum

__all__ = ['NoWay']


class NoWay(str, Enum):
    """The kinds of "no way" the planner reports, each with a message beside it."""

    #: the goal is inside an obstacle, or nearer to one than the stance margin
    INSIDE_OBSTACLE = 'inside_obstacle'
    #: the goal is below the floor or above anything the end effector can reach
    OUT_OF_REACH = 'out_of_reach'
    #: no base pose around the goal lets the arm reach it with the clearances asked
    NO_STANCE = 'no_stance'
    #: the robot's current pose is not clear of the obstacles by the travel margin, and no
    #: short way out keeps the clearance it has
    START_BLOCKED = 'start_blocked'
    #: no base path to any stance was found within the searches' iterations
    NO_PATH = 'no_path'
    #: a base path search reached its time budget, the safety cap on a machine too slow or
    #: loaded for its iterations (no path rather than one the machine's speed chose)
    TIMED_OUT = 'timed_out'
