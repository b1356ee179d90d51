"""Offline identification of single-input single-output logs (ROS-free).

The paper's procedure, made quantitative: split a log into operating points (DC
offsets), estimate each one's frequency response (the paper's FFT ratio, and a Welch
H1 with coherence and uncertainty), fit the static map ``h_s``, test whether the
dynamics depend on the operating point, fit a stable continuous transfer function
(frequency-domain start, output-error refinement on the whole log, order chosen on
held-out blocks), validate it in the time domain on held-out data and check it
(:mod:`~hasel.ident.checks`: ``usable`` and the reasons). Any sample rate and units
work; kV -> mm for the actuator.

- :func:`identify` -> :class:`IdentResult` (``.to_model_json()`` gives MODEL.json);
- building blocks: :mod:`~hasel.ident.segments`, :mod:`~hasel.ident.freqresp`,
  :mod:`~hasel.ident.staticmap`, :mod:`~hasel.ident.dependence`,
  :mod:`~hasel.ident.tffit`, :mod:`~hasel.ident.timefit`, :mod:`~hasel.ident.validation`,
  :mod:`~hasel.ident.checks`; :mod:`~hasel.ident.varpro`, the output-error fit by variable
  projection on timefit's ARX regression and modal simulation (no start model needed; the
  diagnosis uses it when it is given no nominal model);
- figures and report: :mod:`hasel.ident.report`; the command: :mod:`hasel.ident.cli`.
"""
from hasel.ident.checks import ModelCheck, check_model, check_model_json
from hasel.ident.dependence import DependenceTest, offset_dependence, residual_dependence
from hasel.ident.freqresp import FreqResp, detect_period, excited_band, fft_ratio, log_bin, pool, welch_h1, welch_plan
from hasel.ident.identify import IdentOptions, IdentResult, OperatingPoint, Validation, identify, unit_from_name
from hasel.ident.segments import Segment, SegmentSearch, find_segments, segments_from_markers
from hasel.ident.staticmap import StaticMap, fit_static_map
from hasel.ident.tffit import TFFit, TFModel, fit_tf, fit_tf_order
from hasel.ident.validation import compare_fit, nrmse, simulate

__all__ = [
    "identify", "IdentOptions", "IdentResult", "OperatingPoint", "Validation", "unit_from_name",
    "FreqResp", "fft_ratio", "welch_h1", "welch_plan", "pool", "log_bin", "excited_band", "detect_period",
    "Segment", "SegmentSearch", "find_segments", "segments_from_markers",
    "StaticMap", "fit_static_map", "DependenceTest", "offset_dependence",
    "TFModel", "TFFit", "fit_tf", "fit_tf_order", "compare_fit", "nrmse", "simulate",
    "ModelCheck", "check_model", "check_model_json", "residual_dependence",
]
