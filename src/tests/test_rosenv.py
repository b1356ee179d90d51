"""hasel.rosenv: the environment of the install space and private domains (no rclpy here)."""
from __future__ import annotations

import subprocess
import sys

from hasel.rosenv import ros_environment


def test_environment_is_local_and_has_a_domain():
    env = ros_environment({"PATH": "/usr/bin"})
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert env["ROS_DOMAIN_ID"].isdigit()
    env2 = ros_environment({"ROS_DOMAIN_ID": "7", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})
    assert env2["ROS_DOMAIN_ID"] == "7" and env2["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"  # the user's choice


def test_two_processes_get_different_private_domains():
    code = "import sys, time; from hasel.rosenv import private_domain; print(private_domain(), flush=True); time.sleep(3)"
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                              env={"PATH": "/usr/bin", "HOME": "/tmp"}) for _ in range(3)]
    ids = [int(p.stdout.readline()) for p in procs]
    for p in procs:
        p.wait(timeout=30)
    assert len(set(ids)) == 3 and all(110 <= i <= 200 for i in ids)
