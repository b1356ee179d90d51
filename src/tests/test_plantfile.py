"""Plant-model files: the reader (lossless for MODEL.json, one-line errors), the actuator it builds, export."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hasel import paper
from hasel.cli import main as hasel_main
from hasel.effects.base import run_chunked  # noqa: F401 - the chunking the plant node relies on
from hasel.plant import NominalActuator
from hasel.plantchain import FileActuator
from hasel.plantfile import PlantFileError, parse_plant, read_plant, write_plant
from hasel.plantspec import make_actuator
from hasel.signals import protocol_schedule
from hasel.simulator import PlantSimulator

NUM, DEN = (list(map(float, c)) for c in paper.plant_tf())
KVMM = {"input": "kV", "output": "mm"}


def _command(n: int = 20000) -> np.ndarray:
    """Steps up and down with a chirp on top, kV, at 10 kHz."""
    t = np.arange(n) * 1e-4
    return np.clip(3.0 + 2.0 * np.sign(np.sin(2 * np.pi * 1.5 * t)) + 0.5 * np.sin(2 * np.pi * (1 + 5 * t) * t), 0, 9)


def _identify_like() -> dict:
    """A MODEL.json as ``hasel identify`` writes it (its own keys, the tool's version string)."""
    return {"num": [0.0187, 17.43, 449.75, 247868.1, 1445826.98], "den": [1.0, 134.55, 11871.46, 217482.2, 583054.3],
            "delay_s": 0.0021, "zeros": [], "poles": [], "gain": 0.0187,
            "units": {"input": "kV", "output": "mm", "gain": "mm/kV", "time": "s", "frequency": "Hz", "s": "rad/s"},
            "tool": "hasel identify", "version": "0.1.0", "fit": {"fit_percent": 94.8}}


def test_identify_model_json_reads_losslessly_and_round_trips(tmp_path):
    src = _identify_like()
    (tmp_path / "model.json").write_text(json.dumps(src))
    m = read_plant(tmp_path / "model.json")
    assert list(m.num) == src["num"] and list(m.den) == src["den"] and m.delay_s == src["delay_s"]
    assert m.extra["fit"] == src["fit"] and not m.effects
    write_plant(tmp_path / "plant.json", m)
    back = read_plant(tmp_path / "plant.json")
    assert (back.num, back.den, back.delay_s) == (m.num, m.den, m.delay_s)
    out = json.loads((tmp_path / "plant.json").read_text())
    assert out["format"] == "hasel-plant" and out["version"] == 1 and out["units"] == KVMM


def test_a_file_of_the_papers_model_runs_bit_for_bit_as_the_nominal_plant(tmp_path):
    (tmp_path / "p.json").write_text(json.dumps({"num": NUM, "den": DEN, "units": KVMM}))
    u = _command()
    a, b = make_actuator(str(tmp_path / "p.json")), NominalActuator()
    for act in (a, b):
        act.reset(0.0)
    np.testing.assert_array_equal(a.run(u).stroke_mm, b.run(u).stroke_mm)
    np.testing.assert_array_equal(a.run_held(4.0, 50).stroke_mm, b.run_held(4.0, 50).stroke_mm)


def test_dead_time_delays_the_stroke_and_not_the_applied_voltage():
    u = _command()
    d = FileActuator(parse_plant({"num": NUM, "den": DEN, "delay_s": 0.01, "units": KVMM}))
    n = NominalActuator()
    n.reset(0.0)
    out, ref = d.run(u), n.run(u)
    np.testing.assert_allclose(out.stroke_mm[100:], ref.stroke_mm[:-100], rtol=0, atol=1e-12)
    assert np.all(out.stroke_mm[:100] == 0.0)
    np.testing.assert_array_equal(out.applied_kv, ref.applied_kv)


def test_stated_units_are_converted_to_kv_and_mm():
    u = _command(5000)
    vm = FileActuator(parse_plant({"num": [c * 1e-6 for c in NUM], "den": DEN, "units": {"input": "V", "output": "m"}}))
    factors = FileActuator(parse_plant({"num": [c * 2.0 for c in NUM], "den": DEN,
                                        "units": {"input": "mV", "output": "mm", "kv_to_input": 0.5,
                                                  "output_to_mm": 1.0}}))
    n = NominalActuator()
    n.reset(0.0)
    ref = n.run(u).stroke_mm
    for act in (vm, factors):
        np.testing.assert_allclose(act.run(u).stroke_mm, ref, rtol=0, atol=1e-10)  # rounding of the scaled num


def test_truth_effects_in_a_file_run_as_the_truth_spec():
    spec = "truth:time_delay(delay_s=0.004)+static_nonlinearity(kind=electrostatic,strength=0.3)+charge_drift"
    f = FileActuator(parse_plant({"num": NUM, "den": DEN, "units": KVMM, "effects": [
        {"name": "time_delay", "params": {"delay_s": 0.004}},
        {"name": "static_nonlinearity", "params": {"kind": "electrostatic", "strength": 0.3}},
        {"name": "charge_drift", "params": {}}]}))
    t = make_actuator(spec)
    t.reset(0.0)
    u = _command()
    np.testing.assert_array_equal(f.run(u).stroke_mm, t.run(u).stroke_mm)


FITTED = {"format": "hasel-plant", "version": 1, "num": NUM, "den": DEN, "units": KVMM,
          "effects": [{"name": "time_delay", "form": "fitted", "variant": "input", "params": {"delay_s": 0.003}},
                      {"name": "hysteresis", "form": "fitted", "variant": "input",
                       "params": {"w_1": 0.1, "w_2": 0.05, "w_3": 0.0, "w_4": 0.1, "w_5": 0.0}},
                      {"name": "asymmetric_dynamics", "form": "fitted", "variant": "output",
                       "params": {"tau_rising_s": 0.002, "tau_falling_s": 0.05, "falling_tau_level_slope": 0.0}},
                      {"name": "charge_drift", "form": "fitted", "variant": "output",
                       "params": {"tau_s": 5.0, "gain_per_charge": 0.05, "offset_per_charge": 0.01}}],
          "scales": {"u_c": 3.0, "u_s": 2.5, "y_c": 4.0, "y_s": 3.0, "thresholds": [0.05, 0.15, 0.35, 0.75, 1.5],
                     "tau_smooth_s": 0.5}}


def test_fitted_chain_in_5ms_blocks_equals_one_call_and_is_not_the_nominal():
    u = _command()
    a, b = FileActuator(parse_plant(FITTED)), FileActuator(parse_plant(FITTED))
    whole = a.run(u).stroke_mm
    blocks = np.concatenate([b.run(u[i:i + 50]).stroke_mm for i in range(0, u.size, 50)])
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-12)
    n = NominalActuator()
    n.reset(0.0)
    assert np.max(np.abs(whole - n.run(u).stroke_mm)) > 0.05


