"""The verdict's words: why each named effect was named (:func:`_evidence`), in the data's units."""
from __future__ import annotations

from hasel.diagnose.augment import EffectFit, Pipeline
from hasel.effects.asymmetric import INPUT as ASYM_INPUT
from hasel.effects.drift import ABSORB
from hasel.effects.hysteresis import OUTPUT as OUTPUT_HYST
from hasel.effects.load import damping_factor, keeps_zeta, load_offset, mode_of, zero_form
from hasel.effects.saturation import OUTPUT_SLEW, stop_limit

__all__: list[str] = []


def _load_text(fit: EffectFit) -> str:
    """What a ``load_mass`` fit changed, in words, by its form (:mod:`hasel.effects.load`): frequencies in Hz,
    factors and damping ratios dimensionless."""
    mu = float(fit.theta[0])
    res = f"x{(1.0 + mu) ** -0.5:.3g}" if mu > -1.0 else "(undefined)"
    zf, md, d = zero_form(fit), mode_of(fit), damping_factor(fit)
    if zf is not None and zf[0] == "real":
        return (f"the real poles {'slowed' if zf[1] < 1.0 else 'sped'} (a viscous load): their frequencies "
                f"x{zf[1]:.3g}, static gain kept")
    if zf is not None and zf[0] == "notch":
        return (f"the anti-resonance moved: the zero pairs' frequency x{zf[1]:.3g}, damping ratio {zf[2]:.3g}, "
                f"static gain kept")
    if zf is not None:
        return (f"an added pole-zero pair below the resonance (a payload swinging on its mount): poles at "
                f"{zf[1]:.3g} Hz (damping ratio {zf[2]:.3g}), zeros at {zf[1] * zf[3]:.3g} Hz, static gain kept")
    if md is not None:
        return f"an added mode at {md[0]:.3g} Hz (damping ratio {md[1]:.3g}), static gain kept"
    if d is not None:
        return f"the resonance's frequency {res} and its damping ratio x{d:.3g} (mass ratio {mu:+.3g})"
    if keeps_zeta(fit):
        return f"the resonance's frequency {res}, its damping ratio kept (mass ratio {mu:+.3g})"
    return (f"the resonance's inertia {'grew' if mu >= 0 else 'fell'}: frequency and damping ratio {res} (mass "
            f"ratio {mu:+.3g})")


def _repeat_text(tm: dict) -> str:
    rp = tm.get("repeats") or {}
    if rp.get("repeat_difference_rms") is None:
        return ""
    return (f"; between repeats of the excitation ({rp['period_s']:.3g} s apart) the residual changes by "
            f"{rp['repeat_difference_rms']:.3g} rms ({rp['over_noise']:.1f} x noise), "
            f"{rp['mean_change_per_period']:+.3g} on average")


def _rate_unit(unit: str) -> str:
    """A rate's unit from a signal's unit name ("kV" -> "kV/s"); "per second" without one."""
    return f" {unit}/s" if unit else " per second"


def _saturation_text(fit: EffectFit, lv: dict, input_unit: str = "", output_unit: str = "") -> str:
    if fit.variant == "slew":
        return (f"the residual appears where the input moves fast (steps, the fast part of a sweep), whatever "
                f"the level, and its lag grows with amplitude times frequency: the input cannot move faster "
                f"than {fit.theta[0]:.4g}{_rate_unit(input_unit)} (a slew-rate limit)")
    if fit.variant == OUTPUT_SLEW:
        return (f"the residual appears where the output moves fast, either way, whatever the level: the stroke "
                f"cannot move faster than {fit.theta[0]:.4g}{_rate_unit(output_unit)} (a speed limit of the output)")
    side, end = fit.variant.split(":")
    if side == "measured":
        clipped = lv.get("clipped_output", {})
        ends = [e for e in ("lower", "upper") if e in clipped and (end == "both" or end == e)]
        return ("the measured output piles up on " + " and ".join(
            f"{clipped[e]['value']:.4g} ({clipped[e]['samples']} samples, its {e} end)" for e in ends)
                + " while the model goes beyond: the measured range is clipped there")
    if end.startswith("stop_"):
        e = end[len("stop_"):]
        k, _, g, c = fit.theta
        return (f"the output follows the model up to {c + g * k:.4g} and flattens beyond it towards "
                f"{stop_limit(fit):.4g} while the rest of the range stays straight: a smooth end stop at the {e} end")
    return (f"the residual is confined to the {end} end of the {side} range: a hard limit at "
            f"{fit.theta[0]:.4g}")


def _tau(x: float) -> str:
    return "0 s (at once)" if x < 1e-6 else f"{x:.3g} s"


