"""Figures and a markdown report of an identification (matplotlib, Agg backend).

- :func:`plot_bode`: magnitude and phase of every operating point (the estimate the
  fit used, with its two-standard-deviation band), the fitted model and, for a
  kV -> mm model (or on request), the paper's P(s) for reference;
- :func:`plot_coherence`: the Welch coherence of every operating point;
- :func:`plot_static_map`: mean output against operating point, and the fitted curve;
- :func:`plot_validation`: measured and simulated output on held-out data;
- :func:`write_report`: ``report.md`` plus those PNGs in one directory.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hasel.errors import BadInputError
from hasel.ident.identify import IdentResult

__all__ = ["plot_bode", "plot_coherence", "plot_static_map", "plot_validation", "write_report"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | Path) -> Path:
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=110)
    except OSError as err:
        raise BadInputError(f"cannot write {p}: {err.strerror or err}") from err
    finally:
        _plt().close(fig)
    return p


def _label(r: IdentResult, v: float) -> str:
    return f"{v:.3g} {r.input_unit}".strip()


def plot_bode(result: IdentResult, path: str | Path, *, paper: bool | None = None) -> Path:
    """Bode plot PNG of the data, the fit and (optionally) the paper's P(s).

    Parameters
    ----------
    result : IdentResult
        From :func:`~hasel.ident.identify.identify`.
    path : str or Path
        PNG file to write.
    paper : bool, optional
        Draw the paper's P(s) (17); default: when the model maps kV to mm.

    Returns
    -------
    Path
    """
    plt = _plt()
    from hasel.paper import plant_tf

    show_paper = (result.input_unit == "kV" and result.output_unit == "mm") if paper is None else paper
    fig, (am, ap) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    cmap = plt.get_cmap("viridis")
    n = len(result.points)
    seen: set[str] = set()
    for i, pt in enumerate(result.points):
        fr = pt.fft if result.estimator == "periodic_fft" else pt.h1
        c = cmap(i / max(n - 1, 1))
        lo, hi = fr.bounds_db(2.0)
        label = _label(result, pt.mean_input)
        am.semilogx(fr.f_hz, fr.magnitude_db, ".", ms=2, color=c, label=None if label in seen else label)
        seen.add(label)
        ok = np.isfinite(lo) & np.isfinite(hi)
        am.fill_between(fr.f_hz[ok], lo[ok], hi[ok], color=c, alpha=0.15, lw=0)
        ph = np.degrees(np.angle(fr.H))
        pb = fr.phase_bound_deg(2.0)
        ap.semilogx(fr.f_hz, ph, ".", ms=2, color=c)
        okp = np.isfinite(pb) & (pb < 90)
        ap.fill_between(fr.f_hz[okp], (ph - pb)[okp], (ph + pb)[okp], color=c, alpha=0.15, lw=0)
    f = np.geomspace(max(result.fit.band_hz[0] / 2, 1e-4), result.fit.band_hz[1] * 1.5, 600)
    G = result.fit.model.freqresp(f)
    am.semilogx(f, 20 * np.log10(np.abs(G)), "k-", lw=1.8,
                label=f"fit ({result.fit.nz} zeros / {result.fit.np} poles)")
    ap.semilogx(f, np.degrees(np.angle(G)), "k-", lw=1.8)
    if show_paper:
        num, den = plant_tf()
        P = np.polyval(num, 2j * np.pi * f) / np.polyval(den, 2j * np.pi * f)
        am.semilogx(f, 20 * np.log10(np.abs(P)), "r--", lw=1.2, label="paper P(s) (17)")
        ap.semilogx(f, np.degrees(np.angle(P)), "r--", lw=1.2)
    gdb = 20 * np.log10(np.abs(G))
    am.set_ylim(max(float(np.min(gdb)), float(np.max(gdb)) - 80.0) - 10.0, float(np.max(gdb)) + 10.0)
    ap.set_ylim(-200, 200)
    am.set_ylabel(f"magnitude (dB, {result.gain_unit})")
    ap.set_ylabel("phase (deg, wrapped)")
    ap.set_xlabel("frequency (Hz)")
    am.grid(True, which="both", alpha=0.3)
    ap.grid(True, which="both", alpha=0.3)
    am.legend(fontsize=7, ncol=2, loc="lower left")
    method = "FFT ratio over whole periods" if result.estimator == "periodic_fft" else "Welch H1"
    am.set_title(f"{result.output_name} / {result.input_name}: {method}, 2-sigma bands", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def plot_coherence(result: IdentResult, path: str | Path) -> Path:
    """PNG of the Welch magnitude-squared coherence of every operating point."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 3.5))
    cmap = plt.get_cmap("viridis")
    n = len(result.points)
    for i, pt in enumerate(result.points):
        ax.semilogx(pt.h1.f_hz, pt.h1.coherence, "-", lw=1, color=cmap(i / max(n - 1, 1)),
                    label=_label(result, pt.mean_input))
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("coherence")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=3, loc="lower left")
    ax.set_title("magnitude-squared coherence (Welch, Hann, 50 % overlap)")
    fig.tight_layout()
    return _save(fig, path)


