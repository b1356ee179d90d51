"""``hasel bench --quick``: the table and the JSON have every row and finite values, and what each figure
measures is what it claims (the same computation, every message, the operating points); no timing target."""
from __future__ import annotations

import argparse
import json
import math

import pytest

from hasel import paper
from hasel_bench import figures as bench
from hasel_bench.offline import CAMPAIGN_GAINS
from hasel_bench.realtime import PERIOD_S, WorkerSpec, latency_summary, run_worker


def _finite_numbers(obj, path="") -> list[str]:
    """Paths of numbers in ``obj`` that are not finite (NaN became null in the JSON)."""
    bad = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            bad += _finite_numbers(v, f"{path}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            bad += _finite_numbers(v, f"{path}[{i}]")
    elif isinstance(obj, float) and not math.isfinite(obj):
        bad.append(path)
    return bad


def test_quick_bench_writes_a_table_and_finite_json(tmp_path, capfd):
    # capfd, not capsys: EventsExecutor() calls faulthandler.enable(), which needs a real stderr
    out = tmp_path / "bench.json"
    args = argparse.Namespace(quick=True, json=str(out), only="1,2,5,8", cache=str(tmp_path / "cache"))
    assert bench.run(args) == 0
    table = capfd.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["errors"] == {} and doc["figures"] == [1, 2, 5, 8]
    head = table.splitlines()[0]
    assert [c.strip() for c in head.split("|")] == ["figure", "value", "baseline", "ratio", "target", "pass"]
    figs = {r["figure"].split()[0] for r in doc["table"]}
    assert figs == {"1", "2", "5", "8"}
    for r in doc["table"]:
        assert r["figure"] in table and r["value"] in table
        assert r["ratio"] is None or (isinstance(r["ratio"], float) and r["ratio"] > 0)
    res = doc["results"]
    g = res["1_graph_sim_time"]
    for ex in ("events", "single"):
        assert g[ex]["speed"] > 0 and g[ex]["sim_time_ok"] is True
    assert res["2_core_loop"]["max_abs_diff_mm"] < 1e-6  # lsim and the loop's plant agree
    r5 = res["5_ident_recording"]
    assert r5["identify_vs_load"]["files"] == 3 and r5["recorder_vs_bare"]["recorder_bytes"] > 0
    # the identification timed is a real one: it finds each actuator's offsets (Table I: 2-7 kV, 1 kV chirps),
    # less those whose stroke the laser's full scale clips (identify leaves them out)
    num, den = paper.plant_tf()
    full_scale_mm = paper.ADC_FULL_SCALE_V * paper.LASER_MM_PER_V
    unclipped = [sum(g * num[-1] / den[-1] * (v + 1.0) < full_scale_mm for v in range(2, 8)) for g in CAMPAIGN_GAINS]
    assert [m["operating_points"] for m in r5["identify_vs_load"]["models"]] == unclipped
    fl = res["floor"]  # the empty ring and one plant step: nothing with this graph's work can beat it
    # delivery_us is a difference of two wall times (clipped at 0 under load): a ratio for make bench, not a test
    assert fl["n_nodes"] == 5 and fl["round_cpu_us"] > 0 and fl["hop_us"] > 0
    ev = g["events"]
    assert ev["speed"] < fl["speed_ceiling"]
    assert any(r["figure"].startswith("1 ceiling") for r in doc["table"])
    assert ev["deliveries_per_tick"] >= ev["publishes_per_tick"] >= 8  # every loop message, each recorded
    assert ev["speed"] < ev["pattern_ceiling"] * 1.2  # nothing beats its own empty-callback ceiling by much
    assert not (tmp_path / "cache").exists()  # the campaign cache lives for the run only
    f = res["8_fuzz"]  # the loaders, on damaged files: rejected or read, never another exception or a hang
    assert f["cases"] > 0 and f["ok"] > 0 and f["rejected"] > 0 and f["crashed"] == 0 and f["hangs"] == []
    nums = dict(res)
    nums.pop("8_fuzz")  # crash details are text
    assert _finite_numbers(nums) == []


def test_realtime_worker_reports_every_tick_of_one_loop():
    from hasel.rosenv import private_domain

    r = run_worker(WorkerSpec((0,), duration_s=1.0, warmup_s=0.5, domain_id=private_domain()))
    (loop,) = r["loops"]
    assert loop["ns"] == "/rt0" and loop["expected"] == pytest.approx(200, abs=2)
    # every period of the window is either a tick or one the timer skipped (counted from its schedule)
    assert abs(loop["ticks"] + loop["skipped"] - loop["expected"]) <= 1
    s = latency_summary(r["loops"])
    # the answers to the ticks are matched to them: most ticks get one, typically within the period
    assert s["ticks"] >= 150 and s["samples"] >= 0.5 * s["ticks"]
    for k in ("p50_us", "p99_us", "max_us"):
        assert math.isfinite(s[k]) and s[k] > 0
    assert s["p50_us"] <= s["p99_us"] <= s["max_us"] and s["p50_us"] < 1e6 * PERIOD_S


def test_only_rejects_unknown_figures(tmp_path):
    args = argparse.Namespace(quick=True, json=str(tmp_path / "b.json"), only="12", cache=str(tmp_path))
    with pytest.raises(bench.BadInputError, match="--only"):
        bench.run(args)


def test_misses_are_grouped_in_bursts_and_counted_from_the_loops():
    from hasel_bench.realtime import _bursts

    # two loops stalled together at 4.48 s (one burst), one late tick of its own at 7 s
    loops = [{"latencies_us": [200.0] * 10, "missed": 2, "ticks": 1600, "expected": 1600, "skipped": 1,
              "missed_at_s": [4.481, 4.49], "skipped_at_s": [4.52]},
             {"latencies_us": [300.0] * 10, "missed": 1, "ticks": 1600, "expected": 1600, "skipped": 1,
              "missed_at_s": [7.0], "skipped_at_s": [4.5]}]
    s = latency_summary(loops)
    assert s["missed"] == 5 and s["late_outputs"] == 3 and s["skipped_ticks"] == 2
    assert s["missed_fraction"] == pytest.approx(5 / 3200)
    assert s["miss_bursts"] == [[4.481, 4.52, 4], [7.0, 7.0, 1]]
    assert _bursts([]) == [] and _bursts([1.0, 1.05, 1.2], gap_s=0.1) == [[1.0, 1.05, 2], [1.2, 1.2, 1]]
