"""The diagnosis report: ``report.md`` and its figures (matplotlib, Agg backend).

Figures:

- ``residual_spectrum.png``: the nominal residual's spectrum against the noise
  floor, and the model-error model ``|G_err|`` with its 99 % bound against the
  nominal model's ``|G|`` (the bands where the error is significant are shaded);
- ``residual_level.png``: the residual against the operating level (input and
  nominal output), rising and falling apart;
- ``residual_time.png``: the residual against time with its slow part;
- ``overlay.png``: measured, nominal and augmented outputs over held-out data;
- ``nrmse.png``: held-out NRMSE of the nominal model, after each named effect, and
  the noise floor.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from hasel.diagnose.wording import unsettled_start_text
from hasel.errors import BadInputError

__all__ = ["write_report", "verdict_lines", "closest_unnamed", "LEFT_OVER_FLOOR"]


def verdict_lines(v, units: tuple[str, str] = ("", "")) -> list[str]:
    """A short plain-text summary of a verdict (the CLI prints it), every figure from the verdict's JSON."""
    h = v.heldout
    floor = v.noise_floor_nrmse
    lines = [f"held-out NRMSE: nominal {h['nrmse_nominal']:.4f} -> augmented {h['nrmse_augmented']:.4f} "
             f"(noise floor {floor:.4f}; gap shrink {_share(h['gap_shrink'])})"]
    warn = (getattr(v, "model", {}) or {}).get("warning")
    if warn:
        lines.insert(0, f"warning: {warn}")
    tm = getattr(v, "timing_offset", {}) or {}
    lag = tm.get("lag_taken_as_timing") or {}
    if tm.get("original_samples") or lag:
        lines.append(f"timing offset (a sampling convention, not physics): the output lags the zero-order-hold "
                     f"convention by {_signed(tm['original_samples'], 2)} samples ({1e3 * tm['seconds'] + 0.0:+.3g} ms)")
    if lag:
        # the set-up's estimate was biased by an effect; say which lag the re-estimate replaced
        lines.append(f"  re-estimated beside the named effects (set-up: {_signed(tm['set_up_original_samples'], 2)} samples); "
                     f"an output lag of {1e3 * lag['tau_rising_s']:.3g} / {1e3 * lag['tau_falling_s']:.3g} ms "
                     f"(rising / falling), under one sample, is this offset and is not named")
    lines += [unsettled_start_text(n, units[0]) for n in h.get("unsettled_start") or []]
    inp = (getattr(v, "noise", {}) or {}).get("input_noise") or {}
    if inp.get("counted") and inp.get("floor_add", 0.0) > 0.0:
        # errors in variables: without this line a reader sees a floor above the output sensor's noise
        amp = f"{1e3 * inp['sigma_u']:.3g} V" if units[0] in ("", "kV") else f"{inp['sigma_u']:.3g} {units[0]}"
        lines.append(f"noise on the recorded input: {amp} rms measurement noise (its share "
                     f"in the residual {inp['share']:.2g}, t {inp['t']:.3g}); through the model "
                     f"{math.sqrt(inp['residual_var']):.3g} {units[1]} rms, counted in the noise floor")
    test = getattr(v, "test", {}) or {}
    over = h["nrmse_nominal"] / floor if floor > 0 else float("inf")
    if not v.effects:
        if test.get("max_effects") == 0:
            lines.append(f"no effect searched (--max-effects 0); the nominal model is {over:.3g} x the noise floor")
        elif over <= 1.1:
            lines.append("no effect named: the nominal model explains the held-out data down to the noise floor")
        else:
            lines.append(f"no effect named: the nominal model is {over:.3g} x the noise floor, but no augmentation "
                         f"passed the acceptance tests")
    for i, e in enumerate(v.effects, 1):
        lines.append(f"{i}. {e['name']} (NRMSE after {e['nrmse_after']:.4f}): {e['evidence']}")
    left = h["nrmse_augmented"] / floor if floor > 0 else float("inf")
    closest = closest_unnamed(getattr(v, "rounds", []) or [])
    small = closest is not None and not v.effects and set(closest["gates"]) <= SIZE_GATES
    if small:
        # a first effect that passed every test but the size gates: say so, however close to the floor
        lines.append(f"seen, too small to name: {closest['name']} (removes {_share(closest['gain'])} of the validation "
                     "error): " + "; ".join(closest["why"]))
    elif closest is not None and test.get("max_effects") != 0 and left > LEFT_OVER_FLOOR:
        # a gap well above the floor is left: say which explanation came closest and which test it failed
        low = list((getattr(v, "noise", {}) or {}).get("trust_notes", []) or [])
        lines.append(f"left unexplained: {left:.3g} x the noise floor"
                     + (" (a lower bound of the noise here, " + "; ".join(low) + ")" if low else "")
                     + f"; closest unnamed: {closest['name']} (round {closest['round']}, removes "
                       f"{_share(closest['gain'])} of the validation error), not named: " + "; ".join(closest["why"]))
    for nt in getattr(v, "notes", []) or []:
        lines.append(f"form may not fit: {nt['note']}")
    for d in getattr(v, "dropped", []) or []:
        lines.append(f"dropped: {d['name']} ({d['reason']}; final held-out NRMSE {d['final_nrmse_with']:.4f} with "
                     f"it, {d['final_nrmse_without']:.4f} without)")
    for a in getattr(v, "ambiguous", []) or []:
        g = a["gap_removed"]
        lines.append(f"cannot separate: {a['chosen']} (removes {_share(g['chosen'])}) and {a['alternative']} "
                     f"(removes {_share(g['alternative'])}) score alike; to tell them apart: {a['experiment']}")
    if test.get("false_alarm_rate"):
        lines.append(f"test: {test['false_alarm_rate']}")
    return lines


