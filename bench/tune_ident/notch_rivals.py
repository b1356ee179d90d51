"""The tied rival orders of check 7, kept per log (notch_eval.py --rivals judges them up to 15 Hz).

Usage: python bench/tune_ident/notch_rivals.py OUT.pkl all|SPEC ...   (SPEC and ``all`` as notch_dump.py)
Patches ``checks._spread`` in this process only to record the chosen model, its timing offset, and each tied
rival (order, model num/den, timing offset s, held-out NRMSE) with check 6's grid and standard errors.
"""
import os, sys, pickle
import numpy as np
sys.path.insert(0, os.path.dirname(__file__))
import diag_logs  # noqa: E402
import notch_dump_specs  # noqa: E402
from hasel.ident import identify  # noqa: E402
C = sys.modules["hasel.ident.checks"]
_orig = C._spread
_cap = {}


def _wrap(model, spread, *a, **k):
    tau = a[-1] if len(a) >= 6 else k.get("timing_offset_s", 0.0)
    _cap["s"] = dict(num=np.asarray(model.num), den=np.asarray(model.den), tau=float(tau), f=np.asarray(spread["f_hz"]),
                     sd_db=spread.get("sd_db"), sd_deg=spread.get("sd_deg"),
                     rivals=[dict(order=(r[0], r[1]), num=np.asarray(r[2].num), den=np.asarray(r[2].den),
                                  score=float(r[3]), sd=r[4] if len(r) > 4 else None,
                                  tau=float(r[5]) if len(r) > 5 else float(tau)) for r in spread.get("rivals", [])])
    return _orig(model, spread, *a, **k)


C._spread = _wrap
out, specs = sys.argv[1], sys.argv[2:]
if specs == ["all"]:
    specs = notch_dump_specs.all_specs()
res = []
for spec in specs:
    label, log, c = diag_logs.log_of(spec)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    res.append(dict(spec=spec, label=label, cmp=r.paper_comparison(), usable=r.usable, order=(r.fit.nz, r.fit.np),
                    spread=_cap.pop("s", None), reasons=list(r.reasons)))
    print(spec, label, r.usable, len(res[-1]["spread"]["rivals"]) if res[-1]["spread"] else None, flush=True)
    with open(out, "wb") as fh:
        pickle.dump(res, fh)
