"""The set-up stages of :func:`hasel.diagnose.core.diagnose`: the nominal model, the working-rate
problem, the timing offset, the gain check and the noise floor.

They run before any effect is fitted and return what the selection stages read: the model
(given, or identified from the log, :func:`_identify`), the prepared log
(:func:`_model_stage`), the output's sampling offset against the zero-order-hold convention
(:func:`timing_stage`, with a load as a nuisance so that a changed resonance is not read as
timing), the model's scale against the log (:func:`_gain_stage`) and the noise floor with the
residual's localisation (:func:`_noise_stage`).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import optimize

from hasel.diagnose.augment import Pipeline
from hasel.diagnose.inputnoise import InputNoise, input_noise
from hasel.diagnose.nominal import scale_check
from hasel.diagnose.options import DiagnoseOptions, DiagnosisFailed
from hasel.diagnose.prep import Prepared, estimate_noise, flat_extremes, noise_trust, zoh_offset
from hasel.diagnose.where import analyse
from hasel.effects.load import LOAD_SAG_MIN_MU, loaded_den
from hasel.errors import BadInputError
from hasel.ident.identify import SAMPLE_READ

__all__ = ["timing_stage"]


def _model_delay(model) -> float:
    if isinstance(model, dict) and model.get("delay_s") is not None:
        try:
            d = float(model["delay_s"])
        except (TypeError, ValueError) as err:
            raise BadInputError(f"model delay_s must be a number of seconds, got {model['delay_s']!r}") from err
        if not math.isfinite(d) or d < 0:
            raise BadInputError(f"model delay_s must be finite and >= 0, got {d}")
        return d
    return 0.0


def _as_model(model) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(model, dict):
        if "num" not in model or "den" not in model:
            raise BadInputError("the model needs 'num' and 'den' (continuous transfer function, descending powers of s)")
        num, den = model["num"], model["den"]
    else:
        try:
            num, den = model
        except (TypeError, ValueError) as err:
            raise BadInputError("model must be (num, den) or a dict with 'num' and 'den'") from err
    try:
        num = np.atleast_1d(np.asarray(num, float))
        den = np.atleast_1d(np.asarray(den, float))
    except (TypeError, ValueError) as err:
        raise BadInputError(f"model coefficients must be numbers: {err}") from err
    if num.ndim != 1 or den.ndim != 1 or not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
        raise BadInputError("model num/den must be 1-D lists of finite numbers")
    den = np.trim_zeros(den, "f")
    if den.size == 0:
        raise BadInputError("model den is all zeros")
    return num, den


def _linear_outputs(prep: Prepared, num: np.ndarray, den: np.ndarray, delay_s: float = 0.0) -> list[np.ndarray]:
    """A linear model's simulated output of every record (output units), its input delayed ``delay_s`` s."""
    sim = prep.sim(num, den)
    return [sim.run(np.interp(r.t_s - delay_s, r.t_s, r.u, left=r.u[0]) if delay_s > 0 else r.u)
            for r in prep.records]


def _train_fit(prep: Prepared, num: np.ndarray, den: np.ndarray, delay_s: float = 0.0) -> float:
    """Training NRMSE of a linear model's simulation, with its best output offset."""
    es, ys = [], []
    for r, yh in zip(prep.records, _linear_outputs(prep, num, den, delay_s)):
        if r.train.any():
            es.append((r.y - yh)[r.train])
            ys.append(r.y[r.train])
    e, y = np.concatenate(es), np.concatenate(ys)
    e = e - e.mean()
    return float(np.linalg.norm(e) / max(np.linalg.norm(y - y.mean()), 1e-300))


