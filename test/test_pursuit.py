"""GoalPursuit, the goal_planner node's decisions, ROS-free: goals checked as the resolver checks
them, a goal within reach sent on unchanged, a plan's points then the goal, no way with the
planner's reason, a plan made again when an obstacle comes onto the rest of the path or progress
stalls, and the robot held whenever the pursuit stops or changes course."""

import time

import numpy as np
import pytest

from wmm_control.geometry import quaternion_from_matrix, rotation_z
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.obstacles import Obstacle, load_obstacles
from wmm_control.planning.follow import FollowParams
from wmm_control.planning.pursuit import GoalPursuit, PursuitState
from wmm_control.robot_config import load_robot

ROBOT = load_robot('steerable')
START = np.asarray(ROBOT.start.base_pose, dtype=float)
Q_ARM = np.asarray(ROBOT.start.arm, dtype=float)
BEHIND_TABLE = np.array([2.4, -0.2, 1.0])


def _start_ee():
    model = KinematicModel(ROBOT)
    model.update(START, Q_ARM)
    return model.ee_placement_world()


def pose(position, yaw=0.0):
    rotation = rotation_z(yaw) @ _start_ee()[1]
    return np.concatenate((position, quaternion_from_matrix(rotation)))


@pytest.fixture
def pursuit():
    out = GoalPursuit(ROBOT, load_obstacles('table_pillar'), 'world', 50.0, FollowParams(stall_time=1.0), max_replans=1)
    yield out
    out.close()


def settle(pursuit, base=START, timeout=120.0):
    """Step (0.025 s each, the base standing at ``base``) until the plan is in; every step's output."""
    steps = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        steps.append(pursuit.step(0.025, base, Q_ARM))
        if pursuit.state is not PursuitState.PLANNING:
            return steps
        time.sleep(0.01)
    raise AssertionError('no plan in time')


def events(steps):
    return [e for s in steps for e in s.events]


def test_bad_goals_are_refused_with_the_resolvers_reasons_and_nothing_is_sent(pursuit):
    for frame, values, reason in (
        ('world', pose([np.nan, 0.0, 1.0]), 'non-finite'),
        ('map', pose([1.0, 0.0, 1.0]), "frame 'map'"),
        ('world', pose([0.0, 90.0, 1.0]), 'max_goal_distance'),
        ('world', pose([1.0, 0.0, -1.0]), 'below the floor'),
        ('world', np.array([1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]), 'zero quaternion'),
    ):
        said = pursuit.new_goal(frame, values)
        assert pursuit.state is PursuitState.REJECTED and reason in said[-1].message
        out = pursuit.step(0.025, START, Q_ARM)
        assert out.reference is None and not out.forward_goal and out.hold is None  # nothing given yet: no hold
    assert pursuit.counters.goals_rejected == 5 and pursuit.counters.plans == 0


def test_a_goal_within_reach_is_sent_on_unchanged_and_the_same_goal_again_changes_nothing(pursuit):
    near = pose(_start_ee()[0] + [0.1, 0.0, 0.0])
    pursuit.new_goal('world', near)
    steps = settle(pursuit)
    assert pursuit.state is PursuitState.DIRECT and steps[-1].forward_goal
    assert not any(s.reference is not None for s in steps) and steps[-1].path.shape == (0, 3)
    assert pursuit.new_goal('world', near) == [] and pursuit.state is PursuitState.DIRECT
    # a refused goal now holds the robot where its end effector is
    pursuit.new_goal('world', pose([np.inf, 0.0, 1.0]))
    hold = pursuit.step(0.025, START, Q_ARM).hold
    assert hold is not None and hold.position == pytest.approx(_start_ee()[0])
    assert pursuit.step(0.025, START, Q_ARM).hold is None  # once


def test_a_goal_waits_for_the_base_pose_and_says_so_and_a_nan_goal_leaves_no_nan_in_the_status(pursuit):
    assert not pursuit.needs_base
    pursuit.new_goal('world', pose(_start_ee()[0] + [0.1, 0.0, 0.0]))
    for _ in range(3):  # stale odometry: no plan, and the pursuit says it needs the base's pose
        out = pursuit.step(0.025, None, Q_ARM)
        assert not out.forward_goal and pursuit.state is PursuitState.PLANNING and pursuit.needs_base
    settle(pursuit)
    assert pursuit.state is PursuitState.DIRECT and not pursuit.needs_base
    pursuit.new_goal('world', pose([np.nan, 0.0, 1.0]))
    assert not pursuit.needs_base
    _, message, values = pursuit.status()
    assert 'position.x' in values['reason'] and 'nan' not in (message + values['reason']).lower()


