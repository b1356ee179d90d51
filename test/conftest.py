"""Integration tests: real rclpy and Fast DDS, nodes built in-process, executors spun.

Every test run gets its own ROS_DOMAIN_ID (from the process id) and localhost-only
discovery, so two runs on one machine never see each other and nothing leaks onto
a network. Set here, before any rclpy context is created.
"""
from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")


def _domain_id() -> int:
    """This test process's ROS domain, 1-100: from the process id, or under pytest-xdist one per worker
    (workers of one run share a base drawn from the run's id and never share a domain)."""
    worker, uid = os.environ.get("PYTEST_XDIST_WORKER", ""), os.environ.get("PYTEST_XDIST_TESTRUNUID", "")
    if not worker.startswith("gw") or not uid:
        return 1 + os.getpid() % 100
    n, k = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")), int(worker[2:])
    slots = max(1, 100 // n)
    return 1 + (int(uid, 16) % slots) * n + k


os.environ["ROS_DOMAIN_ID"] = str(_domain_id())
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


def pytest_configure(config) -> None:
    """The ``wallclock`` marker: tests that assert on wall-clock timing (watchdogs, starvation, stalls).
    `make test` runs them after the rest, alone on the machine, so a parallel neighbour cannot starve them."""
    config.addinivalue_line("markers", "wallclock: asserts on wall-clock timing; run alone (see Makefile)")
