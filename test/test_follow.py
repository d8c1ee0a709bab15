"""Following a plan at the robot's pace (:class:`~wmm_control.planning.follow.PlanFollower`): the
plan's clock waits for a base that lags, catches up with one that follows, is pulled forward by
one that is ahead, reports a stall only after the stall time without motion, and hands over to
the goal at the plan's end.

The plan is an L-shaped holonomic path of robot A timed by the planner's own timing (no search).
"""

import math

import numpy as np
import pytest

from wmm_control.errors import ConfigError
from wmm_control.geometry import wrap_angle
from wmm_control.kinematics import KinematicModel
from wmm_control.planning.follow import FollowParams, FollowState, PlanFollower
from wmm_control.planning.handoff import Handoff
from wmm_control.planning.timing import LinearPiece, time_path
from wmm_control.resolvers.interface import PoseTarget
from wmm_control.robot_config import load_robot

PARAMS = FollowParams()


@pytest.fixture(scope='module')
def plan():
    """(hand-off, goal): 1.5 m along x, then 1 m along y while turning a quarter turn."""
    cfg = load_robot('steerable')
    corner = np.array((1.5, 0.0, 0.0))
    pieces = [LinearPiece(np.zeros(3), corner), LinearPiece(corner, np.array((1.5, 1.0, 0.5 * math.pi)))]
    trajectory = time_path(pieces, cfg.base, cfg.period)
    handoff = Handoff.of(KinematicModel(cfg), trajectory, cfg.start.arm)
    goal = PoseTarget(handoff.points[-1].position + (0.2, 0.1, 0.0), handoff.points[-1].rotation)
    return handoff, goal


def _lag(a, b):
    return math.hypot(a[0] - b[0], a[1] - b[1]), abs(wrap_angle(float(a[2] - b[2])))


def test_the_handoff_keeps_the_planned_base_pose_of_each_point(plan):
    handoff, _ = plan
    assert handoff.base_poses.shape == (len(handoff.points), 3)
    assert np.allclose(handoff.base_poses[0], 0.0) and np.allclose(handoff.base_poses[-1], (1.5, 1.0, 0.5 * math.pi))


def test_the_clock_waits_for_a_base_that_lags_and_catches_up_when_it_follows(plan):
    handoff, goal = plan
    follower = PlanFollower(handoff, goal, PARAMS)
    dt = handoff.dt
    base = np.zeros(3)
    # the base does not move: the clock runs on until the planned pose is a lead ahead, then waits
    for _ in range(int(5.0 / dt)):
        step = follower.step(dt, base)
        assert step.state is not FollowState.APPROACH
        planned = follower.planned_pose()
        distance, angle = _lag(planned, base)
        assert distance <= PARAMS.base_lead_distance + 1e-9 and angle <= PARAMS.base_lead_angle + 1e-9
    waited = follower.clock
    assert 0.0 < waited < 0.5 * handoff.duration and follower.rate == pytest.approx(0.0, abs=1e-6)
    distance, _ = _lag(follower.planned_pose(waited), base)
    assert distance > PARAMS.slow_from * PARAMS.base_lead_distance  # it went as far as the lead lets it
    # the point given while waiting is a point of the plan, held still (no feedforward pulling on)
    assert np.allclose(step.target.velocity, 0.0, atol=1e-9) and np.allclose(step.target.acceleration, 0.0, atol=1e-9)
    assert any(
        step.target.position is p.position or np.allclose(step.target.position, p.position) for p in handoff.points
    )
    # the base now follows the plan one period behind: the clock runs at full pace again and the
    # plan ends within its duration plus what the wait and the ramps cost
    steps = 0
    while step.state is not FollowState.APPROACH:
        base = follower.planned_pose()
        step = follower.step(dt, base)
        steps += 1
        assert steps * dt < handoff.duration + 2.0
        assert 0.0 <= step.progress <= 1.0
    assert steps * dt > handoff.duration - waited - dt
    assert follower.rate == pytest.approx(1.0)
    # the plan done: the goal, for good, with the plan's last base pose (the stance) held at rest
    assert step.progress == 1.0 and follower.remaining_poses().shape == (0, 3)
    for target in (step.target, follower.step(dt, base).target):
        assert np.array_equal(target.position, goal.position) and np.array_equal(target.rotation, goal.rotation)
        assert not np.any(target.velocity) and np.allclose(target.base.pose, handoff.base_poses[-1])
        assert not np.any(target.base.rates) and not np.any(target.base.acceleration)
    # without hold_base, the goal itself
    alone = PlanFollower(handoff, goal, FollowParams(hold_base=False))
    while (step := alone.step(dt, alone.planned_pose())).state is not FollowState.APPROACH:
        pass
    assert step.target is goal


