"""What the selection stages of :func:`hasel.diagnose.core.diagnose` share: the read-only
:class:`_Context` (data, model, options, noise floor, the held-out test's set-up), the
:class:`_State` they change (the chosen effects and their scores), and the small rules every
stage applies (a load that raises a resonance is not adopted; fixed parts are not searched;
ties between candidates go to the simpler, earlier family).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hasel.diagnose.augment import FAMILIES, INPUT_SIDE, LINEAR, EffectFit, Pipeline, measured_clip
from hasel.diagnose.options import DiagnoseOptions
from hasel.diagnose.prep import Prepared
from hasel.diagnose.significance import ar_whitener, block_test, coloured_z, whitened_scores
from hasel.effects.heldout import block_labels
from hasel.effects.load import mode_of, zero_form
from hasel.errors import BadInputError

__all__ = ["raised_resonance"]


#: A candidate: (validation mse, n_params, name, fit, training mse, validation residual, effects).
Candidate = tuple


@dataclass
class _Context:
    """What every selection stage reads: data, model, options, noise and the held-out test's set-up.

    Set once by the set-up stages; ``scores`` and the NRMSE helpers are the only way the
    stages measure a set of effects (training and validation choose, the final part reports)."""

    prep: Prepared
    pipe: Pipeline
    opts: DiagnoseOptions
    say: Callable[[str], None]
    source: dict
    den: np.ndarray
    sigma2: float
    noise_method: str
    identified: bool
    labels_va: np.ndarray
    slow_n: int
    lag_va: int
    slow_zc: int
    n_tr: int
    n_va: int
    norm_ho: float
    norm_fi: float
    floor: float
    floor_va: float
    nominal_offset: float = 0.0

    @classmethod
    def build(cls, prep: Prepared, pipe: Pipeline, opts: DiagnoseOptions, say, source: dict, den: np.ndarray,
              sigma2: float, method: str, identified: bool) -> "_Context":
        """The context of a prepared log; raises :class:`BadInputError` when too little is held out."""
        y_ho = prep.stacked("y", "valid")
        y_fi = prep.stacked("y", "hold")
        if y_ho.size < 10 or y_fi.size < 10:
            raise BadInputError("too little held-out data to score a model")
        norm_ho = float(np.sum((y_ho - y_ho.mean()) ** 2))
        norm_fi = float(np.sum((y_fi - y_fi.mean()) ** 2))
        labels_va = block_labels(prep, "valid")
        pipe.t_min = opts.t_min  # a family choosing between its forms on held-out blocks asks the acceptance's score
        # the slow part left out of the held-out test: opts.wander_s of the log, in stacked validation samples
        n_all = sum(r.t_s.size for r in prep.records)
        per_s = prep.rate_hz * labels_va.size / max(n_all, 1)
        ctx = cls(prep=prep, pipe=pipe, opts=opts, say=say, source=source, den=den, sigma2=sigma2,
                  noise_method=method, identified=identified, labels_va=labels_va,
                  slow_n=int(round(opts.wander_s * per_s)),
                  # the span of noise correlation the coloured z allows for: a median validation block
                  lag_va=int(np.median(np.bincount(labels_va))) if labels_va.size else 0,
                  slow_zc=int(round(opts.wander_zc_s * per_s)),
                  n_tr=prep.stacked("y", "train").size, n_va=int(y_ho.size), norm_ho=norm_ho, norm_fi=norm_fi,
                  floor=math.sqrt(sigma2 * y_fi.size / norm_fi) if norm_fi > 0 else float("inf"),
                  floor_va=math.sqrt(sigma2 * y_ho.size / norm_ho) if norm_ho > 0 else float("inf"))
        if identified:
            # a model identified here leaves the log's output offset out (for the static map to name)
            ctx.nominal_offset = float(np.mean(pipe.residuals({}, "train")))
        return ctx

    def scores(self, eff: dict[str, EffectFit]) -> tuple[float, float, np.ndarray]:
        """Training and validation mean squared errors, and the validation residual."""
        e_tr = self.pipe.residuals(eff, "train")
        e_ho = self.pipe.residuals(eff, "valid")
        return float(np.mean(e_tr ** 2)), float(np.mean(e_ho ** 2)), e_ho

    def final_sse(self, eff: dict[str, EffectFit]) -> float:
        """Squared error on the final held-out samples (reported only, never chosen on)."""
        e = self.pipe.residuals(eff, "hold")
        return float(np.sum(e * e))

    def final_nrmse(self, eff: dict[str, EffectFit]) -> float:
        """NRMSE on the final held-out samples (reported only, never chosen on)."""
        return math.sqrt(self.final_sse(eff) / self.norm_fi) if self.norm_fi > 0 else float("inf")

    def to_nrmse(self, mse: float) -> float:
        """A validation mean squared error as an NRMSE."""
        return math.sqrt(max(mse, 0.0) * self.n_va / self.norm_ho)

    def fast_block(self, e_old: np.ndarray, e_new: np.ndarray) -> float:
        """The held-out block score of ``e_old -> e_new`` on their fast parts: both residuals lose their slow
        part (a moving average over ``opts.wander_zc_s``, as :func:`coloured_z`) first."""
        return block_test(e_old, e_new, self.labels_va, self.slow_zc)

    def whitened(self, e_old: np.ndarray, e_new: np.ndarray, eff_new: dict) -> tuple[float, float, int]:
        """Block score and z of ``e_old -> e_new`` on residuals whitened by an AR model of the training residual
        of ``eff_new`` (the candidate: where it is right, what is left is the noise; the residual before it would
        hold the effect, and its AR model would whiten the effect away) (:func:`ar_whitener`,
        :func:`whitened_scores`), and the AR order."""
        e_tr = self.pipe.residuals(eff_new, "train")
        lab_tr = block_labels(self.prep, "train")
        a = ar_whitener(e_tr, lab_tr, max(1, min(30, self.lag_va // 3)))
        t, z = whitened_scores(e_old, e_new, self.labels_va, a)
        return t, z, a.size - 1

    def held_out(self, e_old: np.ndarray, e_new: np.ndarray) -> tuple[float, float]:
        """The two held-out scores of ``e_old -> e_new``: block score and coloured-noise z."""
        return (block_test(e_old, e_new, self.labels_va, self.slow_n),
                coloured_z(e_old, e_new, self.lag_va, self.slow_zc))


@dataclass
class _State:
    """The selection so far: the chosen effects and their scores, and what the verdict records."""

    current: dict[str, EffectFit]
    mse_tr: float
    mse_ho: float
    e_ho: np.ndarray
    mse_nom: float
    rounds: list[dict] = field(default_factory=list)
    evidence_of: dict[str, tuple] = field(default_factory=dict)
    ambiguous: list[dict] = field(default_factory=list)
    pending_evidence: dict | None = None

    def adopt(self, current: dict[str, EffectFit], m_tr: float, m_ho: float, e_ho: np.ndarray) -> None:
        """Make ``current`` the selection, with its training/validation errors and residual."""
        self.current, self.mse_tr, self.mse_ho, self.e_ho = current, m_tr, m_ho, e_ho


def _start_state(ctx: _Context) -> _State:
    """Stage: the empty selection (or the measured clip every fit sees), scored."""
    mse_tr, mse_ho, e_ho = ctx.scores({})
    mse_nom = mse_ho
    if ctx.identified:
        # the nominal gap later effects are measured against is that of the model with its training
        # offset, else any offset-absorbing first effect would leave every further effect a
        # negligible share of it
        mse_nom = min(mse_nom, float(np.mean((e_ho - ctx.nominal_offset) ** 2)))
    st = _State({}, mse_tr, mse_ho, e_ho, mse_nom)
    clip0 = measured_clip(ctx.pipe.clips)
    if clip0 is not None:
        # the measured output piles up on its extremes: every fit sees the model clipped there (a
        # prediction beyond the measured range can only be further from what was measured); whether
        # to name it is decided in _clip_check
        st.adopt({"saturation": clip0}, *ctx.scores({"saturation": clip0}))
        ctx.say(f"the measured output piles up on {', '.join(f'{v:.6g} ({k})' for k, v in ctx.pipe.clips.items())}"
                f": the fits see the model clipped there (validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f})")
    return st


def _without(effects: dict[str, EffectFit], name: str) -> dict[str, EffectFit]:
    """``effects`` without ``name`` (and without a re-identified linear part no input-side effect needs)."""
    out = {k: v for k, v in effects.items() if k != name}
    if LINEAR in out and not any(k in INPUT_SIDE for k in out):
        out.pop(LINEAR)
    return out


#: Largest |mass ratio| a load form that holds it at 0 (``model:mode``, ``model:notch``, ``model:pair``,
#: ``model:real``) may reach in a joint refinement and still keep the model's resonances (``forms3.py`` seed 8,
#: zstop2 + antires: a notch load at -0.000164 was removed as raising them).
HELD_MU_TOL = 0.01


def raised_resonance(effects: dict[str, EffectFit], den: np.ndarray | None = None) -> bool:
    """True when ``effects`` holds a ``load_mass`` fit with a negative mass ratio (``mu < 0``) on a model
    with a resonance (``den``, descending powers of s, has a complex pole pair; None: assumed).

    On a model with resonances a load scales their inertia (:func:`hasel.effects.load.loaded_den`):
    an added load lowers them, ``mu > 0``. A fit that raises them (the family's bounds allow ``mu``
    down to -0.8 so that its refinement can pass through zero) is a correction of the model or of
    another effect's form, not a load: beside a rate limit, a drift or a hysteresis it patched their
    forms on the ``bench/tune_diag`` combinations (``mu`` -0.38 to -0.73; every load named there with
    a load in its truth had ``mu`` 0.18 or more). Without a resonance the load moves the slowest real
    pole, and a faster pole (``mu < 0``) is a changed load too (a brake's damping on a motor): False."""
    f = effects.get("load_mass")
    if f is None or not f.theta or f.theta[0] >= 0.0:
        return False
    if (zero_form(f) is not None or mode_of(f) is not None) and f.theta[0] > -HELD_MU_TOL:
        # these forms hold mu at 0 (the model's resonances kept); a joint refinement's nudge is no raised resonance
        return False
    if den is None:
        return True
    p = np.roots(np.asarray(den, float))
    return bool(np.any(np.abs(p.imag) > 1e-9 * np.maximum(1.0, np.abs(p))))


def _raises(ctx: _Context, effects: dict[str, EffectFit]) -> bool:
    """True when ``load_adds_mass`` is on and ``effects`` hold a load that raises the nominal model's
    resonances (:func:`raised_resonance`): a set not to adopt."""
    return ctx.opts.load_adds_mass and raised_resonance(effects, ctx.pipe.den)


def _fixed(name: str, fit: EffectFit) -> bool:
    """A part of the chain that is not searched: a re-identified linear model, a measured clip."""
    return name == LINEAR or fit.variant.startswith("measured")


_PRIOR = {n: i for i, n in enumerate(FAMILIES)}


def _pick(results: list[Candidate]) -> Candidate:
    """Lowest validation error; near-ties (1 %) go to fewer parameters, then to the earlier family.

    The family order (FAMILIES) is the tie-break prior: an offset or a curvature that the
    data cannot place before or after the dynamics is read as the actuator's static map
    rather than the sensor's.
    """
    best = results[0]
    for r in results[1:]:
        if r[0] <= 1.01 * best[0] and (r[1] < best[1] or (r[1] == best[1] and r[0] <= 1.005 * best[0]
                                                          and _PRIOR[r[2]] < _PRIOR[best[2]])):
            best = r
    return best