def _identify(prep: Prepared, opts: DiagnoseOptions, say) -> tuple[np.ndarray, np.ndarray, dict]:
    """A linear model of the log: the internal output-error fit and/or ``hasel.ident``.

    ``"auto"`` fits both when ``hasel.ident`` is there and keeps the one whose simulation
    fits the training samples better (``hasel.ident`` fits frequency responses of
    operating points; the internal fit the time-domain simulation the diagnosis uses).
    """
    if opts.identify not in ("auto", "internal", "ident"):
        raise BadInputError(f"identify must be 'auto', 'internal' or 'ident', got {opts.identify!r}")
    cands = []
    note = None
    if opts.identify in ("auto", "ident"):
        try:
            from hasel.ident import identify as ident_identify  # type: ignore[attr-defined]

            say("identifying a linear model (hasel.ident)")
            # hasel.ident splits and validates on its own: it sees the whole log (at the working rate)
            rec = prep.records[0]
            with np.errstate(all="ignore"):
                res = ident_identify(rec.t_s, rec.u, rec.y)
            mj = res.to_model_json()
            if mj.get("usable") is False:  # hasel.ident's own checks failed: never a nominal model
                raise ValueError("its model failed its own checks: " + "; ".join(map(str, mj.get("reasons", []))))
            num, den = _as_model(mj)
            if np.any(np.real(np.roots(den)) >= 0):
                raise ValueError("unstable model")
            d = _model_delay(mj)
            # simulated the way it was fitted: interpolated, or exactly (block means, hasel.ident.timefit.READ)
            read = mj.get("sample_read", SAMPLE_READ)
            cands.append((_train_fit(replace(prep, exact_offset=read != SAMPLE_READ), num, den, d), num, den,
                          {"source": "hasel.ident", "delay_s": d, "sample_read": read,
                           "details": {"order": int(den.size - 1),
                                       **{k: mj[k] for k in ("fit", "frequency_band_hz", "static_gain") if k in mj}}}))
        except Exception as err:  # noqa: BLE001 - any failure falls back to the internal fit
            if opts.identify == "ident":
                raise BadInputError(f"hasel.ident could not identify a model: {err}") from err
            note = f"hasel.ident unavailable or failed ({type(err).__name__}: {err})"
    if opts.identify in ("auto", "internal"):
        from hasel.diagnose.linfit import fit_linear

        say("identifying a linear model (internal output-error fit)")
        with np.errstate(all="ignore"):
            num, den, info = fit_linear(prep, max_order=opts.max_order)
        if note:
            info["note"] = note
        cands.append((_train_fit(prep, num, den), num, den, {"source": "identified from the log", "details": info,
                                                             "sample_read": SAMPLE_READ}))
    fit, num, den, src = min(cands, key=lambda c: c[0])
    src["training_nrmse_with_offset"] = fit
    if note and src["source"] == "identified from the log":
        # identify refused every linear model of this log: the verdict must not read as a gap to a trusted model
        src["warning"] = (f"the nominal model is a fallback: hasel.ident refused a linear model of this log "
                          f"(its reasons in model.details.note), so the internal output-error fit is used "
                          f"(training compare fit {100 * (1 - fit):.0f} %); the effects are relative to that fit, "
                          f"not to a trusted model: give the simulator's model with --model, or identify one first "
                          f"from a small-amplitude linear experiment (hasel chirp, then hasel identify)")
    if len(cands) > 1:
        src["alternatives"] = {c[3]["source"]: c[0] for c in cands}
    return num, den, src


#: The ``timing_offset`` note of a shift search that reached its bound (the convention kept).
AT_BOUND_NOTE = ("the best shift reached one original sample: not a sampling convention but a lag; the "
                 "zero-order-hold convention is kept and any delay is left to the time_delay effect")


def shift_range(q: int) -> tuple[float, float, float]:
    """The zero-order-hold sampling point for block means of ``q`` samples (:func:`zoh_offset`) and the range the
    timing offset is searched over: one original sample either side, within one working sample (working samples)."""
    a0 = zoh_offset(q)
    return a0, max(-1.0, a0 - 1.0 / q), min(1.0, a0 + 1.0 / q)


def at_shift_bound(a: float, lo: float, hi: float, q: int) -> bool:
    """Whether the shift ``a`` (working samples) found in ``[lo, hi]`` sits at a bound (within 2 % of an original
    sample): a lag, not a sampling convention."""
    return min(a - lo, hi - a) < 0.02 / q


def grid_then_bounded(cost, grid: np.ndarray, xatol: float) -> tuple[float, float]:
    """The minimiser of the scalar ``cost`` over ``grid``'s range and its cost: the best grid point, then a bounded
    search between its neighbours, kept only when it beats that point (none when no grid point is finite)."""
    costs = [cost(float(x)) for x in grid]
    i = int(np.argmin(costs))
    if not np.isfinite(costs[i]):
        return float(grid[i]), float("inf")
    res = optimize.minimize_scalar(cost, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]),
                                   method="bounded", options={"xatol": xatol})
    return (float(res.x), float(res.fun)) if res.fun < costs[i] else (float(grid[i]), float(costs[i]))


