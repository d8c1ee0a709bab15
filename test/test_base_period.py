"""wmm_control.base.period: where a base controller's period starts from and what of its answer
goes out, without a ROS graph."""

import math

import numpy as np
import pytest

from wmm_control.base import BaseCommand, make_base_controller
from wmm_control.base.period import BasePeriod
from wmm_control.robot_config import load_robot


class RecordingBase:
    """A base controller that answers with a set command and records its resets."""

    command_groups = {'steer': ('s1', 's2'), 'drive': ('d1', 'd2')}
    required_groups = ('steer',)
    rate_limits = {'steer': 1.0, 'drive': 10.0}
    resync_from_rates = False

    def __init__(self):
        self.resets = []
        self.answer = BaseCommand({'drive': np.array([1.0, 2.0]), 'steer': np.zeros(2)}, np.ones(3), 'ok', None)

    def reset(self, positions=None, rates=None):
        self.resets.append((positions, rates))

    def step(self, reference, positions=None):
        return self.answer


POSITIONS = {'steer': np.zeros(2), 'drive': np.zeros(2)}
APPLIED = {'steer': np.zeros(2), 'drive': np.array([1.0, 2.0])}


def test_a_resync_restarts_a_steerable_base_at_rest_and_a_wheeled_one_from_its_rates():
    base = RecordingBase()
    period = BasePeriod(base, applied_rate_tolerance=0.1)
    assert period.start(POSITIONS, APPLIED, resync=True) == ''
    assert base.resets == [(POSITIONS, None)]
    base.resync_from_rates = True
    period.start(POSITIONS, APPLIED, resync=True)
    assert base.resets[-1] == (POSITIONS, APPLIED)


def test_a_command_not_applied_or_a_dropped_answer_restarts_from_the_measured_state():
    base = RecordingBase()
    period = BasePeriod(base, applied_rate_tolerance=0.1)
    assert period.start(POSITIONS, APPLIED, resync=False) == '' and base.resets == []  # nothing sent yet
    answer = period.step(np.zeros(3), POSITIONS)
    assert list(answer.rates) == ['steer', 'drive']  # the controller's group order
    period.published(answer)
    assert period.start(POSITIONS, APPLIED, resync=False) == '' and base.resets == []  # applied: goes on
    lost = {'steer': np.zeros(2), 'drive': np.array([1.0, 2.5])}
    why = period.start(POSITIONS, lost, resync=False)
    assert 'not applied as sent' in why and base.resets == [(POSITIONS, lost)]
    assert period.start(POSITIONS, None, resync=False) == ''  # no rates: nothing to check
    period.dropped()
    assert period.start(POSITIONS, None, resync=False) == '' and base.resets[-1] == (POSITIONS, None)
    assert period.start(POSITIONS, lost, resync=False)  # once: the drop is forgotten
    assert BasePeriod(base, 0.0).start(POSITIONS, lost, resync=False) == ''  # tolerance 0: never checked


def test_a_non_finite_command_goes_out_as_zero_rates_and_resets_the_controller():
    base = RecordingBase()
    base.answer = BaseCommand({'steer': np.zeros(2), 'drive': np.array([math.nan, 1.0])}, np.ones(3), 'ok', None)
    answer = BasePeriod(base, 0.1).step(None, POSITIONS)
    assert answer.non_finite == 'non-finite command [[0.0, 0.0], [nan, 1.0]]: zero rates'
    assert all(not np.any(v) for v in answer.rates.values()) and not np.any(answer.twist)
    assert base.resets == [(POSITIONS, None)] and answer.command is base.answer


@pytest.mark.parametrize('robot', ['mecanum', 'steerable'])
def test_a_real_controllers_answer_goes_out_as_it_gave_it(robot):
    config = load_robot(robot)
    base = make_base_controller(config, config.period)
    positions = {g: np.zeros(len(j)) for g, j in base.command_groups.items()}
    period = BasePeriod(base, applied_rate_tolerance=0.01)
    period.start(positions, None, resync=True)
    answer = period.step(np.array([0.1, 0.0, 0.0]), positions)
    assert answer.non_finite == '' and answer.twist is answer.command.feasible_twist
    for group, rates in answer.rates.items():
        assert rates is answer.command.rates[group]


def test_a_joint_state_is_refused_on_a_required_group_and_goes_on_without_another():
    """:meth:`BasePeriod.check`, what both engines run on a joint state's base joints: a required
    group that fails its checks refuses the state; another one is left out, with the rates."""
    period = BasePeriod(RecordingBase(), 0.1)
    positions, rates, why = period.check(POSITIONS, APPLIED)
    assert why == '' and set(positions) == {'steer', 'drive'} and rates is not None
    bad_steer = dict(POSITIONS, steer=np.array([math.nan, 0.0]))
    assert period.check(bad_steer, APPLIED) == ({}, None, period.check(bad_steer, None)[2])
    assert 'non-finite' in period.check(bad_steer, APPLIED)[2]
    glitch = dict(APPLIED, drive=np.array([0.0, 101.0]))  # beyond ten times the drive limit
    positions, rates, why = period.check(POSITIONS, glitch)
    assert why == '' and set(positions) == {'steer'} and rates is None
    positions, rates, why = period.check({'drive': POSITIONS['drive']}, None)
    assert positions == {} and 'steer' in why
