#!/usr/bin/env bash
# Run the whole test suite in the project environment: `scripts/run_tests.sh [PYTEST ARGS...]`.
# Called by `make test` after the set-up. pytest's exit status 5 (no test collected) is turned into a
# failure, so a suite that silently ran nothing never passes.
set -o pipefail  # no -u: colcon's setup.sh reads unset variables
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)"
cd "$ROOT" || exit 1
# shellcheck disable=SC1091
source "$ROOT/env.sh" || { echo "run_tests: could not source env.sh; run 'make setup' first" >&2; exit 1; }
# No path given: pytest runs its testpaths (pyproject.toml: tests), i.e. `pytest tests`.
# In parallel (pytest-xdist): one worker per free core plus one, as scripts/test_workers.py reads the machine
# now (RIMD_TEST_WORKERS=N sets the workers, 0 runs serially). A test file stays on one worker (its module
# fixtures are made once), the files handed out heaviest first in the order tests/conftest.py sorts them (not
# xdist's by count of tests), and the ROS tests never hear each other (each leases its own domain).
# Bytecode is cached (the __pycache__ directories are ignored by git) even where the environment sets
# PYTHONDONTWRITEBYTECODE: without it each worker compiles and assertion-rewrites every test module again, and each
# node, CLI and pytest process the tests start compiles the package's modules again.
unset PYTHONDONTWRITEBYTECODE
WORKERS="${RIMD_TEST_WORKERS:-$(python "$ROOT/scripts/test_workers.py")}"
if [ "$WORKERS" = "0" ]; then
    python -m pytest "$@"
else
    python -m pytest -n "$WORKERS" --dist loadfile --no-loadscope-reorder "$@"
fi
rc=$?
if [ "$rc" -eq 5 ]; then
    echo "run_tests: pytest collected no test (exit status 5): counted as a failure" >&2
    exit 1
fi
exit "$rc"
