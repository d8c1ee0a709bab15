"""TargetManager, CompensationExchange, MeasuredInputs and LatestInputs (ROS-free): what
redundancy_resolver pursues, the arm command's wait for the base's answer, the checks of the
measured inputs and the state made of the latest, which events it logs and what it reports."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.kinematics.workspace import Workspace
from wmm_control.resolvers.exchange import CompensationExchange
from wmm_control.resolvers.inputs import LatestInputs, MeasuredInputs
from wmm_control.resolvers.targets import LogEvent, LogThrottle, TargetManager

IDENTITY = (0.0, 0.0, 0.0, 1.0)
TIMEOUT = 0.5


@pytest.fixture(scope='module')
def workspace(steerable_model):
    return Workspace(steerable_model)


@pytest.fixture
def targets(workspace):
    return TargetManager(workspace, 'world', 50.0, TIMEOUT, (0.01, 0.05), 1.0, 0.1, 0.1)


def kinds(events):
    return [e.kind for e in events]


def diag(position_error, orientation_error=0.0):
    return SimpleNamespace(
        position_error=position_error, orientation_error=orientation_error, mode='mobile', reference_time_left=0.0
    )


def goal(targets, xyz=(1.5, 0.3, 1.0), quat=IDENTITY, frame='world', base=None):
    return targets.goal(frame, [*xyz, *quat], base)


def point(targets, now, xyz=(1.5, 0.3, 1.0), quat=IDENTITY, velocity=(0.1, 0.0, 0.0, 0.0, 0.0, 0.2)):
    return targets.trajectory_point('world', [*xyz, *quat], velocity, np.zeros(6), now)


def test_a_goal_becomes_the_target(targets):
    half_turn_z = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))
    events = goal(targets, (1.5, 0.3, 1.0), half_turn_z)
    assert kinds(events) == ['accepted'] and events[0].message.startswith('new goal: position [1.5, 0.3, 1.0]')
    np.testing.assert_allclose(targets.target.position, [1.5, 0.3, 1.0])
    np.testing.assert_allclose(targets.target.rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    assert not targets.tracking and targets.goals == 1


def test_the_same_goal_again_is_not_restarted(targets):
    goal(targets)
    for _ in range(5):
        targets.judge(diag(0.2))
    assert goal(targets) == [] and targets.goals == 1
    assert targets.progress.cycles == 5, 'its progress goes on'
    # the same goal to within rounding, and a non-unit quaternion of the same rotation: the same goal
    assert kinds(goal(targets, (1.5 + 1e-12, 0.3, 1.0), (0.0, 0.0, 0.0, 2.0))) == ['normalised']
    assert targets.goals == 1 and targets.progress.cycles == 5
    assert kinds(goal(targets, (1.5, 0.31, 1.0))) == ['accepted']
    assert targets.goals == 2 and targets.progress.cycles == 0


@pytest.mark.parametrize(
    'frame, xyz, quat, reason',
    [
        ('map', (1.0, 0.0, 1.0), IDENTITY, "frame 'map', expected 'world'"),
        ('world', (math.nan, 0.0, 1.0), IDENTITY, 'non-finite values of position.x;'),
        ('world', (1.0, 0.0, 1.0), (0.0, 0.0, math.inf, 1.0), 'non-finite values of orientation.z;'),
        ('world', (1.0, 0.0, 1.0), (0.0, 0.0, 0.0, 0.0), 'zero quaternion'),
        ('world', (1.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1e-9), 'zero quaternion'),
        ('world', (60.0, 0.0, 1.0), IDENTITY, 'is beyond max_goal_distance 50.0 m'),
        ('world', (1.0, 0.0, -0.1), IDENTITY, 'below the floor'),
        ('world', (1.0, 0.0, 5.0), IDENTITY, 'above the highest the end effector can reach'),
    ],
)
def test_a_bad_goal_is_rejected_with_its_reason_and_leaves_no_target(targets, frame, xyz, quat, reason):
    goal(targets)
    events = goal(targets, xyz, quat, frame)
    assert kinds(events) == ['rejected']
    assert events[0].message.startswith('rejected goal_pose: ') and reason in events[0].message
    assert events[0].message.endswith('; holding still')
    assert targets.target is None and targets.rejected == 1 and targets.goals == 1
    assert kinds(goal(targets)) == ['accepted'], 'the goal rejected in between is forgotten: the old one is new again'


def test_a_goal_inside_the_body_or_an_obstacle_is_rejected(targets):
    base = np.array([0.0, 0.0, 0.0])
    assert kinds(goal(targets, (0.0, 0.0, 0.3), base=None)) == ['accepted'], 'no base pose: the body is not checked'
    events = goal(targets, (0.0, 0.0, 0.3), base=base)
    assert kinds(events) == ['rejected'] and "inside the robot's own body" in events[0].message
    targets.obstacles = (Obstacle('crate', 'sphere', (0.2,), np.array([2.0, 0.0, 1.0]), np.eye(3)),)
    events = goal(targets, (2.05, 0.0, 1.0), base=base)
    assert kinds(events) == ['rejected'] and "inside the obstacle 'crate'" in events[0].message
    assert kinds(goal(targets, (2.5, 0.0, 1.0), base=base)) == ['accepted']


def test_a_target_with_a_planned_base_is_checked_against_the_body_where_the_base_is_planned(targets):
    """A plan's point, or its final approach's goal with the stance, is met with the base at its
    planned pose: the body is checked there, not where the base is now. Checked at the measured
    pose, robot B's final approach to a goal 0.12 m below its base frame, with the base over the
    goal at the path's end, was refused, and the robot held there for the rest of the run."""
    here, there = np.zeros(3), np.array([3.0, 0.0, 0.0])
    planned = (there, np.zeros(3), np.zeros(3))
    under_here, under_there = [0.0, 0.0, 0.3, *IDENTITY], [3.0, 0.0, 0.3, *IDENTITY]
    assert targets.workspace.impossible(under_here[:3], here)  # inside the body where the base is
    events = targets.trajectory_point('world', under_here, np.zeros(6), np.zeros(6), 1.0, here, planned)
    assert kinds(events) == ['tracking']
    assert kinds(targets.goal('world', under_here, here, planned_base=planned)) == ['accepted']
    for events in (
        targets.trajectory_point('world', under_there, np.zeros(6), np.zeros(6), 2.0, here, planned),
        targets.goal('world', under_there, here, planned_base=planned),
    ):
        assert kinds(events) == ['rejected'] and "inside the robot's own body" in events[0].message


