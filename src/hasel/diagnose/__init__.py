"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far it shrinks.

- :func:`diagnose` (:mod:`hasel.diagnose.core`): any SISO log and a nominal model
  (or one identified first) -> :class:`Verdict` (VERDICT.json, ``shared/interfaces.md``).
- :mod:`hasel.diagnose.augment`: the generic parametric augmentation of each effect.
- :mod:`hasel.diagnose.where`: the residual localised in frequency, time, level,
  direction and amplitude.
- :mod:`hasel.diagnose.report`: markdown report with PNGs; :mod:`hasel.diagnose.cli`:
  ``hasel diagnose``; :mod:`hasel_bench.blind`: the blind withheld check.
"""
from hasel.diagnose.core import DiagnoseOptions, Verdict, diagnose

__all__ = ["diagnose", "DiagnoseOptions", "Verdict"]
