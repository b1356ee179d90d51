"""hasel compare: a closed-loop log recorded from a known plant, replayed through the graph per plant."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hasel.cli import main as hasel_main
from hasel.compare import load_closed_loop, nrmse
from hasel.io.loader import load_signals
from hasel_sysid.steps import run_steps


def test_compare_finds_the_recording_plant_at_the_noise_floor_and_the_nominal_far_off(tmp_path):
    log = tmp_path / "truth.mcap"
    run_steps("laser", [2.0, 4.0, 6.0, 4.0, 2.0], 0.4, seed=5, plant="truth", record=str(log), quiet=True)
    out = tmp_path / "cmp.json"
    assert hasel_main(["compare", str(log), "--plant", "nominal", "--plant", "truth", "--json", str(out),
                       "--plot", str(tmp_path / "cmp.png")]) == 0
    res = json.loads(out.read_text())
    assert [p["plant"] for p in res["plants"]] == ["nominal", "truth"]
    nominal, truth = res["plants"]
    # the noise floor: the recorded laser against the recorded true stroke
    sig = load_signals(log, ["/plant/batch.stroke_mm", "/plant/batch.true_stroke_mm"])
    floor = nrmse(sig["/plant/batch.stroke_mm"].values, sig["/plant/batch.true_stroke_mm"].values)
    assert 0 < floor < 0.01
    assert truth["stroke_nrmse"] < 1.5 * floor, (truth["stroke_nrmse"], floor)
    assert nominal["stroke_nrmse"] > 20 * truth["stroke_nrmse"]
    assert truth["voltage_nrmse"] < 0.05 < nominal["voltage_nrmse"]
    assert len(res["measured"]["steps"]) == 4 and all(len(p["steps"]) == 4 for p in res["plants"])
    for m, t in zip(res["measured"]["steps"], truth["steps"]):  # the right plant gives the measured steps
        assert abs(m["rise_s"] - t["rise_s"]) < 0.005 and abs(m["overshoot_pct"] - t["overshoot_pct"]) < 3.0
    assert (tmp_path / "cmp.png").stat().st_size > 10_000

    # the same test as a CSV log with the project's columns reads the same signals
    data = load_closed_loop(log)
    csv = tmp_path / "log.csv"
    ref = data.ref_mm[np.searchsorted(data.ref_t_s, data.t_s, side="right") - 1]
    np.savetxt(csv, np.column_stack([data.t_s, ref, data.stroke_mm, data.voltage_kv]), delimiter=",",
               header="t_s,reference_mm,stroke_mm,voltage_kv", comments="", fmt="%.12g")
    assert hasel_main(["compare", str(csv), "--plant", "truth", "--json", str(tmp_path / "c2.json")]) == 0
    again = json.loads((tmp_path / "c2.json").read_text())["plants"][0]
    # a CSV row carries the reference from its first sample on: the replay starts one sample (0.1 ms) later
    assert abs(again["stroke_nrmse"] - truth["stroke_nrmse"]) < 0.1 * truth["stroke_nrmse"]


def test_compare_replays_a_test_whose_steps_are_held_unevenly(tmp_path):
    """A rig's test holds each step as long as its operator chose: the replay follows those holds."""
    holds = [0.3, 0.5, 0.25, 0.45, 0.4]
    log = tmp_path / "uneven.mcap"
    run_steps("laser", [2.0, 4.0, 6.0, 4.0, 2.0], holds, seed=3, plant="truth", record=str(log), quiet=True)
    out = tmp_path / "cmp.json"
    assert hasel_main(["compare", str(log), "--plant", "nominal", "--plant", "truth", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["hold_s"][:4] == pytest.approx(holds[:4], abs=2e-3)
    assert 0.3 < res["hold_s"][4] <= 0.5  # the last step runs to the log's end
    nominal, truth = res["plants"]
    sig = load_signals(log, ["/plant/batch.stroke_mm", "/plant/batch.true_stroke_mm"])
    floor = nrmse(sig["/plant/batch.stroke_mm"].values, sig["/plant/batch.true_stroke_mm"].values)
    assert truth["stroke_nrmse"] < 1.5 * floor < 20 * truth["stroke_nrmse"] < nominal["stroke_nrmse"]
    for m, t in zip(res["measured"]["steps"], truth["steps"]):
        assert abs(m["rise_s"] - t["rise_s"]) < 0.005 and abs(m["overshoot_pct"] - t["overshoot_pct"]) < 3.0


def test_compare_refuses_a_bad_plant_or_log_with_one_line(tmp_path, capsys):
    (tmp_path / "bad.json").write_text(json.dumps({"num": [1.0], "den": [1.0, -1.0],
                                                   "units": {"input": "kV", "output": "mm"}}))
    (tmp_path / "flat.csv").write_text("t_s,reference_mm,stroke_mm,voltage_kv\n0,2,0,0\n1,2,1,1\n2,2,2,2\n")
    for argv, words in ((["compare", str(tmp_path / "flat.csv"), "--plant", str(tmp_path / "bad.json")], "not stable"),
                        (["compare", str(tmp_path / "flat.csv"), "--plant", "nominal"], "never changes"),
                        (["compare", str(tmp_path / "none.mcap"), "--plant", "nominal"], "no such file")):
        capsys.readouterr()
        assert hasel_main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err


def test_the_exported_augmented_plant_closes_the_closed_loop_gap(tmp_path):
    """identify-free chain: a chirp of an actuator relaxing slower than P(s), diagnosed against P(s) and
    exported; its closed-loop steps through the graph then predict the actuator's far better than P(s)."""
    from hasel import paper
    from hasel.plantspec import make_actuator
    from hasel.signals import protocol_schedule
    from hasel.simulator import PlantSimulator

    truth = "truth:asymmetric_dynamics(tau_relax_s=0.08)"
    sched = protocol_schedule([4.0], repeats=1, duration_s=8.0, precondition_s=0.5)
    sim = PlantSimulator(make_actuator(truth), seed=3)
    n = sim.samples_per_period
    u = sched.command_kv[: (sched.command_kv.size // n) * n]
    b = [sim.step(u[i:i + n]) for i in range(0, u.size, n)]
    cols = [np.concatenate([getattr(x, k) for x in b]) for k in ("times_s", "applied_kv", "laser_mm")]
    np.savetxt(tmp_path / "chirp.csv", np.column_stack(cols)[::10], delimiter=",",
               header="t_s,voltage_kv,stroke_mm", comments="", fmt="%.10g")
    num, den = paper.plant_tf()
    (tmp_path / "p.json").write_text(json.dumps({"num": list(num), "den": list(den)}))
    aug = tmp_path / "augmented.json"
    assert hasel_main(["diagnose", str(tmp_path / "chirp.csv"), "--model", str(tmp_path / "p.json"),
                       "--max-effects", "2", "--export-plant", str(aug)]) == 0
    log = tmp_path / "steps.mcap"
    run_steps("laser", [2.0, 4.0, 6.0, 4.0, 2.0], 0.4, seed=5, plant=truth, record=str(log), quiet=True)
    out = tmp_path / "cmp.json"
    assert hasel_main(["compare", str(log), "--plant", "nominal", "--plant", str(aug), "--json", str(out)]) == 0
    nominal, augmented = json.loads(out.read_text())["plants"]
    assert augmented["stroke_nrmse"] < nominal["stroke_nrmse"] / 3, (nominal["stroke_nrmse"],
                                                                     augmented["stroke_nrmse"])
    assert augmented["voltage_nrmse"] < nominal["voltage_nrmse"] / 3