def test_a_non_unit_quaternion_is_normalised_with_a_note(targets):
    q = np.array([0.0, 0.0, math.sin(0.2), math.cos(0.2)]) * 3.0
    events = goal(targets, quat=q)
    assert kinds(events) == ['normalised', 'accepted']
    assert events[0].message == '/goal_pose quaternion has norm 3: normalised'
    np.testing.assert_allclose(np.linalg.det(targets.target.rotation), 1.0, atol=1e-12)
    np.testing.assert_allclose(targets.target.rotation[:2, 0], [math.cos(0.4), math.sin(0.4)], atol=1e-12)


def test_a_fresh_trajectory_is_followed(targets):
    goal(targets)
    assert kinds(point(targets, 10.0)) == ['tracking']
    assert targets.tracking and targets.progress.cycles == 0
    for k in range(1, 10):  # points every 0.1 s: each one the target, velocity and all
        assert point(targets, 10.0 + 0.1 * k, xyz=(1.5 + 0.01 * k, 0.3, 1.0)) == []
        target, events = targets.current(10.0 + 0.1 * k + 0.05)
        assert events == [] and target is targets.target
        np.testing.assert_allclose(target.position, [1.5 + 0.01 * k, 0.3, 1.0])
        np.testing.assert_allclose(target.velocity, [0.1, 0.0, 0.0, 0.0, 0.0, 0.2])
    assert targets.goals == 1, 'a trajectory is no goal'


