"""sim_bridge.supervision: the simulator node's rules between steps, without a ROS graph."""

import math

import numpy as np
import pytest

from sim_bridge import SimWorld
from sim_bridge.slip import VARIANCE_FLOOR, OdometryCovariance
from sim_bridge.supervision import CommandWatchdog, LockstepWait, ObstacleContact, poll_period
from sim_bridge.supervision import statuses, step_world, wait_groups
from wmm_control.kinematics.obstacles import Obstacle

GROUPS = ('arm', 'steer', 'drive')


@pytest.fixture
def world_a():
    w = SimWorld('A', start_base_pose=(0.0, 0.0, 0.0))
    yield w
    w.close()


def test_wait_groups_reads_all_a_list_and_names_unknown_groups():
    assert wait_groups('all', GROUPS) == (frozenset(GROUPS), '')
    assert wait_groups(' arm , drive,', GROUPS) == (frozenset({'arm', 'drive'}), '')
    chosen, reason = wait_groups('arm,wheel', GROUPS)
    assert chosen == {'arm', 'wheel'}
    assert reason == "lockstep_groups: unknown groups ['wheel']; this robot has ['arm', 'drive', 'steer']"
    assert wait_groups(' , ', GROUPS)[1].startswith('lockstep_groups: unknown groups []')


def test_poll_period_is_a_quarter_of_the_timeout_at_most_ten_milliseconds():
    assert poll_period(0.02) == pytest.approx(0.005)
    assert poll_period(60.0) == 0.01


def test_the_watchdog_reports_a_group_once_when_its_command_grows_old():
    dog = CommandWatchdog(GROUPS, timeout=0.1)
    assert all(dog.timed_out(g) for g in GROUPS)  # nothing commanded yet
    assert dog.expire(5.0) == []  # already timed out: not reported again
    dog.accepted('arm', 1.0)
    assert not dog.timed_out('arm') and dog.age('arm', 1.05) == pytest.approx(0.05)
    assert dog.expire(1.09) == []  # younger than 0.1 s: still fresh
    assert dog.expire(1.2) == [('arm', pytest.approx(0.2), 0.1)]
    assert dog.timed_out('arm') and dog.expire(1.3) == []
    dog.accepted('arm', 2.0)
    dog.set_timeout(1.0)
    assert dog.expire(2.5) == []
    assert dog.expire(3.5) == [('arm', pytest.approx(1.5), 1.0)]
    assert dog.age('steer', 3.5) == math.inf


def test_lockstep_steps_when_the_last_awaited_group_answers_the_state():
    wait = LockstepWait(frozenset({'arm', 'steer'}))
    assert not wait.arrived('arm') and not wait.arrived('steer')  # nothing awaited yet
    wait.begin(10.0)
    assert not wait.arrived('arm')
    assert not wait.arrived('drive')  # not awaited: counts for nothing
    assert wait.missing() == ['steer']
    assert wait.arrived('steer')
    wait.end()
    assert not wait.overdue(100.0, 0.5) and wait.missing() == ['arm', 'steer']
    wait.begin(20.0)
    assert not wait.overdue(20.5, 0.5) and wait.overdue(20.6, 0.5)
    wait.begin(30.0)  # a new state forgets the answers to the last one
    assert not wait.arrived('steer')


def test_obstacle_contact_counts_contacts_and_keeps_the_deepest():
    contact = ObstacleContact()
    assert contact.values['clearance_m'] == math.inf and not contact.touching
    assert contact.update(0.2, 'base_link', 'wall') == ''
    assert contact.update(-0.004, 'arm_link_3', 'wall') == "arm_link_3 is 4.0 mm into obstacle 'wall'"
    assert contact.touching
    contact.update(-0.001, 'arm_link_3', 'wall')
    assert contact.update(0.05, 'base_link', 'pillar') == '' and not contact.touching
    assert contact.values == {
        'clearance_m': 0.05,
        'closest_link': 'base_link',
        'closest_obstacle': 'pillar',
        'contact_periods': 2,
        'deepest_contact_m': 0.004,
    }


def test_statuses_warn_on_stale_or_clamped_commands_and_err_in_contact():
    dog = CommandWatchdog(('arm', 'wheel'), timeout=0.1)
    dog.accepted('arm', 1.0)
    counters = {'arm': {'clamped': 0, 'rejected': 0}, 'wheel': {'clamped': 0, 'rejected': 0}}
    contact = ObstacleContact()
    found = statuses(counters, dog, 1.05, 'lockstep, kinematic', (2.0, 80, 4.0), contact, 0)
    assert [(s.part, s.level, s.message) for s in found] == [
        ('arm commands', 'ok', 'commanded'),
        ('wheel commands', 'warn', 'no fresh command (zero velocity)'),
        ('simulation', 'ok', 'lockstep, kinematic'),
    ]
    assert found[0].values['command_age_s'] == pytest.approx(0.05)
    assert found[2].values == {'sim_time_s': 2.0, 'steps': 80, 'real_time_factor': 0.5}
    counters['arm']['clamped'] = 1
    contact.update(-0.01, 'wheel_fl', 'box')
    found = statuses(counters, dog, 1.05, 'realtime, physics', (0.0, 0, 0.0), contact, 2)
    assert found[0].level == 'warn'
    assert found[2].values['real_time_factor'] == 0.0  # no wall time yet
    assert found[3] == ('obstacles', 'error', 'wheel_fl in contact with box', contact.values)
    contact.update(0.3, 'wheel_fl', 'box')
    assert statuses(counters, dog, 1.05, '', (0.0, 0, 1.0), contact, 2)[3][1:3] == ('ok', 'clear (2 obstacles)')


def test_a_step_zeroes_an_expired_command_and_advances_the_covariance(world_a):
    dog = CommandWatchdog(world_a.command_groups, timeout=0.1)
    world_a.set_command('drive', np.full(4, 2.0))
    dog.accepted('drive', 0.0)
    covariance = OdometryCovariance()
    contact = ObstacleContact()
    assert step_world(world_a, dog, contact, covariance, 0.05) == ([], '')
    assert world_a.odom_twist()[0] == pytest.approx(0.18)  # r_w·φ̇ straight ahead
    timeouts, touching = step_world(world_a, dog, contact, covariance, 0.2)
    assert timeouts == ['drive command timed out (age 0.200 s > 0.1 s): zero velocity'] and touching == ''
    np.testing.assert_allclose(world_a.odom_twist(), 0.0, atol=1e-12)
    assert contact.values['contact_periods'] == 0  # no obstacles: not checked
    np.testing.assert_allclose(covariance.twist, VARIANCE_FLOOR)  # no slip: odometry exact


def test_a_step_into_an_obstacle_reports_the_contact(world_a):
    world_a.set_obstacles([Obstacle('block', 'box', (0.4, 0.4, 0.4), np.array([0.0, 0.0, 0.2]), np.eye(3))])
    contact = ObstacleContact()
    dog = CommandWatchdog(world_a.command_groups, timeout=0.1)
    _, touching = step_world(world_a, dog, contact, OdometryCovariance(), 0.0)
    assert touching.endswith("into obstacle 'block'")
    assert contact.touching and contact.values['contact_periods'] == 1
