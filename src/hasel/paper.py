"""Numbers of the HASEL paper (identification and control of foldable HASELs).

Source: ``shared/reference/paper-numbers.md``. Units: kV in, mm out, seconds, Hz.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "P_GAIN", "P_NOTCH_RAD_S", "plant_zpk", "plant_tf", "C_PLUS", "C_MINUS",
    "LOOP_PERIOD_S", "PLANT_RATE_HZ", "AMP_GAIN_KV_PER_V", "AMP_FILTER_HZ",
    "FILTER_CUTOFF_HZ", "V_MAX_KV", "LASER_MM_PER_V", "ADC_BITS", "ADC_FULL_SCALE_V",
    "TIMER_TRIGGER_HZ", "TIMER_DUTY", "TABLE_II", "CHIRP_PROTOCOL", "STEP_SEQUENCE_MM",
]

#: K of P(s) (17), mm/kV scaled so that P(0) is the static gain below.
P_GAIN = 10.836
#: Anti-resonance (notch) of P(s), rad/s (19.45 Hz).
P_NOTCH_RAD_S = 122.2


def plant_zpk() -> tuple[np.ndarray, np.ndarray, float]:
    """Zeros (rad/s), poles (rad/s) and gain K of the identified P(s) (17), kV -> mm."""
    w = P_NOTCH_RAD_S
    zeros = np.array([-50.27, -62.83, -628.3, 1j * w, -1j * w])
    # (s^2 + 230 s + w^2)^2: a double pair of complex poles
    pair = np.roots([1.0, 230.0, w * w])
    poles = np.concatenate([[-18.85, -56.55], pair, pair])
    return zeros, poles, P_GAIN


def plant_tf() -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of P(s) (17) in descending powers of s (kV -> mm)."""
    w2 = P_NOTCH_RAD_S**2
    num = P_GAIN * np.polymul(np.polymul(np.polymul([1, 50.27], [1, 62.83]), [1, 628.3]), [1, 0, w2])
    quad = np.array([1.0, 230.0, w2])
    den = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(quad, quad))
    return np.asarray(num, float), np.asarray(den, float)


#: Dual-mode PID gains (14)-(15): (kp [kV/mm], ki [kV/(mm s)], kd [kV s/mm]).
C_PLUS = (1.15, 25.0, 1.74e-5)
C_MINUS = (1.25, 26.0, 3.2e-5)

LOOP_PERIOD_S = 0.005          # 200 Hz control loop
PLANT_RATE_HZ = 10_000.0       # identification sampling rate, also the simulator's step
AMP_GAIN_KV_PER_V = 5.0        # high-voltage amplifier gain, kV per DAC volt
AMP_FILTER_HZ = 500.0          # analog 2nd-order low-pass after the amplifier
FILTER_CUTOFF_HZ = 40.0        # digital 2nd-order low-pass on the strain sensor
V_MAX_KV = 9.0                 # dielectric breakdown above 9 kV: hard ceiling
LASER_MM_PER_V = 3.0           # laser displacement sensor output scale
ADC_BITS = 12
ADC_FULL_SCALE_V = 3.3
TIMER_TRIGGER_HZ = 4500.0      # LMC555 trigger frequency
TIMER_DUTY = 0.899             # trigger duty cycle
STEP_SEQUENCE_MM = (2.0, 4.0, 6.0, 4.0, 2.0)

#: Table II as agreed by the paper's table and text: {(mode, test): (rise_s, settling_s, overshoot_pct)}.
TABLE_II: dict[tuple[str, str], tuple[float | None, float | None, float | None]] = {
    ("activation", "open loop"): (0.13, None, 0.0),
    ("activation", "laser"): (0.026, 0.185, 6.0),
    ("activation", "strain"): (0.029, 0.14, 16.0),
    ("activation", "strain, 25.5 g load"): (0.025, 0.23, 0.0),
    ("relaxation", "open loop"): (0.275, None, 0.0),
    ("relaxation", "laser"): (0.12, None, None),
    ("relaxation", "strain"): (0.071, 0.67, 5.5),
    ("relaxation", "strain, 25.5 g load"): (0.12, 0.17, 0.0),
}

#: The chirp identification protocol, Table I.
CHIRP_PROTOCOL = {
    "offsets_kv": (2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
    "amplitude_kv": 1.0,
    "f0_hz": 0.001,
    "f1_hz": 20.0,
    "duration_s": 20.0,
    "repeats": 3,
    "rate_hz": 10_000.0,
    "precondition_kv": -1.0,
}
