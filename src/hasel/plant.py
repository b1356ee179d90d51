"""The simulated actuator: amplifier, its 500 Hz analog filter and the paper's P(s).

Signal chain (paper Fig. 1/5): the controller's command in kV is what the DAC and the
5 kV/V amplifier deliver (the DAC volts are command/5); the amplified voltage passes a
2nd-order 500 Hz analog low-pass and reaches the actuator,
whose stroke follows P(s) (17). The command is piecewise constant at the simulator's
rate (10 kHz), so both paths, command -> applied voltage and command -> stroke, are
discretised exactly by zero-order hold.

Every actuator model obeys :class:`Actuator`, so a variant with unmodelled effects
(the "truth" plant) drops in wherever the nominal one is used.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from hasel import paper
from hasel.lti import SosFilter, critical2_analog, zoh_sos
from hasel.validate import positive

__all__ = ["Actuator", "ActuatorSamples", "NominalConfig", "NominalActuator", "amplifier_sos", "amplifier_filter_tf"]


@dataclass(frozen=True)
class ActuatorSamples:
    """Samples of one run of an actuator model, all at its rate.

    Sample n is taken at the end of the n-th command sample, i.e. at t_0 + (n+1)/rate.

    Attributes
    ----------
    applied_kv : ndarray
        Voltage on the actuator after the amplifier's filter, kV.
    stroke_mm : ndarray
        True stroke of the actuator, mm.
    """

    applied_kv: np.ndarray
    stroke_mm: np.ndarray


@runtime_checkable
class Actuator(Protocol):
    """What the simulator needs of an actuator model (nominal or with effects)."""

    rate_hz: float

    def reset(self, command_kv: float = 0.0) -> None:
        """Put the model at rest with ``command_kv`` applied forever."""

    def run(self, command_kv: np.ndarray) -> ActuatorSamples:
        """Advance by ``len(command_kv)`` samples of the commanded voltage (kV)."""


@dataclass(frozen=True)
class NominalConfig:
    """Parameters of the nominal actuator (defaults: the paper's).

    Attributes
    ----------
    num, den : tuple of float
        P(s), kV -> mm, descending powers of s (rad/s).
    rate_hz : float
        Simulation rate, Hz (10 kHz: the paper's sampling rate).
    amp_filter_hz : float
        -3 dB frequency of the amplifier's 2nd-order output filter, Hz.
    """

    num: tuple[float, ...] = field(default_factory=lambda: tuple(paper.plant_tf()[0]))
    den: tuple[float, ...] = field(default_factory=lambda: tuple(paper.plant_tf()[1]))
    rate_hz: float = paper.PLANT_RATE_HZ
    amp_filter_hz: float = paper.AMP_FILTER_HZ


def amplifier_sos(cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """ZOH model of the amplifier's analog low-pass (unity gain in kV), as SOS."""
    num, den = amplifier_filter_tf(cutoff_hz)
    return zoh_sos(num, den, 1.0 / positive("rate_hz", rate_hz), output="end")


def amplifier_filter_tf(cutoff_hz: float = paper.AMP_FILTER_HZ) -> tuple[np.ndarray, np.ndarray]:
    """The high-voltage output filter, analog: (num, den), unity gain in kV.

    The paper gives only "2nd-order, 500 Hz". At kilovolts such a filter is a passive
    RC-RC ladder (an active filter cannot sit behind a 5 kV/V amplifier), whose poles
    are real; it is modelled with a double real pole, -3 dB at 500 Hz. That choice
    matters for safety: a Butterworth (Q = 0.707) filter would overshoot a 9 kV
    command step to 9.4 kV on the actuator, while this one never leaves the range of
    the commands it received.
    """
    return critical2_analog(cutoff_hz)


class NominalActuator:
    """The paper's linear model: command kV -> 500 Hz filter -> P(s) -> stroke mm.

    Parameters
    ----------
    config : NominalConfig, optional
        Model parameters; the paper's by default.
    """

    def __init__(self, config: NominalConfig | None = None) -> None:
        self.config = config or NominalConfig()
        self.rate_hz = float(self.config.rate_hz)
        dt = 1.0 / self.rate_hz
        amp_num, amp_den = amplifier_filter_tf(self.config.amp_filter_hz)
        chain_num = np.polymul(amp_num, self.config.num)
        chain_den = np.polymul(amp_den, self.config.den)
        # outputs at the end of each held sample: a block's last sample is the next tick
        self._amp = SosFilter(zoh_sos(amp_num, amp_den, dt, output="end"))
        self._chain = SosFilter(zoh_sos(chain_num, chain_den, dt, output="end"))
        self._held: dict[int, np.ndarray] = {}

    def reset(self, command_kv: float = 0.0) -> None:
        """At rest with ``command_kv`` (kV) applied forever."""
        self._amp.reset(command_kv)
        self._chain.reset(command_kv)

    def run(self, command_kv: np.ndarray) -> ActuatorSamples:
        """Advance by the samples of ``command_kv`` (kV, at ``rate_hz``)."""
        u = np.asarray(command_kv, dtype=float)
        if u.size > 1 and u[0] == u[-1] and np.all(u == u[0]):  # a held command: the fast exact path
            return self.run_held(float(u[0]), u.size)
        return ActuatorSamples(applied_kv=self._amp.run(u), stroke_mm=self._chain.run(u))

    def run_held(self, command_kv: float, n: int) -> ActuatorSamples:
        """Advance by ``n`` samples of one command held constant (kV): a loop period.

        Both filters' outputs and next states are one linear map of their states and
        the command, applied as a single matrix product (the same numbers as
        :meth:`run` to rounding; the simulator calls this once per 200 Hz tick).
        """
        W = self._held.get(n)
        if W is None:
            W = self._held[n] = self._held_map(n)
        amp, chain = self._amp, self._chain
        ka = amp.zi.size
        x = np.concatenate((amp.zi.ravel(), chain.zi.ravel(), (command_kv,)))
        r = W @ x
        amp.zi = r[2 * n:2 * n + ka].reshape(amp.zi.shape)
        chain.zi = r[2 * n + ka:].reshape(chain.zi.shape)
        return ActuatorSamples(applied_kv=r[:n], stroke_mm=r[n:2 * n])

    def _held_map(self, n: int) -> np.ndarray:
        """[applied; stroke; amp state'; chain state'] = W @ [amp state; chain state; u]."""
        Ya, ya, Za, za = self._amp._block_maps(n)
        Yc, yc, Zc, zc = self._chain._block_maps(n)
        ka, kc = Za.shape[0], Zc.shape[0]
        W = np.zeros((2 * n + ka + kc, ka + kc + 1))
        W[:n, :ka], W[:n, -1] = Ya, ya
        W[n:2 * n, ka:ka + kc], W[n:2 * n, -1] = Yc, yc
        W[2 * n:2 * n + ka, :ka], W[2 * n:2 * n + ka, -1] = Za, za
        W[2 * n + ka:, ka:ka + kc], W[2 * n + ka:, -1] = Zc, zc
        return W
