"""Generated documentation stays in step with the code.

The parameter tables of docs/nodes.md and docs/viewer.md are generated from the nodes' ``Param``
declarations and their defaults (``scripts/param_tables.py``): a parameter added, removed or
changed without regenerating them fails here.
"""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _script(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / 'scripts' / f'{name}.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_parameter_tables_match_the_declarations(capsys):
    param_tables = _script('param_tables')
    code = param_tables.main(['--check'])
    assert code == 0, (
        'the parameter tables differ from the declarations; run python scripts/param_tables.py '
        '--write\n' + capsys.readouterr().out
    )


def test_every_node_with_parameters_has_a_table():
    param_tables = _script('param_tables')
    params = param_tables.node_params()
    assert set(params) >= {
        'wmm_sim',
        'swmr_controller',
        'mecanum_controller',
        'differential_controller',
        'redundancy_resolver',
        'goal_sequencer',
        'wmm_viewer',
    }
    text = ''.join(path.read_text() for path in param_tables.DOCS)
    for exe, specs in params.items():
        assert f'<!-- params:{exe} -->' in text
        for spec in specs:
            assert f'| `{spec.name}` |' in text


def test_a_new_parameter_makes_the_check_fail():
    param_tables = _script('param_tables')
    generated = param_tables.tables()
    generated['goal_sequencer'] += '| `new_parameter` | `1` | — | yes | Not regenerated. |\n'
    texts = {path: path.read_text() for path in param_tables.DOCS}
    assert param_tables.render(texts, generated) != texts
