"""Integration tests: real rclpy and Fast DDS, nodes built in-process, executors spun.

Every test run gets its own ROS_DOMAIN_ID (from the process id) and localhost-only
discovery, so two runs on one machine never see each other and nothing leaks onto
a network. Set here, before any rclpy context is created.
"""
from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")

os.environ["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RCUTILS_LOGGING_MIN_SEVERITY", "WARN")
# the workspace environment is already in place (rclpy imported below): CLI calls made
# in-process must not re-execute the test process to set it up
os.environ["HASEL_ROS_ENV_READY"] = "1"

import pytest  # noqa: E402

try:
    import rclpy  # noqa: F401,E402
    import hasel_msgs.msg  # noqa: F401,E402
except ImportError as err:  # the workspace is not built or not on the path
    raise pytest.UsageError(f"integration tests need the built workspace: run them via `make test` ({err})")
