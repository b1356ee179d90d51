"""The checks of :func:`hasel.diagnose.core.diagnose` after forward selection.

Two signatures seen directly in the data, which a flexible augmentation can hide: a drift
from the change of the residual between repeats (:func:`_repeat_check`) and a measured clip
(:func:`_clip_check`); then the joint refinement of the chosen parameters
(:func:`_joint_refine_stage`), the input- against output-side map check
(:func:`_map_side_stage`) and the backward check that each named effect still earns its
place beside the others (:func:`_backward_check`). Each changes only the :class:`_State` it
is given.
"""
from __future__ import annotations

import math

import numpy as np

from hasel.diagnose.augment import LINEAR, EffectFit, fit_drift_on_repeats, fit_family, joint_refine, linear_static, measured_clip
from hasel.diagnose.context import _Context, _fixed, _pick, _raises, _State, _without, raised_resonance
from hasel.diagnose.significance import _SEPARATING, block_test, white_z
from hasel.effects.evidence import magnitude_evidence
from hasel.effects.hysteresis import input_loop
from hasel.effects.static_map import AFTER_HYST, AFTER_HYST_KNEE, fit_after_hysteresis, is_after_hysteresis

__all__: list[str] = []


def _direct_check(ctx: _Context, st: _State, kind: str, label: str, trial: dict[str, EffectFit], ok: bool,
                  info: dict, text: str) -> None:
    """Record a check of a signature seen directly in the data; adopt ``trial`` if ``ok``."""
    m_tr, m_ho, e_new = ctx.scores(trial)
    name = next(k for k in trial if k not in st.current)
    gain = (st.mse_ho - m_ho) / st.mse_ho if st.mse_ho > 0 else 0.0
    st.rounds.append({"round": len(st.rounds) + 1, kind: True, "best": label, "accepted": bool(ok), "gain": gain,
                      "candidates": [{"name": name, "nrmse_validation": ctx.to_nrmse(m_ho),
                                      "n_params": trial[name].n_params}], **info})
    ctx.say(f"{text}; validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f} -> {ctx.to_nrmse(m_ho):.4f} -> "
            f"{'accepted' if ok else 'rejected'}")
    if ok:
        st.evidence_of[name] = (gain, None)
        st.adopt(trial, m_tr, m_ho, e_new)


def _repeat_check(ctx: _Context, st: _State, where: dict) -> None:
    """Stage: a drift seen directly in the data.

    The residual changes between repeats of the excitation, where every time-invariant
    effect predicts the same output; levels that follow the log's history let a static map
    take over the drift's level part, so this asks the repeats."""
    opts, pipe, sigma2 = ctx.opts, ctx.pipe, ctx.sigma2
    rp = where["time"].get("repeats") or {}
    if not (rp.get("repeat_difference_rms") is not None and "charge_drift" not in st.current
            and rp["over_noise"] >= opts.repeat_over_noise_min):
        return
    got = fit_drift_on_repeats(pipe, st.current, float(rp["period_s"]))
    if got is None:
        return
    drift, stats_ = got
    b0, b1, n_pairs, fit2 = stats_["valid"]
    share = (b0 - b1) / max(b0 - 2.0 * sigma2 * n_pairs, 1e-300)
    z_rep = (b0 - b1) / (2.0 * math.sqrt(2.0 * sigma2) * max(math.sqrt(fit2), 1e-300))
    trial = {**st.current, "charge_drift": drift}
    for _ in range(2):  # the other effects follow, no longer taking the drift's level part
        for k2 in [k for k, v in st.current.items() if not _fixed(k, v)]:
            f2 = fit_family(pipe, {kk: vv for kk, vv in trial.items() if kk != k2}, k2, init=trial[k2])
            if f2 is not None:
                trial[k2] = f2
    _, m_ho, e_trial = ctx.scores(trial)
    t_blk, z_col = ctx.held_out(st.e_ho, e_trial)
    ok = (share >= opts.repeat_share_min and z_rep >= opts.z_min and m_ho <= opts.repeat_mse_ratio * st.mse_ho
          and opts.held_out_passes(t_blk, z_col))
    _direct_check(ctx, st, "repeat_check", "charge_drift", trial, ok,
                  {"period_s": rp["period_s"], "repeat_change_share_explained": share, "z": z_rep,
                   "t_block": t_blk, "z_coloured": z_col},
                  f"repeat check: the residual changes between repeats ({rp['over_noise']:.1f} x noise); "
                  f"a drift explains {100 * share:.0f} % of that change above noise (z {z_rep:.1f})")


