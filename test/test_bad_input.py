"""Every node against every kind of bad input (the fault matrix, :mod:`fault_matrix`; its table
is in docs/robustness.md, printed by ``scripts/fault_table.py``).

Each column runs every kind on one node, in process on a private domain: no crash, no NaN on any output, no command beyond the
limits, the node still answers afterwards, and a throttled warning that says what was wrong
(or, for valid input in another layout, the very same commands).
"""

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

import fault_matrix
import wmm_control.base.period as period_module
import wmm_control.nodes.base_controller as node_module
from ros_helpers import ROSOUT_QOS
from wmm_control.nodes.obstacle_topic import ObstacleSet
from wmm_control.nodes.stamps import StampGate
from wmm_control.nodes.mecanum_controller import MecanumControllerNode


def test_the_matrix_has_at_least_25_kinds_and_every_node_meets_some():
    assert len(fault_matrix.KINDS) >= 25
    families = {'sim', 'base', 'resolver', 'sequencer', 'planner'}
    for family in families:
        applicable = [k for k in fault_matrix.KINDS if family in k.cases or k.param is not None]
        assert len(applicable) >= 6, family


@pytest.mark.parametrize('column', list(fault_matrix.RIGS))
def test_no_kind_of_bad_input_hurts_the_node(column):
    results = fault_matrix.run_matrix(columns=[column])
    failed = {kind: f'{cell.outcome}: {cell.detail}' for (kind, _), cell in results.items() if not cell.ok}
    assert not failed, failed
    ran = [cell for cell in results.values() if cell.outcome != 'n/a']
    assert len(ran) >= 6


def test_the_matrix_sees_a_node_that_runs_a_cycle_per_duplicate(monkeypatch):
    """Without the stamp gate, a second publisher's copy runs a second cycle, silently (once the
    check that the last command was applied, which notices the second cycle's effect, is off too)."""
    monkeypatch.setattr(StampGate, 'admit', lambda self, stamp: '')
    monkeypatch.setattr(period_module, 'unapplied_command', lambda measured, commanded, tolerance: '')
    kind = next(k for k in fault_matrix.KINDS if k.name == 'duplicated message')
    cell = fault_matrix.run_cell(fault_matrix.RIGS['mecanum_controller'], kind)
    assert cell.outcome == 'SILENT'


def test_the_matrix_sees_a_node_that_takes_an_oversized_obstacle_message(monkeypatch):
    """Without the limit the message's markers become obstacles (far from the robot: nothing else
    shows it), and nothing is logged: the cell reads CHANGED."""
    monkeypatch.setattr(ObstacleSet, 'take', lambda self, msg, logger, max_markers: self.apply(msg).changed)
    kind = next(k for k in fault_matrix.KINDS if k.name == 'obstacles: too many markers')
    cell = fault_matrix.run_cell(fault_matrix.RIGS['redundancy_resolver (B, amp)'], kind)
    assert cell.outcome == 'CHANGED', cell


@pytest.mark.parametrize('column', ['redundancy_resolver (A, task_sharing)', 'redundancy_resolver (B, amp)'])
def test_a_nan_planned_base_on_ee_reference_is_rejected_and_the_robot_held(column):
    """A plan's point with a NaN base (joint ``base`` of /ee_reference): the point is refused with
    the reason logged, the resolver pursues nothing and commands zero, and nothing NaN goes out."""
    kind = next(k for k in fault_matrix.KINDS if k.name == 'planned base NaN')
    _, _, mutate = kind.cases['resolver']
    rig = fault_matrix.RIGS[column]()
    try:
        result, failed = fault_matrix._harm(rig, lambda: fault_matrix._run_steps(rig, mutate), 'the bad input')
        assert failed is None, failed  # no crash, no NaN or inf on any output, alive afterwards
        warnings = [m.msg for m in rig.logs if m.level >= Log.WARN]
        assert any('rejected ee_reference: non-finite values of the planned base' in w for w in warnings), warnings
        assert rig.node.target is None
        commands = [v for topic, v in rig.records[-6:]]  # the cycles after it: arm and base commands
        assert len(commands) == 6 and all(np.all(v == 0.0) for v in commands), commands
    finally:
        rig.close()


def test_the_table_prints_one_row_per_kind_and_one_column_per_node():
    results = fault_matrix.run_matrix(kinds=['NaN field', 'command empty'], columns=['wmm_sim (A)', 'goal_sequencer'])
    table = fault_matrix.format_table(results).splitlines()
    assert table[0] == '| kind | wmm_sim (A) | goal_sequencer |'
    assert table[2] == '| NaN field | rejected | n/a |'
    assert table[3] == '| command empty | rejected | n/a |'


def test_without_the_clock_guard_a_negative_clock_crashes_the_node(monkeypatch):
    """rclpy's own time source raises on a negative /clock; the guard is what the matrix sees."""
    monkeypatch.setattr(node_module, 'guard_clock', lambda node: None)
    kind = next(k for k in fault_matrix.KINDS if k.name == 'negative /clock')
    cell = fault_matrix.run_cell(fault_matrix.RIGS['swmr_controller'], kind)
    assert cell.outcome == 'CRASH', cell


def test_use_sim_time_set_at_run_time_is_guarded_too(ros):
    """The time source subscribes to /clock when use_sim_time is set; that subscription drops a
    negative time with a warning too, and the clock takes the next valid one."""
    node = ros.add(MecanumControllerNode(context=ros.context))
    probe = ros.probe('clock_probe')
    warnings = []
    probe.create_subscription(
        Log, '/rosout', lambda m: warnings.append(m.msg) if m.level >= Log.WARN else None, ROSOUT_QOS
    )
    pub = probe.create_publisher(Clock, '/clock', 10)
    assert node.set_parameters([Parameter('use_sim_time', value=True)])[0].successful
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(Clock(clock=Time(sec=-5)))
    assert ros.spin_until(lambda: any('negative time' in w for w in warnings))
    pub.publish(Clock(clock=Time(sec=7)))
    assert ros.spin_until(lambda: node.get_clock().now().nanoseconds == 7_000_000_000)
