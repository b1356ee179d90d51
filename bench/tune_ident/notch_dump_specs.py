"""The 115 tuning logs of RESULT_h-ident3.md as diag_logs.py specs (varied.py seeds 1-2 at 200 Hz / 1 kHz with 2
draws, seed 1 at 10 kHz, --widened seeds 1-2)."""
import os, sys
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
import designs  # noqa: E402
import varied  # noqa: E402


def all_specs():
    """The specs, in varied.py's order."""
    out = [f"{seed}:{d}:{rate}:{k}" for seed in (1, 2) for rate in (200, 1000) for d in designs.DESIGNS for k in (0, 1)]
    out += [f"1:{d}:10000:0" for d in designs.DESIGNS]
    for seed in (1, 2):
        out += [f"w{seed}:{i}" for i in range(len(varied.WIDENED))]
    return out