def test_a_stale_trajectory_is_held_at_its_last_pose(targets):
    point(targets, 10.0, xyz=(1.4, 0.2, 0.9))
    target, events = targets.current(10.0 + TIMEOUT)
    assert events == [] and targets.tracking, 'within the timeout: still followed'
    target, events = targets.current(10.0 + TIMEOUT + 0.01)
    assert kinds(events) == ['held'] and not targets.tracking
    np.testing.assert_allclose(target.position, [1.4, 0.2, 0.9])
    np.testing.assert_allclose(target.velocity, 0.0)
    np.testing.assert_allclose(target.acceleration, 0.0)
    assert targets.current(20.0) == (target, []), 'held once, told once'
    assert kinds(point(targets, 30.0)) == ['tracking'], 'a new point tracks again'


def test_a_clock_that_jumps_back_makes_the_trajectory_stale(targets):
    point(targets, 10.0)
    assert kinds(targets.current(9.0)[1]) == ['held']


@pytest.mark.parametrize(
    'pose, velocity, reason',
    [
        (None, np.zeros(6), 'no point or no transform'),
        ([1.5, 0.3, math.nan, *IDENTITY], np.zeros(6), 'non-finite values'),
        ([1.5, 0.3, 1.0, *IDENTITY], [2e3, 0, 0, 0, 0, 0], 'a twist or acceleration beyond 1e3'),
        ([1.5, 0.3, 1.0, 0.0, 0.0, 0.0, 0.0], np.zeros(6), 'zero quaternion'),
        ([1.5, 0.3, -1.0, *IDENTITY], np.zeros(6), 'below the floor'),
    ],
)
def test_a_bad_trajectory_point_is_rejected(targets, pose, velocity, reason):
    point(targets, 1.0)
    events = targets.trajectory_point('world', pose, velocity, np.zeros(6), 1.1)
    assert kinds(events) == ['rejected'] and events[0].message.startswith('rejected ee_reference: ')
    assert reason in events[0].message
    assert targets.target is None and not targets.tracking


@pytest.mark.parametrize(
    'planned, reason',
    [
        ((np.array((0.3, math.nan, 0.2)), np.zeros(3), np.zeros(3)), 'non-finite values of the planned base'),
        ((np.array((0.3, 0.1, 0.2)), np.array((1e4, 0.0, 0.0)), np.zeros(3)), 'its rates beyond 1e3'),
        ((np.array((80.0, 0.1, 0.2)), np.zeros(3), np.zeros(3)), 'planned base beyond max_goal_distance'),
        ((np.zeros(2), np.zeros(3), np.zeros(3)), 'a planned base needs a pose'),
        ((np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(6)), 'a planned arm posture needs 7 joint positions'),
        ((np.zeros(3), np.zeros(3), np.zeros(3), np.full(7, math.nan)), 'non-finite values of the planned base'),
    ],
)
def test_a_followed_plan_s_base_comes_with_its_point_checked_as_the_point_is(targets, planned, reason):
    good = (np.array((0.3, 0.1, 0.2)), np.array((0.5, 0.0, 0.1)), np.zeros(3))
    targets.trajectory_point('world', [1.5, 0.3, 1.0, *IDENTITY], np.zeros(6), np.zeros(6), 1.0, planned_base=good)
    assert np.allclose(targets.target.base.pose, good[0]) and np.allclose(targets.target.base.rates, good[1])
    assert not targets.target.base.stance  # a point of the way there, not where the base stands
    events = targets.trajectory_point(
        'world', [1.5, 0.3, 1.0, *IDENTITY], np.zeros(6), np.zeros(6), 1.1, planned_base=planned
    )
    assert kinds(events) == ['rejected'] and reason in events[0].message
    assert 'nan' not in events[0].message.lower() and targets.target is None
    # a point without one: the target has none (the methods as the papers have them)
    point(targets, 1.2)
    assert targets.target.base is None


