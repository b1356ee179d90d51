#!/usr/bin/env bash
# Install the core library `hasel` into a venv without any ROS package and run a closed
# loop with it: the core must not need rclpy. Idempotent (the venv is kept in build/).
set -euo pipefail
cd "$(dirname "$0")/.."
V=build/core-venv
if [ ! -x "$V/bin/python" ]; then
  python3 -m venv "$V"
fi
if ! "$V/bin/python" -c "import hasel" 2>/dev/null; then
  "$V/bin/python" -m pip install --quiet --disable-pip-version-check -c constraints.txt \
    numpy scipy control mcap mcap-ros2-support zstandard PyYAML matplotlib setuptools wheel 2>&1 \
    | grep -v "^WARNING: Location" || true
  "$V/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps -e src 2>&1 \
    | grep -v "^WARNING: Location" || true
fi
if "$V/bin/python" -m pip list 2>/dev/null | grep -qi '^ros-'; then
  echo "core-without-ros: a ros-* package is in $V" >&2; exit 1
fi
"$V/bin/python" -c "
import hasel, hasel.loop, hasel.ident, hasel.io
from hasel.loop import run_closed_loop, step_reference
from hasel.simulator import PlantSimulator
r = run_closed_loop(PlantSimulator(), step_reference([2.0, 4.0], 0.2), 0.4)
import sys
assert 'rclpy' not in sys.modules
print(f'core-without-ros: import hasel ok in a venv without ROS; loop ran ({r.command_kv.size} ticks)')
"
