#!/usr/bin/env bash
# Set up a local virtual environment (.venv) and run one job in it.
#
#   bash scripts/dev.sh run     # set-up, then the main job (writes docs/results.md)
#   bash scripts/dev.sh test    # set-up, then the lint and type checks and the test suite
#   bash scripts/dev.sh bench   # set-up, then the benchmarks (they print figures)
#
# Needs only Python >= 3.11 with venv (Debian/Ubuntu: python3 python3-venv). PYTHON picks
# the interpreter (default python3). The set-up is skipped when nothing it depends on
# changed since the last run.
set -euo pipefail
cd "$(dirname "$0")/.."

job=${1:-}
case "$job" in
  run|test|bench) ;;
  *) echo "usage: bash scripts/dev.sh run|test|bench" >&2; exit 2 ;;
esac
shift

PYTHON=${PYTHON:-python3}
VENV=.venv

setup() {
  if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
    echo "dev.sh: Python >= 3.11 is required ($PYTHON is $("$PYTHON" -V 2>&1))" >&2
    exit 2
  fi
  if [ ! -x "$VENV/bin/python" ]; then
    "$PYTHON" -m venv "$VENV"
  fi
  local want
  want=$(cat scripts/requirements.txt scripts/requirements-test.txt setup.py setup.cfg package.xml \
         | "$VENV/bin/python" -c 'import hashlib,sys; print(hashlib.sha256(sys.stdin.buffer.read()).hexdigest())')
  if [ "$(cat "$VENV/.wmm-setup" 2>/dev/null)" != "$want" ]; then
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
      -r scripts/requirements.txt -r scripts/requirements-test.txt
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps -e .
    echo "$want" > "$VENV/.wmm-setup"
  fi
}

setup
case "$job" in
  run)
    # the whole main job writes docs/results.md; a chosen scenario or option set writes only its
    # own output (pass --report PAGE for a page of it)
    if [ "$#" -eq 0 ]; then set -- --report docs/results.md; fi
    exec "$VENV/bin/python" -m wmm_control.cli.experiment "$@" ;;
  test)
    "$VENV/bin/ruff" check .            # lint (ruff.toml)
    "$VENV/bin/ruff" format --check .   # format (ruff.toml)
    "$VENV/bin/mypy" wmm_control sim_bridge   # types (setup.cfg [mypy])
    exec "$VENV/bin/python" -m pytest test -q "$@" ;;
  bench)
    # pink (a QP-based IK) is the benchmarks' yardstick only, not a dependency.
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check pin-pink quadprog
    for b in benchmarks/bench_*.py; do echo "== $b"; "$VENV/bin/python" "$b"; done ;;
esac
