"""The run entry of each method in the randomized study (:mod:`wmm_control.experiments.randomized`),
apart from the study itself: ``wmm_randomized --help`` lists the methods without loading it."""

from typing import Any

__all__ = ['METHOD_RUNS', 'ROBOT_RUNS']

#: The run entry of each method (resolver parameters; the others are the node's defaults).
#: The goals are arbitrary poses: the acceleration-level methods track all six rows
#: (``rows: full``), and the velocity-level methods take the orientation error as a log map
#: (the RPY difference of Sorour eq (12) is singular at pitch ±π/2, where robot B starts) and
#: hold a joint at its braking bound while the others take its share of the task
#: (``hold_joint_limits``; clipped out instead, the end effector can stay put for tens of
#: seconds).
METHOD_RUNS: dict[str, dict[str, Any]] = {
    'pinv': {'method': 'pinv', 'orientation_error': 'log', 'hold_joint_limits': True},
    'task_sharing': {'method': 'task_sharing', 'orientation_error': 'log', 'hold_joint_limits': True},
    'amp': {'method': 'amp', 'rows': 'full'},
    'traditional': {'method': 'traditional', 'rows': 'full'},
}
#: Per robot, parameters added to a method's run entry. Robot B's base accelerates at
#: 0.025 m/s² (Xing Table 1): with the velocity-level methods the arm takes over the share of
#: the task the base cannot follow (``arm_takeover``) instead of the whole body slowing to the
#: base's pace.
ROBOT_RUNS: dict[str, dict[str, dict[str, Any]]] = {
    'mecanum': {'pinv': {'arm_takeover': True}, 'task_sharing': {'arm_takeover': True}}
}
