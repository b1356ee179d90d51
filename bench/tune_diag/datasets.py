"""The README's real-dataset rows diagnosed with the default options: named, dropped, held-out NRMSE, shrink, s.

Run ``python bench/tune_diag/datasets.py [ROW ...]`` (rows: piezo_gain, piezo_ident, tanks, silverbox,
motor, motor_brake); one line per row."""
from __future__ import annotations

import sys
import time
from pathlib import Path

# the real datasets' readers are a test oracle (src/tests/realdata.py)
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "src" / "tests"))
import realdata as D  # noqa: E402
from hasel.diagnose import DiagnoseOptions, diagnose  # noqa: E402


def _rows():
    def piezo_gain():
        d = D.load_piezo()
        k = float(d.u @ d.y / (d.u @ d.u))
        return diagnose(d.t_s, d.u, d.y, model={"num": [k], "den": [1.0]}, units=("V", "um"))

    def piezo_ident():
        d = D.load_piezo()
        return diagnose(d.t_s, d.u, d.y, units=("V", "um"))

    def tanks():
        est, val = D.load_cascaded_tanks()
        return diagnose(est.t_s, est.u, est.y, heldout=(val.t_s, val.u, val.y), units=("V", "V"))

    def silverbox():
        d = D.load_silverbox()
        return diagnose(d.t_s, d.u, d.y)

    def motor():
        d = D.load_dc_motor()
        return diagnose(d.t_s, d.u, d.y, units=("V", "rpm"))

    def motor_brake():
        free, brake = D.load_dc_motor(), D.load_dc_motor(brake=True)
        model = diagnose(free.t_s, free.u, free.y, options=DiagnoseOptions(max_effects=1)).model
        return diagnose(brake.t_s, brake.u, brake.y, model=model)

    return {f.__name__: f for f in (piezo_gain, piezo_ident, tanks, silverbox, motor, motor_brake)}


def main(argv: list[str]) -> int:
    """Diagnose the rows named in ``argv`` (all when none)."""
    rows = _rows()
    for name in argv or list(rows):
        t0 = time.perf_counter()
        v = rows[name]()
        h = v.heldout
        print(f"{name:12s} named {', '.join(v.names) or '-':45s} dropped {', '.join(x['name'] for x in v.dropped) or '-':25s}"
              f" {h['nrmse_nominal']:.3g} -> {h['nrmse_augmented']:.3g} shrink {100 * h['gap_shrink']:.0f} % "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
