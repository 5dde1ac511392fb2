# Source this file at the repository root to get the project environment in an interactive shell:
#     source env.sh          (bash, zsh; `. ./env.sh` in sh/dash, from the repository root)
# It activates the venv (VENV; unset: the venv ros_ws was built with, as `make setup` recorded it in
# ros_ws/install/.rimd-venv, else .venv), puts the venv's ROS 2 Jazzy wheels on AMENT_PREFIX_PATH and
# CMAKE_PREFIX_PATH, sources the colcon workspace ros_ws/install/setup.sh and puts `rimd` on PATH.
# Run `make setup` (or `make test`) first: it creates the venv and builds ros_ws.
# Sourcing it twice is harmless, and so is sourcing it from a script that runs with `set -euo pipefail`.

if [ -n "${BASH_SOURCE:-}" ]; then
    RIMD_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd -P)"
elif [ -n "${ZSH_VERSION:-}" ]; then
    eval 'RIMD_ROOT="$(cd "$(dirname "${(%):-%x}")" && pwd -P)"'
else
    RIMD_ROOT="$(pwd -P)"
fi

_rimd_env_main() {
    # The scripts sourced below (the venv's activate, colcon's setup.sh and the package hooks) read unset
    # variables (COLCON_TRACE, ...) and run commands that may fail: a caller under `set -euo pipefail` would
    # exit silently in the middle. Run them with the caller's -e and -u off; _rimd_env_restore puts them back.
    _rimd_env_opts="$-"
    set +eu
    if [ ! -f "$RIMD_ROOT/env.sh" ] || [ ! -d "$RIMD_ROOT/ros_ws" ]; then
        echo "env.sh: cannot find the repository root (got '$RIMD_ROOT'); source env.sh from the root" >&2
        return 1
    fi
    # VENV set wins (with a warning below when ros_ws was built with another); unset: the build's venv.
    _rimd_venv="${VENV:-}"
    if [ -z "$_rimd_venv" ]; then
        _rimd_venv="$(cat "$RIMD_ROOT/ros_ws/install/.rimd-venv" 2>/dev/null)"
        [ -n "$_rimd_venv" ] || _rimd_venv="$RIMD_ROOT/.venv"
    fi
    if [ ! -f "$_rimd_venv/bin/activate" ]; then
        echo "env.sh: no venv at $_rimd_venv; run 'make setup' first" >&2
        return 1
    fi
    if [ ! -f "$RIMD_ROOT/ros_ws/install/setup.sh" ]; then
        echo "env.sh: ros_ws is not built; run 'make setup' first" >&2
        return 1
    fi
    if [ "$(cat "$RIMD_ROOT/ros_ws/install/.rimd-venv" 2>/dev/null)" != "$_rimd_venv" ]; then
        echo "env.sh: warning: ros_ws was built with another venv ($(cat "$RIMD_ROOT/ros_ws/install/.rimd-venv" 2>/dev/null || echo unknown)), not $_rimd_venv; run 'VENV=$_rimd_venv make setup' to rebuild it" >&2
    fi

    # shellcheck disable=SC1091
    . "$_rimd_venv/bin/activate" || return 1

    # The venv is the underlay: its share/ament_index holds the wheels' packages.
    case ":${AMENT_PREFIX_PATH:-}:" in
        *":$_rimd_venv:"*) ;;
        *) export AMENT_PREFIX_PATH="$_rimd_venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
    esac
    case ":${CMAKE_PREFIX_PATH:-}:" in
        *":$_rimd_venv:"*) ;;
        *) export CMAKE_PREFIX_PATH="$_rimd_venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" ;;
    esac

    # colcon's setup.sh needs COLCON_CURRENT_PREFIX when sourced from a shell other than bash's source.
    COLCON_CURRENT_PREFIX="$RIMD_ROOT/ros_ws/install"
    # shellcheck disable=SC1091
    . "$RIMD_ROOT/ros_ws/install/setup.sh" || return 1
    unset COLCON_CURRENT_PREFIX

    # Import rimd_sim straight from the source tree (colcon's symlinked build copy resolves there too, but
    # this way module paths and tracebacks name the files you edit).
    case ":${PYTHONPATH:-}:" in
        *":$RIMD_ROOT/rimd_sim:"*) ;;
        *) export PYTHONPATH="$RIMD_ROOT/rimd_sim${PYTHONPATH:+:$PYTHONPATH}" ;;
    esac

    # colcon leaves an empty entry (the current directory) at the end of LD_LIBRARY_PATH: drop it.
    LD_LIBRARY_PATH="$(printf '%s' "${LD_LIBRARY_PATH:-}" | tr ':' '\n' | grep -v '^$' | paste -sd: -)"
    export LD_LIBRARY_PATH

    # Console scripts (rimd, node executables) live in lib/rimd_sim, where `ros2 run` looks for them.
    _rimd_bin="$RIMD_ROOT/ros_ws/install/rimd_sim/lib/rimd_sim"
    case ":$PATH:" in
        *":$_rimd_bin:"*) ;;
        *) export PATH="$_rimd_bin:$PATH" ;;
    esac

    export ROS_DISTRO=jazzy ROS_VERSION=2 ROS_PYTHON_VERSION=3
    export RIMD_ROOT
    unset _rimd_venv _rimd_bin
    return 0
}

_rimd_env_main
_rimd_env_status=$?
case "${_rimd_env_opts:-}" in *e*) set -e ;; esac
case "${_rimd_env_opts:-}" in *u*) set -u ;; esac
unset -f _rimd_env_main
unset _rimd_env_opts
if [ "$_rimd_env_status" -ne 0 ]; then
    unset _rimd_env_status
    return 1 2>/dev/null || exit 1
fi
unset _rimd_env_status