def _clip_check(ctx: _Context, st: _State) -> None:
    """Stage: a clip seen directly in the data (the output piles up on its extreme value).

    The measured clip was part of every fit; it is named where the model goes beyond it there
    and clipping helps significantly, else it is taken out."""
    if not ("saturation" in st.current and st.current["saturation"].variant.startswith("measured")):
        return
    opts, pipe, prep = ctx.opts, ctx.pipe, ctx.prep
    kept = {}
    r0 = prep.records[0]  # the signature on the samples choices may see (training and validation)
    seen = r0.train | r0.valid
    without_all = {k2: v for k2, v in st.current.items() if k2 != "saturation"}
    # the nominal model's prediction (with its training offset, if identified here) and the chosen
    # model's without the clip: either going beyond the limit where the output sits on it
    preds = [pipe.simulate({}, 0)[seen] + (ctx.nominal_offset if ctx.identified else 0.0),
             pipe.simulate(without_all, 0)[seen]]
    for end, limit in pipe.clips.items():
        at = (np.abs(r0.y - limit) <= 1e-6 * max(float(np.ptp(r0.y)), 1e-300))[seen]
        share = max(float(((p > limit) if end == "upper" else (p < limit))[at].mean()) if at.any() else 0.0
                    for p in preds)
        others = {e2: v2 for e2, v2 in pipe.clips.items() if e2 != end}
        base = dict(without_all)
        if measured_clip(others) is not None:
            base["saturation"] = measured_clip(others)
        _, m_without, e_without = ctx.scores(base)
        z = white_z(e_without, st.e_ho, ctx.sigma2)
        t_blk, z_col = ctx.held_out(e_without, st.e_ho)
        # the clip is seen directly (samples pile up on one value): held out, it must only help
        # beyond chance (one-sided 5 %), not pass the test that guards against invented effects
        ok = (share >= opts.clip_share_min and st.mse_ho < m_without and z >= opts.z_min
              and (t_blk >= opts.t_min or z_col >= 1.645))
        st.rounds.append({"round": len(st.rounds) + 1, "clip_check": True, "end": end, "limit": float(limit),
                          "share_beyond_at_clip": share, "clipped_samples": int(at.sum()), "z": z, "t_block": t_blk,
                          "z_coloured": z_col, "gain": (m_without - st.mse_ho) / m_without if m_without > 0 else 0.0,
                          "accepted": bool(ok), "candidates": []})
        ctx.say(f"clip check: the output piles up on {limit:.6g} ({end}); a model goes beyond it on "
                f"{100 * share:.0f} % of those samples; clipping there removes {100 * st.rounds[-1]['gain']:.1f} % "
                f"(z {z:.1f}, held-out block score {t_blk:.1f}, coloured-noise z {z_col:.1f}) -> "
                f"{'named' if ok else 'not named'}")
        if ok:
            kept[end] = limit
    clip = measured_clip(kept)
    current = dict(without_all)
    if clip is not None:
        current["saturation"] = clip
        st.evidence_of["saturation"] = (max(r["gain"] for r in st.rounds if r.get("clip_check")), None)
    st.adopt(current, *ctx.scores(current))


def _joint_refine_stage(ctx: _Context, st: _State) -> None:
    """Stage: refine all chosen effects' parameters together; kept if validation does not worsen."""
    if len(st.current) > 1 and ctx.opts.joint_refine:
        refined = joint_refine(ctx.pipe, st.current, max_nfev=ctx.opts.joint_refine_nfev)
        m_tr, m_ho, e_new = ctx.scores(refined)
        if (m_ho <= st.mse_ho and not linear_static(ctx.pipe, refined)
                and not _raises(ctx, refined)):
            ctx.say(f"joint refinement: validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f} -> {ctx.to_nrmse(m_ho):.4f}")
            st.adopt(refined, m_tr, m_ho, e_new)


