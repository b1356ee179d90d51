"""Tuning logs identified, with check 8's residual response kept (for notch_eval.py's top-of-band test).

Usage: python bench/tune_ident/notch_dump.py OUT.pkl SPEC [SPEC ...]   (SPEC as diag_logs.py; ``all`` = the 115
logs of RESULT_h-ident3.md: varied.py seeds 1-2 at 200 Hz / 1 kHz with 2 draws, seed 1 at 10 kHz, --widened 1-2)
Writes after every log: spec, the paper comparison (max dB / deg over 0.1-15 Hz), usable, reasons, check
details, the model (num, den), band (Hz) and the residual response (f Hz, H, sigma, coherence).
"""
import os, sys, pickle, time
import numpy as np
_here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, _here)
import diag_logs, designs, varied  # noqa: E402
from hasel.ident import identify  # noqa: E402
I = sys.modules["hasel.ident.identify"]
_orig = I._residual_response
_cap = {}


def _wrap(*a, **k):
    out = _orig(*a, **k); _cap['r'] = out; return out


I._residual_response = _wrap


def all_specs():
    out = []
    for seed in (1, 2):
        for rate in (200, 1000):
            for d in designs.DESIGNS:
                for k in (0, 1):
                    out.append(f"{seed}:{d}:{rate}:{k}")
    out += [f"1:{d}:10000:0" for d in designs.DESIGNS]
    for seed in (1, 2):
        out += [f"w{seed}:{i}" for i in range(len(varied.WIDENED))]
    return out


out = sys.argv[1]
specs = sys.argv[2:]
if specs == ["all"]:
    specs = all_specs()
elif specs and specs[0] == "first":
    first = specs[1:]
    specs = first + [s for s in all_specs() if s not in first]
res = []
for spec in specs:
    label, log, c = diag_logs.log_of(spec)
    t0 = time.time()
    try:
        r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    except Exception as e:  # noqa: BLE001 - a bench row
        print("ERR", spec, e, flush=True); continue
    cmp_ = r.paper_comparison()
    rr = _cap.pop('r', None)
    res.append(dict(spec=spec, label=label, cmp=cmp_, usable=r.usable, reasons=list(r.reasons),
                    details=dict(r.check.details), num=np.asarray(r.fit.model.num), den=np.asarray(r.fit.model.den),
                    order=(r.fit.nz, r.fit.np), band=r.band_hz, tau=r.timing_offset_s,
                    resid=None if rr is None else dict(f=np.asarray(rr.f_hz), H=np.asarray(rr.H),
                                                       sigma=np.asarray(rr.sigma), coh=np.asarray(rr.coherence)),
                    secs=time.time() - t0))
    print(spec, label, round(cmp_["max_db"], 3), round(cmp_["max_deg"], 2), r.usable, f"{r.fit.nz}/{r.fit.np}",
          flush=True)
    with open(out, "wb") as fh:
        pickle.dump(res, fh)
