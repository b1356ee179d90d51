"""The timing offset of a non-periodic input is judged on held-out data only (session 10, branch h-ident3).

``_timing_or_not`` keeps a timing offset when the held-out error or the in-band disagreement with
the measured response says so. For a non-periodic input (one paper chirp per offset, steps) that
measured response is a Welch estimate whose leakage and transient bias near the band's top its
error bars do not hold (why check 5 is skipped for it): there it voted against offsets that the
held-out data asked for, and the model bent the convention's lead into G's phase (8.4 deg at
15 Hz on a 200 Hz paper chirp, 20 deg on 200 Hz voltage steps, both usable on main 22c5e5c). The
logs are the tuning corpus's (``bench/tune_ident/varied.py``), rebuilt from their drawn
conditions; errors are against the paper's P(s) over 0.1-15 Hz.
"""
from __future__ import annotations

import designs
from hasel.ident import identify


def test_paper_chirp_at_200_hz_keeps_the_offset_the_held_out_data_ask_for():
    """varied.py --widened --seed 1, case 13: first-order hold, output 0.19 samples late. The offset (-1.27 ms)
    lowers the held-out error by 4 % (beyond the 2 % tie margin): kept, and G is within 1 dB / 5 deg (it was
    8.4 deg off at 15 Hz and usable on main)."""
    log = designs.make_log("paper_chirp", 200.0, seed=712938904, convention="foh", offset_samples=0.1856707449294197,
                           noise_kind="coloured", noise_mm=0.023241774525434723, noise_fc_hz=19.204043739080248,
                           lsb_mm=0.0, amplitude=0.6918870136239956, settle_s=1.9824649214790562, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert -2.0e-3 < r.timing_offset_s < -0.5e-3, r.timing_offset_s
    assert any("timing offset between input and output estimated" in n for n in r.notes), r.notes
    assert c["max_db"] <= 1.0 and c["max_deg"] <= 5.0, c
    assert r.usable, r.reasons


def test_voltage_steps_at_200_hz_keep_the_offset():
    """varied.py --seed 2, voltage steps at 200 Hz, k 0: an output read mid-sample and 0.26 samples early. The
    offset (-2.9 ms) lowers the held-out error by 24 %: kept, and the error at 15 Hz falls from 20 deg (main) to
    about 5.5 deg; the model is still beyond the tolerance at the band's top (a 3/4 model of the notch at 19.5 Hz
    from steps), so only the phase's size is asserted here."""
    log = designs.make_log("voltage_steps", 200.0, seed=334168248, convention="centred",
                           offset_samples=-0.2605864463327918, noise_kind="coloured", noise_mm=0.005185268791151049,
                           noise_fc_hz=7.097147262904065, lsb_mm=0.0, amplitude=0.966842740312627,
                           settle_s=1.5178456556869189, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    assert r.timing_offset_s < -2.0e-3, r.timing_offset_s
    assert r.paper_comparison()["max_deg"] < 8.0
