"""Independent fits of the diagnosis run in parallel processes.

The candidate families of a selection round (and the points of a delay's profile, and the
finite-difference columns of the joint refinement's Jacobian: ``least_squares(workers=pmap)``)
are fitted independently of each other on the same data, so :func:`pmap` runs them in
forked worker processes: a fork shares the prepared data and the closures of the
diagnosis without pickling them, and only the small results (fitted parameters, a
validation residual) come back. Every task is the same computation as in a serial run,
only in another process; the caches a worker fills are lost with it. One cache is not
exact: a load's simulator is kept under its inertia rounded to 12 digits, so which of two
nearly equal inertias built it depends on the order of the fits, and an optimiser may then
stop a step apart (seen: validation NRMSEs of candidates differing by 1e-6; the verdicts
of the real datasets and tuning cases are the same, see FAULTS.md).

The number of processes is :func:`jobs` (``--jobs`` of ``hasel diagnose``; default the
cores this process may run on). Nested calls (a task that maps again), a single job and
a diagnosis inside another pool's worker (the benches run one diagnosis per core) run
serially, in order. Platforms without ``fork`` run serially too.
"""
from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from hasel import interrupt

__all__ = ["pmap", "jobs", "set_jobs", "available_cores"]

T = TypeVar("T")
R = TypeVar("R")

_state: dict[str, Any] = {"jobs": None, "in_worker": False, "fn": None, "items": None}


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def set_jobs(n: int | None) -> None:
    """Use ``n`` processes for the diagnosis's parallel fits (``None``: the cores available; 1: serial)."""
    if n is not None and int(n) < 1:
        raise ValueError(f"jobs must be >= 1, got {n}")
    _state["jobs"] = None if n is None else int(n)


def jobs() -> int:
    """Processes :func:`pmap` uses: the number set by :func:`set_jobs`, else the cores available."""
    n = _state["jobs"]
    return available_cores() if n is None else n


def _init_worker() -> None:
    """In a new worker: the stop signals end it at once (the parent handles them and terminates its workers)."""
    import signal

    _state["in_worker"] = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)


def _run(i: int) -> Any:
    """In a worker: task ``i`` of the map being run (the function and items came with the fork)."""
    return _state["fn"](_state["items"][i])


def pmap(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[fn(x) for x in items]``, the items spread over :func:`jobs` forked processes.

    ``fn`` may be a closure (it is not pickled: the workers are forks); its results must
    pickle. Items are handed out one at a time in order, so put the slowest first. An
    exception in a task is raised here, as a serial loop would raise it.
    """
    # a stop whose raise was lost in a fork's at-fork hook (only printed by Python) ends the run here,
    # at the next map, instead of after the whole diagnosis
    interrupt.check()
    items = list(items)
    n = min(jobs(), len(items))
    if (n <= 1 or _state["in_worker"] or multiprocessing.current_process().daemon
            or "fork" not in multiprocessing.get_all_start_methods()):
        # serially: one job, inside a worker of ours, or inside another pool's worker (a daemon may
        # have no children; the benches already run one diagnosis per core)
        return [fn(x) for x in items]
    ctx = multiprocessing.get_context("fork")
    saved = (_state["fn"], _state["items"])
    _state["fn"], _state["items"] = fn, items
    try:
        with ctx.Pool(n, initializer=_init_worker) as pool:
            return pool.map(_run, range(len(items)), chunksize=1)
    finally:
        _state["fn"], _state["items"] = saved
