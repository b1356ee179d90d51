"""The held-out block test, below the diagnosis so that a family can ask it of its own forms.

:func:`block_test` scores a residual's improvement over held-out blocks (a signed-rank test; no noise level
assumed); :func:`block_labels` cuts a prepared log's validation (or final) samples into those blocks. The diagnosis
accepts an effect on it (:mod:`hasel.diagnose.significance`); the drift family asks it before its swing form takes
the level form's place, the load family before its anti-resonance and pole-zero pair forms take another form's
(:func:`held_out_prefers`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["block_labels", "block_test", "held_out_prefers", "moving_average"]


def block_labels(prep, mask: str, min_blocks: int = 40, min_len: int = 5) -> np.ndarray:
    """Block index of each stacked ``mask`` sample for the held-out test.

    The blocks are the contiguous runs of the mask, record by record; when there are fewer
    than ``min_blocks`` of them (a short log), each run is cut into equal pieces of at least
    ``min_len`` samples until there are about that many (a rank test over ten blocks
    cannot reach a small p-value whatever the data).
    """
    out, nb = [], 0
    runs = []
    for r in prep.records:
        m = getattr(r, mask)
        if not m.any():
            continue
        starts = np.concatenate([[True], ~m[:-1]]) & m
        runs.append(np.cumsum(starts)[m] - 1)
    n_runs = sum(int(x.max()) + 1 for x in runs)
    for lab in runs:
        if n_runs < min_blocks:
            pieces = int(np.ceil(min_blocks / max(n_runs, 1)))
            sub = np.zeros(lab.size, int)
            for b in range(int(lab.max()) + 1):
                idx = np.flatnonzero(lab == b)
                k = max(1, min(pieces, idx.size // min_len))
                sub[idx] = np.minimum(np.arange(idx.size) * k // max(idx.size, 1), k - 1)
            lab = np.unique(lab * 10_000 + sub, return_inverse=True)[1]
        lab = lab + nb
        nb = int(lab.max()) + 1
        out.append(lab)
    return np.concatenate(out) if out else np.zeros(0, int)


def block_test(e_old: np.ndarray, e_new: np.ndarray, labels: np.ndarray, slow_n: int = 0) -> float:
    """Held-out improvement of a residual ``e_old -> e_new`` as a one-sided normal score over blocks.

    Each residual first loses its slow part (a moving average over ``slow_n`` stacked samples,
    several seconds of the log: a slow sensor offset wander is no evidence of an effect; 0
    keeps it). Each held-out block's squared-error drop is then one observation, and the
    drops are ranked by size (Wilcoxon's signed-rank test: coloured noise within a block
    counts as it really varies, a few blocks with large drops neither make nor break the
    test, and no noise level is assumed). The one-sided p-value is given as the normal score
    with the same p-value. No noise floor enters.
    """
    from scipy import stats

    nb = int(labels.max()) + 1 if labels.size else 0
    if nb < 3:
        return 0.0
    if slow_n > 1:
        e_old = e_old - moving_average(e_old, slow_n)
        e_new = e_new - moving_average(e_new, slow_n)
    d = (np.bincount(labels, weights=e_old * e_old, minlength=nb)
         - np.bincount(labels, weights=e_new * e_new, minlength=nb))
    if not np.any(d):
        return 0.0
    p = float(stats.wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue)
    return float(min(stats.norm.isf(max(p, 1e-300)), 40.0))


def moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples (ends padded with the end values)."""
    n = int(min(max(n, 1), x.size))
    pad = np.concatenate([np.full(n // 2, x[0]), x, np.full(n - n // 2 - 1, x[-1])])
    c = np.cumsum(np.concatenate([[0.0], pad]))
    return (c[n:] - c[:-n]) / n


def held_out_prefers(pipe, old: dict, new: dict, score: float | None = None) -> bool:
    """True when the effects ``new`` predict the validation samples better than ``old`` by :func:`block_test`
    (slow part kept) at ``score`` (default the context's ``t_min``: the diagnosis sets it from
    ``DiagnoseOptions.t_min``, its acceptance score); True as well where the context has no ``t_min`` or no
    validation samples (a fit outside a diagnosis). A family's choice of a richer form on training alone may not
    generalise (the drift's swing form beside a level drift; a load's pole-zero pair in place of its damping-kept
    form)."""
    t_min = getattr(pipe, "t_min", None)
    prep = getattr(pipe, "prep", None)
    if t_min is None or prep is None or not any(r.valid.any() for r in prep.records):
        return True
    labels = block_labels(prep, "valid")
    return block_test(pipe.residuals(old, "valid"), pipe.residuals(new, "valid"), labels) >= (
        t_min if score is None else score)
