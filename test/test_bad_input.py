"""Every node against every kind of bad input (the matrix that ``wmm_bad_input`` prints).

Each column runs every kind on one node, in process on a private domain
(:mod:`wmm_control.cli.bad_input`): no crash, no NaN on any output, no command beyond the
limits, the node still answers afterwards, and a throttled warning that says what was wrong
(or, for valid input in another layout, the very same commands).
"""

import pytest

from wmm_control.cli import bad_input
from wmm_control.nodes.common import StampGate


def test_the_matrix_has_at_least_25_kinds_and_every_node_meets_some():
    assert len(bad_input.KINDS) >= 25
    families = {'sim', 'base', 'resolver', 'sequencer'}
    for family in families:
        applicable = [k for k in bad_input.KINDS if family in k.cases or k.param is not None]
        assert len(applicable) >= 6, family


@pytest.mark.parametrize('column', list(bad_input.RIGS))
def test_no_kind_of_bad_input_hurts_the_node(column):
    results = bad_input.run_matrix(columns=[column])
    failed = {kind: f'{cell.outcome}: {cell.detail}' for (kind, _), cell in results.items() if not cell.ok}
    assert not failed, failed
    ran = [cell for cell in results.values() if cell.outcome != 'n/a']
    assert len(ran) >= 6


def test_the_matrix_sees_a_node_that_runs_a_cycle_per_duplicate(monkeypatch):
    """Without the stamp gate, a second publisher's copy runs a second cycle, silently."""
    monkeypatch.setattr(StampGate, 'admit', lambda self, stamp: '')
    kind = next(k for k in bad_input.KINDS if k.name == 'duplicated message')
    cell = bad_input.run_cell(bad_input.RIGS['mecanum_controller'], kind)
    assert cell.outcome == 'SILENT'


def test_the_table_prints_one_row_per_kind_and_one_column_per_node():
    results = bad_input.run_matrix(kinds=['NaN field', 'command empty'], columns=['wmm_sim (A)', 'goal_sequencer'])
    table = bad_input.format_table(results).splitlines()
    assert table[0] == '| kind | wmm_sim (A) | goal_sequencer |'
    assert table[2] == '| NaN field | rejected | n/a |'
    assert table[3] == '| command empty | rejected | n/a |'
