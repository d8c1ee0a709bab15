"""One orchestration of a period for both engines (:class:`wmm_control.cycle.Cycle`): inputs
checked as they come, the robot held on a refused or stale input, and the nodes and the direct
engine answering the same inputs with the same commands."""

import math

import numpy as np
import pinocchio as pin

from sim_bridge.world import SimWorld
from wmm_control.base import make_base_controller
from wmm_control.cycle import Cycle
from wmm_control.experiments.direct import run_scenario
from wmm_control.experiments.ros_run import run_with_nodes
from wmm_control.experiments.scenario import load_scenario
from wmm_control.resolvers import make_resolver
from wmm_control.robot_config import load_robot


def _quat_xyzw(rotation):
    return pin.Quaternion(rotation).coeffs()


def _cycle(method='task_sharing', robot='steerable'):
    config = load_robot(robot)
    resolver = make_resolver(method, config)
    return Cycle(resolver, make_base_controller(config, config.period), config.period), config


def _step(cycle, config, now, q=None):
    n = config.arm.n
    q = np.asarray(config.start.arm, dtype=float) if q is None else q
    groups = {g: np.zeros(len(j)) for g, j in cycle.base_controller.command_groups.items()}
    return cycle.step(q, np.zeros(n), groups, None, now)


def test_the_cycle_holds_the_robot_on_a_refused_goal_and_on_stale_odometry():
    cycle, config = _cycle()
    period, rp = config.period, None
    rp = cycle.resolver_period
    start_pose = np.zeros(3)
    rp.odometry(start_pose[:2], (0, 0, 0, 1), np.zeros(3), 0.0)
    held = _step(cycle, config, 0.0)
    assert held.command is None and not held.stale  # no goal yet
    assert not np.any(held.arm_velocity) and not np.any(held.base.twist)
    good = np.array([1.5, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0])
    assert [e.kind for e in rp.goal('world', good, 0.0)] == ['accepted']
    moving = _step(cycle, config, period)
    assert moving.command is not None and np.any(moving.arm_velocity) and np.any(moving.command.base_twist)
    # a goal with NaN, one inside the chassis, one in another frame: each refused, the robot held
    for bad, frame in (
        (np.full(7, math.nan), 'world'),
        (np.array([0.0, 0.0, 0.2, 0, 0, 0, 1]), 'world'),
        (good, 'map'),
    ):
        rp.odometry(start_pose[:2], (0, 0, 0, 1), np.zeros(3), 2 * period)
        assert [e.kind for e in rp.goal(frame, bad, 2 * period)] == ['rejected']
        answer = _step(cycle, config, 2 * period)
        assert answer.command is None and not np.any(answer.arm_velocity)
    # the same good goal again is taken; odometry older than state_timeout holds the robot
    rp.goal('world', good, 3 * period)
    stale = _step(cycle, config, 3 * period + rp.settings.state_timeout + 0.01)
    assert stale.command is None and stale.stale == 'no fresh /odom' and rp.stale_cycles == 1


def test_a_feasible_twist_beyond_reason_leaves_the_arm_command_uncompensated():
    cycle, config = _cycle()
    rp = cycle.resolver_period
    rp.odometry((0.0, 0.0), (0, 0, 0, 1), np.zeros(3), 0.0)
    rp.goal('world', np.array([2.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0]), 0.0)
    plan = rp.plan(np.asarray(config.start.arm, dtype=float), np.zeros(config.arm.n), 0.0)
    rp.hold('k', plan.command)
    twist, events = rp.feasible_twist(np.array([1e308, 0.0, 0.0]))
    assert twist is None and [e.kind for e in events] == ['feasible twist']
    command, _ = rp.finish(twist)
    assert command is plan.command and rp.counters['compensation_dropped'] == 1


REFUSED_YAML = """scenario:
  name: refused_goal
  robot: steerable
  frame: world
  duration: 3.0
  goals:
    - {t: 0.0, pose: [1.2, 0.4, 1.0, pi/2, 0.0, 0.3]}
    - {t: 1.0, pose: [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]}
    - {t: 2.0, pose: [1.0, -0.3, 1.0, pi/2, 0.0, 0.0]}
  experiment:
    runs:
      - {name: ts, method: task_sharing, feedback: ground_truth}
"""


def test_both_engines_hold_the_robot_on_a_goal_inside_its_body_and_go_on_alike(tmp_path):
    """A goal inside the chassis between two good ones: the resolver node and the direct engine
    both refuse it and hold the robot for that second (no command logged), then take the next
    goal, with the same commands (to the messages' round-off, amplified by the closed loop)."""
    path = tmp_path / 'refused.yaml'
    path.write_text(REFUSED_YAML)
    scenario = load_scenario(str(path))
    nodes = run_with_nodes(scenario, scenario.runs[0])
    world = SimWorld('steerable')
    direct = run_scenario(world, make_resolver('task_sharing', 'steerable'), scenario)
    world.close()
    for log in (nodes, direct):
        t = np.asarray(log.t)
        assert not np.any((t > 1.05) & (t < 1.95))  # held: the node publishes zeros, nothing is logged
        assert np.any(t < 1.0) and np.any(t > 2.05)
    # the nodes' goal reaches the resolver one period after the first state
    shift = 0.025
    for a, b in ((nodes, direct),):
        ta, tb = np.asarray(a.t), np.asarray(b.t) + shift
        common = [(i, int(np.argmin(np.abs(tb - x)))) for i, x in enumerate(ta) if np.min(np.abs(tb - x)) < 1e-6]
        assert len(common) > 60
        i, j = np.array(common).T
        np.testing.assert_allclose(np.asarray(a.arm_command)[i], np.asarray(b.arm_command)[j], atol=2e-3)