def test_a_goal_inside_the_table_has_no_way_with_the_planners_reason(pursuit):
    pursuit.new_goal('world', pose([1.5, -0.2, 0.3]))
    steps = settle(pursuit)
    assert pursuit.state is PursuitState.NO_WAY and "obstacle 'table'" in pursuit.reason
    assert not any(s.forward_goal or s.reference is not None for s in steps)
    assert pursuit.status()[0] == 'warn' and 'no_way' in pursuit.status()[1]


def test_a_base_that_keeps_to_the_plan_gets_its_points_then_the_goal(pursuit):
    pursuit.new_goal('world', pose(BEHIND_TABLE, yaw=0.5 * np.pi))
    steps = settle(pursuit)
    assert pursuit.state is PursuitState.FOLLOWING
    planned = steps[-1].path
    assert len(planned) > 10 and planned[-1, 0] > 1.75
    follower = pursuit.follower
    out, points = None, 0
    handoff = follower.handoff
    for _ in range(5 * len(handoff.points)):  # the base and the arm where the plan's clock says they are
        k = min(int(follower.clock / handoff.dt), len(handoff.points) - 1)
        out = pursuit.step(0.025, handoff.base_poses[k], handoff.points[k].base.arm)
        if pursuit.state is PursuitState.APPROACH:
            break
        points += out.reference is not None
    assert pursuit.state is PursuitState.APPROACH and points > 0.9 * len(handoff.points)
    # the final approach: the goal itself, at rest, with the stance (the plan's last pose) as its
    # base and the arm's posture there (the last point's: the arm's motion to it came after the path)
    approach = out.reference
    assert approach is not None and not out.forward_goal
    np.testing.assert_allclose(approach.position, BEHIND_TABLE)
    np.testing.assert_allclose(approach.velocity, 0.0)
    np.testing.assert_allclose(approach.base.pose, planned[-1])
    np.testing.assert_allclose(approach.base.rates, 0.0)
    assert len(handoff.points) > len(planned) and np.array_equal(approach.base.arm, handoff.stance_arm)
    np.testing.assert_allclose(handoff.points[-1].base.arm, handoff.stance_arm)
    assert 'as the last point, with the stance' in ' '.join(e.message for e in out.events)
    later = [pursuit.step(0.025, planned[-1], Q_ARM) for _ in range(5)]
    assert all(s.reference is None and not s.forward_goal for s in later), 'sent once: the resolver holds it'


def test_an_obstacle_on_the_rest_of_the_path_makes_it_plan_again(pursuit):
    pursuit.new_goal('world', pose(BEHIND_TABLE, yaw=0.5 * np.pi))
    settle(pursuit)
    ahead = pursuit.follower.remaining_poses()[200]
    box = Obstacle('moved/1', 'box', (0.3, 0.3, 0.6), np.array([ahead[0], ahead[1], 0.3]), np.eye(3))
    pursuit.step(0.025, START, Q_ARM)  # a point given: the resolver pursues it
    pursuit.set_obstacles((*pursuit.obstacles, box))
    steps = []
    end = time.monotonic() + 10.0
    while pursuit.state is PursuitState.FOLLOWING and time.monotonic() < end:
        steps.append(pursuit.step(0.0, START, Q_ARM))
        time.sleep(0.01)
    said = [e.message for e in events(steps)]
    assert any('from the planned path' in m and 'planning again' in m for m in said), said
    assert any(s.hold is not None for s in steps)  # held while it plans again
    steps = settle(pursuit)
    assert pursuit.state is PursuitState.FOLLOWING
    path = steps[-1].path
    assert np.min(np.hypot(path[:, 0] - ahead[0], path[:, 1] - ahead[1])) > 0.2


