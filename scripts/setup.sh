#!/usr/bin/env bash
# Set up (or refresh) the project environment: the venv and the colcon workspace ros_ws.
#
# Usage: scripts/setup.sh [--only STEP]...      (STEP: preflight, venv, requirements, build, warmup)
# Environment:
#   VENV    the project venv (default: <repo>/.venv); created if missing, never deleted
#   PYTHON  the interpreter to create it with: Python 3.11 or 3.12 (default: python3.11, or the Python of an
#           existing VENV); given, an existing VENV must be of that version. A pythonX.Y that is not on PATH
#           (or a pyenv shim of a version pyenv does not activate) is taken from pyenv's versions when it has one.
#
# Steps, in order; each is skipped quickly when its stamp says nothing changed:
#   preflight     Python 3.11 or 3.12 with venv/ensurepip, cmake (>= 3.19), gcc, g++, make on PATH
#   venv          create VENV when it does not exist
#   requirements  pip install -r requirements.txt (every wheel pinned) when the lock or the venv changed;
#                 stamp: VENV/.rimd-requirements.sha256
#   build         colcon build --symlink-install of ros_ws when a build input changed (package manifests,
#                 setup.py/.cfg, the registry of nodes (its console scripts), launch files, .msg/.srv, cmake/,
#                 the venv, this script); stamp: .stamps/build-*.sha256
#                 Python sources are symlinked, so editing a .py never needs a rebuild.
#   warmup        `rimd warmup`: numba compiles the physics (the models' drivers, the sensors, the ensembles)
#                 into its on-disk cache once, here, instead of in the first rig or test that runs (the two
#                 models in two processes; a second each later); stamp: .stamps/warmup-*.sha256 (the sources)
# A failing step stops the set-up with "set-up step 'NAME' failed: WHY" and a non-zero exit status.
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)"
VENV="${VENV:-$ROOT/.venv}"
PYTHON_GIVEN="${PYTHON:+yes}"
PYTHON="${PYTHON:-python3.11}"
PYTHON_ASKED="$PYTHON"   # as given (PYTHON may become pyenv's path to it)
SUPPORTED_PYTHONS="3.11 3.12"   # the ROS 2 Jazzy wheels exist as cp311 and cp312; Ubuntu 24.04's ROS runs 3.12
WS="$ROOT/ros_ws"
STAMPS="$ROOT/.stamps"
CMAKE_MINIMUM="3.19"   # cmake_language(DEFER) in cmake/drop_missing_includes.cmake

CURRENT_STEP=""
fail() {
    echo "set-up step '$CURRENT_STEP' failed: $*" >&2
    exit 1
}

now() { date +%s.%N; }
elapsed() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

# Hash of the named files' paths and contents plus extra strings (stdin), as one hex digest.
hash_inputs() {
    {
        cat
        local file
        for file in "$@"; do
            printf '%s\n' "${file#"$ROOT"/}"
            if [ -L "$file" ]; then readlink "$file"; elif [ -f "$file" ]; then cat "$file"; fi
        done
    } | sha256sum | cut -d' ' -f1
}

# ---------------------------------------------------------------------------------------------------
python_version() {   # "X.Y" of the interpreter $1, or nothing when it does not run
    "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null
}

# pythonX.Y from pyenv's installed versions (the newest X.Y.*), for a PYTHON that is not callable as it is.
pyenv_python() {
    local name="$1" minor pyenv_root version
    minor="$(printf '%s' "$name" | sed -n 's/^python\([0-9]*\.[0-9]*\)$/\1/p')"
    [ -n "$minor" ] || return 1
    pyenv_root="${PYENV_ROOT:-}"
    if [ -z "$pyenv_root" ] && command -v pyenv >/dev/null 2>&1; then pyenv_root="$(pyenv root 2>/dev/null)"; fi
    [ -n "$pyenv_root" ] || pyenv_root="$HOME/.pyenv"
    [ -d "$pyenv_root/versions" ] || return 1
    version="$(cd "$pyenv_root/versions" && ls -1d "$minor".* 2>/dev/null | grep -E "^$minor\.[0-9]+$" | sort -V | tail -n1)"
    [ -n "$version" ] && [ -x "$pyenv_root/versions/$version/bin/$name" ] || return 1
    printf '%s\n' "$pyenv_root/versions/$version/bin/$name"
}

