"""The diagnosis's parallel fits (:mod:`hasel.diagnose.pool`): same results as in series."""
from __future__ import annotations

import os

import numpy as np
import pytest

from hasel.diagnose import pool
from hasel.diagnose.core import DiagnoseOptions, diagnose
from hasel.diagnose.prep import LinearSim


@pytest.fixture
def jobs():
    yield pool.set_jobs
    pool.set_jobs(None)


def test_pmap_keeps_the_order_runs_in_other_processes_and_raises_what_a_task_raises(jobs):
    jobs(2)
    if pool.jobs() < 2 or not hasattr(os, "fork"):
        pytest.skip("no fork here")
    base = np.arange(5.0)  # a closure over the parent's data: not pickled, forked
    got = pool.pmap(lambda i: (float(base[i] ** 2), os.getpid()), range(5))
    assert [g[0] for g in got] == [0.0, 1.0, 4.0, 9.0, 16.0]
    assert os.getpid() not in {g[1] for g in got}
    # a nested map runs serially inside its worker
    nested = pool.pmap(lambda i: {p for _, p in pool.pmap(lambda j: (j, os.getpid()), range(3))}, range(2))
    assert all(len(s) == 1 for s in nested)

    def bad(i: int) -> int:
        if i == 3:
            raise ValueError("task 3")
        return i

    with pytest.raises(ValueError, match="task 3"):
        pool.pmap(bad, range(5))
    jobs(1)
    assert {p for _, p in pool.pmap(lambda i: (i, os.getpid()), range(3))} == {os.getpid()}
    with pytest.raises(ValueError):
        jobs(0)


def test_parallel_and_serial_diagnoses_agree(jobs):
    rate = 200.0
    rng = np.random.default_rng(3)
    u = np.repeat(rng.uniform(0.0, 2.0, 40), 40) + 0.3 * np.sin(np.arange(1600) / 7.0)
    x = u + 0.25 * u ** 2  # an input-side static map
    y = LinearSim([40.0], [1.0, 6.0, 40.0], rate).run(x) + 0.002 * rng.normal(size=u.size)
    t = np.arange(u.size) / rate
    out = {}
    for n in (1, 2):
        jobs(n)
        v = diagnose(t, u, y, options=DiagnoseOptions(max_effects=1))
        out[n] = v
    a, b = out[1], out[2]
    assert a.names == b.names and a.names  # an identified model: the delay's profile runs in parallel too
    for ea, eb in zip(a.effects, b.effects):
        assert np.allclose(ea["theta"], eb["theta"], rtol=1e-6, atol=1e-9)
    ca = {c["name"]: c["nrmse_validation"] for c in a.rounds[0]["candidates"]}
    cb = {c["name"]: c["nrmse_validation"] for c in b.rounds[0]["candidates"]}
    assert ca.keys() == cb.keys() and all(abs(ca[k] - cb[k]) <= 1e-6 * ca[k] for k in ca)


def _in_a_daemon(_: int) -> list[int]:
    return pool.pmap(lambda i: os.getpid(), range(3))


def test_inside_another_pools_worker_it_runs_serially(jobs):
    import multiprocessing

    jobs(2)
    with multiprocessing.get_context("spawn").Pool(1) as other:  # as othersim and the benches run diagnoses
        pids = other.map(_in_a_daemon, [0])[0]
    assert len(set(pids)) == 1
