"""Print the fault matrix (``test/fault_matrix.py``): every node against every kind of bad
input, as the Markdown table of docs/robustness.md, then the failures if any.

Usage::

    python scripts/fault_table.py                    # the table, then the failures if any
    python scripts/fault_table.py --reasons          # and, per cell, what was sent and logged
    python scripts/fault_table.py --kinds 'NaN field,command empty' --nodes swmr_controller
    python scripts/fault_table.py --list             # the kinds

Exit code 0 when every cell passes, 1 otherwise.
"""

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))  # the fault matrix and its ROS harness
sys.path.insert(0, str(ROOT))  # run from a source checkout

import fault_matrix  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(prog='fault_table.py', description=__doc__.split('\n\n')[0])
    parser.add_argument('--kinds', help='comma-separated kind names (default: all)')
    parser.add_argument('--nodes', help='comma-separated column names (default: all): ' + ', '.join(fault_matrix.RIGS))
    parser.add_argument('--reasons', action='store_true', help='print what each cell sent and logged')
    parser.add_argument('--list', action='store_true', help='list the kinds and exit')
    args = parser.parse_args(argv)
    if args.list:
        for kind in fault_matrix.KINDS:
            print(kind.name)
        return 0
    kinds = args.kinds.split(',') if args.kinds else None
    columns = args.nodes.split(',') if args.nodes else None
    if columns:
        columns = [c for c in fault_matrix.RIGS if any(c.startswith(n.strip()) for n in columns)]
    t0 = time.monotonic()
    results = fault_matrix.run_matrix(
        kinds,
        columns,
        progress=lambda k, c, cell: print(f'  {c:<40} {k:<36} {cell.outcome}', file=sys.stderr, flush=True),
    )
    print(fault_matrix.format_table(results))
    bad = {key: cell for key, cell in results.items() if not cell.ok}
    if args.reasons or bad:
        print()
        for (kind, column), cell in results.items():
            if cell.detail and (args.reasons or not cell.ok):
                print(f'- {kind} / {column}: {cell.outcome}: {cell.detail}')
    cells = [c for c in results.values() if c.outcome != 'n/a']
    print(
        f'\n{len(cells)} cells run ({len(fault_matrix.KINDS)} kinds), {len(bad)} failed, {time.monotonic() - t0:.0f} s'
    )
    return 1 if bad else 0


if __name__ == '__main__':
    raise SystemExit(main())