#: The two sides a static map can sit on: before the dynamics (``static_nonlinearity``) or on the measured
#: stroke (``sensor_nonlinearity``); see :func:`_map_side_stage`.
_MAP_SIDES = {"static_nonlinearity": "sensor_nonlinearity", "sensor_nonlinearity": "static_nonlinearity"}


def _map_side_stage(ctx: _Context, st: _State) -> None:
    """Stage: a map beside other effects is put on the side of the dynamics the final set favours.

    An input-side map distorts the voltage before the dynamics (its harmonics are filtered by the
    model, and its effect follows the input's level); a sensor curve bends the measured output (its
    effect follows the stroke's level at any frequency). Beside an effect not yet in place (a delay, a
    drift, a hysteresis) the first rounds compare the two against a residual that other effect
    still dominates, and the curve that soaks up more of *that* wins. Here, once the set is complete,
    the map is replaced by the other side's (fitted given the others, then every effect refined jointly,
    as the set itself was), and the two complete sets are compared on validation as the rounds compare
    candidates (:func:`_pick`: the lower error, near-ties to fewer parameters, then to the input side).
    Beside a hysteresis the map is instead compared with a map of the hysteresis output
    (:func:`_after_hysteresis_side`). When the held-out block test prefers neither by ``t_min``, the verdict lists both as
    ambiguous with their numbers and the experiment that separates them. Only for sets of two or more
    searched effects (alone, the first round already compared the two sides on equal terms)."""
    names_ = [k for k, v in st.current.items() if k != LINEAR and not _fixed(k, v)]
    have = [n for n in _MAP_SIDES if n in st.current]
    if (len(have) != 1 or len(names_) < 2 or _fixed(have[0], st.current[have[0]])
            or input_loop(st.current)):
        # beside a hysteresis the chain puts an input map before it, while a map after the hysteresis (an
        # actuator's curve of its hysteretic strain) is closer to a sensor curve at low frequencies: the
        # comparison would favour the output side for the chain's order, not for the data
        # (``maps.py`` seed 41, map_10: a power law after a Duhem lag moved to the output side). Instead the
        # map is compared with one of the hysteresis output (the slot between the hysteresis and the dynamics),
        # offered only here: the one branch point from main's code path (every set without an accepted
        # hysteresis, or without exactly one searched map beside it, returns here unchanged)
        if (len(have) == 1 and len(names_) >= 2 and input_loop(st.current)
                and not _fixed(have[0], st.current[have[0]])):
            _after_hysteresis_side(ctx, st, have[0])
        return
    name = have[0]
    other = _MAP_SIDES[name]
    rest = _without(st.current, name)
    fit = fit_family(ctx.pipe, rest, other)
    if fit is None:
        ctx.say(f"map side with the others in place: {other} could not be fitted beside them; {name} kept")
        return
    alt = joint_refine(ctx.pipe, {**rest, other: fit}, max_nfev=ctx.opts.joint_refine_nfev)
    why = ("its joint refinement dropped it" if other not in alt else
           "it came out a gain and an offset" if linear_static(ctx.pipe, alt) else
           "the set raises a resonance" if _raises(ctx, alt) else "")
    if why:
        # said, because a check that silently does not run reads like one that kept the map
        ctx.say(f"map side with the others in place: {other} not compared ({why}); {name} kept")
        return
    m_tr, m_ho, e_alt = ctx.scores(alt)
    # the forward selection's own choice between two sets (near-ties to fewer parameters, then the prior)
    n_cur = sum(f.n_params for f in st.current.values())
    n_alt = sum(f.n_params for f in alt.values())
    switch = _pick(sorted([(st.mse_ho, n_cur, name), (m_ho, n_alt, other)], key=lambda r: (r[0], r[1])))[2] == other
    e_win, e_lose = (e_alt, st.e_ho) if switch else (st.e_ho, e_alt)
    pref = block_test(e_lose, e_win, ctx.labels_va, ctx.slow_n)
    m_win, m_lose = (m_ho, st.mse_ho) if switch else (st.mse_ho, m_ho)
    win, lose = (other, name) if switch else (name, other)
    ctx.say(f"map side with the others in place: {name} validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f}, {other} "
            f"{ctx.to_nrmse(m_ho):.4f} (block preference {pref:.1f}) -> {win}")
    _side_round(ctx, st, alt, win, switch, pref, st.mse_ho, m_ho)
    st.ambiguous = [a for a in st.ambiguous if {a["chosen"], a["alternative"]} != {name, other}]
    if pref < ctx.opts.t_min:
        st.ambiguous.append(_side_ambiguity(ctx, st, win, lose, m_win, m_lose, pref, rest))
    if switch:
        if name in st.evidence_of:
            st.evidence_of[other] = st.evidence_of.pop(name)
        st.adopt(dict(alt), m_tr, m_ho, e_alt)


