"""A lower order with a timing offset that is no sampling convention is judged against the higher order (session 9).

A lower order plus a timing offset that only ties with a higher order on held-out data may be a
too-short offset that the lower order's phase makes up for. It is kept as before when the offset
is within two standard errors of a sampling convention (0, +-0.5, +-1 sample) or when the held-out
data prefer it; otherwise the higher order refitted with the offset free is its rival in check 9
(branch h-ident2; keeping the higher order outright turned 2 right 200 Hz models wrong on the
tuning logs). The logs are the tuning corpus's
(``bench/tune_ident/varied.py --seed 1``), rebuilt from their drawn conditions; errors are against
the paper's P(s) over 0.1-15 Hz; "before" is main at e58afee.
"""
from __future__ import annotations

import numpy as np

import designs
from hasel.ident import identify
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import interleaved, oe_fit, shift_standard_error, simulate_zoh

TRUE = TFModel(np.array([400.0]), np.array([1.0, 16.0, 400.0]))   # 3.2 Hz, damping 0.4, G(0) = 1


def test_shift_standard_error_matches_the_spread_of_repeated_fits():
    """The offset's standard error (samples) is within a factor 2 of 12 noise draws' spread, and covers the truth."""
    rate = 100.0
    rng0 = np.random.default_rng(5)
    u = np.concatenate([np.zeros(50), np.repeat(rng0.uniform(-1, 1, 300), 10)])
    clean = simulate_zoh(TRUE, u, rate, shift=0.3)
    pieces = interleaved(u.size, [(0, u.size)], 200, 1.0 / 3.0, 0)
    shifts, ses = [], []
    for k in range(12):
        y = clean + 0.02 * np.random.default_rng(300 + k).standard_normal(u.size)
        oe = oe_fit(TRUE, u, y, rate, pieces, max_nfev=60, max_shift=1.5)
        shifts.append(oe.shift)
        ses.append(shift_standard_error(oe, u, y, rate, pieces, max_shift=1.5))
    spread, se = float(np.std(shifts, ddof=1)), float(np.median(ses))
    assert 0.5 * spread < se < 2.0 * spread, (se, spread)
    assert abs(float(np.mean(shifts)) - 0.3) < 3 * se
    assert np.isnan(shift_standard_error(oe, u, y, rate, pieces, max_shift=0.0))


def test_a_too_short_offset_is_judged_against_the_higher_order():
    """Paper chirp at 200 Hz, first-order hold and the output 0.15 samples early (seed 1, k 0): 0.65 samples of
    lead in all. Order 2/3 with 0.35 samples (no convention) tied with 4/5 and was kept, 5.9 deg off at 15 Hz and
    usable (before). Order 4/5 with the offset free ties too and its G differs by 6 deg at 14 Hz (beyond both
    uncertainties and the tolerance): exit 1, with the experiments that would separate them."""
    log = designs.make_log("paper_chirp", 200.0, seed=202260106, convention="foh", offset_samples=-0.15009055250047365,
                           noise_kind="wander", noise_mm=0.012130064070347208, noise_fc_hz=15.398626738552165,
                           lsb_mm=0.0, amplitude=0.5522381515161876, settle_s=0.7034724822382386, precondition=False)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert c["max_deg"] > 5.0, c             # the model is wrong ...
    assert not r.usable                      # ... and says so, for this reason
    assert any("no sampling convention" in n for n in r.notes), r.notes
    assert any("order 4/5 (its offset free)" in x and "cannot be told from the model's phase" in x
               for x in r.reasons), r.reasons
    assert r.check.details["timing_rival_max_deg"] > 5.0
    assert any("--input-hold" in f for f in r.check.fixes)
    assert r.to_model_json()["usable"] is False