def _ee(handoff, k):
    """The end effector exactly on the point of sample k."""
    return handoff.points[k].position, handoff.points[k].rotation


def test_with_the_end_effector_the_clock_waits_for_it_and_slows_for_a_lagging_base_until_far_behind(plan):
    handoff, goal = plan
    dt = handoff.dt
    # the end effector stays where it starts: the point goes no further than the lead from it
    follower = PlanFollower(handoff, goal, PARAMS)
    still = _ee(handoff, 0)
    for _ in range(int(5.0 / dt)):
        step = follower.step(dt, handoff.base_poses[0], *still)
        assert np.linalg.norm(step.target.position - still[0]) <= PARAMS.lead_distance + 1e-9
    assert 0.0 < follower.clock < handoff.duration and follower.rate == pytest.approx(0.0, abs=1e-9)
    # the end effector on its point while the base stays behind (the arm reaches out): the clock
    # goes on at the base's floor a lead behind, not to a stop (a method whose end effector is on
    # its point does not move its base on), the floor fading to a stop at base_floor_lag leads:
    # the arm is not led on without limit
    follower = PlanFollower(handoff, goal, PARAMS)
    base = handoff.base_poses[0]
    paces = []
    for _ in range(int(20.0 / dt)):
        k = min(int(math.floor(follower.clock / dt + 1e-9)), len(handoff.points) - 1)
        lag = _lag(follower.planned_pose(), base)
        behind = max(lag[0] / PARAMS.base_lead_distance, lag[1] / PARAMS.base_lead_angle)
        step = follower.step(dt, base, *_ee(handoff, k))
        if behind >= 1.0:
            paces.append((behind, follower.rate))
    behind, rate = np.array(paces).T
    first = behind < 1.0 + 0.5 * (PARAMS.base_floor_lag - 1.0)
    assert first.sum() > 10 and np.all(rate[first] > 0.5 * PARAMS.base_floor - 1e-9)
    assert rate[0] == pytest.approx(PARAMS.base_floor, rel=0.05)
    fade = np.clip((PARAMS.base_floor_lag - behind) / (PARAMS.base_floor_lag - 1.0), 0.0, 1.0)
    assert np.all(rate <= PARAMS.base_floor * fade + 1e-9)
    assert rate[-1] < 0.05 * PARAMS.base_floor and PARAMS.base_floor_lag - 0.2 < behind[-1] <= PARAMS.base_floor_lag
    assert follower.clock < handoff.duration
    # and both on the plan: full pace
    follower = PlanFollower(handoff, goal, PARAMS)
    for _ in range(int(2.0 / dt)):
        k = min(int(math.floor(follower.clock / dt + 1e-9)), len(handoff.points) - 1)
        follower.step(dt, follower.planned_pose(), *_ee(handoff, k))
    assert follower.rate == pytest.approx(1.0)


def test_a_base_ahead_of_the_plan_pulls_its_clock_forward(plan):
    handoff, goal = plan
    follower = PlanFollower(handoff, goal, PARAMS)
    follower.step(handoff.dt, np.zeros(3))
    ahead = 1.0  # [s] of the plan
    follower.step(handoff.dt, handoff.base_poses[int(ahead / handoff.dt)])
    assert follower.clock >= ahead
    remaining = follower.remaining_poses()
    assert np.allclose(remaining[0], handoff.base_poses[int(round(follower.clock / handoff.dt))])
    assert np.allclose(remaining[-1], handoff.base_poses[-1])
    assert len(remaining) < len(handoff.base_poses)


def test_stalled_after_the_stall_time_without_motion_and_not_before(plan):
    handoff, goal = plan
    follower = PlanFollower(handoff, goal, PARAMS)
    dt = handoff.dt
    base = np.zeros(3)
    window = int(round(PARAMS.stall_time / dt))
    # the base never moves: the clock runs to the lead, creeps and stops
    planned = []
    for _ in range(int(30.0 / dt)):
        step = follower.step(dt, base)
        planned.append(follower.planned_pose())
        if step.state is FollowState.STALLED:
            break
    assert step.state is FollowState.STALLED, 'never stalled'
    # not before: over the stall time before it, the planned pose stayed within the progress steps
    k = len(planned) - 1
    assert k + 1 >= window
    recent = np.array(planned[-window:])
    assert np.max(np.linalg.norm(recent[:, :2] - recent[-1, :2], axis=1)) < 2.0 * PARAMS.stall_distance
    # and not long after the plan's pose stopped moving
    moving = np.linalg.norm(np.diff(np.array(planned)[:, :2], axis=0), axis=1) > 1e-3 * dt
    assert k * dt <= (np.flatnonzero(moving)[-1] + 1) * dt + PARAMS.stall_time + dt
    # it stays stalled while nothing moves, or the base moves but no nearer to the plan (pushed
    # sideways along an obstacle), and follows again once the base comes nearer
    assert follower.step(dt, base).state is FollowState.STALLED
    aside = base + (-PARAMS.stall_distance, 2.0 * PARAMS.stall_distance, 0.0)
    assert follower.step(dt, aside).state is FollowState.STALLED
    moved = base + (2.0 * PARAMS.stall_distance, 0.0, 0.0)
    assert follower.step(dt, moved).state is FollowState.FOLLOWING