def _side_round(ctx: _Context, st: _State, alt: dict[str, EffectFit], best: str, accepted: bool, pref: float,
                m_cur: float, m_alt: float, after_hysteresis: bool = False) -> None:
    """Record a map-side comparison in ``st.rounds``: the final set (validation MSE ``m_cur``) against ``alt``
    (``m_alt``), the winner ``best`` and the held-out block preference ``pref``; ``after_hysteresis`` marks
    (and labels) the comparison with a map of the hysteresis output."""
    rec = {"round": len(st.rounds) + 1, "map_side_check": True}
    if after_hysteresis:
        rec["after_hysteresis"] = True
    label = " (map after the hysteresis)" if after_hysteresis else ""
    rec.update({"best": best, "accepted": bool(accepted), "preference": pref, "candidates": [
        {"name": " + ".join(k for k in st.current if k != LINEAR), "nrmse_validation": ctx.to_nrmse(m_cur)},
        {"name": " + ".join(k for k in alt if k != LINEAR) + label, "nrmse_validation": ctx.to_nrmse(m_alt)}]})
    st.rounds.append(rec)


def _side_ambiguity(ctx: _Context, st: _State, chosen: str, alternative: str, m_chosen: float, m_alt: float,
                    pref: float, rest: dict[str, EffectFit]) -> dict:
    """The verdict's entry for two maps the held-out blocks cannot separate: their validation NRMSE (from the
    validation MSEs ``m_chosen``, ``m_alt``), the share of the nominal gap each removes, the preference, the
    other effects beside them and the experiment that would separate them."""
    norm = max(st.mse_nom, 1e-300)
    return {"chosen": chosen, "alternative": alternative,
            "validation_nrmse": {"chosen": ctx.to_nrmse(m_chosen), "alternative": ctx.to_nrmse(m_alt)},
            "gap_removed": {"chosen": 1.0 - m_chosen / norm, "alternative": 1.0 - m_alt / norm},
            "preference": pref, "with_others": [k for k in rest if k != LINEAR],
            "experiment": _SEPARATING[frozenset((chosen, alternative))]}


#: Rounds in which every searched effect of a set beside a hysteresis is refitted given the others (each from
#: its current values) before the joint refinement, in :func:`_after_hysteresis_side`: the map of the hysteresis
#: output is fitted after the others, which were fitted beside the other map (as the repeat check's two rounds;
#: on ``other_pairs.py`` seed 5 case 6 the first round took the map after the hysteresis from validation NRMSE
#: 0.0189 to 0.0183, the second to 0.0178, the joint refinement to 0.0175). The set it is compared with gets
#: the same rounds (only to score it: it is kept as it was unless the map after the hysteresis wins).
AFTER_HYST_ROUNDS = 2
#: A sensor curve is renamed ``static_nonlinearity`` after the hysteresis only when, besides the lower validation
#: error (:func:`_pick`), the held-out block test prefers the map after the hysteresis by at least this score (a
#: renaming needs evidence beyond a lower mean: the first version, on validation error alone, renamed a true
#: sensor curve). Set on two tuning cases: ``maps.py`` seed 41 map_15 (a knee input map after a Duhem
#: hysteresis, the map after the hysteresis 0.0136 against the sensor curve's 0.0142, block preference 2.9)
#: and ``multi2.py`` seed 21 m2_09 (a tanh sensor beside a backlash: 0.0258 against 0.0265, block preference
#: -0.1); 1.0 is a one-sigma preference, between the two.
AFTER_HYST_PREF_MIN = 1.0


