"""Test oracle: readers of the measured datasets from real (non-HASEL) systems in ``shared/datasets/``.

Each reader returns :class:`Dataset` records ``(t_s, u, y)`` with their units and the
effect that the benchmark's literature documents, so that the diagnosis can be
checked on data this project did not generate:

================================ ============================== =========================
reader                           system, input -> output        documented effect
================================ ============================== =========================
:func:`load_piezo`               piezo stack, V -> um, 5 kHz    hysteresis
:func:`load_cascaded_tanks`      two tanks, pump V -> level V,  saturation (overflow at
                                 Ts = 4 s (estimation,          10 V), square-root
                                 validation)                    outflow (static map)
:func:`load_silverbox`           Duffing circuit, V -> V,       cubic stiffness inside the
                                 610.35 Hz                      dynamics
:func:`load_dc_motor`            DC motor, V -> rpm, 100 Hz     affine map (dead zone),
                                 (with/without brake)           dead time; brake: load
================================ ============================== =========================

The directory is ``path`` if given, else ``$HASEL_DATASETS``, else the first
``shared/datasets`` directory beside this checkout or above it (a checkout in
``X/repo`` or ``X/worktrees/repo`` finds ``X/shared/datasets``). Where there is none,
:data:`MISSING` says how to point the tests at it, and the tests that need it skip
(``conftest.py``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hasel.errors import DataFileError

__all__ = ["Dataset", "datasets_dir", "find_datasets", "MISSING", "load_piezo", "load_cascaded_tanks",
           "load_silverbox", "load_dc_motor", "SILVERBOX_RATE_HZ"]

#: Silverbox sampling rate: 10 MHz / 2^14, Hz.
SILVERBOX_RATE_HZ = 1e7 / 2 ** 14


@dataclass(frozen=True)
class Dataset:
    """One input/output record of a real system.

    Attributes
    ----------
    name : str
        Short name.
    t_s, u, y : ndarray
        Times (s), input and output.
    input_unit, output_unit : str
        Units of ``u`` and ``y``.
    documented : tuple of str
        The effect names (VERDICT.json's) that its literature documents.
    description : str
        One line about the system and the record.
    """

    name: str
    t_s: np.ndarray
    u: np.ndarray
    y: np.ndarray
    input_unit: str
    output_unit: str
    documented: tuple[str, ...]
    description: str

    @property
    def rate_hz(self) -> float:
        """Sample rate, Hz."""
        return float(1.0 / np.median(np.diff(self.t_s)))

    def crop(self, t0_s: float, t1_s: float) -> "Dataset":
        """The part with ``t0_s <= t < t1_s``."""
        m = (self.t_s >= t0_s) & (self.t_s < t1_s)
        return Dataset(self.name, self.t_s[m], self.u[m], self.y[m], self.input_unit, self.output_unit,
                       self.documented, self.description)


def find_datasets() -> Path | None:
    """The datasets directory (``$HASEL_DATASETS``, else the first ``shared/datasets`` above this file), or None."""
    env = os.environ.get("HASEL_DATASETS")
    if env:
        return Path(env) if Path(env).is_dir() else None
    for parent in Path(__file__).resolve().parents:
        cand = parent / "shared" / "datasets"
        if cand.is_dir():
            return cand
    return None


#: Why the tests that read the real datasets were skipped.
MISSING = ("the real datasets (shared/datasets) were not found beside or above this checkout, and "
           "HASEL_DATASETS is unset or not a directory: set HASEL_DATASETS=DIR to run the tests that read them")


def datasets_dir(path: str | os.PathLike[str] | None = None) -> Path:
    """The datasets directory: ``path`` if given, else :func:`find_datasets`, else a placeholder
    ``shared/datasets`` that does not exist (reading from it raises, naming it)."""
    if path is not None:
        return Path(path)
    found = find_datasets()
    if found is not None:
        return found
    env = os.environ.get("HASEL_DATASETS")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "datasets"


def _file(name: str, path: str | os.PathLike[str] | None) -> Path:
    p = datasets_dir(path) / name
    if not p.is_file():
        raise DataFileError(f"dataset file not found: {p} (set HASEL_DATASETS or pass path=)")
    return p


def _csv(p: Path, skip_header: int = 0) -> np.ndarray:
    try:
        return np.genfromtxt(p, delimiter=",", skip_header=skip_header)
    except (OSError, ValueError) as err:
        raise DataFileError(f"cannot read {p}: {err}") from err


def load_piezo(path: str | os.PathLike[str] | None = None) -> Dataset:
    """Piezoelectric stack (SmartHysteresis): voltage (V) -> displacement (um), 5 kHz, 10 s.

    0 V until 3.257 s, then a 150 V, 1 Hz sine. Documented: rate-independent
    hysteresis (loop width about 15 % of the 39 um peak-to-peak).
    """
    a = _csv(_file("piezo_hysteresis_v_150_1hz.csv", path))
    if a.ndim != 2 or a.shape[1] < 4:
        raise DataFileError("piezo file: expected columns index, time, displacement, voltage")
    t, y, u = a[:, 1], a[:, 2], a[:, 3]
    ok = np.isfinite(t) & np.isfinite(u) & np.isfinite(y)
    return Dataset("piezo", t[ok], u[ok], y[ok], "V", "um", ("hysteresis",),
                   "piezoelectric stack actuator, 150 V 1 Hz sine (SmartHysteresis)")


def load_cascaded_tanks(path: str | os.PathLike[str] | None = None) -> tuple[Dataset, Dataset]:
    """Cascaded tanks benchmark: pump voltage -> lower tank level sensor (V), Ts = 4 s.

    Returns the estimation and the validation records (1024 samples each).
    Documented: output saturation (overflow clips the level at 10 V) and a
    square-root outflow (a static map that is not a line).
    """
    a = _csv(_file("CTS_dataBenchmark.csv", path), skip_header=1)
    if a.ndim != 2 or a.shape[1] < 5:
        raise DataFileError("tanks file: expected columns uEst, uVal, yEst, yVal, Ts")
    ts = float(a[0, 4])
    n = a.shape[0]
    t = ts * np.arange(n)
    doc = ("saturation", "static_nonlinearity")
    est = Dataset("tanks_estimation", t, a[:, 0], a[:, 2], "V", "V", doc, "cascaded tanks, estimation record")
    val = Dataset("tanks_validation", t, a[:, 1], a[:, 3], "V", "V", doc, "cascaded tanks, validation record")
    return est, val


def load_silverbox(part: str = "multisine", path: str | os.PathLike[str] | None = None) -> Dataset:
    """Silverbox (an electronic Duffing oscillator): V1 -> V2, 610.35 Hz.

    Parameters
    ----------
    part : {"multisine", "noise", "all"}
        The multisine part (from row 40,000), the band-limited noise of rising
        amplitude before it, or everything.
    path : path-like, optional
        Datasets directory.

    Notes
    -----
    Documented: a hardening cubic stiffness inside the dynamics. Among the effect
    names it is a ``static_nonlinearity``: the static force-displacement map of the
    spring is not a line (``k y + k3 y^3``), and the diagnosis's internal
    (stiffness-like, fed back through the dynamics) form of that family is its shape.
    """
    a = _csv(_file("SNLS80mV.csv", path))
    if a.ndim != 2 or a.shape[1] < 2:
        raise DataFileError("Silverbox file: expected two columns, input and output")
    u, y = a[:, 0], a[:, 1]
    t = np.arange(u.size) / SILVERBOX_RATE_HZ
    if part == "multisine":
        sl = slice(40_000, None)
    elif part == "noise":
        sl = slice(0, 40_000)
    elif part == "all":
        sl = slice(None)
    else:
        raise ValueError(f"part must be 'multisine', 'noise' or 'all', got {part!r}")
    return Dataset("silverbox", t[sl], u[sl], y[sl], "V", "V", ("static_nonlinearity",),
                   f"Silverbox electronic Duffing oscillator ({part})")


def load_dc_motor(brake: bool = False, path: str | os.PathLike[str] | None = None) -> Dataset:
    """DC motor voltage step 5 -> 15 V (rt-l): voltage (V) -> speed (rpm), 100 Hz.

    Parameters
    ----------
    brake : bool
        With the eddy-current brake (``rtl_dc_step_5_15_05.mat``) or without
        (``rtl_dc_step_5_15_00.mat``).
    path : path-like, optional
        Datasets directory.

    Notes
    -----
    Documented: an affine static map (intercept about -160 rpm: friction, a dead
    zone: ``static_nonlinearity``) and a dead time of about 0.09 s (``time_delay``);
    the brake lowers the static gain from about 245 to about 151 rpm/V
    (``load_mass``: a changed mechanical load).
    """
    from scipy.io import loadmat

    p = _file("rtl_dc_step_5_15_05.mat" if brake else "rtl_dc_step_5_15_00.mat", path)
    try:
        m = loadmat(p)
        t = np.asarray(m["Zeit"], float).ravel()
        u = np.asarray(m["Motorspannung"], float).ravel()
        y = np.asarray(m["Geschwindigkeit"], float).ravel()
    except (OSError, ValueError, KeyError) as err:
        raise DataFileError(f"cannot read {p}: {err}") from err
    doc = ("load_mass",) if brake else ("static_nonlinearity", "time_delay")
    return Dataset("dc_motor_brake" if brake else "dc_motor", t, u, y, "V", "rpm", doc,
                   f"DC motor, 5 -> 15 V step{' with eddy-current brake' if brake else ''}")