def _with(**changes):
    obj = json.loads(json.dumps(FITTED))
    obj.update(changes)
    return obj


MALFORMED = [
    ({"num": [1.0], "den": [1.0, -3.0, 2.0], "units": KVMM}, "not stable"),
    ({"num": [1.0, 0.0, 0.0], "den": [1.0, 1.0], "units": KVMM}, "not proper"),
    ({"num": [1.0, float("nan")], "den": [1.0, 1.0], "units": KVMM}, "non-finite"),
    ({"num": [1.0], "den": [1.0, float("inf")], "units": KVMM}, "non-finite"),
    ({"num": [1.0], "den": [1.0, 1.0], "units": KVMM, "effects": [{"name": "backlash", "params": {}}]},
     "unknown effect 'backlash'"),
    ({"num": [1.0], "den": [1.0, 1.0], "units": KVMM,
      "effects": [{"name": "charge_drift", "params": {"tau_h": 3}}]}, "no parameter tau_h"),
    (_with(effects=[{"name": "time_delay", "form": "fitted", "variant": "input", "params": {"lag_s": 0.01}}]),
     "unknown parameter(s) lag_s"),
    ({"num": [1.0], "den": [1.0, 1.0]}, "states no units"),
    ({"num": [1.0], "den": [1.0, 1.0], "units": {"input": "kV", "output": "in"}}, "output unit 'in'"),
    ({"num": [1.0], "den": [1.0, 1.0], "units": {"input": "", "output": "mm"}}, "input unit ''"),
    ({"num": [1.0], "den": [1.0, 1.0], "units": {"input": "V", "output": "mm"},
      "effects": [{"name": "time_delay", "params": {}}]}, "effects need the graph's units"),
    (_with(version=2), "version 2 is not supported"),
    (_with(format="other"), "format is 'other'"),
    (_with(effects=FITTED["effects"][::-1]), "not in the chain order"),
    (_with(scales={"u_c": 1.0}), "scales lack"),
    ({"num": [1.0], "den": [1.0, 1.0], "units": KVMM,
      "effects": [{"name": "time_delay", "params": {}}, {"name": "time_delay", "params": {}}]}, "given twice"),
    ({"num": "1", "den": [1.0, 1.0], "units": KVMM}, "'num' must be a non-empty list"),
]