def _follow(ctx: _Context, effects: dict[str, EffectFit]) -> dict[str, EffectFit]:
    """``effects`` after :data:`AFTER_HYST_ROUNDS` rounds of refitting each searched effect given the others
    (a map of the hysteresis output by :func:`fit_after_hysteresis`, the rest by their families' fits
    warm-started from their values), then refined jointly (:func:`joint_refine`)."""
    pipe = ctx.pipe
    trial = dict(effects)
    for _ in range(AFTER_HYST_ROUNDS):
        for k in [k for k, v in trial.items() if not _fixed(k, v)]:
            others = {kk: vv for kk, vv in trial.items() if kk != k}
            try:
                f = (fit_after_hysteresis(pipe, others, trial[k].variant) if is_after_hysteresis(trial[k].variant)
                     else fit_family(pipe, others, k, init=trial[k]))
            except (np.linalg.LinAlgError, ValueError, FloatingPointError):
                f = None
            if f is not None and f.variant == trial[k].variant:
                trial[k] = f
    return joint_refine(pipe, trial, max_nfev=ctx.opts.joint_refine_nfev)


def _after_hysteresis_side(ctx: _Context, st: _State, name: str) -> None:
    """Stage (beside an accepted hysteresis only): the map ``name`` of the final set (an input map before the
    hysteresis or a sensor curve after the dynamics) against a ``static_nonlinearity`` acting on the
    hysteresis output, before the dynamics (variant :data:`hasel.effects.static_map.AFTER_HYST`).

    The map of the hysteresis output is fitted with the others in place (least squares, its fit is
    nonlinear in the hysteresis weights), then every searched effect is refitted given the others and all
    are refined jointly (:func:`_follow`). The final set gets the same treatment, only to score it fairly
    (the better of it as it is and as refitted stands for it). The two are compared on validation as the map
    sides are (:func:`_pick`: the lower error; near-ties to fewer parameters, then to the input side), and a
    renaming also needs the held-out block test to prefer it by :data:`AFTER_HYST_PREF_MIN`. A sensor curve
    that loses is renamed ``static_nonlinearity`` (the
    verdict names families, not slots); an input map that loses keeps its name and moves after the
    hysteresis (the lower validation error decides between two forms of one name)."""
    pipe = ctx.pipe
    cur = st.current[name]
    if name == "static_nonlinearity" and is_after_hysteresis(cur.variant):
        return
    rest = _without(st.current, name)
    # both forms (the polynomial and the knee), each refitted with the others (:func:`_follow`), the lower
    # validation error kept: chosen before the refits the knee lost where it won after them (``other_pairs.py``
    # seed 5 case 6: 29.4 against 16.2 before, NRMSE 0.0134 against 0.0175 after; ``maps.py`` seed 41 map_15)
    alt, m_best = None, np.inf
    for form in (AFTER_HYST, AFTER_HYST_KNEE):
        try:
            fit = fit_after_hysteresis(pipe, rest, form)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            fit = None
        if fit is None:
            continue
        cand = _follow(ctx, {**rest, "static_nonlinearity": fit})
        m_c = ctx.scores(cand)[1]
        if m_c < m_best:
            alt, m_best = cand, m_c
    if alt is None:
        ctx.say(f"map after the hysteresis: could not be fitted beside the others; {name} kept")
        return
    alt_fit = alt.get("static_nonlinearity")
    why = ("its refinement dropped it" if alt_fit is None or not is_after_hysteresis(alt_fit.variant)
           or not input_loop(alt) else
           "it came out a gain and an offset" if linear_static(pipe, alt) else
           # a load raising the resonance is no reason when the final set's does too (the backward check takes
           # such a load out of either: ``combos.py`` seed 21, combo_13)
           "the set raises a resonance" if _raises(ctx, alt) and not _raises(ctx, st.current) else "")
    if why:
        ctx.say(f"map after the hysteresis: not compared ({why}); {name} kept")
        return
    m_tr, m_ho, e_alt = ctx.scores(alt)
    # the final set refitted the same way (scored only): the map after the hysteresis must beat the better
    ref = _follow(ctx, st.current)
    m_ref, e_ref = st.mse_ho, st.e_ho
    if ((not _raises(ctx, ref) or _raises(ctx, st.current)) and not linear_static(pipe, ref)
            and set(ref) == set(st.current)):
        _, m_r, e_r = ctx.scores(ref)
        if m_r < m_ref:
            m_ref, e_ref = m_r, e_r
    n_cur = sum(f.n_params for f in st.current.values())
    n_alt = sum(f.n_params for f in alt.values())
    if name == "static_nonlinearity":  # the same name on both sides: the lower validation error decides
        switch = m_ho < m_ref
    else:
        switch = _pick(sorted([(m_ref, n_cur, name), (m_ho, n_alt, "static_nonlinearity")],
                              key=lambda r: (r[0], r[1])))[2] == "static_nonlinearity"
    e_win, e_lose = (e_alt, e_ref) if switch else (e_ref, e_alt)
    pref = block_test(e_lose, e_win, ctx.labels_va, ctx.slow_n)
    if switch and name != "static_nonlinearity" and pref < AFTER_HYST_PREF_MIN:
        ctx.say(f"map after the hysteresis: lower validation error ({ctx.to_nrmse(m_ho):.4f} against "
                f"{ctx.to_nrmse(m_ref):.4f}) but the held-out blocks prefer it by only {pref:.1f} (needs "
                f"{AFTER_HYST_PREF_MIN}); {name} kept")
        switch = False
    here = f"{name} ({cur.variant})" if name == "static_nonlinearity" else name
    ctx.say(f"map after the hysteresis: {here} validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f} (refitted "
            f"{ctx.to_nrmse(m_ref):.4f}), static_nonlinearity after the hysteresis {ctx.to_nrmse(m_ho):.4f} "
            f"(block preference {pref:.1f}) -> {'the map after the hysteresis' if switch else here}")
    _side_round(ctx, st, alt, "static_nonlinearity" if switch else name, switch, pref, m_ref, m_ho,
                after_hysteresis=True)
    if not switch:
        return
    if name != "static_nonlinearity":
        st.ambiguous = [a for a in st.ambiguous if {a["chosen"], a["alternative"]} != {name, "static_nonlinearity"}]
        if pref < ctx.opts.t_min:
            st.ambiguous.append(_side_ambiguity(ctx, st, "static_nonlinearity", name, m_ho, m_ref, pref, rest))
        if name in st.evidence_of:
            st.evidence_of["static_nonlinearity"] = st.evidence_of.pop(name)
    st.adopt(dict(alt), m_tr, m_ho, e_alt)


