"""Identification on effect-free logs with drawn measurement conditions (the tuning corpus's harder half).

Every log is P(s) of one design of ``src/tests/designs.py`` at one rate, with drawn
sampling convention (zoh/foh/centred), timing offset (-0.5..0.5 samples, a third none),
noise (white/coloured/wander, 0.003-0.03 mm), laser quantisation (half of them),
excitation amplitude (0.5-1), settling time (0-3 s) and pre-conditioning.

Usage: python bench/tune_ident/varied.py [--rates 200,1000,10000] [--designs a,b] [--draws 1] [--seed 0] [--more]
       [--widened] [--opt NAME=VALUE ...]

``--widened`` runs the cases of :data:`WIDENED` instead (session 9, branch h-ident2: the designs the drawn grid
covers thinly): PRBS and random steps at 200 Hz and 500 Hz, repeated paper chirps at 200 Hz, closed-loop
step logs with a drawn loop gain, long settle segments (10-30 s), one paper chirp with and without the -1 kV
pre-conditioning (otherwise the same draw), coloured noise forced. Each case draws its conditions as
``draw`` does from its own stream ``[seed, rate, 100 + case index]``, then applies its overrides.
Prints one row per log and a tally: good (within 1 dB / 5 deg over 0.1-15 Hz), and the two
failure kinds: wrong yet usable (the worst: a wrong model at exit 0) and right yet refused.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
import designs  # noqa: E402

from hasel.errors import BadInputError  # noqa: E402
from hasel.ident import identify  # noqa: E402

LASER_LSB_MM = 10.0 / 4096


def draw(rng: np.random.Generator) -> dict:
    """Measurement conditions of one log (see the module)."""
    return {"convention": ("zoh", "foh", "centred")[int(rng.integers(3))],
            "offset_samples": 0.0 if rng.random() < 1 / 3 else float(rng.uniform(-0.5, 0.5)),
            "noise_kind": ("white", "coloured", "wander")[int(rng.integers(3))],
            "noise_mm": float(np.exp(rng.uniform(np.log(0.003), np.log(0.03)))),
            "noise_fc_hz": float(rng.uniform(2.0, 20.0)),
            "lsb_mm": LASER_LSB_MM if rng.random() < 0.5 else 0.0,
            "amplitude": float(rng.uniform(0.5, 1.0)),
            "settle_s": float(rng.uniform(0.0, 3.0)),
            "precondition": bool(rng.random() < 0.5)}


def draw_more(rng: np.random.Generator) -> dict:
    """The extra conditions of ``--more``: hold times of random steps, closed-loop gain, long settling."""
    lo = float(np.exp(rng.uniform(np.log(0.01), np.log(0.5))))
    return {"hold_s": (lo, lo * float(np.exp(rng.uniform(np.log(4.0), np.log(20.0))))),
            "loop_gain": float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))),
            "settle_s": float(rng.uniform(0.0, 30.0)) if rng.random() < 0.5 else float(rng.uniform(0.0, 3.0))}


#: The widened cases: (design, rate Hz, overrides of the drawn conditions); ``more`` draws draw_more's too.
WIDENED = (("prbs", 200.0, {}), ("prbs", 500.0, {}), ("prbs", 200.0, {"noise_kind": "coloured"}),
           ("random_steps", 200.0, {}), ("random_steps", 500.0, {}),
           ("random_steps", 500.0, {"noise_kind": "coloured", "more": True}),
           ("paper_chirp3", 200.0, {}), ("paper_chirp3", 200.0, {"convention": "zoh", "offset_samples": 0.0}),
           ("paper_chirp3", 200.0, {"noise_kind": "coloured"}),
           ("closed_loop", 200.0, {"more": True}), ("closed_loop", 500.0, {"more": True}),
           ("paper_chirp", 200.0, {"settle_long": True}), ("voltage_steps", 500.0, {}),
           ("paper_chirp", 200.0, {"precondition": True}), ("paper_chirp", 200.0, {"precondition": False}),
           ("multisine", 500.0, {"noise_kind": "coloured"}), ("log_chirp", 500.0, {}))


def widened_cases(seed: int) -> list[tuple[str, float, int, dict]]:
    """The cases of :data:`WIDENED` for ``seed``: (design, rate Hz, case index, conditions)."""
    out = []
    for i, (d, rate, over) in enumerate(WIDENED):
        # the two pre-conditioning cases share one stream (the same draw, pre on and off)
        j = i - 1 if over.get("precondition") is False else i
        rng = np.random.default_rng([seed, int(rate), 100 + j])
        c = draw(rng)
        c["log_seed"] = int(rng.integers(1 << 30))
        if over.get("more"):
            c.update(draw_more(np.random.default_rng([seed, int(rate), 100 + j, 7])))
        if over.get("settle_long"):
            c["settle_s"] = float(rng.uniform(10.0, 30.0))
        c.update({k: v for k, v in over.items() if k not in ("more", "settle_long")})
        out.append((d, rate, i, c))
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", default="200,1000,10000")
    ap.add_argument("--designs", default=",".join(designs.DESIGNS))
    ap.add_argument("--draws", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--more", action="store_true",
                    help="also draw the step-hold range of random_steps (0.01-0.2 .. 0.5-4 s), the closed loop's "
                         "gain factor (0.5-2) and settling times up to 30 s (a separate stream: the other draws "
                         "stay as without it)")
    ap.add_argument("--widened", action="store_true", help="run the cases of WIDENED (see the module)")
    ap.add_argument("--opt", action="append", default=[], metavar="NAME=VALUE",
                    help="an identify option (Python literal), e.g. --opt max_timing_samples=1")
    a = ap.parse_args()
    import ast
    opts = {kv.split("=", 1)[0]: ast.literal_eval(kv.split("=", 1)[1]) for kv in a.opt}
    tally = {"good": 0, "wrong_usable": 0, "right_refused": 0, "wrong_refused": 0, "error": 0, "n": 0}
    dep_n = dep_rej = 0
    secs = []
    print(f"{'design':14s} {'rate':>6s} {'k':>2s} {'max_dB':>7s} {'max_deg':>7s} {'G0':>7s} {'use':>5s} "
          f"{'dep_p':>6s} {'fit%':>6s} {'s':>6s}  conditions / reasons")
    if a.widened:
        runs = widened_cases(a.seed)
    else:
        runs = []
        for rate in [float(r) for r in a.rates.split(",")]:
            for di, d in enumerate(a.designs.split(",")):
                for k in range(a.draws):
                    rng = np.random.default_rng([a.seed, int(rate), di, k])
                    c = draw(rng)
                    if a.more:
                        c.update(draw_more(np.random.default_rng([a.seed, int(rate), di, k, 7])))
                    c["log_seed"] = int(rng.integers(1 << 30))
                    runs.append((d, rate, k, c))
    for d, rate, k, c in runs:
        log_seed = c.pop("log_seed")
        log = designs.make_log(d, rate, seed=log_seed, **c)
        cond = (f"{c['convention']} off={c['offset_samples']:+.2f} {c['noise_kind']} {c['noise_mm']:.3f}mm "
                f"lsb={'y' if c['lsb_mm'] else 'n'} amp={c['amplitude']:.2f} settle={c['settle_s']:.1f} "
                f"pre={'y' if c['precondition'] else 'n'}" + (f" hold={c['hold_s'][0]:.2f}-{c['hold_s'][1]:.2f} "
                                                     f"gain={c['loop_gain']:.2f}" if "hold_s" in c else ""))
        tally["n"] += 1
        t0 = time.perf_counter()
        try:
            r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm",
                         **opts)
        except BadInputError as err:
            tally["error"] += 1
            print(f"{d:14s} {rate:6.0f} {k:2d} REFUSED(exit 2): {err} | {cond}", flush=True)
            continue
        dt = time.perf_counter() - t0
        secs.append(dt)
        cmp_ = r.paper_comparison()
        good = cmp_["max_db"] <= 1.0 and cmp_["max_deg"] <= 5.0
        key = ("good" if r.usable else "right_refused") if good else \
            ("wrong_usable" if r.usable else "wrong_refused")
        tally[key] += 1
        p = r.dependence.p_value
        if p == p:
            dep_n += 1
            dep_rej += p < 0.05
        fit = r.validation.compare_fit_pct if r.validation is not None else float("nan")
        print(f"{d:14s} {rate:6.0f} {k:2d} {cmp_['max_db']:7.3f} {cmp_['max_deg']:7.2f} "
              f"{r.model.dc_gain:7.4g} {str(r.usable):>5s} {p:6.3f} {fit:6.1f} {dt:6.2f}  "
              f"{r.fit.nz}/{r.fit.np} {key.upper() if key != 'good' else ''} | {cond} | "
              f"{'; '.join(r.reasons)}", flush=True)
    print(f"logs {tally['n']}: good and usable {tally['good']}, WRONG YET USABLE {tally['wrong_usable']}, "
          f"right yet refused {tally['right_refused']}, wrong and refused {tally['wrong_refused']}, "
          f"bad-input errors {tally['error']}; offset test rejections at p<0.05: {dep_rej}/{dep_n}; "
          f"median {np.median(secs) if secs else float('nan'):.1f} s, max {max(secs) if secs else float('nan'):.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