def test_a_goal_after_a_plan_holds_the_stance_as_its_base(targets):
    stance = (np.array((0.3, 0.1, 0.2)), np.zeros(3), np.zeros(3))
    assert kinds(targets.goal('world', [1.5, 0.3, 1.0, *IDENTITY], None, planned_base=stance)) == ['accepted']
    assert np.allclose(targets.target.base.pose, stance[0]) and targets.target.base.stance
    assert targets.target.base.arm is None
    posture = stance + (np.linspace(-0.5, 0.5, 7),)  # with the arm's posture at the stance
    assert kinds(targets.goal('world', [1.5, 0.2, 1.0, *IDENTITY], None, planned_base=posture)) == ['accepted']
    assert targets.target.base.stance and np.array_equal(targets.target.base.arm, posture[3])
    bad = (np.array((0.3, math.inf, 0.2)), np.zeros(3), np.zeros(3))
    events = targets.goal('world', [1.5, 0.4, 1.0, *IDENTITY], None, planned_base=bad)
    assert kinds(events) == ['rejected'] and 'non-finite values of the planned base' in events[0].message
    assert kinds(goal(targets)) == ['accepted'] and targets.target.base is None


def test_a_plan_s_last_point_is_held_with_its_stance_and_judged_as_a_goal(targets):
    """The final approach after a plan (goal_planner): the goal as the last point, at rest, with
    the stance and the arm's posture there as its base; once no point follows it is held with
    them and reported reached."""
    moving = (np.array((0.2, 0.1, 0.1)), np.array((0.4, 0.0, 0.1)), np.zeros(3), np.zeros(7))
    targets.trajectory_point(
        'world', [1.4, 0.3, 1.0, *IDENTITY], [0.4, 0, 0, 0, 0, 0.1], np.zeros(6), 1.0, None, moving
    )
    for _ in range(40):  # followed with a lag that never falls: no progress
        targets.judge(diag(0.05))
    stance = (np.array((0.3, 0.1, 0.2)), np.zeros(3), np.zeros(3), np.linspace(-0.5, 0.5, 7))
    targets.trajectory_point('world', [1.5, 0.3, 1.0, *IDENTITY], np.zeros(6), np.zeros(6), 1.1, None, stance)
    target, events = targets.current(1.1 + TIMEOUT + 0.01)
    assert kinds(events) == ['held'] and not targets.tracking
    np.testing.assert_allclose(target.position, [1.5, 0.3, 1.0])
    np.testing.assert_allclose(target.base.pose, stance[0])
    assert target.base.stance  # as a goal given with the stance: the methods put it first
    np.testing.assert_allclose(target.base.rates, 0.0)
    np.testing.assert_array_equal(target.base.arm, stance[3])  # the stance's posture kept
    # judged afresh: the approach (from 0.3 m, halving) is not a stall of the trajectory's lag
    said = [(targets.judge(diag(0.3 * 0.5**k)), targets.progress.stalled) for k in range(10)]
    assert not any(stalled for _, stalled in said) and [kinds(e) for e, _ in said].count(['reached']) == 1
    # its arrival is told with the time since the trajectory began (40 cycles tracked, then 6)
    assert [e[0].message for e, _ in said if kinds(e) == ['reached']] == [
        'goal reached: 0.0094 m, 0.0000 rad away after 4.60 s (46 cycles)'
    ]
    assert targets.progress.cycles == 10
    # a held trajectory without a planned base has none
    point(targets, 5.0)
    assert targets.current(5.0 + TIMEOUT + 0.01)[0].base is None