def _refit_rest(ctx: _Context, rest: dict[str, EffectFit]) -> tuple[dict[str, EffectFit], float, float, np.ndarray]:
    """``rest`` (the set without the effect under test) as it is or refined jointly from its values,
    whichever has the lower training error (validation decides nothing here); a refinement into a
    raised resonance is not taken. Returns (effects, training mse,
    validation mse, validation residual).

    Fitting each family afresh (grids, variants) instead was tried on the tuning combinations: it
    removed no extra name and lost a true 6 ms delay beside a drift and a hysteresis
    (``other_pairs.py`` seed 5, case 13), whose share fell below ``min_next_gain``."""
    opts = ctx.opts
    tries = [rest] + ([joint_refine(ctx.pipe, rest, max_nfev=opts.joint_refine_nfev)] if rest else [])
    scored = [(ctx.scores(e), e) for e in tries if not _raises(ctx, e)]
    (m_tr, m_ho, e_ho), eff = min(scored or [(ctx.scores(rest), rest)], key=lambda x: x[0][0])
    return eff, m_tr, m_ho, e_ho


def _backward_round(ctx: _Context, st: _State, name: str, refit: dict[str, EffectFit], m_ho_r: float,
                    accepted: bool, **extra: float | bool) -> None:
    """Record one test of the backward check in ``st.rounds``: ``name`` judged against the others refitted
    (``refit``, validation mse ``m_ho_r``); ``extra`` keys (its held-out test, or why it was taken out)."""
    st.rounds.append({"round": len(st.rounds) + 1, "backward_check": True, "best": name,
                      "gain": _gain_without(st, m_ho_r), **extra, "accepted": bool(accepted),
                      "candidates": [{"name": " + ".join(k for k in refit if k != LINEAR),
                                      "nrmse_validation": ctx.to_nrmse(m_ho_r)}]})