# The Python to check and to create the venv with: PYTHON as given, else an existing venv's own, else python3.11.
# Sets PYTHON (resolved through pyenv when needed) and PYTHON_VERSION.
resolve_python() {
    if [ -z "$PYTHON_GIVEN" ] && [ -x "$VENV/bin/python" ]; then
        PYTHON_VERSION="$(python_version "$VENV/bin/python")"
        if [ -n "$PYTHON_VERSION" ]; then
            PYTHON="python$PYTHON_VERSION"   # the venv's; no interpreter needed to use it
            return 0
        fi
    fi
    PYTHON_VERSION="$(python_version "$PYTHON")"
    if [ -z "$PYTHON_VERSION" ]; then
        local found
        if found="$(pyenv_python "$PYTHON")"; then
            echo "set-up: $PYTHON is not callable here; using pyenv's $found" >&2
            PYTHON="$found"
            PYTHON_VERSION="$(python_version "$PYTHON")"
        fi
    fi
    if [ -z "$PYTHON_VERSION" ]; then
        command -v "$PYTHON" >/dev/null 2>&1 && fail "$PYTHON does not run (a pyenv shim of a version pyenv does not activate? PYENV_VERSION=3.11.7:3.12.1 makes both callable)"
        fail "$PYTHON not found on PATH nor in pyenv's versions; install Python 3.11 or 3.12 (apt-get install python3.12 python3.12-venv, or pyenv install 3.12) or set PYTHON=/path/to/python3.12"
    fi
}

step_preflight() {
    resolve_python
    case " $SUPPORTED_PYTHONS " in
        *" $PYTHON_VERSION "*) ;;
        *) fail "$PYTHON is Python $PYTHON_VERSION; the project supports Python ${SUPPORTED_PYTHONS// / and } (the ROS 2 Jazzy wheels are cp311 and cp312): set PYTHON=python3.11 or PYTHON=python3.12" ;;
    esac
    if [ ! -x "$VENV/bin/python" ]; then   # only to create the venv
        "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1 \
            || fail "$PYTHON cannot create venvs (no venv/ensurepip module); install it with apt-get install python$PYTHON_VERSION-venv"
    fi
    command -v cmake >/dev/null 2>&1 \
        || fail "cmake not found on PATH; install it with apt-get install cmake"
    local cmake_version
    cmake_version="$(cmake --version 2>/dev/null | sed -n 's/^cmake version \([0-9.]*\).*/\1/p')"
    [ -n "$cmake_version" ] || fail "cmake --version does not run"
    if [ "$(printf '%s\n%s\n' "$CMAKE_MINIMUM" "$cmake_version" | sort -V | head -n1)" != "$CMAKE_MINIMUM" ]; then
        fail "cmake $cmake_version is older than $CMAKE_MINIMUM; install a newer one (apt-get install cmake)"
    fi
    local tool
    for tool in gcc g++ make; do
        command -v "$tool" >/dev/null 2>&1 || fail "$tool not found on PATH; install it with apt-get install build-essential"
    done
}

step_venv() {
    [ -n "${PYTHON_VERSION:-}" ] || resolve_python
    if [ -e "$VENV" ]; then
        [ -x "$VENV/bin/python" ] \
            || fail "$VENV exists but has no bin/python; remove it (rm -rf $VENV) or set VENV to another path"
        local version
        version="$(python_version "$VENV/bin/python")" \
            || fail "$VENV/bin/python does not run; remove the venv (rm -rf $VENV) and run the set-up again"
        [ -n "$version" ] || fail "$VENV/bin/python does not run; remove the venv (rm -rf $VENV) and run the set-up again"
        if [ "$version" != "$PYTHON_VERSION" ]; then
            fail "$VENV is a Python $version venv but PYTHON=$PYTHON_ASKED is Python $PYTHON_VERSION; remove the venv (rm -rf $VENV), set VENV to another path, or set PYTHON=python$version"
        fi
        case " $SUPPORTED_PYTHONS " in
            *" $version "*) ;;
            *) fail "$VENV is a Python $version venv; the project supports Python ${SUPPORTED_PYTHONS// / and }: remove it (rm -rf $VENV) or set VENV" ;;
        esac
        VENV_STATUS="present (Python $version)"
        return 0
    fi
    "$PYTHON" -m venv "$VENV" || fail "$PYTHON -m venv $VENV exited with an error"
    VENV_STATUS="created (Python $PYTHON_VERSION)"
}