def plot_static_map(result: IdentResult, path: str | Path) -> Path:
    """PNG of the static map: mean output per operating point and the fitted polynomial."""
    plt = _plt()
    sm = result.static_map
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.plot(sm.offsets, sm.means, "o", label="operating points")
    span = np.ptp(sm.offsets) if sm.offsets.size > 1 else 1.0
    v = np.linspace(sm.offsets.min() - 0.05 * span, sm.offsets.max() + 0.05 * span, 200)
    ax.plot(v, sm(v), "k-", label=f"fit, degree {sm.degree}")
    ax.set_xlabel(f"operating point {result.input_name} ({result.input_unit or '-'})")
    ax.set_ylabel(f"mean {result.output_name} ({result.output_unit or '-'})")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("static map h_s")
    fig.tight_layout()
    return _save(fig, path)


def plot_validation(result: IdentResult, path: str | Path, *, max_points: int = 3) -> Path:
    """PNG of measured and simulated output on the held-out part of up to ``max_points`` operating points."""
    plt = _plt()
    pts = [p for p in result.points if p.y_holdout.size]
    if not pts:
        raise BadInputError("no held-out data to plot (holdout_fraction is 0)")
    pick = [pts[int(round(i))] for i in np.linspace(0, len(pts) - 1, min(max_points, len(pts)))]
    fig, axes = plt.subplots(len(pick), 1, figsize=(8, 2.4 * len(pick)), squeeze=False)
    for ax, p in zip(axes[:, 0], pick):
        ax.plot(p.t_holdout_s, p.y_holdout, "-", lw=0.8, label="measured")
        ax.plot(p.t_holdout_s, p.y_hat_holdout, "--", lw=0.8, label="model")
        ax.set_ylabel(f"{result.output_unit or '-'}")
        ax.set_title(f"{_label(result, p.mean_input)}: fit {p.compare_fit_pct:.1f} %", fontsize=9)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    return _save(fig, path)