def _gain_without(st: _State, m_ho_r: float) -> float:
    """Share of the validation mse ``m_ho_r`` of a set without one effect that the effect removes."""
    return (m_ho_r - st.mse_ho) / m_ho_r if m_ho_r > 0 else 0.0


def _heavier_restart(ctx: _Context, st: _State, rest: dict[str, EffectFit], m_ho_r: float, e_r: np.ndarray
                     ) -> tuple[dict[str, EffectFit], tuple[float, float, np.ndarray], dict] | None:
    """A load that raises the resonances beside an earlier effect, restarted on the heavier side, when the
    frequency response says a load is there; None otherwise (the load is then taken out).

    A delay fitted first takes the phase a lower resonance adds, and the load fitted beside it then
    *raises* the resonance to give some back (``bench/tune_diag/loads.py`` seed 3: a 28 ms delay beside a
    resonance 27 % lower, fitted as a 32 ms delay and a mass ratio below 0). A delay moves only the
    phase, a slow drift nothing near the resonance: when the magnitude near the resonance, with the
    others (``rest``, refitted without the load) in place, moves by 1 dB or more and the load's set
    leaves at most half of it (:func:`hasel.effects.evidence.magnitude_evidence`), the load is
    restarted at mass ratios 0.15, 0.4 and 0.8 in both of its forms and refined jointly with the
    others (:func:`joint_refine`); the best by training error whose load stays heavier is kept if,
    like every member in the backward check, it removes ``min_next_gain`` of ``rest``'s validation
    residual and passes the held-out test (``t_min`` or ``zc_min``). Returns (set, (training mse,
    validation mse, validation residual), the round's figures)."""
    opts = ctx.opts
    mag = magnitude_evidence(ctx.pipe, rest, st.current, ctx.pipe.den)
    ctx.say(f"  magnitude near the resonance: {mag['near_db_without']:.2f} dB without the load, "
            f"{mag['near_db_with']:.2f} dB with it -> {'a load' if mag['shown'] else 'no load shown'}")
    if not mag["shown"]:
        return None
    kappa = st.current["load_mass"].theta[1]
    best = None
    for variant in ("model", "model:zeta"):
        for mu0 in (0.15, 0.4, 0.8):
            start = dict(rest) | {"load_mass": EffectFit("load_mass", variant, (mu0, kappa))}
            eff = joint_refine(ctx.pipe, start, max_nfev=opts.joint_refine_nfev)
            if "load_mass" not in eff or raised_resonance(eff, ctx.pipe.den) or linear_static(ctx.pipe, eff):
                continue
            sc = ctx.scores(eff)
            if best is None or sc[0] < best[1][0]:
                best = (eff, sc)
    if best is None:
        return None
    gain = (m_ho_r - best[1][1]) / m_ho_r if m_ho_r > 0 else 0.0
    t_blk, z_col = ctx.held_out(e_r, best[1][2])
    info = {"near_db_without": mag["near_db_without"], "near_db_with": mag["near_db_with"],
            "restart_gain": gain, "t_block": t_blk, "z_coloured": z_col}
    if gain >= opts.min_next_gain and opts.held_out_passes(t_blk, z_col):
        return best[0], best[1], info
    ctx.say(f"  restarted heavier it removes {100 * gain:.1f} % (block score {t_blk:.1f}, coloured z {z_col:.1f}): "
            f"not kept")
    return None


