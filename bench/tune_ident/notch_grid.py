"""Candidate 1 of RESULT_e-notch.md: check 6's grid extended to the top of the tolerance band (15 Hz, or the band's
top if lower), measured by patching ``identify._check_grid`` in this process only (src untouched).

Usage: python bench/tune_ident/notch_grid.py [--top 15] SPEC [SPEC ...]   (SPEC as diag_logs.py)
Prints per log, for main's grid and the extended one: usable, the grid's top (Hz), check 6's largest u95 (deg) and
its u95 at 15 Hz over the tolerance there (plain 5 deg and check 6's widened one), and the true error at 15 Hz.
"""
import math, os, sys
import numpy as np
sys.path.insert(0, os.path.dirname(__file__))
import diag_logs  # noqa: E402
from hasel.ident import identify  # noqa: E402
from hasel.paper import plant_tf  # noqa: E402

I = sys.modules["hasel.ident.identify"]
_orig = I._check_grid
args = sys.argv[1:]
top_hz = 15.0
if args and args[0] == "--top":
    top_hz, args = float(args[1]), args[2:]


def _extended(model, band, n=48):
    f = _orig(model, band, n)
    hi = min(float(band[1]), top_hz)
    if f.size == 0 or f[-1] >= hi:
        return f
    return np.geomspace(f[0], hi, n)


num_p, den_p = plant_tf()
for spec in args:
    label, log, c = diag_logs.log_of(spec)
    for name, grid in (("main", _orig), ("ext", _extended)):
        I._check_grid = grid
        r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
        cmp_ = r.paper_comparison()
        d = r.check.details
        fu = np.asarray(d.get("response_f_hz", []), float)
        ud = np.asarray(d.get("response_u95_deg", []), float)
        s = 2j * math.pi * 15.0
        e15 = math.degrees(np.angle(r.fit.model.freqresp(np.array([15.0]))[0] / (np.polyval(num_p, s) / np.polyval(den_p, s))))
        g = abs(r.fit.model.freqresp(np.array([15.0]))[0]) / abs(r.fit.model.dc_gain)
        u15 = float(np.interp(15.0, fu, ud)) if fu.size and fu[-1] >= 14.99 else float("nan")
        print(f"{spec:22s} {label.split()[1]:13s} {name:4s} usable={r.usable!s:5s} max_deg={cmp_['max_deg']:5.2f} "
              f"err15={e15:+5.2f} grid_top={fu[-1] if fu.size else float('nan'):5.3g} u95max={ud.max() if ud.size else float('nan'):5.2f} "
              f"u95@15={u15:5.2f} widen@15={max(1.0, 0.1 / g):.2f} | " + "; ".join(x[:110] for x in r.reasons), flush=True)