def test_a_base_held_behind_while_the_end_effector_keeps_on_its_point_is_stalled(plan):
    handoff, goal = plan
    follower = PlanFollower(handoff, goal, PARAMS)
    dt = handoff.dt
    base = handoff.base_poses[0]
    # the base is held where it starts (by an obstacle the plan did not know, by the safety
    # stage) while the arm keeps the end effector on its point: the clock creeps on at the
    # base's floor, which is no progress once the base is a lead behind the planned pose
    behind = None
    for i in range(int(handoff.duration / (PARAMS.base_floor * dt))):
        k = min(int(math.floor(follower.clock / dt + 1e-9)), len(handoff.points) - 1)
        step = follower.step(dt, base, *_ee(handoff, k))
        assert step.state is not FollowState.APPROACH, 'crept to the plan\'s end without a stall'
        lag = _lag(follower.planned_pose(), base)
        if behind is None and max(lag[0] / PARAMS.base_lead_distance, lag[1] / PARAMS.base_lead_angle) >= 1.0:
            behind = i
        if step.state is FollowState.STALLED:
            break
    assert step.state is FollowState.STALLED, 'never stalled'
    # within the stall time of falling a lead behind (the last step of progress a little before)
    assert behind is not None and PARAMS.stall_time - 0.5 <= (i - behind + 1) * dt <= PARAMS.stall_time + 2.0 * dt
    assert follower.clock > 0.0 and follower.rate > 0.0  # the clock was still creeping
    # the base moving on along the plan is progress again
    k = min(int(math.floor(follower.clock / dt + 1e-9)), len(handoff.points) - 1)
    ahead = handoff.base_poses[int(round(0.5 / dt))]
    assert follower.step(dt, ahead, *_ee(handoff, k)).state is FollowState.FOLLOWING


def test_a_slow_base_is_not_stalled(plan):
    handoff, goal = plan
    follower = PlanFollower(handoff, goal, PARAMS)
    dt = handoff.dt
    base = np.zeros(3)
    # the base creeps at a quarter of the plan's pace: slower than planned, never stalled
    for _ in range(int(3.0 * handoff.duration / dt)):
        step = follower.step(dt, base)
        assert step.state is not FollowState.STALLED
        if step.state is FollowState.APPROACH:
            break
        target = follower.planned_pose()
        base = base + 0.25 * (target - base) * dt / 0.1
    assert step.state is FollowState.APPROACH


@pytest.mark.parametrize(
    'bad',
    [
        {'lead_distance': 0.0},
        {'lead_angle': -0.1},
        {'base_lead_distance': math.inf},
        {'base_floor': 1.5},
        {'base_floor_lag': 1.0},
        {'base_floor_lag': math.inf},
        {'slow_from': 1.0},
        {'slow_from': -0.1},
        {'rate_slew': math.nan},
        {'stall_time': 0.0},
        {'stall_distance': -1.0},
        {'lookahead': -1.0},
        {'settle_distance': 0.0},
        {'settle_time': math.inf},
        {'lead_distance': 'far'},
    ],
)
def test_bad_params_are_rejected(bad):
    with pytest.raises(ConfigError, match=next(iter(bad))):
        FollowParams(**bad)


def test_bad_steps_are_rejected(plan):
    handoff, goal = plan
    follower = PlanFollower(handoff, goal)
    with pytest.raises(ValueError):
        follower.step(-0.01, np.zeros(3))
    with pytest.raises(ValueError):
        follower.step(0.01, (0.0, math.nan, 0.0))
    with pytest.raises(ValueError):
        follower.step(0.01, (0.0, 0.0))
    with pytest.raises(ValueError):
        follower.step(0.01, np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError):
        follower.step(0.01, np.zeros(3), (0.0, math.inf, 0.0), np.eye(3))
    assert follower.clock == 0.0