step_requirements() {
    local stamp="$VENV/.rimd-requirements.sha256" digest
    digest="$(echo "$VENV" | hash_inputs "$ROOT/requirements.txt")"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$digest" ]; then
        REQUIREMENTS_STATUS="up to date"
        return 0
    fi
    echo "set-up: installing the pinned wheels of requirements.txt into $VENV" >&2
    local pip=("$VENV/bin/python" -m pip --disable-pip-version-check)
    # pip and setuptools first: the venv's own may be older than the pins. A line may carry an environment marker
    # (setuptools differs between Python 3.11 and 3.12): pip skips the line whose marker does not hold.
    local pin
    while IFS= read -r pin; do
        "${pip[@]}" install --quiet "$pin" 2>&1 | grep -v -e "^WARNING: Location" -e "^Ignoring " >&2
        [ "${PIPESTATUS[0]}" -eq 0 ] || fail "pip install $pin exited with an error (see above)"
    done < <(grep -iE '^(pip|setuptools)==' "$ROOT/requirements.txt")
    "${pip[@]}" install --quiet -r "$ROOT/requirements.txt" 2>&1 | grep -v "^WARNING: Location" >&2
    [ "${PIPESTATUS[0]}" -eq 0 ] \
        || fail "pip install -r requirements.txt exited with an error (see above); is the package registry reachable?"
    # Never two ROS distributions in one venv.
    local kilted
    kilted="$("${pip[@]}" list --format=freeze 2>/dev/null | grep -i '^ros-kilted-' | tr '\n' ' ')"
    [ -z "$kilted" ] || fail "the venv contains Kilted wheels ($kilted); this project is ROS 2 Jazzy only: remove them"
    local check
    check="$("${pip[@]}" check 2>&1)" || fail "pip check found inconsistent requirements in $VENV: $check"
    echo "$digest" > "$stamp"
    REQUIREMENTS_STATUS="installed"
}

SMOKE_CHECK="import rimd_msgs.msg as m, rimd_msgs.srv, rimd_sim.cli
from rclpy.serialization import serialize_message as s, deserialize_message as d
assert d(s(m.SampleBlock(first_index=7)), m.SampleBlock).first_index == 7"

# The environment colcon builds with: the venv as the only underlay, nothing from a sourced env.sh.
build_environment() {
    env -u PYTHONPATH -u COLCON_PREFIX_PATH -u AMENT_CURRENT_PREFIX -u LD_LIBRARY_PATH \
        -u _ROS_WHEELS_BOOTSTRAP_COMPLETE \
        VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH" \
        AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" \
        "$@"
}

step_build() {
    mkdir -p "$STAMPS" || fail "cannot create $STAMPS"
    local inputs=(
        "$ROOT/scripts/setup.sh"
        "$ROOT/cmake/"*.cmake
        "$ROOT/rimd_msgs/CMakeLists.txt" "$ROOT/rimd_msgs/package.xml"
        "$ROOT/rimd_msgs/msg/"*.msg "$ROOT/rimd_msgs/srv/"*.srv
        "$ROOT/rimd_sim/package.xml" "$ROOT/rimd_sim/setup.py" "$ROOT/rimd_sim/setup.cfg"
        "$ROOT/rimd_sim/rimd_sim/ros/nodes/registry.py"
        "$ROOT/rimd_sim/resource/"* "$ROOT/rimd_sim/launch/"* "$ROOT/rimd_sim/bin/"*
        "$WS/src/"*
    )
    # Names only: config files are installed as symlinks, so their contents need no rebuild.
    local config_names
    config_names="$(cd "$ROOT/config" 2>/dev/null && ls -1 -- *.yaml 2>/dev/null)"
    local stamp_key venv_key digest
    venv_key="$(printf '%s' "$VENV" | sha256sum | cut -c1-12)"
    stamp_key="$STAMPS/build-$venv_key.sha256"
    digest="$(printf 'venv=%s\nrequirements=%s\nconfig=%s\n' "$VENV" \
        "$(cat "$VENV/.rimd-requirements.sha256" 2>/dev/null)" \
        "$config_names" | hash_inputs "${inputs[@]}")"
    if [ -f "$stamp_key" ] && [ "$(cat "$stamp_key")" = "$digest" ] && [ -f "$WS/install/setup.sh" ] \
        && [ "$(cat "$WS/install/.rimd-venv" 2>/dev/null)" = "$VENV" ]; then
        BUILD_STATUS="up to date"
        return 0
    fi
    # CMake caches the paths of the venv it configured with: a build made with another venv is wiped.
    if [ -d "$WS/install" ] && [ "$(cat "$WS/install/.rimd-venv" 2>/dev/null)" != "$VENV" ]; then
        echo "set-up: ros_ws was built with another venv ($(cat "$WS/install/.rimd-venv" 2>/dev/null || echo unknown)); rebuilding from scratch" >&2
        rm -rf "$WS/build" "$WS/install" "$WS/log"
    fi
    rm -f "$stamp_key"
    local log="$STAMPS/colcon-build.log"
    echo "set-up: building ros_ws with colcon (output in $log)" >&2
    (
        cd "$WS" && build_environment colcon build --symlink-install \
            --cmake-args \
            "-DCMAKE_PROJECT_INCLUDE=$ROOT/cmake/drop_missing_includes.cmake" \
            "-DPython3_EXECUTABLE=$VENV/bin/python" \
            -DBUILD_TESTING=OFF
    ) >"$log" 2>&1
    local rc=$?
    if [ $rc -ne 0 ]; then
        tail -n 40 "$log" >&2
        fail "colcon build exited with status $rc; full output in $log, per-package logs in ros_ws/log/latest_build"
    fi
    echo "$VENV" > "$WS/install/.rimd-venv"
    # Smoke check: the freshly built interfaces import in the venv.
    build_environment sh -c ". '$WS/install/setup.sh' && python -c '$SMOKE_CHECK'" \
        >>"$log" 2>&1 || { tail -n 20 "$log" >&2; fail "the built packages do not import (see $log)"; }
    echo "$digest" > "$stamp_key"
    BUILD_STATUS="built"
}

