"""varied.py's logs, identified, pickled with check 8's error response (for check8_eval.py's threshold sweep).

Usage: python bench/tune_ident/check8_dump.py SEED RATES DRAWS OUT.pkl   (e.g. 1 200,1000 2 /tmp/s1.pkl)
Same draws as ``varied.py --seed SEED --rates RATES --draws DRAWS``.
"""
import os, sys, pickle, time
import numpy as np
_here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(_here, "..", "..", "src", "tests"))
sys.path.insert(0, _here)
import designs
from varied import draw
from hasel.ident import identify
I = sys.modules["hasel.ident.identify"]
_orig = I._residual_response
_cap = {}
def _wrap(*a, **k):
    out = _orig(*a, **k); _cap['r'] = out; return out
I._residual_response = _wrap
seed = int(sys.argv[1]); rates = [float(r) for r in sys.argv[2].split(",")]; draws = int(sys.argv[3]); out = sys.argv[4]
res = []
for rate in rates:
    for di, d in enumerate(designs.DESIGNS):
        for k in range(draws):
            rng = np.random.default_rng([seed, int(rate), di, k])
            c = draw(rng)
            log = designs.make_log(d, rate, seed=int(rng.integers(1 << 30)), **c)
            try:
                r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
            except Exception as e:
                print("ERR", d, rate, k, e, flush=True); continue
            cmp_ = r.paper_comparison()
            res.append(dict(design=d, rate=rate, k=k, seed=seed, cmp=cmp_, r=r, resid=_cap.get('r'))); _cap.clear()
            print(d, rate, k, cmp_, r.usable, flush=True)
            with open(out, "wb") as fh:
                pickle.dump(res, fh)