def _evidence(name: str, fit: EffectFit, where: dict, gain: float, runner_up: tuple[str, float] | None,
              pipe: Pipeline, units: tuple[str, str] = ("", ""), credit_final: float | None = None) -> str:
    lv, dr, tm, fr = where["level"], where["direction"], where["time"], where["frequency"]
    me = fr["model_error"]
    bands = me.get("significant_bands_hz") or []
    band_txt = ", ".join(f"{a:.3g}-{b:.3g} Hz" for a, b in bands[:3]) or "no band"
    level_share = max(lv['share_input_level'], lv['share_output_level'])
    sig = {
        "static_nonlinearity": lambda: ((f"the residual follows the operating level (level bins explain "
                                         f"{_pct(level_share)} of it, the direction {_pct(dr['extra_share'])} more)"
                                         if level_share >= 0.05 else
                                         f"a level-dependent gain shows in the fit though level bins alone explain "
                                         f"{_pct(level_share)} of the residual (a map is curved within each bin)")
                                        + f"; the distortion passes through the dynamics ({fit.variant} map)"),
        "sensor_nonlinearity": lambda: (f"the residual is a function of the output level (instantaneous output bins "
                                f"explain {_pct(lv['share_instant_output'])}) applied after the dynamics: "
                                f"an output-side map fits better than an input-side one"),
        "saturation": lambda: _saturation_text(fit, lv, units[0], units[1]),
        "time_delay": lambda: (f"the residual tracks the nominal output's rate (correlation "
                       f"{where['rate']['corr_residual_vs_nominal_rate']:+.2f}, as a lag does) and the "
                       f"model-error model is significant in {band_txt}; delay {fit.theta[0]:.4g} s"),
        "load_mass": lambda: (f"the gap is linear (a linear model-error model explains {_pct(me['linear_share'])} of "
                      f"the residual, significant in {band_txt}): {_load_text(fit)}; gain factor {fit.theta[1]:.3g}"
                      + (f", and the load's weight offsets the output by {load_offset(fit):+.3g}{units[1] and ' ' + units[1]}"
                         if "sag" in fit.variant.split(":") else "")),
        "hysteresis": lambda: (f"at equal output level the residual depends on the direction (rising minus falling "
                       f"{dr['rising_minus_falling']:+.3g}, {dr['rising_minus_falling_over_noise']:+.1f} x noise; "
                       f"direction adds {_pct(dr['extra_share'])} to the level's share; at equal input "
                       f"levels the input's direction adds {_pct(dr.get('input_direction_extra_share', 0.0))}) "
                       f"and a rate-independent play-operator memory "
                       + ("of the stroke (after the dynamics: friction or backlash of the measured point or the "
                          "sensor's mount, a stick-slip) explains it" if fit.variant == OUTPUT_HYST else
                          "of the voltage (before the dynamics) explains it")
                       + (f", the log starting on the {'rising' if fit.theta[-1] < 0 else 'falling'} branch "
                          f"(c = {fit.theta[-1]:+.2f})" if len(fit.theta) > 5 and abs(fit.theta[-1]) > 0.05 else "")),
        "asymmetric_dynamics": lambda: (f"the residual depends on the direction (rising minus falling "
                                f"{dr['rising_minus_falling']:+.3g}) but fades at slow rates: the "
                                + ("input (before the dynamics) " if fit.variant == ASYM_INPUT else "output ")
                                + (f"cannot move faster than {fit.theta[0]:.4g}{_rate_unit(units[1])} while "
                                   f"{fit.variant.split(':')[1]} (a speed limit; the other way it follows at once)"
                                   if fit.variant.startswith("rate_limit") else
                                   f"rises with tau {_tau(fit.theta[0])} and falls with tau {_tau(fit.theta[1])}")),
        "charge_drift": lambda: ((f"part of the response arrives late (dielectric absorption or creep): "
                                  f"shares {100 * fit.theta[2]:+.3g} % of it through a lag of {fit.theta[0]:.3g} s and "
                                  f"{100 * fit.theta[3]:+.3g} % through one of {fit.theta[1]:.3g} s (negative: an "
                                  f"overshoot that relaxes), the static gain kept "
                                  f"(slow share of the residual {_pct(tm['slow_share'])})")
                                 if fit.variant == ABSORB else
                                 f"the residual varies slowly in time (slow share {_pct(tm['slow_share'])}, trend "
                                 f"t = {tm['trend_t']:+.1f}) following the history of the input (tau "
                                 f"{fit.theta[0]:.3g} s), not its present level") + _repeat_text(tm),
    }[name]()
    txt = f"{sig}; taken out alone, {_pct(gain)} of the nominal residual energy comes back on validation"
    if credit_final is not None:
        txt += f" ({_pct(credit_final)} on the final held-out samples)"
    if runner_up is not None and runner_up[1] > 0:
        txt += f" (next best when it was chosen: {runner_up[0]}, removing {_pct(runner_up[1])})"
    return txt


def _pct(x: float) -> str:
    """A share as a percentage, never a bare "0 %": below half a percent it says so."""
    x = float(x)
    if abs(x) < 0.005:
        return "less than 0.5 %" if x >= 0 else "a negative share (it helps nothing)"
    return f"{100 * x:.0f} %" if abs(x) >= 0.1 else f"{100 * x:.1f} %"


def unsettled_start_text(note: dict, input_unit: str = "") -> str:
    """One line for a record that starts unsettled (an entry of the verdict's ``heldout.unsettled_start``:
    ``record``, ``level`` and ``first_input`` in the input unit, ``left_out_s`` in s)."""
    u = f" {input_unit}" if input_unit else ""
    return (f"{'held-out log' if note['record'] else 'log'} starts unsettled (input {note['first_input']:.4g}{u} "
            f"at its first sample, output far from rest with it): simulated from rest at {note['level']:.4g}{u}, "
            f"its first {note['left_out_s']:.3g} s left out of every score")