def test_a_goal_is_reached_once_and_a_stall_is_told_once_until_progress(targets):
    goal(targets)
    events = [targets.judge(diag(0.5 * 0.5**k)) for k in range(12)]
    reached = [e for e in sum(events, []) if e.kind == 'reached']
    assert [kinds(e) for e in events].index(['reached']) == 6, '0.5 m halved each cycle is under 1 cm at cycle 6'
    assert [e.message for e in reached] == ['goal reached: 0.0078 m, 0.0000 rad away after 0.70 s (7 cycles)']
    goal(targets, (1.6, 0.3, 1.0))
    stalls = [k for k in range(40) if 'stalled' in kinds(targets.judge(diag(0.3)))]
    assert len(stalls) == 1, 'a goal that stays 0.3 m away stalls, told once'
    message = targets.status(diag(0.3))[1]
    assert targets.status(diag(0.3))[0] == 'warn' and message.startswith('goal not reached: 0.300 m')
    assert 'no progress in 1.0 s (best error down by less than 10 %, 1 mm, 1 mrad)' in message
    errors = [0.3 * 0.9**k for k in range(1, 25)] + [0.3 * 0.9**24] * 40  # approaching, then held
    later = [(targets.progress.stalled, kinds(targets.judge(diag(e)))) for e in errors]
    assert not all(stalled for stalled, _ in later), 'progress clears the stall...'
    assert sum('stalled' in k for _, k in later) == 1, '...and a new stall is told once'


def test_a_trajectory_is_never_reported_reached(targets):
    point(targets, 0.0)
    assert all('reached' not in kinds(targets.judge(diag(0.0))) for _ in range(5))
    assert targets.status(diag(0.0)) == ('ok', 'goal reached')


def test_a_position_only_method_ignores_the_orientation(workspace):
    targets = TargetManager(workspace, 'world', 50.0, TIMEOUT, (0.01, 0.05), 1.0, 0.1, 0.1, position_only=True)
    assert targets.progress.tolerance == (0.01, math.inf)
    goal(targets)
    assert kinds(targets.judge(diag(0.005, 3.0))) == ['reached']


class _Resolver:
    def compensate(self, command, feasible):
        return ('compensated', command, tuple(feasible))


def test_the_arm_command_waits_for_the_answer_to_its_own_cycle():
    exchange = CompensationExchange(_Resolver())
    assert not exchange.pending and not exchange.awaits((1, 0))
    exchange.hold((1, 0), 'cmd1', 'stamp1')
    assert exchange.pending and exchange.awaits((1, 0)) and not exchange.awaits((0, 900))
    assert exchange.finish([0.1, 0.0, 0.0]) == (('compensated', 'cmd1', (0.1, 0.0, 0.0)), 'stamp1')
    assert not exchange.pending and exchange.dropped == 0
    exchange.hold((2, 0), 'cmd2', 'stamp2')
    assert exchange.finish() == ('cmd2', 'stamp2') and exchange.dropped == 1, 'no answer: sent as it is, counted'
    exchange.hold((3, 0), 'cmd3', 'stamp3')
    exchange.clear()
    assert not exchange.pending and exchange.dropped == 1


@pytest.fixture
def inputs():
    return MeasuredInputs('world', 50.0, (1.0, 1.0, 2.0), 10.0)


