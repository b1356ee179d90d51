"""Repeated noise draws of one tuning log's conditions: is the top-of-band error a bias or noise (check 6's bound)?

Usage: python bench/tune_ident/notch_draws.py SPEC N   (SPEC as diag_logs.py; the conditions kept, the log's noise
seed redrawn N times). Prints per draw: order, usable, the error against P(s) at 14 Hz (check 6's last point) and
15 Hz (deg), and check 6's u95 at its last judged point (deg); then their mean and spread.
"""
import os, sys
import numpy as np
sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
import designs, diag_logs  # noqa: E402
from hasel.ident import identify  # noqa: E402
from hasel.paper import plant_tf  # noqa: E402

spec, n = sys.argv[1], int(sys.argv[2])
label, _, c = diag_logs.log_of(spec)
d, rate = label.split()[1], float(label.split()[2])
num, den = plant_tf()
rows = []
for k in range(n):
    log = designs.make_log(d, rate, seed=1000 + k, **c)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    det = r.check.details
    fu = np.asarray(det.get("response_f_hz", []), float)
    ud = np.asarray(det.get("response_u95_deg", []), float)
    f_top = float(fu[-1]) if fu.size else 14.0
    f = np.array([f_top, 15.0])
    e = np.degrees(np.angle(r.fit.model.freqresp(f) / (np.polyval(num, 2j * np.pi * f) / np.polyval(den, 2j * np.pi * f))))
    u = float(ud[ud > 0][-1]) if np.any(ud > 0) else float("nan")  # the last judged point (|G| >= 0.1 G(0))
    rows.append((e[0], e[1], u))
    print(f"draw {k} order {r.fit.nz}/{r.fit.np} usable={r.usable} max_deg={r.paper_comparison()['max_deg']:.2f} "
          f"err@{f_top:.3g}Hz={e[0]:+.2f} err@15={e[1]:+.2f} u95@top={u:.2f} offset={1e3 * r.timing_offset_s:+.2f} ms "
          f"heldout={[round(o.heldout_cost, 5) for o in r.fit.scores]}", flush=True)
a = np.array(rows)
print(f"{spec} {label}: err@top mean {a[:, 0].mean():+.2f} sd {a[:, 0].std(ddof=1):.2f}; err@15 mean {a[:, 1].mean():+.2f} "
      f"sd {a[:, 1].std(ddof=1):.2f}; u95@top median {np.median(a[:, 2]):.2f} (sd implied {np.median(a[:, 2]) / 2:.2f})")
