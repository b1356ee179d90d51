"""A kept timing offset must be pinned by the data (session 15, branch h-ident5; session 16, branch h-pin).

A timing offset that :func:`hasel.ident.identify._timing_or_not` keeps is a parameter of check 6's covariance and
widens the response's uncertainty near the band's top. It is kept only when the estimate is at least two of its
standard errors from none and the held-out blocks do not prefer the fit without it (a paired t test over the
blocks, :func:`hasel.ident.identify.heldout_preference`); otherwise the fit without it is kept (a tie, check 9's
rival). The logs are
the tuning corpus's (``bench/tune_ident/varied.py``), rebuilt from their drawn conditions; errors are against the
paper's P(s) over 0.1-15 Hz.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import designs
from hasel.ident import identify
from hasel.ident.identify import heldout_preference
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import interleaved, simulate_zoh
from hasel.paper import plant_tf


def _paper_log(noise_mm: float, shift: float, seed: int = 0):
    """The paper's P(s) driven by random steps at 200 Hz for 60 s (kV, held), read ``shift`` samples late, plus
    white noise of ``noise_mm`` mm; with the identification's interleaved held-out blocks (2 s, every fifth)."""
    rate, n = 200.0, 12000
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1.0, 1.0, n // 20), 20)
    num, den = plant_tf()
    m = TFModel(num=np.asarray(num, float), den=np.asarray(den, float))
    y = simulate_zoh(m, u, rate, shift=shift) + noise_mm * rng.standard_normal(n)
    pieces = interleaved(n, [(0, n)], 400, 0.2, 0)
    return m, u, y, rate, pieces


def test_the_held_out_blocks_prefer_the_right_offset_and_not_one_of_two_equally_wrong_ones():
    """Output 0.5 samples late, noise 5 um: the read at +0.5 beats the read at 0 on each of the 6 held-out blocks
    (t 8.1, 2.02 needed at 5 %), and the other way round the statistic is as negative. Even +0.51 against +0.5
    (0.45 um rms apart, under a tenth of the noise) is told apart over 2400 samples a block (t 3.5): the test is not
    blunt. Reads at +0.4 and +0.6, equally far from the truth either side, tie (t 0.52)."""
    m, u, y, rate, pieces = _paper_log(0.005, 0.5)
    right, none = simulate_zoh(m, u, rate, shift=0.5), simulate_zoh(m, u, rate, shift=0.0)
    t, k, crit = heldout_preference(y, none, right, pieces.heldout)
    assert k == 6 and crit == pytest.approx(2.015, abs=1e-3)
    assert t > 5.0
    t_rev, _, _ = heldout_preference(y, right, none, pieces.heldout)
    assert t_rev == pytest.approx(-t)
    t_close, _, _ = heldout_preference(y, simulate_zoh(m, u, rate, shift=0.51), right, pieces.heldout)
    assert t_close > crit
    t_tie, _, _ = heldout_preference(y, simulate_zoh(m, u, rate, shift=0.4), simulate_zoh(m, u, rate, shift=0.6),
                                     pieces.heldout)
    assert abs(t_tie) < crit
    # fewer than three held-out blocks: no test (no preference)
    few = np.zeros(y.size, bool)
    few[100:200] = few[5000:5100] = True
    t_few, k_few, crit_few = heldout_preference(y, none, right, few)
    assert k_few == 2 and math.isnan(t_few) and crit_few == math.inf


