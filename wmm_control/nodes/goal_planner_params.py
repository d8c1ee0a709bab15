"""The parameters of ``goal_planner`` (:mod:`wmm_control.nodes.goal_planner`): the node's own,
with their defaults in ``config/goal_planner.yaml``; the planner's, with their defaults in
:class:`~wmm_control.planning.GoalPlanner`'s signature; the follower's, with their defaults in
:class:`~wmm_control.planning.follow.FollowParams` (and ``max_replans`` from
:data:`~wmm_control.planning.follow.MAX_REPLANS`); the period from the robot YAML."""

import dataclasses
import inspect

from wmm_control.nodes.obstacle_topic import obstacle_params
from wmm_control.nodes.parameters import Param, defaults_elsewhere, robot_param, robot_period
from wmm_control.planning.follow import MAX_REPLANS, FollowParams
from wmm_control.planning.planner import GoalPlanner

__all__ = ['PARAMS', 'PLANNER_PARAMS', 'FOLLOW_PARAMS']

#: The parameters that are :class:`~wmm_control.planning.GoalPlanner`'s keyword arguments.
PLANNER_PARAMS = ('travel_margin', 'narrow_margin', 'budget', 'seed', 'stances_tried', 'fraction')
#: The parameters that are :class:`~wmm_control.planning.follow.FollowParams`' fields.
FOLLOW_PARAMS = tuple(f.name for f in dataclasses.fields(FollowParams))