def _backward_check(ctx: _Context, st: _State) -> None:
    """Stage: every named effect must pass a later round's acceptance test given all the others, refitted.

    Forward selection tests a newcomer against the earlier effects *as they were fitted before it*;
    a newcomer can then be credited with what re-fitting the earlier effects' parameters would have
    removed anyway. On ``combos.py`` seed 21 (combo_16: a voltage clip beside an input map) a sensor
    curve was named first and the input map beside it; with the sensor curve taken out, the input map
    refitted alone explained more on validation (-4.7 %): the sensor curve was dropped. Here, for each
    searched effect of the final set, the others are refined jointly without it
    (:func:`hasel.diagnose.augment.joint_refine`, from their current values) and the effect must
    remove ``min_next_gain`` of that set's validation residual and pass the held-out test
    (``t_min`` or ``zc_min``). The weakest failing effect (lowest coloured z) is dropped and the
    test repeated on what is left; measured clips and a re-identified linear part are not tested,
    and effects named by the repeat or clip checks (seen directly in the data) keep their own tests.
    """
    opts = ctx.opts
    first = next((r["best"] for r in st.rounds if "candidates" in r and r.get("accepted")
                  and not any(r.get(k) for k in ("backward_check", "repeat_check", "clip_check"))), "")
    if _raises(ctx, st.current) and "load_mass" not in first.split(" + "):
        # a raised resonance added beside an earlier effect is no added load (see raised_resonance): out of
        # the final set, the others refitted. Not during the rounds: a first load fitted alone may raise the
        # resonance and still be the path to the true set, its mass ratio turning positive once the other
        # effects are in. A first effect that raises the resonance is a change of the dynamics the user
        # must see (the DC motor with brake: its identified model's resonance raised, 1.74 -> 0.0088)
        refit, m_tr_r, m_ho_r, e_r = _refit_rest(ctx, _without(st.current, "load_mass"))
        heavier = _heavier_restart(ctx, st, refit, m_ho_r, e_r) if opts.load_magnitude_evidence else None
        if heavier is not None:
            eff_h, (m_tr_h, m_ho_h, e_h), info = heavier
            _backward_round(ctx, st, "load_mass", refit, m_ho_r, True, raised_resonance=True, heavier_restart=True,
                            mass_ratio=float(st.current["load_mass"].theta[0]), **info)
            ctx.say(f"load_mass raises the resonances (mass ratio {st.current['load_mass'].theta[0]:.3g}), but the "
                    f"magnitude near the resonance moved {info['near_db_without']:.2f} dB (a delay or a drift does not "
                    f"move it): restarted heavier, mass ratio {eff_h['load_mass'].theta[0]:.3g} (validation NRMSE "
                    f"{ctx.to_nrmse(m_ho_h):.4f}, {ctx.to_nrmse(m_ho_r):.4f} without the load)")
            st.adopt(dict(eff_h), m_tr_h, m_ho_h, e_h)
        else:
            _backward_round(ctx, st, "load_mass", refit, m_ho_r, False, raised_resonance=True,
                            mass_ratio=float(st.current["load_mass"].theta[0]))
            ctx.say(f"load_mass raises the resonances (mass ratio {st.current['load_mass'].theta[0]:.3g}): no added "
                    f"load, taken out (validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f} -> {ctx.to_nrmse(m_ho_r):.4f})")
            st.evidence_of.pop("load_mass", None)
            st.adopt(dict(refit), m_tr_r, m_ho_r, e_r)
    if not opts.backward_check:
        return
    direct = {r["best"] for r in st.rounds if r.get("repeat_check") and r.get("accepted")}
    while True:
        names_ = [k for k, v in st.current.items() if not _fixed(k, v) and k not in direct]
        if len(names_) < 2 and len([k for k in st.current if k != LINEAR]) < 2:
            return
        fails = []
        for name in names_:
            rest = _without(st.current, name)
            refit, m_tr_r, m_ho_r, e_r = _refit_rest(ctx, rest)
            gain = _gain_without(st, m_ho_r)
            t_blk, z_col = ctx.held_out(e_r, st.e_ho)
            ok = gain >= opts.min_next_gain and opts.held_out_passes(t_blk, z_col)
            _backward_round(ctx, st, name, refit, m_ho_r, ok, t_block=t_blk, z_coloured=z_col)
            ctx.say(f"backward check: {name} given the others refitted removes {100 * gain:.1f} % (held-out block "
                    f"score {t_blk:.1f}, coloured-noise z {z_col:.1f}) -> {'kept' if ok else 'fails'}")
            if not ok:
                fails.append((z_col, name, refit, m_tr_r, m_ho_r, e_r))
        if not fails:
            return
        z_col, name, refit, m_tr_r, m_ho_r, e_r = min(fails, key=lambda f: f[0])
        ctx.say(f"backward check: {name} dropped (validation NRMSE {ctx.to_nrmse(st.mse_ho):.4f} with it, "
                f"{ctx.to_nrmse(m_ho_r):.4f} without, the others refitted)")
        st.evidence_of.pop(name, None)
        st.adopt(dict(refit), m_tr_r, m_ho_r, e_r)