@pytest.mark.parametrize("obj,words", MALFORMED, ids=[w for _, w in MALFORMED])
def test_every_malformed_file_is_refused_with_one_line_naming_it(tmp_path, obj, words):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(obj))
    with pytest.raises(PlantFileError) as err:
        read_plant(path)
    msg = str(err.value)
    assert words in msg and msg.startswith(f"plant file {path}:") and "\n" not in msg


def test_unreadable_files_are_refused_with_one_line(tmp_path):
    for name, text, words in (("missing.json", None, "does not exist"), ("bad.json", "{num", "is not JSON"),
                              ("list.json", "[1, 2]", "not a JSON object")):
        if text is not None:
            (tmp_path / name).write_text(text)
        with pytest.raises(PlantFileError, match=words):
            read_plant(tmp_path / name)


def test_diagnose_export_plant_writes_a_file_whose_simulation_closes_the_gap(tmp_path):
    """A log of an actuator relaxing slower than P(s): the exported file predicts its true stroke."""
    sched = protocol_schedule([4.0], repeats=1, duration_s=8.0, precondition_s=0.5)

    def run(plant: str):
        sim = PlantSimulator(make_actuator(plant), seed=3)
        n = sim.samples_per_period
        u = sched.command_kv[: (sched.command_kv.size // n) * n]
        b = [sim.step(u[i:i + n]) for i in range(0, u.size, n)]
        return [np.concatenate([getattr(x, k) for x in b]) for k in ("times_s", "applied_kv", "laser_mm",
                                                                        "true_stroke_mm")]

    truth = "truth:asymmetric_dynamics(tau_relax_s=0.08)"
    t, v, y, z = run(truth)
    np.savetxt(tmp_path / "log.csv", np.column_stack([t, v, y])[::10], delimiter=",",
               header="t_s,voltage_kv,stroke_mm", comments="", fmt="%.10g")
    (tmp_path / "paper.json").write_text(json.dumps({"num": NUM, "den": DEN}))
    out = tmp_path / "augmented.json"
    assert hasel_main(["diagnose", str(tmp_path / "log.csv"), "--model", str(tmp_path / "paper.json"),
                       "--max-effects", "2", "--export-plant", str(out)]) == 0
    m = read_plant(out)
    assert m.fitted and "asymmetric_dynamics" in [e.name for e in m.effects]
    assert (m.num, m.den) == (tuple(NUM), tuple(DEN))

    def nrmse(a, b):
        return float(np.linalg.norm(a - b) / np.linalg.norm(b - b.mean()))

    nominal, augmented = nrmse(run("nominal")[3], z), nrmse(run(str(out))[3], z)
    assert augmented < nominal / 10, (nominal, augmented)



def test_an_exported_plant_leaves_the_logs_timing_offset_out(tmp_path):
    """A delay within one sample that the diagnosis folded into the log's timing offset (not named) is not put
    into the simulator's chain: the plant file carries the named effects only and lists the delay under
    ``not_simulated`` with its seconds. The log (``test_load_pair``'s moved anti-resonance, 500 Hz, no timing offset
    written): the set-up shifts the output by about -0.9 sample and the fitted delay (1.8 ms, +0.9 sample) takes it
    back, a net offset of 0.02 sample; a simulator given the delay would lag the actuator by 0.9 sample."""
    import designs
    from hasel.diagnose import diagnose
    from hasel.plantfile import export_plant
    from test_load_pair import _notch_plant

    t, u, y, model = designs.multisine_through(_notch_plant(0.75, 0.12), 13, 500.0, 0.0, 0.004, 16.0)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert v.names == ["load_mass"]
    folded = v.timing_offset["delay_fit_within_one_sample_s"]
    assert 0.5 < folded * 500.0 < 1.0 and abs(v.timing_offset["original_samples"]) < 0.1
    m = read_plant(export_plant(v, tmp_path / "plant.json"))
    assert [e.name for e in m.effects] == ["load_mass"]
    entry = m.extra["not_simulated"][0]
    assert entry["name"] == "time_delay" and entry["params"]["delay_s"] == pytest.approx(folded, rel=1e-9)
