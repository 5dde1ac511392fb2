#!/usr/bin/env bash
# Run your repository's DAQ tests against the RIMD twin installed from its wheels (docs/testing.md,
# "From your repository's CI"). From your repository's root:
#     RIMD_WHEELS=wheels bash run-daq-tests.sh [PYTEST ARGS]        (default PYTEST ARGS: tests)
#   RIMD_WHEELS   the directory holding rimd_sim-*.whl and ros_jazzy_rimd_msgs-*.whl (the twin's `make dist`)
#   RIMD_VERSION  the twin's version to install (default 0.4.0)
#   RIMD_VENV     the venv to install into (default .venv-rimd; made when missing, reused when present)
#   PYTHON        the interpreter that makes the venv: Python 3.11 or 3.12 (default python3)
# Needs no ROS installation and no environment to source: the ROS 2 Jazzy wheels come from the package registry.
set -euo pipefail
: "${RIMD_WHEELS:?set RIMD_WHEELS to the directory holding the wheels of the twin}"
RIMD_VERSION="${RIMD_VERSION:-0.4.0}"
RIMD_VENV="${RIMD_VENV:-.venv-rimd}"
PYTHON="${PYTHON:-python3}"

[ -x "$RIMD_VENV/bin/python" ] || "$PYTHON" -m venv "$RIMD_VENV"
# rimd_sim and the rimd_msgs wheel of this Python from RIMD_WHEELS, everything else from the package registry.
"$RIMD_VENV/bin/python" -m pip install --find-links "$RIMD_WHEELS" "rimd_sim[testing]==$RIMD_VERSION"
"$RIMD_VENV/bin/rimd" info
# Compile what the rig runs (its model and sensors) into numba's cache once, not in the first test's rig.
"$RIMD_VENV/bin/rimd" warmup
if [ $# -eq 0 ]; then set -- tests; fi
"$RIMD_VENV/bin/python" -m pytest "$@"