step_warmup() {
    mkdir -p "$STAMPS" || fail "cannot create $STAMPS"
    local venv_key stamp digest
    venv_key="$(printf '%s' "$VENV" | sha256sum | cut -c1-12)"
    stamp="$STAMPS/warmup-$venv_key.sha256"
    digest="$(printf 'venv=%s\nrequirements=%s\n' "$VENV" "$(cat "$VENV/.rimd-requirements.sha256" 2>/dev/null)" \
        | hash_inputs "$ROOT/rimd_sim/rimd_sim/model/"*.py "$ROOT/rimd_sim/rimd_sim/instruments/"*.py \
            "$ROOT/rimd_sim/rimd_sim/settings/"*.py "$ROOT/rimd_sim/rimd_sim/cli/verbs/warmup.py")"
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$digest" ]; then
        WARMUP_STATUS="up to date"
        return 0
    fi
    echo "set-up: compiling the physics into numba's cache (rimd warmup; the first time takes a minute or so)" >&2
    env -u PYTHONPATH PYTHONPATH="$ROOT/rimd_sim" "$VENV/bin/python" -m rimd_sim.cli warmup --all >&2 \
        || fail "rimd warmup exited with an error (see above)"
    echo "$digest" > "$stamp"
    WARMUP_STATUS="compiled"
}

# ---------------------------------------------------------------------------------------------------
ALL_STEPS=(preflight venv requirements build warmup)
STEPS=()
while [ $# -gt 0 ]; do
    case "$1" in
        --only) [ $# -ge 2 ] || { echo "setup.sh: --only needs a step name" >&2; exit 2; }
                STEPS+=("$2"); shift 2 ;;
        -h|--help) sed -n '2,23p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "setup.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
[ ${#STEPS[@]} -gt 0 ] || STEPS=("${ALL_STEPS[@]}")

VENV_STATUS="" REQUIREMENTS_STATUS="" BUILD_STATUS="" WARMUP_STATUS=""
START="$(now)"
SUMMARY=""
# One set-up at a time per checkout (two `make test` in the same tree would build ros_ws concurrently); the checks
# and the venv alone need no lock.
if [ -n "$(printf '%s\n' "${STEPS[@]}" | grep -vxE 'preflight|venv')" ]; then
    mkdir -p "$STAMPS" && exec 9>"$STAMPS/setup.lock" \
        || { echo "set-up step 'lock' failed: cannot create $STAMPS/setup.lock" >&2; exit 1; }
    if ! flock -n 9; then
        echo "set-up: waiting for another set-up of this checkout to finish (lock $STAMPS/setup.lock)" >&2
        flock -w 900 9 || { echo "set-up step 'lock' failed: another set-up held $STAMPS/setup.lock for 15 min" >&2; exit 1; }
    fi
fi
for step in "${STEPS[@]}"; do
    case " ${ALL_STEPS[*]} " in *" $step "*) ;; *) echo "setup.sh: unknown step '$step'" >&2; exit 2 ;; esac
    CURRENT_STEP="$step"
    step_start="$(now)"
    "step_$step"
    status_var="$(echo "$step" | tr '[:lower:]' '[:upper:]')_STATUS"
    status="${!status_var:-ok}"
    SUMMARY+="${SUMMARY:+, }$step ${status:-ok} $(elapsed "$step_start")s"
done
echo "set-up done in $(elapsed "$START") s ($SUMMARY) [venv: $VENV]"