def timing_stage(prep: Prepared, num: np.ndarray, den: np.ndarray, delay_s: float, say,
                 exclude: np.ndarray | None = None, nuisance_load: bool = True) -> dict:
    """Estimate the output sampling point as a nuisance (a timing offset) and set it in ``prep``.

    The nominal simulation holds the input over each working interval and takes the output
    at :attr:`Prepared.sample_offset` into it (the zero-order-hold convention of the
    original samples). A log sampled another way (first-order hold, centred samples, an
    input clock a fraction of a sample off the output's) moves that point; it is fitted on
    the training samples within one *original* sample either side (with an output offset,
    also a nuisance). A shift that reaches the bound is not a convention but a lag: the
    convention is then kept and a time delay is left to be found as an effect.

    A linear change of the system (a load's phase near the resonance) would bias a shift fitted
    on the nominal model alone by up to the bound (on the tuning logs a 17 % lower double pole
    moved it by 0.84 of a sample, and the load was then fitted against the wrong timing); so
    the shift is fitted jointly with a nuisance load (:func:`_load_nuisance`: the resonances'
    inertia and the gain, the ``load_mass`` family's form), which is not kept: whether a load
    is there is for the selection to say. A time delay fitted later that stays within one
    original sample is folded back into the shift (see :func:`_timing_fold`). Not for a model
    identified from the same log (``nuisance_load`` False): it has no load to miss, and a
    nuisance load there took part of the DC motor's dead time into the shift.

    Returns the ``timing_offset`` entry of the verdict (output lag behind the zero-order
    hold convention, in seconds and original samples; positive: the output lags).
    """
    from hasel.diagnose.prep import estimate_timing

    q = prep.decimation
    a0, lo, hi = shift_range(q)
    r0 = prep.records[0]
    u = np.interp(r0.t_s - delay_s, r0.t_s, r0.u, left=r0.u[0]) if delay_s > 0 else r0.u
    use = r0.train & ~exclude if exclude is not None else r0.train  # clipped samples bound the output only
    mu, kappa = _load_nuisance(prep, num, den, u, use, lo, hi) if nuisance_load else (0.0, 1.0)
    ys = prep.sim(num, loaded_den(den, mu), 0.0).run_start(u).scaled(kappa)
    a, sse = estimate_timing(ys, r0.y, use, lo, hi)
    _, sse0 = estimate_timing(ys, r0.y, use, a0, a0)
    at_bound = at_shift_bound(a, lo, hi, q)
    used = a0 if at_bound else a
    prep.sample_offset = used
    lag_samples = -(used - a0) * q
    out = {"seconds": lag_samples / prep.info.get("original_rate_hz", prep.rate_hz),
           "original_samples": lag_samples, "bound_original_samples": 1.0,
           "training_sse_reduction": (sse0 - sse) / sse0 if sse0 > 0 else 0.0,
           "convention": "zero-order hold (input held over each sample, output sampled at its start)",
           "note": ("a timing offset between the input and output samples (a sampling convention or clock "
                    "offset), estimated as a nuisance within one original sample; not a delay of the system")}
    if at_bound:
        out["note"] = AT_BOUND_NOTE
        out["seconds"] = out["original_samples"] = 0.0
        # which end: at the lag end the delay is the time_delay effect's (and is not folded back, _timing_fold)
        out["bound_reached"] = "lag" if a < a0 else "lead"
    out["fitted_beside"] = {"load_mass_ratio": mu, "gain_factor": kappa,
                            "note": "a nuisance load fitted with the shift so that a changed resonance's phase is "
                                    "not read as timing; not part of the model"}
    say(f"timing offset: output lags the zero-order-hold convention by {out['original_samples']:+.2f} samples "
        f"({1e3 * out['seconds']:+.3g} ms){' (bound reached: kept at 0)' if at_bound else ''}")
    return out