#: The gates that refuse a first effect for its size alone (``DiagnoseOptions.first_over_floor_min``, ``min_gap_nrmse``).
SIZE_GATES = frozenset({"near_floor", "practical_size"})

#: Held-out NRMSE over the noise floor's NRMSE above which the text summary says what came closest to explaining
#: the rest (below it the remainder is within what the floor's estimate itself may be off by).
LEFT_OVER_FLOOR = 2.0


def closest_unnamed(rounds: list[dict]) -> dict | None:
    """The best candidate of the last forward round that failed acceptance, from a verdict's ``rounds``: ``name``
    (the newcomer's family or families beside what the round started from), ``round``, ``gain`` (share of the
    validation residual energy it removed), ``why`` (the failed gates in words) and ``gates`` (their keys); None when
    no forward round failed (selection stopped at the floor or at ``max_effects``)."""
    forward = [r for r in rounds if "candidates" in r and "accepted" in r]
    for i in range(len(forward) - 1, -1, -1):
        r = forward[i]
        if r["accepted"]:
            # a refusal before an accepted round was superseded (a round-1 map refused alone, then
            # accepted with a second effect)
            return None
        if not r.get("failed"):
            continue
        before = next((set(p["best"].split(" + ")) for p in reversed(forward[:i]) if p["accepted"]), set())
        new = [n for n in str(r["best"]).split(" + ") if n not in before]
        return {"name": " + ".join(new) or str(r["best"]), "round": int(r["round"]), "gain": float(r["gain"]),
                "why": [g["why"] for g in r["failed"]], "gates": [g["gate"] for g in r["failed"]]}
    return None


def _signed(x: float, digits: int) -> str:
    """``x`` with its sign and ``digits`` decimals, ``+0.00`` for anything that rounds to zero (never ``-0.00``)."""
    return f"{round(float(x), digits) + 0.0:+.{digits}f}"


def _share(x: float) -> str:
    """A share as a percentage (never a bare "0 %")."""
    x = float(x)
    if abs(x) < 0.005:
        return "less than 0.5 %" if x >= 0 else "a negative share"
    if 0.995 <= x < 1.0:
        # never "100 %" for a share that leaves something: one decimal, rounded down
        return f"{math.floor(1000 * x) / 10:.1f} %"
    return f"{100 * x:.0f} %"