@pytest.mark.parametrize(
    'xy, quat, twist, kind, reason',
    [
        ((math.nan, 0.0), IDENTITY, (0.0, 0.0, 0.0), 'odom non-finite', 'rejected /odom with non-finite values [nan, '),
        ((0.0, 0.0), (0.0, 0.0, math.inf, 1.0), (0.0, 0.0, 0.0), 'odom non-finite', 'non-finite values'),
        (
            (0.0, 60.0),
            IDENTITY,
            (0.0, 0.0, 0.0),
            'odom far',
            'rejected /odom at (0, 60): beyond max_goal_distance 50.0 m',
        ),
        ((0.0, 0.0), IDENTITY, (0.0, 0.0, 25.0), 'odom twist', 'beyond 10 times the base velocity limits'),
        (
            (0.0, 0.0),
            (0.0, 0.0, 0.0, 0.0),
            (0.0, 0.0, 0.0),
            'odom zero quaternion',
            'rejected /odom with a zero quaternion',
        ),
    ],
)
def test_implausible_odometry_is_rejected_each_reason_apart(inputs, xy, quat, twist, kind, reason):
    odom, events = inputs.odometry(xy, quat, twist)
    assert odom is None and kinds(events) == [kind] and reason in events[0].message


@pytest.mark.parametrize('scale', [1.0, 3.0, 1e200, 1e-3])
def test_odometry_gives_the_heading_of_its_quaternion_at_any_scale(inputs, scale):
    quat = np.array([0.0, 0.0, math.sin(1.2), math.cos(1.2)]) * scale
    (pose, twist), events = inputs.odometry((1.0, -2.0), quat, (0.5, 0.0, 0.1))
    np.testing.assert_allclose(pose, [1.0, -2.0, 2.4], atol=1e-12)
    np.testing.assert_allclose(twist, [0.5, 0.0, 0.1])
    assert kinds(events) == ([] if scale == 1.0 else ['normalised'])


def test_a_differential_base_measuring_some_sideways_slip_is_not_a_glitch():
    """A differential base has no vy limit (it cannot drive sideways), yet its wheels slip: a
    measured vy of a few mm/s is odometry, not a glitch; one beyond ten times its driving
    speed limit still is."""
    differential = MeasuredInputs('world', 50.0, (1.0, 0.0, 2.0), 10.0)
    (pose, twist), events = differential.odometry((0.0, 0.0), IDENTITY, (0.3, 0.004, 0.1))
    np.testing.assert_allclose(twist, [0.3, 0.004, 0.1]) and not events
    odom, events = differential.odometry((0.0, 0.0), IDENTITY, (0.0, 12.0, 0.0))
    assert odom is None and kinds(events) == ['odom twist']


def test_the_measured_end_effector_pose_is_checked(inputs):
    pose = [0.5, 0.0, 1.0, 0.0, 1e200 * math.sqrt(0.5), 0.0, 1e200 * math.sqrt(0.5)]
    (position, rotation), events = inputs.ee_pose('world', pose)
    np.testing.assert_allclose(position, [0.5, 0.0, 1.0])
    np.testing.assert_allclose(rotation, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)
    assert kinds(events) == ['normalised']
    assert kinds(inputs.ee_pose('map', pose)[1]) == ['ee_pose frame']
    assert kinds(inputs.ee_pose('world', [0.5, 0.0, math.nan, *IDENTITY])[1]) == ['ee_pose invalid']
    assert kinds(inputs.ee_pose('world', [0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0])[1]) == ['ee_pose invalid']


def test_an_implausible_feasible_twist_is_rejected(inputs):
    twist, events = inputs.feasible_twist([0.5, -0.5, 1.0])
    np.testing.assert_allclose(twist, [0.5, -0.5, 1.0])
    assert events == []
    for bad in ([math.nan, 0.0, 0.0], [0.0, 0.0, 25.0]):
        twist, events = inputs.feasible_twist(bad)
        assert twist is None and kinds(events) == ['feasible twist']
        assert events[0].message.endswith('non-finite or beyond 10 times the base velocity limits')