def _load_nuisance(prep: Prepared, num: np.ndarray, den: np.ndarray, u: np.ndarray, use: np.ndarray,
                   lo: float, hi: float) -> tuple[float, float]:
    """The inertia factor ``mu`` of the model's resonances and the gain ``kappa`` that, with the best
    output sampling shift in ``[lo, hi]`` (working samples) and an output offset, fit the first
    record's training samples ``use`` best (``mu`` in [-0.6, 3]; ``(0, 1)`` when nothing is gained).

    Each trial is one linear simulation: a grid of ``mu`` then a bounded scalar search, ``kappa``
    by least squares at each shift's side."""
    from hasel.diagnose.prep import at_offset, estimate_timing

    y = prep.records[0].y

    def cost(mu: float) -> tuple[float, float]:
        try:
            ys = prep.sim(num, loaded_den(den, float(mu)), 0.0).run_start(u)
        except (BadInputError, ValueError, np.linalg.LinAlgError):
            return float("inf"), 1.0
        a, _ = estimate_timing(ys, y, use, lo, hi)
        m = at_offset(ys, a)[use]
        mc, yc = m - m.mean(), y[use] - y[use].mean()
        k = float(mc @ yc / max(mc @ mc, 1e-300))
        if not 0.2 <= k <= 5.0:
            return float("inf"), 1.0
        _, sse = estimate_timing(ys.scaled(k), y, use, lo, hi)
        return sse, k

    grid = np.array([-0.5, -0.3, -0.15, 0.0, 0.15, 0.3, 0.5, 0.8, 1.2, 2.0])
    mu, best = grid_then_bounded(lambda m: cost(m)[0], grid, 0.005)
    if not np.isfinite(best):
        return 0.0, 1.0
    sse, kappa = cost(mu)
    sse0 = estimate_timing(prep.sim(num, den, 0.0).run_start(u), y, use, lo, hi)[1]
    n = int(use.sum())
    # kept only when the two parameters pay for themselves (BIC, noise variance unknown): on an
    # effect-free log the shift is then the nominal model's, as before. Not only when the gap is
    # mostly load-like: beside a large drift (load + drift tuning cases) the load is a small part
    # of the gap and its phase still biased the shift (the load was then lost)
    # And only a load that moves the resonance by 5 % or more (``|mu| >= 0.1``): a smaller one biases
    # the shift by little, and one fitted to a sampling convention on an effect-free log (mu 0.017)
    # left the load's own residual for the selection to name
    if (abs(mu) >= LOAD_SAG_MIN_MU and sse > 0 and sse0 > sse
            and n * math.log(sse0 / sse) > 2.0 * math.log(max(n, 2))):
        return mu, kappa
    return 0.0, 1.0


def _nominal_model(model) -> tuple[np.ndarray | None, np.ndarray | None, dict]:
    """Stage: the given model as ``(num, den, source)`` (``None, None, {}`` without one).

    Raises :class:`DiagnosisFailed` when the model file says it is unusable."""
    if isinstance(model, dict) and model.get("usable") is False:
        reasons = model.get("reasons") or model.get("reason") or ["the model file says it is not usable"]
        reasons = [str(r) for r in (reasons if isinstance(reasons, list) else [reasons])]
        raise DiagnosisFailed("the nominal model is marked unusable (" + "; ".join(reasons) + "): identify it "
                              "again from a log that passes its checks, or diagnose without --model",
                              {"usable": False, "reasons": ["nominal model marked unusable"] + reasons,
                               "effects": [], "dropped": [], "ambiguous": []})
    if model is None:
        return None, None, {}
    num, den = _as_model(model)
    src = {"source": "given", "delay_s": _model_delay(model)}
    if isinstance(model, dict) and model.get("sample_read") == SAMPLE_READ:
        # fitted by a simulation that interpolates between interval starts (hasel identify's, or this
        # diagnosis's own identification): simulated the same way
        src["sample_read"] = SAMPLE_READ
    return num, den, src


def _model_stage(prep: Prepared, num, den, source: dict, opts: DiagnoseOptions, say
                 ) -> tuple[np.ndarray, np.ndarray, dict, dict, dict]:
    """Stage: the linear model (identified without clipped samples when none is given), the timing
    offset (set in ``prep``) and the measured clips. Returns ``num, den, source, timing, clips``."""
    clips = flat_extremes(prep.records[0].y)
    given = num is not None
    if not given or source.get("sample_read") == SAMPLE_READ:
        # simulated the way the identification fitted it (linear interpolation between interval starts)
        prep.exact_offset = False
    if not given:
        prep_id = prep
        if clips:
            # clipped samples only bound the output: identify the linear model without them
            at = np.logical_or.reduce([m for _, m in clips.values()])
            prep_id = replace(prep, records=[replace(prep.records[0], train=prep.records[0].train & ~at)]
                              + prep.records[1:])
            say(f"the output piles up on {', '.join(f'{v:.4g}' for v, _ in clips.values())} "
                f"({int(at.sum())} samples, a clip): identifying without them")
        num, den, source = _identify(prep_id, opts, say)
        # hasel.ident's model fitted on block means read exactly is simulated exactly too
        prep.exact_offset = source.get("sample_read", SAMPLE_READ) != SAMPLE_READ
    else:
        g = _gain_stage(prep, num, den, float(source.get("delay_s", 0.0) or 0.0), say)
        source = {**source, "nominal_scale": {k: g[k] for k in ("scale", "checked", "band_hz", "band_share")}}
    clipped = np.logical_or.reduce([m for _, m in clips.values()]) if clips else None
    timing = timing_stage(prep, num, den, float(source.get("delay_s", 0.0) or 0.0), say, clipped, nuisance_load=given)
    return num, den, source, timing, clips