def _fig(path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    """Lay out, write (PNG, 110 dpi) and close one figure."""
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt  # already loaded by _fig

    plt.close(fig)


def write_report(v, directory: str | os.PathLike[str], units: tuple[str, str] = ("", ""),
                 title: str = "Sim-to-real gap diagnosis") -> Path:
    """Write ``report.md`` and PNG figures for verdict ``v`` into ``directory``.

    Parameters
    ----------
    v : Verdict
        From :func:`hasel.diagnose.diagnose`.
    directory : path-like
        Created if needed.
    units : (str, str)
        Input and output units for the labels.
    title : str
        Heading of the report.

    Returns
    -------
    Path
        The markdown file.
    """
    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BadInputError(f"cannot create report directory {d}: {err.strerror or err}") from err
    plt = _fig(d)
    ui, uo = units
    a = v.plots["arrays"]
    where = v.where
    lab_o = f" ({uo})" if uo else ""
    lab_i = f" ({ui})" if ui else ""

    # 1. spectra
    fig, ax = plt.subplots(2, 1, figsize=(8, 7))
    f, p = a["f_hz"], a["psd"]
    m = f > 0
    ax[0].loglog(f[m], p[m], label="residual (measured - nominal)")
    ax[0].axhline(a["noise_psd"], color="k", ls="--", label="noise floor")
    ax[0].axvline(where["frequency"]["excited_band_hz"][1], color="0.6", ls=":", label="top of excited band")
    ax[0].set_ylabel(f"PSD{' (' + uo + '^2/Hz)' if uo else ''}")
    ax[0].set_xlabel("frequency (Hz)")
    ax[0].legend(fontsize=8)
    me = where["frequency"]["model_error"]
    fg = np.asarray(me["f_hz"])
    mag, bound = np.asarray(me["mag"]), np.asarray(me["bound"])
    floor_g = 1e-3 * max(float(np.max(a["gnom"])), float(np.max(mag)), 1e-300)
    ax[1].loglog(fg, np.maximum(a["gnom"], floor_g), "k", label="nominal |G|")
    ax[1].loglog(fg, np.maximum(mag, floor_g), label="model error |G_err|")
    ax[1].fill_between(fg, np.maximum(mag - bound, floor_g), np.maximum(mag + bound, floor_g), alpha=0.3,
                       label="99 % bound")
    ax[1].set_ylim(floor_g, None)
    for lo, hi in me.get("significant_bands_hz", []):
        ax[1].axvspan(lo, hi, color="r", alpha=0.08)
    ax[1].set_xlabel("frequency (Hz)")
    ax[1].set_ylabel(f"gain{' (' + uo + '/' + ui + ')' if ui and uo else ''}")
    ax[1].legend(fontsize=8)
    _save(fig, d / "residual_spectrum.png")

    # 2. level and direction
    r, up = a["r"], a["up"]
    idx = np.linspace(0, r.size - 1, min(r.size, 4000)).astype(int)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for k, (x, name) in enumerate(((a["lvl_u"], f"input level{lab_i}"), (a["y_nom"], f"nominal output{lab_o}"))):
        ax[k].plot(x[idx][up[idx]], r[idx][up[idx]], ".", ms=2, alpha=0.5, label="rising")
        ax[k].plot(x[idx][~up[idx]], r[idx][~up[idx]], ".", ms=2, alpha=0.5, label="falling")
        ax[k].set_xlabel(name)
        ax[k].set_ylabel(f"residual{lab_o}")
        ax[k].legend(fontsize=8)
    _save(fig, d / "residual_level.png")

    # 3. time
    t = a["t"]
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, r, lw=0.5, label="residual")
    w = max(int(where["time"]["slow_window_s"] * v.working_rate_hz), 1)
    slow = np.convolve(np.pad(r, (w // 2, w - w // 2 - 1), mode="edge"), np.ones(w) / w, mode="valid")
    ax.plot(t, slow, "r", label=f"slow part ({where['time']['slow_window_s']:.3g} s average)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"residual{lab_o}")
    ax.legend(fontsize=8)
    _save(fig, d / "residual_time.png")

    # 4. overlay
    ex = v.export
    n = ex["t_s"].size
    seg = slice(0, n)
    gaps = np.flatnonzero(np.diff(ex["t_s"]) > 1.5 / v.working_rate_hz)
    if gaps.size:  # the longest held-out stretch
        edges = np.concatenate([[0], gaps + 1, [n]])
        k = int(np.argmax(np.diff(edges)))
        seg = slice(edges[k], edges[k + 1])
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(ex["t_s"][seg], ex["measured"][seg], "k", lw=1, label="measured")
    ax.plot(ex["t_s"][seg], ex["nominal"][seg], lw=1, label="nominal")
    ax.plot(ex["t_s"][seg], ex["augmented"][seg], "--", lw=1, label="augmented")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"output{lab_o}")
    ax.legend(fontsize=8)
    _save(fig, d / "overlay.png")

    # 5. NRMSE steps
    names = ["nominal"] + [e["name"] for e in v.effects]
    vals = [v.heldout["nrmse_nominal"]] + [e["nrmse_after"] for e in v.effects]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.bar(range(len(vals)), vals)
    ax.axhline(v.noise_floor_nrmse, color="k", ls="--", label="noise floor")
    ax.set_xticks(range(len(vals)), ["nominal"] + [f"+ {x}" for x in names[1:]], rotation=20, fontsize=8)
    ax.set_ylabel("held-out NRMSE")
    ax.legend(fontsize=8)
    _save(fig, d / "nrmse.png")

    lv, dr, tm = where["level"], where["direction"], where["time"]
    md = [f"# {title}", "",
          f"Model: {v.model.get('source', '')}; working rate {v.working_rate_hz:.4g} Hz; "
          f"held-out: {v.heldout['split']} ({v.heldout['n_samples']} samples).", "",
          "## Verdict", ""]
    md += [f"- {line}" for line in verdict_lines(v, units)]
    md += ["", "## How far", "", "| model | held-out NRMSE |", "|---|---|",
           f"| nominal | {v.heldout['nrmse_nominal']:.4f} |"]
    md += [f"| + {e['name']} | {e['nrmse_after']:.4f} |" for e in v.effects]
    md += [f"| noise floor | {v.noise_floor_nrmse:.4f} |", "", "![NRMSE](nrmse.png)", "",
           "## Where", "",
           f"- noise: rms {where['noise_rms']:.4g}{lab_o} ({where['noise_method']}); residual rms "
           f"{where['residual_rms']:.4g}{lab_o} ({where['gap_to_noise_ratio']:.1f} x noise)",
           f"- frequency: a linear model-error model explains {100 * where['frequency']['model_error']['linear_share']:.0f} % "
           f"of the residual; significant in "
           f"{', '.join(f'{x:.3g}-{y:.3g} Hz' for x, y in where['frequency']['model_error']['significant_bands_hz']) or 'no band'}; "
           f"{100 * where['frequency']['share_above_excited_band']:.0f} % of the residual power lies above the excited band",
           f"- level: input-level bins explain {100 * lv['share_input_level']:.0f} %, output-level bins "
           f"{100 * lv['share_output_level']:.0f} %",
           f"- direction: rising minus falling {dr['rising_minus_falling']:+.4g}{lab_o} "
           f"({dr['rising_minus_falling_over_noise']:+.1f} x noise); direction adds {100 * dr['extra_share']:.0f} %",
           f"- time: trend {tm['trend_per_s']:+.3g}{lab_o}/s (t = {tm['trend_t']:+.1f}); slow part "
           f"{100 * tm['slow_share']:.0f} % of the residual variance",
           f"- rate: correlation with the nominal output's rate {where['rate']['corr_residual_vs_nominal_rate']:+.2f}",
           "", "![spectra](residual_spectrum.png)", "", "![level](residual_level.png)", "",
           "![time](residual_time.png)", "", "## Before and after (held-out)", "", "![overlay](overlay.png)", "",
           "## Selection rounds", ""]
    for rd in v.rounds:
        md.append(f"- round {rd['round']}: best {rd.get('best')} "
                  f"({'accepted' if rd.get('accepted') else 'rejected'}; removes {100 * rd.get('gain', 0):.1f} % "
                  f"of the validation residual, z {rd.get('z', 0):.1f})"
                  + ("; refused for its slow part alone, its pairs tried next" if rd.get("retried_as_pairs") else ""))
        md += [f"    - {c['name']}: {c['nrmse_validation']:.4f}" for c in rd["candidates"][:8]]
    md += ["", "## Fitted parameters", ""]
    for e in v.effects:
        md.append(f"- **{e['name']}**: `{_short(e['params'])}`")
    path = d / "report.md"
    path.write_text("\n".join(md) + "\n")
    return path


def _short(params: dict) -> str:
    def fmt(x):
        if isinstance(x, float):
            return f"{x:.4g}"
        if isinstance(x, list):
            return "[" + ", ".join(fmt(y) for y in x[:9]) + (", ..." if len(x) > 9 else "") + "]"
        if isinstance(x, dict):
            return "{" + ", ".join(f"{k}: {fmt(y)}" for k, y in x.items()) + "}"
        return str(x)

    return fmt(params)
