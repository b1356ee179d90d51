"""The diagnosis's linear identification, for logs diagnosed without a nominal model.

The fit is the identifier's variable-projection mode (:func:`hasel.ident.varpro.vp_fit`);
this module hands it the training samples of a :class:`~hasel.diagnose.prep.Prepared`
problem.
"""
from __future__ import annotations

import numpy as np

from hasel.diagnose.prep import Prepared
from hasel.ident.varpro import vp_fit

__all__ = ["fit_linear"]


def fit_linear(prep: Prepared, max_order: int = 4, orders: tuple[int, ...] | None = None,
               init_poles: np.ndarray | None = None, warm_only: bool = False) -> tuple[np.ndarray, np.ndarray, dict]:
    """Identify a stable, strictly proper, minimum-phase model ``num/den`` from ``prep``'s training samples.

    Each record is a segment simulated from rest at its first input, its output taken at
    ``prep.sample_offset`` into each working interval; one output offset is fitted and left
    out of the model. ``max_order``, ``orders``, ``init_poles`` (rad/s) and ``warm_only`` are
    :func:`~hasel.ident.varpro.vp_fit`'s.

    Returns ``num, den`` (descending powers of s, s in rad/s) and ``{"order", "nrmse_train",
    "orders", "method"}``; raises :class:`~hasel.errors.BadInputError` (one line) when no
    model can be fitted.
    """
    t = prep.records[0].t_s
    return vp_fit([(r.u, r.y, r.train) for r in prep.records], prep.rate_hz, span_s=float(t[-1] - t[0]),
                  f_excited_hz=prep.f_excited_hz, shift=prep.sample_offset, max_order=max_order, orders=orders,
                  init_poles=init_poles, warm_only=warm_only)