def test_progress_that_stalls_is_planned_again_then_the_goal_goes_to_the_resolver(pursuit):
    pursuit.new_goal('world', pose(BEHIND_TABLE, yaw=0.5 * np.pi))
    settle(pursuit)
    said, forwarded = [], False
    for _ in range(2):  # the base never moves: stalled after 1 s, planned again once, then the goal
        for _ in range(400):
            out = pursuit.step(0.025, START, Q_ARM)
            said += [e.message for e in out.events]
            forwarded = forwarded or out.forward_goal
            if pursuit.state is not PursuitState.FOLLOWING:
                break
        if pursuit.state is PursuitState.PLANNING:
            settle(pursuit)
    assert any('progress stalled' in m and 'planning again' in m for m in said), said
    assert pursuit.state is PursuitState.APPROACH and forwarded
    assert any('after 1 plans made again: the goal goes to the resolver' in m for m in said), said


def test_a_stall_at_the_stance_planned_again_gives_the_final_approach_with_the_stance_not_the_bare_goal(pursuit):
    pursuit.new_goal('world', pose(BEHIND_TABLE, yaw=0.5 * np.pi))
    settle(pursuit)
    follower = pursuit.follower
    handoff = follower.handoff
    stance = handoff.base_poses[handoff.path_end]
    for _ in range(20 * len(handoff.points)):  # the base keeps to the path; the arm never takes the stance's posture
        k = min(int(follower.clock / handoff.dt), handoff.path_end)
        pursuit.step(0.025, handoff.base_poses[k], handoff.points[k].base.arm)
        if pursuit.state is not PursuitState.FOLLOWING:
            break
    assert pursuit.state is PursuitState.PLANNING and pursuit.replans == 1
    steps = settle(pursuit, base=stance)
    # the plan made again finds the goal within reach from the stance: the resolver gets it as
    # the final approach, held at this stance with the posture found for it, not as a bare goal
    # (which left task sharing's posture pull free to move the base from the stance)
    assert pursuit.state is PursuitState.APPROACH and not any(s.forward_goal for s in steps)
    approach = steps[-1].reference
    assert approach is not None and approach.base is not None and approach.base.stance
    np.testing.assert_allclose(approach.position, BEHIND_TABLE)
    np.testing.assert_allclose(approach.base.pose, stance)
    model = KinematicModel(ROBOT)
    model.update(stance, approach.base.arm)
    assert np.linalg.norm(model.ee_placement_world()[0] - BEHIND_TABLE) < 0.01  # the stance's posture reaches it
    later = [pursuit.step(0.025, stance, Q_ARM) for _ in range(5)]
    assert all(s.reference is None and not s.forward_goal for s in later), 'sent once: the resolver holds it'


def test_the_first_plans_path_end_gives_the_runs_limit_and_a_plan_made_again_does_not_move_it(pursuit):
    """A study's run (``wmm_randomized --plan``) counts its limit from when the base path of the
    goal's first plan is planned to end: the time the plan came, on the clock of the periods
    stepped, plus the path's timed duration; a plan made again does not move it, a new goal
    starts afresh."""
    assert pursuit.planned_end is None and pursuit.limit(90.0) == 90.0
    pursuit.new_goal('world', pose(BEHIND_TABLE, yaw=0.5 * np.pi))
    steps = settle(pursuit)
    handoff = pursuit.follower.handoff
    came = 0.025 * len(steps)  # the step that took the plan
    assert pursuit.elapsed == pytest.approx(came)
    assert pursuit.planned_end == pytest.approx(came + handoff.path_end * handoff.dt)
    assert handoff.path_end * handoff.dt > 1.0 and handoff.path_end < len(handoff.points) - 1
    assert pursuit.limit(90.0) == pytest.approx(90.0 + pursuit.planned_end)
    first = pursuit.planned_end
    for _ in range(400):  # the base never moves: stalled after 1 s, planned again
        pursuit.step(0.025, START, Q_ARM)
        if pursuit.state is not PursuitState.FOLLOWING:
            break
    settle(pursuit)
    assert pursuit.replans == 1 and pursuit.planned_end == first
    assert pursuit.account()['planned_end_s'] == first
    pursuit.new_goal('world', pose(BEHIND_TABLE + np.array([0.0, 0.1, 0.0]), yaw=0.5 * np.pi))
    assert pursuit.planned_end is None
