"""The core imports and runs with every ROS package made unimportable."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

CORE = Path(__file__).resolve().parents[1] / "hasel"
ROS_ROOTS = {"rclpy", "rosidl_runtime_py", "hasel_msgs", "hasel_driver", "hasel_control", "sim_plant", "hasel_ros",
             "hasel_sysid", "std_msgs", "builtin_interfaces", "rosgraph_msgs", "diagnostic_msgs"}


def test_no_core_module_imports_ros():
    offenders = []
    for path in CORE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in ROS_ROOTS]
    assert offenders == []


def test_core_runs_with_ros_blocked():
    code = """
import importlib.abc, sys
BLOCK = %r
class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split('.')[0] in BLOCK:
            raise ImportError('blocked ROS package ' + name)
sys.meta_path.insert(0, Blocker())
import pkgutil, hasel
for m in pkgutil.walk_packages(hasel.__path__, 'hasel.'):
    importlib.import_module(m.name)
from hasel.loop import run_closed_loop, step_reference
from hasel.simulator import PlantSimulator
res = run_closed_loop(PlantSimulator(), step_reference([2.0, 3.0], 0.1), 0.2)
assert res.command_kv.size == 40
assert not any(k.split('.')[0] in BLOCK for k in sys.modules)
print('ok')
""" % (sorted(ROS_ROOTS),)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("ok")
