"""A timing offset that the held-out error and the in-band disagreement judge oppositely is a tie (session 10).

``_timing_or_not`` keeps a timing offset when the held-out error or the in-band disagreement with
the measured response says it is better and neither says it is worse. For a non-periodic input
(one paper chirp per offset, steps) that measured response is a Welch estimate whose leakage and
transient bias near the band's top its error bars do not hold: on the tuning logs it voted against
offsets that the held-out data asked for (and the model bent the convention's lead into G's phase:
8.4 deg at 15 Hz on a 200 Hz paper chirp, 20 deg on 200 Hz voltage steps, both usable on main
22c5e5c), and for offsets on which the held-out data tied and that were right. When the two
disagree the data have not decided: the same order with the offset is check 9's rival (branch
h-ident3), and a G that differs beyond both fits' 95 % uncertainty and the tolerance is refused.
The logs are the tuning corpus's (``bench/tune_ident/varied.py``), rebuilt from their drawn
conditions; errors are against the paper's P(s) over 0.1-15 Hz.
"""
from __future__ import annotations

import designs
from hasel.ident import identify


def _refused_by_the_timing_rival(r) -> None:
    assert not r.usable
    assert any("cannot be told from the model's phase" in x and "the same order" in x for x in r.reasons), r.reasons
    assert r.check.details["timing_rival_max_deg"] > 5.0
    assert any("--input-hold" in f for f in r.check.fixes)
    assert r.to_model_json()["usable"] is False


def test_paper_chirp_at_200_hz_whose_offset_the_criteria_disagree_on_is_refused():
    """varied.py --widened --seed 1, case 13: first-order hold, output 0.19 samples late. The offset (-1.27 ms)
    lowers the held-out error by 4 % (beyond the 2 % tie margin) but raises the in-band disagreement by 21 %: the
    model without it is 8.4 deg off at 15 Hz; it was usable on main, now refused (the rival differs by 9 deg)."""
    log = designs.make_log("paper_chirp", 200.0, seed=712938904, convention="foh", offset_samples=0.1856707449294197,
                           noise_kind="coloured", noise_mm=0.023241774525434723, noise_fc_hz=19.204043739080248,
                           lsb_mm=0.0, amplitude=0.6918870136239956, settle_s=1.9824649214790562, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    assert r.paper_comparison()["max_deg"] > 5.0      # the model is wrong ...
    _refused_by_the_timing_rival(r)                    # ... and says so


def test_voltage_steps_at_200_hz_whose_offset_the_criteria_disagree_on_are_refused():
    """varied.py --seed 2, voltage steps at 200 Hz, k 0: an output read mid-sample and 0.26 samples early. The
    offset (-2.9 ms) lowers the held-out error by 24 % and raises the in-band disagreement by 64 %: the model
    without it is 20 deg off at 15 Hz; usable on main, now refused."""
    log = designs.make_log("voltage_steps", 200.0, seed=334168248, convention="centred",
                           offset_samples=-0.2605864463327918, noise_kind="coloured", noise_mm=0.005185268791151049,
                           noise_fc_hz=7.097147262904065, lsb_mm=0.0, amplitude=0.966842740312627,
                           settle_s=1.5178456556869189, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    assert r.paper_comparison()["max_deg"] > 5.0
    _refused_by_the_timing_rival(r)