_SPECS = (
    robot_param(),
    Param(
        'period',
        'Period [s] of the trajectory points sent to the resolver; default: the robot YAML\'s period.',
        lo=1e-3,
        hi=1.0,
        read_only=True,
        default_from=robot_period,
    ),
    *obstacle_params(),
    Param(
        'world_frame',
        'Frame of /goal_pose, /obstacles, ~/path and of what the node sends the resolver (the odometry is taken '
        'in it, as the resolver takes it).',
        read_only=True,
    ),
    Param(
        'state_timeout',
        'Age [s] of odometry or joint states (steady clock at receipt; in lockstep the simulation\'s time) '
        'after which no trajectory point is sent (the resolver then holds its last one).',
        lo=1e-3,
        hi=60.0,
    ),
    Param('max_goal_distance', 'Goals farther than this from the world origin are rejected [m].', lo=1.0, hi=1e6),
    Param(
        'max_replans',
        'Plans made again for one goal (progress stalled, an obstacle moved onto the path); after them the goal '
        'goes to the resolver from where the robot is.',
        lo=0,
        hi=1000,
    ),
    Param('diagnostics_period', 'Time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
    Param(
        'travel_margin',
        'Clearance [m] the base path keeps from every obstacle, arm in the travel posture (planner).',
        lo=1e-3,
        hi=2.0,
        read_only=True,
    ),
    Param(
        'narrow_margin',
        'Clearance [m] a base path may keep instead of travel_margin where one that keeps travel_margin is a '
        'detour (longer than 1.5 times the straight way plus 1 m) and one that keeps this is a quarter shorter: '
        'through a doorway; 0 = travel_margin only (planner).',
        lo=0.0,
        hi=2.0,
        read_only=True,
    ),
    Param(
        'budget',
        'Safety cap [s] on the wall time of each base path search; a search that reaches it ends the plan with '
        '"no way" (planner).',
        lo=0.01,
        hi=60.0,
        read_only=True,
    ),
    Param('seed', 'Random seed of the path search, > 0 (planner).', lo=1, hi=2**31 - 1, read_only=True),
    Param(
        'stances_tried',
        'The most stances a plan tries a path to; the next when a path is a detour (planner).',
        lo=1,
        hi=100,
        read_only=True,
    ),
    Param(
        'fraction',
        'Fraction of the base\'s velocity and acceleration limits the planned trajectory uses (planner).',
        lo=0.05,
        hi=1.0,
        read_only=True,
    ),
    Param(
        'lead_distance',
        'Lag [m] of the end effector behind its point at which the plan\'s clock stops (follower).',
        lo=1e-3,
        hi=10.0,
        read_only=True,
    ),
    Param('lead_angle', 'The same for its orientation [rad] (follower).', lo=1e-3, hi=6.3, read_only=True),
    Param(
        'base_lead_distance',
        'Lag [m] of the base behind its planned pose at which the base\'s pace is least (follower).',
        lo=1e-3,
        hi=10.0,
        read_only=True,
    ),
    Param('base_lead_angle', 'The same for its heading [rad] (follower).', lo=1e-3, hi=6.3, read_only=True),
    Param(
        'slow_from',
        'Fraction of the lead up to which the plan\'s clock keeps full pace, in [0, 1) (follower).',
        lo=0.0,
        hi=0.99,
        read_only=True,
    ),
    Param(
        'base_floor',
        'Pace, in [0, 1], the base\'s lag leaves the plan\'s clock while the end effector is measured (follower).',
        lo=0.0,
        hi=1.0,
        read_only=True,
    ),
    Param(
        'base_floor_lag',
        'Lag of the base, in leads, at which base_floor has faded to nothing (whole up to one lead): '
        'beyond it the plan\'s clock waits for the base (follower).',
        lo=1.001,
        hi=1000.0,
        read_only=True,
    ),
    Param('rate_slew', 'Most the clock\'s rate rises per second [1/s] (follower).', lo=1e-3, hi=1000.0, read_only=True),
    Param(
        'lookahead',
        'Time [s] of the plan ahead of its clock searched for the pose the base has passed (follower).',
        lo=0.0,
        hi=60.0,
        read_only=True,
    ),
    Param(
        'stall_time',
        'Time [s] without progress on the path after which the plan is made again (follower).',
        lo=0.1,
        hi=600.0,
        read_only=True,
    ),
    Param('stall_distance', 'Motion [m] that counts as progress (follower).', lo=1e-4, hi=10.0, read_only=True),
    Param('stall_angle', 'Turn [rad] that counts as progress (follower).', lo=1e-4, hi=6.3, read_only=True),
    Param(
        'settle_distance',
        'Distance [m] from the stance within which, moving slower than this per second, the base is at '
        'rest there and the arm\'s motion to the stance\'s posture starts (follower).',
        lo=1e-4,
        hi=10.0,
        read_only=True,
    ),
    Param(
        'settle_angle',
        'The same for the heading [rad] and its rate [rad/s] (follower).',
        lo=1e-4,
        hi=6.3,
        read_only=True,
    ),
    Param(
        'settle_time',
        'Time [s] the arm\'s motion to the stance\'s posture waits at most for the base at rest; then the final '
        'approach follows without it (follower).',
        lo=0.0,
        hi=600.0,
        read_only=True,
    ),
    Param(
        'hold_base',
        'Send each point\'s planned base pose (joint "base") and the arm\'s posture with it on /ee_reference, '
        'and the final approach\'s goal there as the last point with the stance and its posture: the methods pull the base '
        'towards the plan, and hold it at the stance, below the end effector\'s task (follower); false: '
        'the points alone, the goal on ~/goal.',
        read_only=True,
    ),
)


_SIGNATURE = inspect.signature(GoalPlanner.__init__).parameters
#: The node's parameters (module docstring): the planner's and the follower's take their defaults
#: from their one home, GoalPlanner's signature, FollowParams' fields and MAX_REPLANS.
PARAMS = defaults_elsewhere(
    defaults_elsewhere(
        defaults_elsewhere(_SPECS, {name: _SIGNATURE[name].default for name in PLANNER_PARAMS}, '`GoalPlanner`'),
        {f.name: f.default for f in dataclasses.fields(FollowParams)},
        '`FollowParams`',
    ),
    {'max_replans': MAX_REPLANS},
    '`MAX_REPLANS`',
)
