"""Repair the absolute include paths baked into the ROS wheels' CMake exports.

The ros-jazzy-* wheels were built on a manylinux image; their exported targets
(``share/*/cmake/*Export*.cmake``) name that image's Python and numpy include
directories, which do not exist here, so CMake refuses any package that links
against a message package. This rewrites them to this interpreter's include
directory and this numpy's, inside the given venv only. Idempotent.
"""
from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

import numpy

BUILDER_PY_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
BUILDER_NP_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def main(venv: str) -> int:
    """Rewrite the builder's paths in every Export*.cmake under ``venv/share``."""
    here_py = sysconfig.get_paths()["include"]
    here_np = numpy.get_include()
    fixed = 0
    for path in Path(venv, "share").glob("*/cmake/*Export*.cmake"):
        text = path.read_text()
        if BUILDER_PY_INCLUDE not in text and BUILDER_NP_INCLUDE not in text:
            continue
        text = text.replace(BUILDER_NP_INCLUDE, here_np).replace(BUILDER_PY_INCLUDE, here_py)
        path.write_text(text)
        fixed += 1
    print(f"[setup] repaired {fixed} CMake export files")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
