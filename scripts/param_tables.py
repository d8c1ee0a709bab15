"""The parameter tables of docs/nodes.md, built from the nodes' declarations.

Every node executable (a console script of setup.py whose module has ``PARAMS``) declares its
parameters as a tuple of ``Param`` specs and takes their defaults from ``config/<node>.yaml``,
the robot YAML (``default_from``) or the resolver parameter classes. This script renders, per
node, a Markdown table (name, default, range, read-only, description) and the table of the
parameters that may change at run time, and puts each between its markers in docs/nodes.md
(the viewer's in docs/viewer.md)::

    <!-- params:NODE -->  ...  <!-- /params -->
    <!-- params:live -->  ...  <!-- /params -->

Usage::

    python scripts/param_tables.py            # print the tables
    python scripts/param_tables.py --write    # rewrite the pages in place
    python scripts/param_tables.py --check    # exit 1 when a page differs (and print the diff)

The node modules are imported (their specs are module-level objects); no node is created.
"""

import argparse
import difflib
import importlib
import re
import sys
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a source checkout

from wmm_control.nodes.parameters import load_defaults  # noqa: E402

#: The pages that hold the tables (the viewer's is on its own page).
DOCS = (ROOT / 'docs' / 'nodes.md', ROOT / 'docs' / 'viewer.md')
#: A console script of setup.py: ``'name = module:function'``.
_ENTRY = re.compile(r"'(\w+) = ([\w.]+):\w+'")
_BLOCK = re.compile(r'(<!-- params:([\w-]+) -->\n)(.*?)(<!-- /params -->)', re.S)


def node_params():
    """``{executable: PARAMS}`` of every console script of setup.py whose module declares them,
    in the order of setup.py."""
    out = {}
    for exe, module in _ENTRY.findall((ROOT / 'setup.py').read_text()):
        specs = getattr(importlib.import_module(module), 'PARAMS', None)
        if specs is not None:
            out[exe] = specs
    return out


def _number(value):
    return str(value) if isinstance(value, int) else format(float(value), '.6g')


def _value(value):
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (int, float)):
        return _number(value)
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_value(v) for v in value) + ']'
    return repr(value) if value == '' else str(value)


def _cell(text):
    return text.replace('|', '\\|').replace('\n', ' ')


def _default(exe, spec, values):
    """The default of ``spec`` as shown, and where it comes from ('' for the node YAML)."""
    if spec.default_from is None:
        return values[spec.name], ''
    value = spec.default_from(SimpleNamespace(**values))
    if spec.default_home:
        return value, spec.default_home
    return value, f'robot YAML of `{values.get("robot", "?")}`'


def _range(spec, default):
    parts = []
    if spec.lo is not None:
        scope = 'each in ' if isinstance(default, (list, tuple)) else ''
        parts.append(f'{scope}[{_number(spec.lo)}, {_number(spec.hi)}]')
    if spec.choices:
        parts.append(' \\| '.join(f'`{c}`' for c in spec.choices))
    if spec.size:
        parts.append('length ' + ' or '.join(str(n) for n in spec.size))
    return '; '.join(parts) or '—'


def node_table(exe, specs):
    """The Markdown table of one node's parameters."""
    defaults = load_defaults(f'{exe}.yaml', exe)
    values = {}
    lines = ['| parameter | default | range | read-only | description |', '|---|---|---|---|---|']
    for spec in specs:
        default, home = _default(exe, spec, {**defaults, **values})
        values[spec.name] = default
        shown = f'`{_value(default)}`' + (f' ({home})' if home else '')
        lines.append(
            f'| `{spec.name}` | {_cell(shown)} | {_range(spec, default)} | '
            f'{"yes" if spec.read_only else "no"} | {_cell(spec.description)} |'
        )
    return '\n'.join(lines) + '\n'


def live_table(params):
    """The table of the parameters every node lets change at run time."""
    lines = ['| node | live parameters |', '|---|---|']
    for exe, specs in params.items():
        live = [f'`{s.name}`' for s in specs if not s.read_only]
        lines.append(f'| `{exe}` | {", ".join(live) or "—"} |')
    return '\n'.join(lines) + '\n'


def tables():
    """``{marker: table}``: one per node, and ``live``."""
    params = node_params()
    out = {exe: node_table(exe, specs) for exe, specs in params.items()}
    out['live'] = live_table(params)
    return out


def render(texts, generated):
    """``{path: text}`` with every marked block replaced by its table. Every table has one block
    in one of the pages; an unknown or repeated marker, or a table without a block, is an error."""
    seen = []

    def repl(match):
        name = match.group(2)
        if name not in generated:
            raise SystemExit(f'param_tables.py: a block params:{name} names no node that declares parameters')
        seen.append(name)
        return match.group(1) + generated[name] + match.group(4)

    out = {path: _BLOCK.sub(repl, text) for path, text in texts.items()}
    missing = sorted(set(generated) - set(seen))
    twice = sorted({n for n in seen if seen.count(n) > 1})
    if missing or twice:
        raise SystemExit(
            f'param_tables.py: tables without a block: {missing}; blocks written twice: {twice} '
            '(a block is <!-- params:NAME --> ... <!-- /params -->)'
        )
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(prog='param_tables.py', description=__doc__.split('\n\n')[0])
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument('--write', action='store_true', help='rewrite the pages in place')
    mode.add_argument('--check', action='store_true', help='exit 1 when a page differs from the tables')
    args = parser.parse_args(argv)
    generated = tables()
    if not (args.write or args.check):
        for name, table in generated.items():
            print(f'{name}:\n{table}')
        return 0
    old = {path: path.read_text() for path in DOCS}
    new = render(old, generated)
    stale = [path for path in DOCS if new[path] != old[path]]
    for path in stale:
        rel = str(path.relative_to(ROOT))
        if args.write:
            path.write_text(new[path])
            print(f'wrote {rel}')
        else:
            sys.stdout.writelines(
                difflib.unified_diff(old[path].splitlines(True), new[path].splitlines(True), rel, rel + ' (generated)')
            )
    if args.check and stale:
        print(
            'the parameter tables differ from the declarations; run python scripts/param_tables.py --write',
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