def test_the_arm_moving_to_the_stances_posture_is_progress_and_an_arm_held_is_not():
    """After the path the base rests at the stance while the arm moves to the stance's posture
    (:meth:`Handoff.of` with ``q_stance``), longer than the stall time here: the points moving
    on are progress, and the follower hands over to the goal with that posture. An end effector
    that does not follow them stalls."""
    cfg = load_robot('steerable')
    trajectory = time_path([LinearPiece(np.zeros(3), np.array((0.5, 0.0, 0.0)))], cfg.base, cfg.period)
    q_stance = cfg.start.arm + 1.0
    handoff = Handoff.of(KinematicModel(cfg), trajectory, cfg.start.arm, q_stance, fraction=0.05)
    motion = handoff.duration - trajectory.duration
    assert motion > PARAMS.stall_time + 1.0
    goal = PoseTarget(handoff.points[-1].position, handoff.points[-1].rotation)
    dt = handoff.dt
    follower = PlanFollower(handoff, goal, PARAMS)
    step = follower.step(dt, np.zeros(3), *_ee(handoff, 0))
    for _ in range(int(3.0 * handoff.duration / dt)):
        assert step.state is FollowState.FOLLOWING
        k = int(np.argmin([np.linalg.norm(p.position - step.target.position) for p in handoff.points]))
        step = follower.step(dt, follower.planned_pose(), *_ee(handoff, k))
        if step.state is FollowState.APPROACH:
            break
    assert step.state is FollowState.APPROACH
    assert step.target.base.stance and np.array_equal(step.target.base.arm, q_stance)
    # the end effector held where the path ends: the arm's motion stalls within the stall time
    held = PlanFollower(handoff, goal, PARAMS)
    end = len(trajectory.poses) - 1
    states = []
    for _ in range(int((handoff.duration + PARAMS.stall_time) / dt)):
        k = min(int(round(held.clock / dt)), end)
        states.append(held.step(dt, held.planned_pose(), *_ee(handoff, k)).state)
    assert FollowState.APPROACH not in states and states[-1] is FollowState.STALLED


def test_the_arms_motion_to_the_stances_posture_waits_for_the_base_at_rest_at_the_stance():
    """A base that reaches the path's end short of the stance, then coasts through it, holds the
    plan's clock at the arm's motion's first point (not stalled, however long within
    ``settle_time``); at rest there the arm's motion goes on; a base kept off the stance goes to
    the final approach without it after ``settle_time``."""
    cfg = load_robot('steerable')
    trajectory = time_path([LinearPiece(np.zeros(3), np.array((0.5, 0.0, 0.0)))], cfg.base, cfg.period)
    handoff = Handoff.of(KinematicModel(cfg), trajectory, cfg.start.arm, cfg.start.arm + 1.0, fraction=0.05)
    goal = PoseTarget(handoff.points[-1].position, handoff.points[-1].rotation)
    dt, start = handoff.dt, handoff.path_end * handoff.dt
    stance = handoff.base_poses[handoff.path_end]
    short = stance - (0.25, 0.0, 0.0)
    patient = FollowParams(settle_time=3.0 * PARAMS.stall_time)

    def to_the_path_end(params):
        follower = PlanFollower(handoff, goal, params)
        while follower.clock < start - 0.2:
            follower.step(dt, follower.planned_pose())
        return follower

    follower = to_the_path_end(patient)
    for _ in range(int(1.5 * PARAMS.stall_time / dt)):  # short of the stance, at rest
        assert follower.step(dt, short).state is FollowState.FOLLOWING
    assert follower.clock == pytest.approx(start)
    base = short.copy()
    for _ in range(int(0.5 / 0.1 / dt)):  # coasting through the stance at 0.1 m/s
        base = base + (0.1 * dt, 0.0, 0.0)
        assert follower.step(dt, base).state is FollowState.FOLLOWING
        assert follower.clock == pytest.approx(start)
    for _ in range(int(2.0 / dt)):  # back at rest at the stance: the arm's motion goes on
        step = follower.step(dt, stance)
    assert follower.clock > start and step.state is FollowState.FOLLOWING
    assert not np.array_equal(step.target.base.arm, cfg.start.arm)
    # a base kept off the stance: the arm's motion waits for settle_time, then the final approach
    held = to_the_path_end(PARAMS)
    waited = 0.0
    while (step := held.step(dt, short)).state is not FollowState.APPROACH:
        assert held.clock == pytest.approx(start, abs=0.2)
        waited += dt
        assert waited < PARAMS.settle_time + 1.0
    assert waited > PARAMS.settle_time - 0.2 - dt
    assert np.array_equal(step.target.base.arm, cfg.start.arm + 1.0)
