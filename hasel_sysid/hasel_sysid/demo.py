"""``hasel demo``: the toolkit's story end to end, on the simulator.

1. Calibrate the strain sensor against the laser (paper: 2-7 mm in 1 mm steps).
2. Closed-loop steps 2 -> 4 -> 6 -> 4 -> 2 mm with laser and with strain-sensor
   feedback through the node graph, beside the paper's Table II.
3. The paper's identification experiment (chirps on six DC offsets, recorded to
   MCAP) and the transfer-function fit from that log, against the paper's P(s).
4. The sim-to-real gap: the same loop on a "truth" actuator (the effects the paper
   reports but P(s) leaves out) against the nominal simulation and Table II; that
   actuator's chirp log diagnosed against the nominal model: where the residual lives,
   which effects explain it, and how far the held-out gap shrinks; the augmented model
   is exported as a plant-model file.
5. The gap in the closed loop, and the controller redesigned on the better model: the
   truth actuator's measured steps replayed by ``hasel compare`` with the nominal and
   the augmented plant (rise, settling, overshoot and NRMSE, before and after);
   ``hasel tune`` on the augmented plant; the tuned gains run on the truth actuator
   through the node graph, against the paper's gains.

Everything is written under ``--out`` (default ``out/demo``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["run"]


def _hasel(argv: list[str], what: str) -> None:
    """Run ``hasel ARGV`` in this process; a failure raises ``HaselError(what)``.

    A run stopped by a signal (exit 128 + N) raises :class:`hasel.interrupt.Interrupted`
    again, so the demo stops too and exits 128 + N instead of reporting a failure."""
    from hasel import interrupt
    from hasel.cli import main as hasel_main
    from hasel.errors import HaselError

    code = hasel_main(argv)
    if code > 128:
        raise interrupt.Interrupted(code - 128)
    if code != 0:
        raise HaselError(what)


def _section(title: str) -> None:
    print(f"\n== {title} " + "=" * max(0, 70 - len(title)))


def run(args: argparse.Namespace) -> int:
    """Run the demo; returns the exit code."""
    from hasel_sysid.calibrate import calibrate
    from hasel_sysid.steps import format_table, plot_steps, run_steps

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    hold = 0.5 if args.quick else 1.0

    _section("1. strain-sensor calibration against the laser (2-7 mm)")
    fit = calibrate([2, 3, 4, 5, 6, 7], hold, quiet=True)
    cal_path = out / "calibration.yaml"
    fit.calibration.to_yaml(cal_path, {"max_error_pct": fit.max_error_pct})
    c = fit.calibration.coeffs
    print(f"stroke_mm = {c[0]:.5f} * elapsed_us {c[1]:+.4f}; largest error {fit.max_error_pct:.3f} % -> {cal_path}")

    summary = {"calibration": {"coeffs": list(c), "max_error_pct": fit.max_error_pct}}
    for fb in ("laser", "strain"):
        _section(f"2. closed-loop steps, {fb} feedback (node graph, simulated time)")
        res = run_steps(fb, [2.0, 4.0, 6.0, 4.0, 2.0], hold, calibration_file=str(cal_path) if fb == "strain" else "",
                        quiet=True)
        print(format_table(res["steps"], fb))
        print(f"applied voltage {res['min_applied_kv']:.2f} .. {res['max_applied_kv']:.2f} kV (ceiling 9 kV)")
        (out / f"steps_{fb}.json").write_text(json.dumps({k: v for k, v in res.items() if k != "_signals"}, indent=2))
        plot_steps(res, str(out / f"steps_{fb}.png"))
        summary[f"steps_{fb}"] = res["steps"]
    _section("3. identification: the paper's chirp protocol, recorded, then identified from the log")
    summary["identification"] = _identify_stage(out, args.quick)

    _section("4. the sim-to-real gap: a 'truth' actuator against the nominal model")
    summary["gap"] = _gap_stage(out, args.quick)

    _section("5. the gap in the closed loop, and the gains redesigned on the augmented model")
    summary["retune"] = _retune_stage(out, args.quick)

    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _section("done")
    print(f"files in {out}/: calibration.yaml, steps_*.{{json,png}}, chirp.mcap, model.json, bode.png, "
          "identify/report.md, truth_steps.{json,png}, truth_chirp.mcap, truth_heldout.mcap, verdict.json, "
          "gap_sim.csv, diagnose/report.md, augmented.json, truth_steps.mcap, compare.{json,png}, gains.yaml, "
          "tune.json, truth_tuned_steps.{json,png}, summary.json")
    return 0


def _identify_stage(out: Path, quick: bool) -> dict:
    """Chirp campaign through the graph (recorded), then ``identify`` on the MCAP."""
    import numpy as np

    from hasel import paper
    from hasel.lti import tf_freqresp
    from hasel.signals import protocol_schedule
    from hasel_sysid.chirp import run_chirp

    offsets = [3.0, 5.0] if quick else list(paper.CHIRP_PROTOCOL["offsets_kv"])
    sched = protocol_schedule(offsets)
    log = out / "chirp.mcap"
    res = run_chirp(sched, str(log), quiet=True)
    print(f"recorded {len(offsets)} operating points x 3 chirps (paper formula), {res['simulated_s']:.0f} s "
          f"simulated at 10 kHz in {res['wall_s'] or 0:.1f} s -> {log}")

    print(f"$ hasel identify {log} --json {out / 'model.json'} --plot {out / 'bode.png'} --report {out / 'identify'}")
    _hasel(["identify", str(log), "--json", str(out / "model.json"), "--plot", str(out / "bode.png"),
            "--report", str(out / "identify"), "--overwrite"], "identification of the demo's own log failed")
    model = json.loads((out / "model.json").read_text())
    f = np.geomspace(0.1, 15.0, 200)
    ratio = tf_freqresp(model["num"], model["den"], f) / tf_freqresp(*paper.plant_tf(), f)
    db, deg = float(np.max(np.abs(20 * np.log10(np.abs(ratio))))), float(np.max(np.abs(np.angle(ratio, deg=True))))
    print(f"against the paper's P(s), 0.1-15 Hz: worst {db:.3f} dB, {deg:.2f} deg (target 1 dB, 5 deg)")
    return {"num": model["num"], "den": model["den"], "worst_db": db, "worst_deg": deg}


def _gap_stage(out: Path, quick: bool) -> dict:
    """Closed loop and chirps on the truth plant; diagnosis against the nominal model."""
    from hasel.plantspec import describe, make_actuator
    from hasel.signals import protocol_schedule
    from hasel_sysid.chirp import run_chirp
    from hasel_sysid.steps import format_table, plot_steps, run_steps

    print(f"the 'actuator': {describe(make_actuator('truth'))}")
    hold = 0.5 if quick else 1.0
    # recorded: stage 5 replays this "measurement" with the nominal and the augmented plant
    res = run_steps("laser", [2.0, 4.0, 6.0, 4.0, 2.0], hold, plant="truth", quiet=True,
                    record=str(out / "truth_steps.mcap"))
    nominal = json.loads((out / "steps_laser.json").read_text())["steps"]
    print("closed loop (laser feedback) on the actuator; in brackets: the loop on the nominal P(s)")
    print(format_table(res["steps"], "laser"))
    for s, n in zip(res["steps"], nominal):
        print(f"  {s['from_mm']:g} -> {s['to_mm']:g}: rise {s['rise_s']:.3f} s [{n['rise_s']:.3f}], "
              f"overshoot {s['overshoot_pct']:.1f} % [{n['overshoot_pct']:.1f}]")
    (out / "truth_steps.json").write_text(json.dumps({k: v for k, v in res.items() if k != "_signals"}, indent=2))
    plot_steps(res, str(out / "truth_steps.png"))

    offsets = [3.0, 5.0] if quick else [2.0, 4.0, 6.0]
    # held out: the operating points between the trained ones (inside the trained voltage
    # range, so the check is of the effects, not of extrapolating a static map), other noise
    between = [(a + b) / 2 for a, b in zip(offsets, offsets[1:])]
    runs = {"truth_chirp.mcap": (offsets, 1), "truth_heldout.mcap": (between, 2)}
    for name, (offs, seed) in runs.items():
        sched = protocol_schedule(offs, kind="paper", repeats=3 if not quick else 2)
        run_chirp(sched, str(out / name), plant="truth", seed=seed, quiet=True)
    print(f"recorded the actuator's chirps: {out / 'truth_chirp.mcap'} (offsets {offsets} kV) and, to check the "
          f"verdict on data it has not seen, {out / 'truth_heldout.mcap'} (offsets {between} kV)")
    argv = ["diagnose", str(out / "truth_chirp.mcap"), "--heldout", str(out / "truth_heldout.mcap"),
            "--model", str(out / "model.json"), "--json", str(out / "verdict.json"),
            "--export-sim", str(out / "gap_sim.csv"), "--report", str(out / "diagnose"),
            "--export-plant", str(out / "augmented.json"), "--overwrite"]
    print("$ hasel " + " ".join(argv))
    _hasel(argv, "the diagnosis of the demo's own logs failed")
    verdict = json.loads((out / "verdict.json").read_text())
    named = [e["name"] for e in verdict["effects"]]
    ho = verdict["heldout"]
    print(f"effects named, most important first: {', '.join(named) or 'none'}")
    print(f"held-out NRMSE {ho['nrmse_nominal']:.4f} (nominal P(s)) -> {ho['nrmse_augmented']:.4f} "
          f"(augmented); noise floor {verdict['noise_floor_nrmse']:.4f}")
    print(f"the augmented model as a plant-model file: {out / 'augmented.json'}")
    return {"effects": named, "heldout": ho, "noise_floor_nrmse": verdict["noise_floor_nrmse"],
            "truth_steps": res["steps"]}


_METRICS = (("rise_s", "rise (s)", "{:.3f}"), ("settling_s", "settling (s)", "{:.3f}"),
            ("overshoot_pct", "overshoot (%)", "{:.1f}"))


def _num(x) -> float:
    return float("nan") if x is None else float(x)


def _gap_table(cmp: dict) -> tuple[str, dict]:
    """Per step and metric: measured, nominal and augmented, and whether the augmented is closer."""
    meas = cmp["measured"]["steps"]
    nom, aug = cmp["plants"][0]["steps"], cmp["plants"][1]["steps"]
    lines = [f"{'step (mm)':<12}{'metric':<15}{'measured':>10}{'nominal':>10}{'augmented':>11}  gap nominal -> augmented"]
    closer = {}
    for i, m in enumerate(meas):
        step = label = f"{m['from_mm']:g} -> {m['to_mm']:g}"
        for key, name, fmt in _METRICS:
            mv, nv, av = _num(m[key]), _num(nom[i][key]), _num(aug[i][key])
            gn, ga = abs(nv - mv), abs(av - mv)
            ok = bool(ga <= gn)
            closer[f"{step} {key}"] = {"measured": mv, "nominal": nv, "augmented": av, "closer": ok}
            lines.append(f"{label:<12}{name:<15}{fmt.format(mv):>10}{fmt.format(nv):>10}{fmt.format(av):>11}  "
                         f"{fmt.format(gn)} -> {fmt.format(ga)}{'' if ok else '  (not closer)'}")
            label = ""
    return "\n".join(lines), closer


def _retune_stage(out: Path, quick: bool) -> dict:
    """compare (nominal vs augmented) on the truth log; tune on the augmented plant; the tuned gains on truth."""
    import math

    from hasel.tune import read_gains
    from hasel_sysid.steps import plot_steps, run_steps

    hold = 0.5 if quick else 1.0
    log, aug = out / "truth_steps.mcap", out / "augmented.json"
    argv = ["compare", str(log), "--plant", "nominal", "--plant", str(aug), "--json", str(out / "compare.json"),
            "--plot", str(out / "compare.png"), "--overwrite"]
    print("the truth actuator's closed-loop steps (stage 4, recorded) replayed with the nominal and the augmented plant")
    print("$ hasel " + " ".join(argv))
    _hasel(argv, "hasel compare on the demo's own log failed")
    cmp = json.loads((out / "compare.json").read_text())
    table, closer = _gap_table(cmp)
    nrmse = [p["stroke_nrmse"] for p in cmp["plants"]]
    print("the closed-loop gap, before (nominal P(s)) and after (augmented model):")
    print(table)
    n_closer = sum(v["closer"] for v in closer.values())
    print(f"stroke NRMSE {nrmse[0]:.4f} (nominal) -> {nrmse[1]:.4f} (augmented), ratio {nrmse[1] / nrmse[0]:.2f}; "
          f"{n_closer} of {len(closer)} step metrics closer to the measurement")

    evals = 16 if quick else 60
    argv = ["tune", "--plant", str(aug), "--hold", f"{hold:g}", "--max-evals", str(evals),
            "--out", str(out / "gains.yaml"), "--json", str(out / "tune.json"), "--overwrite"]
    print("\n$ hasel " + " ".join(argv))
    _hasel(argv, "hasel tune on the augmented plant failed")

    gains = read_gains(out / "gains.yaml")
    print(f"\nthe tuned gains ({out / 'gains.yaml'}) on the truth actuator, through the node graph:")
    tuned = run_steps("laser", [2.0, 4.0, 6.0, 4.0, 2.0], hold, plant="truth", quiet=True, gains=gains)
    (out / "truth_tuned_steps.json").write_text(json.dumps({k: v for k, v in tuned.items() if k != "_signals"},
                                                           indent=2))
    plot_steps(tuned, str(out / "truth_tuned_steps.png"))
    paper_steps = json.loads((out / "truth_steps.json").read_text())
    lines = [f"{'step (mm)':<12}{'metric':<15}{'paper gains':>12}{'tuned':>10}"]
    verdict = {}
    for p, t in zip(paper_steps["steps"], tuned["steps"]):
        step = label = f"{p['from_mm']:g} -> {p['to_mm']:g}"
        for key, name, fmt in _METRICS:
            pv, tv = _num(p[key]), _num(t[key])
            lines.append(f"{label:<12}{name:<15}{fmt.format(pv):>12}{fmt.format(tv):>10}")
            verdict[f"{step} {key}"] = {"paper": pv, "tuned": tv}
            label = ""
    lines.append(f"{'highest applied (kV)':<27}{paper_steps['max_applied_kv']:>12.2f}{tuned['max_applied_kv']:>10.2f}")
    print("\n".join(lines))
    worse = [k for k, v in verdict.items() if "rise_s" not in k
             and not (v["tuned"] <= v["paper"] + (0.002 if "settling" in k else 0.2) or math.isnan(v["paper"]))]
    print("settling and overshoot with the tuned gains: "
          + ("no step worse than with the paper's gains" if not worse else "worse in " + ", ".join(worse)))
    return {"compare": {"stroke_nrmse": {"nominal": nrmse[0], "augmented": nrmse[1]}, "metrics": closer},
            "tune": json.loads((out / "tune.json").read_text())["tuned"]["gains"],
            "truth_paper_vs_tuned": verdict, "tuned_max_applied_kv": tuned["max_applied_kv"], "worse": worse}