def test_an_offset_the_data_do_not_pin_is_not_kept():
    """Closed loop at 200 Hz, input centred, white noise 0.022 mm (varied.py seed 2, k 0). The offset refit
    (-0.81 ms) improved the noise-removed held-out error by 2.7 %, past the 2 % tie margin, and was kept; as a
    parameter of the covariance it widened the response to +-5.2 deg at 12.9 Hz and the right model (3.4 deg off)
    was refused (main 39e164c). Its estimate is 1.75 of its standard errors from none (and over the 10 held-out
    blocks its paired t is 0.39): no offset, a tie; the model 2.6 deg off and usable."""
    log = designs.make_log("closed_loop", 200.0, seed=979171906, convention="centred", offset_samples=0.0,
                           noise_kind="white", noise_mm=0.02168795849061244, noise_fc_hz=8.042143937106742,
                           lsb_mm=10.0 / 4096, amplitude=0.8729163407417453, settle_s=0.5635517375543986,
                           precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert r.timing_offset_s == 0.0
    assert any("standard errors of none" in n for n in r.notes), r.notes
    assert c["max_db"] < 1.0 and c["max_deg"] < 5.0, c
    assert r.usable, r.reasons


def test_an_offset_within_two_of_its_standard_errors_of_none_is_not_kept():
    """PRBS at 1 kHz, input centred, the output 0.12 samples early, white noise 3.3 um (varied.py seed 2, k 0): the
    quick demo's case on a tuning log. The 4/5 model's offset refit (+0.62 ms) fits every held-out block better
    (paired t 11 over 10 blocks), but its extra pole pair trades with it: the estimate is 0.67 of its standard
    error from none. Kept (main 39e164c), it widened check 6 to +-6.4 deg at 12.2 Hz and the right model (1.9 deg
    off) was refused; fixed at none (a tie) the 4/5 model is 2.8 deg off and usable."""
    log = designs.make_log("prbs", 1000.0, seed=111403343, convention="centred", offset_samples=-0.11781919330148316,
                           noise_kind="white", noise_mm=0.003299389495753713, noise_fc_hz=16.90090565434555,
                           lsb_mm=0.0, amplitude=0.8313994496193614, settle_s=1.4315584739824532, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert (r.fit.nz, r.fit.np) == (4, 5)
    assert r.timing_offset_s == 0.0
    assert any("standard errors of none" in n for n in r.notes), r.notes
    assert c["max_db"] < 1.0 and c["max_deg"] < 5.0, c
    assert r.usable, r.reasons


def test_a_pinned_offset_is_kept_though_the_held_out_blocks_cannot_tell():
    """Random steps at 1 kHz, white-plus-wander noise 5.7 um (varied.py seed 2, k 1). The 2/3 model's offset refit
    (+0.32 ms) is 11 of its standard errors from none, but random steps carry little above a few hertz and the
    held-out blocks' paired t is 1.3 (1.83 would have been needed to prefer it). Fixed at none (session 15, h-ident5)
    the model was 4.2 deg off P(s) at 15 Hz; kept, 2.2 deg: the offset stands for the lag the 2/3 model cannot hold."""
    log = designs.make_log("random_steps", 1000.0, seed=1053756774, convention="zoh", offset_samples=0.0,
                           noise_kind="wander", noise_mm=0.005671448380211547, noise_fc_hz=6.86317110777745,
                           lsb_mm=0.0, amplitude=0.5808879504591532, settle_s=1.025751428259484, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert r.timing_offset_s == pytest.approx(3.2e-4, abs=0.5e-4)
    assert any("standard errors from none and the held-out blocks do not prefer the fit without it" in n
               for n in r.notes), r.notes
    assert c["max_db"] < 1.0 and c["max_deg"] < 3.0, c
    assert r.usable, r.reasons


def test_a_lower_order_does_not_buy_its_tie_with_an_offset_within_noise_of_none():
    """The paper chirp at 200 Hz on three offsets with pre-conditioning, zero-order hold, no timing offset, white
    noise 10 um (designs.make_log seed 1). Order 5/6 fits the held-out data best; 4/5 ties with it only once a
    timing offset is estimated, and that offset (-0.03 samples) is within two of its standard errors of none.
    Kept (session 37 and before), 4/5 was 4.3 deg off P(s) at 15 Hz (5.9 deg on the first verification corpus's
    id11); now the offset must be pinned, as any kept offset, and 5/6 stands: 0.6 deg."""
    log = designs.make_log("paper_chirp", 200.0, seed=1, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, segments=log.meta["excitation_segments"], input_name="voltage_kv",
                 output_name="stroke_mm")
    c = r.paper_comparison()
    assert (r.model.num.size - 1, r.model.den.size - 1) == (5, 6)
    assert r.timing_offset_s == 0.0
    assert any("ties with order 5/6 only with a timing offset within 2 standard errors of none" in n
               for n in r.notes), r.notes
    assert c["max_db"] < 0.3 and c["max_deg"] < 1.5, c
    assert r.usable, r.reasons