def _fmt(v: float | None, spec: str = ".4g") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def write_report(result: IdentResult, directory: str | Path) -> Path:
    """Write ``report.md`` and its figures into ``directory``; return the markdown's path.

    Parameters
    ----------
    result : IdentResult
        From :func:`~hasel.ident.identify.identify`.
    directory : str or Path
        Created if missing.

    Returns
    -------
    Path
    """
    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BadInputError(f"cannot create the report directory {d}: {err.strerror or err}") from err
    plot_bode(result, d / "bode.png")
    plot_coherence(result, d / "coherence.png")
    plot_static_map(result, d / "static_map.png")
    has_val = result.validation is not None
    if has_val:
        plot_validation(result, d / "validation.png")
    m = result.fit.model
    gu = result.gain_unit
    L = [f"# Identification of {result.output_name} / {result.input_name}", ""]
    L += [f"- {line}" for line in result.summary_lines()]
    L += ["", "## Model", "",
          f"G(s) = num(s) / den(s){' * exp(-s tau)' if m.delay_s > 0 else ''}, s in rad/s, {gu}:", "",
          f"- num = {[float(f'{c:.6g}') for c in m.num]}",
          f"- den = {[float(f'{c:.6g}') for c in m.den]}",
          f"- poles (rad/s): {', '.join(f'{p:.4g}' for p in m.poles)}",
          f"- zeros (rad/s): {', '.join(f'{z:.4g}' for z in m.zeros) or 'none'}",
          f"- gain k = {m.gain:.6g}; G(0) = {m.dc_gain:.6g} {gu}"
          + (f"; delay {m.delay_s:.6g} s" if m.delay_s > 0 else ""), "",
          f"Fitted on {result.fit_data.f_hz.size} frequencies, {result.fit.band_hz[0]:.3g}-"
          f"{result.fit.band_hz[1]:.3g} Hz ({'FFT ratio over whole periods, log-binned' if result.estimator == 'periodic_fft' else 'Welch H1'}); "
          f"weighted cost {result.fit.cost:.3g} (about 1 = at the noise level); "
          f"rms error {result.fit.rms_db:.3g} dB / {result.fit.rms_deg:.3g} deg, "
          f"largest {result.fit.max_db:.3g} dB / {result.fit.max_deg:.3g} deg.", "",
          "Order selection (held-out frequencies):", "",
          "| zeros | poles | fit cost | held-out cost |", "|---|---|---|---|"]
    L += [f"| {s.nz} | {s.np} | {s.fit_cost:.3g} | {s.heldout_cost:.3g} |" for s in result.fit.scores]
    if result.input_unit == "kV" and result.output_unit == "mm":
        pc = result.paper_comparison()
        L += ["", f"Against the paper's P(s) (17) over {pc['band_hz'][0]:g}-{pc['band_hz'][1]:g} Hz: largest "
              f"difference {pc['max_db']:.3g} dB and {pc['max_deg']:.3g} deg; static gain ratio "
              f"{pc['static_gain_ratio']:.4f}. (If the input is the commanded voltage, the amplifier's "
              "500 Hz filter is part of the identified path and adds about 2 deg of lag at 15 Hz.)"]
    L += ["", "![Bode](bode.png)", "", "![Coherence](coherence.png)", "",
          "## Operating points", "",
          f"| offset ({result.input_unit or '-'}) | from (s) | to (s) | mean output ({result.output_unit or '-'}) "
          "| period (s) | held-out fit (%) |", "|---|---|---|---|---|---|"]
    for p in result.points:
        L.append(f"| {p.mean_input:.4g} | {p.segment.start_s:.4g} | {p.segment.end_s:.4g} | {p.mean_output:.4g} | "
                 f"{_fmt(p.period_s)} | {_fmt(p.compare_fit_pct, '.2f')} |")
    if result.skipped:
        L += ["", "Skipped: " + "; ".join(f"{s.start_s:.4g}-{s.end_s:.4g} s at {s.level:.3g} ({s.reason})"
                                          for s in result.skipped[:20])
              + (" ..." if len(result.skipped) > 20 else "")]
    sm = result.static_map
    L += ["", "## Static map", "",
          f"Degree {sm.degree} (leave-one-level-out), coefficients (descending powers): "
          f"{[float(f'{c:.6g}') for c in sm.coefficients]}; rms residual {sm.rmse:.3g} {result.output_unit}.", "",
          "![Static map](static_map.png)", "",
          "## Does the dynamics depend on the operating point?", "", result.dependence.summary, ""]
    if result.dependence.per_offset:
        L += ["| offset | reduced chi2 | mean deviation (dB) | mean deviation (deg) |", "|---|---|---|---|"]
        L += [f"| {q['offset']:.4g} | {q['reduced_chi2']:.3g} | {q['mean_dev_db']:.3g} | {q['mean_dev_deg']:.3g} |"
              for q in result.dependence.per_offset]
    if has_val:
        v = result.validation
        L += ["", "## Validation on held-out data", "",
              f"The last {v.holdout_fraction:.0%} of every operating point was kept out of the estimation. "
              f"Simulating h_s(v_s) + G(s)(u - v_s) there gives a pooled fit of {v.compare_fit_pct:.2f} % "
              f"(NRMSE {v.nrmse:.4g}; MATLAB compare: 100 (1 - NRMSE)).", "", "![Validation](validation.png)"]
    if result.notes:
        L += ["", "## Notes", ""] + [f"- {n}" for n in result.notes]
    path = d / "report.md"
    try:
        path.write_text("\n".join(L) + "\n")
    except OSError as err:
        raise BadInputError(f"cannot write {path}: {err.strerror or err}") from err
    return path