def _gain_stage(prep: Prepared, num: np.ndarray, den: np.ndarray, delay_s: float, say) -> dict:
    """Stage: refuse a given model whose gain or sign contradicts the log (:mod:`hasel.diagnose.nominal`).

    Raises :class:`DiagnosisFailed` (exit 1, ``usable: false``) before any effect is fitted: a
    units or sign error would otherwise be "explained" by a map or a sensor curve."""
    g = scale_check([r.y for r in prep.records], _linear_outputs(prep, num, den, delay_s),
                    [r.train for r in prep.records], den, prep.rate_hz)
    band = "{:.3g}-{:.3g} Hz".format(*g["band_hz"])
    if g["checked"]:
        say(f"nominal scale in {band} on the training samples: {g['scale']:.4g} (1 = the model's gain)")
    else:
        say(f"nominal scale not checked: {100 * g['band_share']:.1f} % of the simulation's variance in {band}")
    if not g["ok"]:
        raise DiagnosisFailed(g["reason"] + ": fix the model or the log's units, or identify a model from this "
                              "rig (hasel identify)",
                              {"usable": False, "reasons": [g["reason"]], "nominal_scale": g["scale"],
                               "effects": [], "dropped": [], "ambiguous": []})
    return g


def _input_noise_stage(prep: Prepared, pipe: Pipeline, r0: np.ndarray) -> InputNoise:
    """The recorded input's measurement noise and its share of the nominal residual ``r0`` of the first record
    (:func:`hasel.diagnose.inputnoise.input_noise`), with the nominal model's working-rate impulse response."""
    u = pipe.inputs[0]
    n = min(u.size, 8192)
    imp = np.zeros(n + 1)
    imp[1] = 1.0
    h = pipe.nominal.run(imp)[1:]

    def floor_view(sigma_u: float) -> float:
        # the floor's estimator on the model's response to white noise: what it already counts (fixed seed, so a
        # diagnosis is repeatable)
        x = np.random.default_rng(0).standard_normal(u.size) * sigma_u
        return estimate_noise(pipe.nominal.run(x), prep.rate_hz, prep.f_excited_hz)[0]

    return input_noise(u, r0, h, floor_view)


def _noise_stage(prep: Prepared, pipe: Pipeline, clips: dict, say=lambda _m: None,
                 check_input: bool = True) -> tuple[float, str, dict, dict, dict]:
    """Stage: the noise variance from the nominal residual (``sigma2``, output units squared), its
    estimator, how far to trust it, and the residual's localisation. With ``check_input``, the recorded
    input's measurement noise through the model is added where the residual shows it
    (:mod:`hasel.diagnose.inputnoise`).

    Returns ``sigma2, method, noise, where, arrays``."""
    r0 = prep.records[0].y - pipe.simulate({}, 0)
    sigma2, method = estimate_noise(r0, prep.rate_hz, prep.f_excited_hz)
    noise_d = noise_trust(r0, prep.rate_hz, prep.f_excited_hz, sigma2, method)
    if check_input:
        inp = _input_noise_stage(prep, pipe, r0)
        noise_d["input_noise"] = inp.as_dict()
        if inp.counted and inp.floor_add > 0.0:
            say(f"recorded input noise: {1e3 * inp.sigma_u:.3g} V rms (differences of order {inp.order}); "
                f"{inp.reason}: its {math.sqrt(inp.residual_var):.3g} rms through the model added to the floor "
                f"(rms {math.sqrt(sigma2):.3g} -> {math.sqrt(sigma2 + inp.floor_add):.3g})")
            sigma2 += inp.floor_add
            noise_d["rms"] = math.sqrt(sigma2)
            noise_d["estimator"] += "; plus the recorded input's measurement noise through the model"
    where = analyse(pipe, sigma2, method)
    where["level"]["clipped_output"] = {end: {"value": v, "samples": int(m.sum()),
                                              "share": float(m.mean())} for end, (v, m) in clips.items()}
    arrays = where.pop("_arrays")
    return sigma2, method, noise_d, where, arrays