def test_the_state_is_made_of_the_latest_inputs_while_they_are_fresh(inputs):
    latest = LatestInputs(inputs, TIMEOUT, ground_truth=False)
    q, dq = np.zeros(7), np.zeros(7)
    assert latest.state(q, dq, 0.0) == (None, 'no fresh /odom') and latest.base_pose(0.0) is None
    assert kinds(latest.odometry((60.0, 0.0), IDENTITY, (0.0, 0.0, 0.0), now=0.0)) == ['odom far']
    assert latest.odom is None  # rejected: not kept
    latest.odometry((1.0, 2.0), IDENTITY, (0.1, 0.0, 0.0), now=1.0)
    state, reason = latest.state(q, dq, 1.2)
    assert reason == '' and state.base_pose.tolist() == [1.0, 2.0, 0.0] and state.ee_position is None
    assert latest.last_state.base_pose.tolist() == [1.0, 2.0, 0.0] and latest.base_pose(1.2).tolist() == [1, 2, 0]
    assert latest.state(q, dq, 1.6) == (None, 'no fresh /odom') and latest.base_pose(1.6) is None
    latest.set_timeout(1.0)
    assert latest.state(q, dq, 1.6)[0] is not None


def test_with_ground_truth_feedback_the_state_needs_a_fresh_end_effector_pose(inputs):
    latest = LatestInputs(inputs, TIMEOUT, ground_truth=True)
    q, dq = np.zeros(7), np.zeros(7)
    latest.odometry((0.0, 0.0), IDENTITY, (0.0, 0.0, 0.0), now=0.0)
    assert latest.state(q, dq, 0.0) == (None, 'no fresh /ee_pose')
    assert kinds(latest.ee_pose('map', [0.5, 0.0, 1.0, *IDENTITY], now=0.0)) == ['ee_pose frame'] and latest.ee is None
    latest.ee_pose('world', [0.5, 0.0, 1.0, *IDENTITY], now=0.1)
    state, _ = latest.state(q, dq, 0.2)
    assert state.ee_position.tolist() == [0.5, 0.0, 1.0] and np.allclose(state.ee_rotation, np.eye(3))
    latest.odometry((0.0, 0.0), IDENTITY, (0.0, 0.0, 0.0), now=0.6)
    assert latest.state(q, dq, 0.7) == (None, 'no fresh /ee_pose')  # the pose came at 0.1


def test_events_are_logged_as_information_or_warnings_each_kind_throttled_apart():
    throttle = LogThrottle()
    events = [LogEvent('accepted', 'a'), LogEvent('rejected', 'r'), LogEvent('held', 'h'), LogEvent('stalled', 's')]
    assert throttle.lines(events, 0.0) == [('info', 'a'), ('warn', 'r'), ('warn', 'h'), ('warn', 's')]
    assert throttle.lines(events, 0.5) == [('info', 'a'), ('warn', 's')]  # rejected and held: too soon
    assert throttle.lines(events, 1.0) == [('info', 'a'), ('warn', 'r'), ('warn', 's')]  # held: 5 s apart
    assert ('warn', 'h') in throttle.lines(events, 5.0)


def test_the_report_gives_the_goals_status_and_the_last_commands_values(targets):
    goal(targets)
    d = SimpleNamespace(
        method='amp',
        mode='mobile',
        psi=0.5,
        position_error=0.3,
        orientation_error=0.1,
        limit_scale=1.0,
        accel_scale=1.0,
        null_scale=1.0,
        compensation_scale=1.0,
        compensated=True,
        limited=('arm',),
        sigma_min=0.02,
        cycle_time_s=0.0005,
        reference_time_left=0.0,
        clearance=math.inf,
        closest_pair='',
        collision_constraints=0,
        collision_changed=False,
    )
    command = SimpleNamespace(diagnostics=d, arm_velocity=np.ones(7), base_twist=np.zeros(3))
    level, message, values = targets.report(command)
    assert (level, message) == ('ok', 'mobile')
    assert values['cycle_time_us'] == pytest.approx(500.0) and values['limited'] == ['arm']
    assert values['goal_reached'] is False and values['arm_command'] is command.arm_velocity
    assert list(values)[:3] == ['method', 'mode', 'psi'] and list(values)[-2:] == ['arm_command', 'base_reference']
