"""The frequency-response reading never sees the final held-out samples, and gating keeps its numbers."""
from __future__ import annotations

import numpy as np

from hasel.effects.evidence import gated_spectra


def _signals(n: int = 100_000, seed: int = 0):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    y = np.convolve(x, [0.5, 0.3, 0.1])[:n] + 0.3 * rng.standard_normal(n)
    return x, y


def test_gating_keeps_the_response_ratio_and_the_coherence():
    x, y = _signals()
    keep = np.ones(x.size, bool)
    full = gated_spectra(x, y, 0.8 * y, keep, 100.0, 512)
    for k in range(0, x.size, 900):
        keep[k:k + 150] = False  # a sixth held out, in blocks
    gated = gated_spectra(x, y, 0.8 * y, keep, 100.0, 512)
    coh = [np.median(np.abs(s[2]) ** 2 / (s[1] * s[4])) for s in (full, gated)]
    assert np.allclose(np.abs(gated[2] / gated[3])[1:], 1.25)  # measured / model, as without the gate
    assert abs(coh[1] - coh[0]) < 0.02 and 0.65 < coh[0] < 0.8  # 0.36 noise power on 0.35 signal: ~0.77


def test_the_held_out_samples_do_not_enter():
    x, y = _signals(20_000)
    keep = np.ones(x.size, bool)
    keep[3000:3400] = keep[12000:12600] = False
    a = gated_spectra(x, y, y, keep, 100.0, 1024)
    y2 = y.copy()
    y2[~keep] += 50.0 * np.random.default_rng(9).standard_normal(int((~keep).sum()))
    b = gated_spectra(x, y2, y2, keep, 100.0, 1024)
    assert all(np.array_equal(p, q) for p, q in zip(a, b))
    # without the gate the changed samples show
    c = gated_spectra(x, y2, y2, np.ones(x.size, bool), 100.0, 1024)
    assert not np.allclose(a[2], c[2])
