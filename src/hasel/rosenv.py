"""Environment for the colcon install space, so ``.venv/bin/hasel`` needs nothing sourced.

A colcon workspace normally asks the user to ``source install/setup.bash``. The
``hasel`` command instead computes the same variables (PYTHONPATH, LD_LIBRARY_PATH,
AMENT_PREFIX_PATH) for the workspace's install space and re-executes itself once
with them. It also pins ROS 2 discovery to this machine (localhost only) and to a
domain of its own unless the user chose one: experiments never leak onto a network
by accident. No rclpy import here.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["workspace_root", "install_space", "ros_environment", "ensure_ros_environment", "private_domain",
           "DEFAULT_DOMAIN_ID"]

#: The domain ``hasel`` uses when ROS_DOMAIN_ID is unset (valid range 0-101 on Linux).
DEFAULT_DOMAIN_ID = 42
_READY = "HASEL_ROS_ENV_READY"


def workspace_root() -> Path | None:
    """The colcon workspace holding this checkout (env ``HASEL_WORKSPACE`` wins), or None."""
    env = os.environ.get("HASEL_WORKSPACE")
    if env:
        return Path(env).resolve()
    here = Path(__file__).resolve()
    # editable install: <root>/src/hasel/rosenv.py
    root = here.parents[2]
    if (root / "hasel_msgs" / "package.xml").is_file():
        return root
    return None


def install_space() -> Path | None:
    """``<workspace>/install`` if it was built, else None."""
    root = workspace_root()
    if root is not None and (root / "install").is_dir():
        return root / "install"
    return None


def _prepend(env: dict[str, str], key: str, parts: list[str]) -> None:
    old = [p for p in env.get(key, "").split(os.pathsep) if p]
    new = [p for p in parts if p not in old]
    env[key] = os.pathsep.join(new + old)


def ros_environment(base: dict[str, str] | None = None) -> dict[str, str]:
    """The environment ``source install/setup.bash`` would give, plus safe discovery.

    Parameters
    ----------
    base : dict, optional
        Environment to extend (default: ``os.environ``).
    """
    env = dict(os.environ if base is None else base)
    inst = install_space()
    if inst is not None:
        pkgs = sorted(p for p in inst.iterdir() if (p / "share").is_dir())
        pyver = f"python{sys.version_info.major}.{sys.version_info.minor}"
        _prepend(env, "AMENT_PREFIX_PATH", [str(p) for p in pkgs] + [sys.prefix])
        _prepend(env, "LD_LIBRARY_PATH", [str(p / "lib") for p in pkgs if (p / "lib").is_dir()])
        _prepend(env, "PYTHONPATH", [str(p / "lib" / pyver / "site-packages") for p in pkgs
                                     if (p / "lib" / pyver / "site-packages").is_dir()])
    env.setdefault("ROS_DOMAIN_ID", str(DEFAULT_DOMAIN_ID))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env[_READY] = "1"
    return env


def ensure_ros_environment() -> None:
    """Re-execute the current process once with :func:`ros_environment` applied."""
    if os.environ.get(_READY):
        return
    env = ros_environment()
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)


_DOMAIN_LOCKS: dict[int, object] = {}


def private_domain(first: int = 110, last: int = 200) -> int:
    """A ROS domain id no other running ``hasel`` job holds, for self-contained graphs.

    A job whose nodes all live in its own process (steps, calibrate, chirp, demo,
    bench) has no reason to share a domain with anything: on a private one, two jobs
    on one machine (or a job and a user's own nodes on the default domain) can never
    exchange messages by accident. Ids are claimed with an advisory lock file (released
    when the process ends); ``HASEL_DOMAIN_ID`` overrides. The range 110-200 is above
    the ids people usually pick and still below Fast DDS's port limit (232).
    """
    import fcntl
    import tempfile

    env = os.environ.get("HASEL_DOMAIN_ID")
    if env:
        return int(env)
    lock_dir = Path(os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()) / "hasel-domains"
    lock_dir.mkdir(parents=True, exist_ok=True)
    start = first + os.getpid() % (last - first + 1)
    for i in range(last - first + 1):
        dom = first + (start - first + i) % (last - first + 1)
        if dom in _DOMAIN_LOCKS:
            return dom
        f = open(lock_dir / f"{dom}.lock", "w")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        _DOMAIN_LOCKS[dom] = f
        return dom
    raise RuntimeError(f"no free ROS domain id in {first}-{last}")
