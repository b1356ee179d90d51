"""The blind-check harness, written once: unlabelled case files, each diagnosed in a spawned process.

A blind check generates cases (a truth actuator simulated on an excitation), writes
each log to an ``.npz`` file holding only ``t_s`` (s), ``voltage_kv``, ``stroke_mm``
and the nominal model ``num``/``den`` (no label: the labels stay in the generating
process), has spawned processes diagnose the files (:func:`diagnose_files`, the worker
:func:`diagnose_file` receives only a path), and then reveals the labels and scores.
Used by :mod:`hasel_bench.blind` (the project's own effect library) and
:mod:`hasel_bench.othersim` (an independent simulator).
"""
from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence

import numpy as np

__all__ = ["case_directory", "diagnose_file", "diagnose_files", "result_line", "say_stderr", "write_json"]


@contextlib.contextmanager
def case_directory(directory: str | None, prefix: str) -> Iterator[str]:
    """``directory`` as given, or a temporary one (named ``prefix...``) removed on exit."""
    if directory is not None:
        yield directory
        return
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        yield tmp


def diagnose_file(job: tuple[str, bool]) -> dict:
    """Worker (spawned process): diagnose an unlabelled file ``job = (path, with_model)``.

    With the file's nominal model when ``with_model``, else the diagnosis identifies one.
    Returns the verdict's essentials (``names``, ``nrmse_nominal``, ``nrmse_augmented``,
    ``floor``, ``effects``, ``rounds``, ``seconds``...), or ``error`` if it raised.
    """
    from hasel.diagnose.core import diagnose

    path, with_model = job
    d = np.load(path)
    t0 = time.perf_counter()
    try:
        v = diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"],
                     model={"num": d["num"].tolist(), "den": d["den"].tolist()} if with_model else None,
                     units=("kV", "mm"))
    except Exception as err:  # noqa: BLE001 - a crash is a result to report
        return {"path": path, "with_model": with_model, "error": f"{type(err).__name__}: {err}",
                "names": [], "seconds": time.perf_counter() - t0}
    return {"path": path, "with_model": with_model, "names": v.names,
            "nrmse_nominal": v.heldout["nrmse_nominal"], "nrmse_augmented": v.heldout["nrmse_augmented"],
            "floor": v.noise_floor_nrmse, "working_rate_hz": v.working_rate_hz,
            "effects": [{k: e[k] for k in ("name", "params", "evidence", "nrmse_after", "gap_removed")}
                        for e in v.effects],
            "rounds": [{k: r.get(k) for k in ("round", "best", "gain", "z", "accepted")}
                       | {"top": [(c.get("name"), c.get("nrmse_heldout", c.get("nrmse_validation")))
                                 for c in r.get("candidates", [])[:4]]}
                       for r in v.rounds],
            "model_source": v.model.get("source"), "seconds": time.perf_counter() - t0}


def diagnose_files(jobs: Sequence[tuple[str, bool]], workers: int = 1,
                   on_result: Callable[[dict], None] | None = None) -> list[dict]:
    """:func:`diagnose_file` on every job in ``workers`` spawned processes; results in job order.

    ``on_result`` is called with each result as it comes (progress lines).
    """
    results: list[dict] = []
    with mp.get_context("spawn").Pool(max(1, int(workers))) as pool:
        for r in pool.imap(diagnose_file, list(jobs)):
            results.append(r)
            if on_result is not None:
                on_result(r)
    return results


def result_line(r: dict) -> str:
    """One progress line for a result of :func:`diagnose_file`: the file, what was named, the time."""
    how = "" if r.get("with_model", True) else " (no model)"
    err = f" ERROR {r['error']}" if r.get("error") else ""
    return f"  {os.path.basename(r['path'])}{how}: {', '.join(r['names']) or 'no effect'}{err} ({r['seconds']:.1f} s)"


def say_stderr(message: str) -> None:
    """Progress on stderr, flushed (the scripts' ``progress``)."""
    sys.stderr.write(message + "\n")
    sys.stderr.flush()


def write_json(scores: dict, path: str | None) -> None:
    """Write the full scores to ``path`` (numpy numbers as floats); nothing when ``path`` is None."""
    if path:
        with open(path, "w") as fh:
            json.dump(scores, fh, indent=1, default=float)
