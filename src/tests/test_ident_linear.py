"""The one linear identifier's shared parts: the modal ZOH basis, the ARX regression, the variable-projection mode."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from hasel.errors import BadInputError
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import arx_lstsq, modal_basis, simulate_zoh
from hasel.ident.varpro import vp_fit

# a real pole and a lightly damped pair (rad/s), with residues
POLES = np.array([-3.0 + 0j, -2.0 + 15.0j])
RES = np.array([4.0 + 0j, 1.5 - 2.0j])


def _model() -> TFModel:
    full = np.array([POLES[0], POLES[1], np.conj(POLES[1])])
    den = np.real(np.poly(full))
    num = np.real(RES[0] * np.poly(full[1:]) + RES[1] * np.poly([full[0], full[2]])
                  + np.conj(RES[1]) * np.poly(full[:2]))
    return TFModel(num=num, den=den)


@pytest.mark.parametrize("shift", [0.0, 0.35, -0.4])
def test_the_modal_basis_adds_up_to_the_simulation_from_rest(shift):
    rng = np.random.default_rng(2)
    rate = 200.0
    u = 1.3 + np.repeat(rng.uniform(-1, 1, 50), 20)   # at rest with u[0] = 1.3 + ... before the log
    cols = modal_basis(POLES, u, rate, shift=shift)
    assert len(cols) == 3
    # 1/(s - p) for the real pole; Re and Im of 1/(s - p) for the pair: the model is r0 c0 + 2 Re(r1 (c1 + j c2))
    y = RES[0].real * cols[0] + 2.0 * (RES[1].real * cols[1] - RES[1].imag * cols[2])
    m = _model()
    ref = simulate_zoh(m, u - u[0], rate, shift=shift) + m.dc_gain * u[0]
    # simulate_zoh holds its last sample when shifted; the basis has the next one
    np.testing.assert_allclose(y[:-1], ref[:-1], rtol=1e-10, atol=1e-10 * np.max(np.abs(ref)))
    assert np.max(np.abs(ref)) > 1.0


def test_arx_regression_recovers_a_discrete_model_over_masked_segments():
    rng = np.random.default_rng(4)
    a, b, c = [1.0, -1.2, 0.5], [0.0, 0.3, 0.1], 0.25
    segs = []
    for n in (400, 700):
        u = rng.standard_normal(n)
        y = signal.lfilter(b, a, u) + c / np.sum(a)   # a constant c in the difference equation
        mask = rng.uniform(size=n) > 0.3
        segs.append((u, y, mask))
    theta = arx_lstsq(segs, 2, constant=True)
    np.testing.assert_allclose(theta, [-1.2, 0.5, 0.3, 0.1, 0.25], atol=1e-9)
    assert arx_lstsq(segs, 2, min_rows=2000) is None   # fewer rows than asked for


def test_variable_projection_recovers_poles_and_gain_across_segments_with_one_offset():
    rng = np.random.default_rng(8)
    rate = 100.0
    m = TFModel(num=np.array([0.0, 30.0]), den=np.array([1.0, 4.0, 25.0]))
    segs = []
    for level in (0.0, 2.0):
        u = level + np.repeat(rng.uniform(-1, 1, 30), 100)
        y = simulate_zoh(m, u - u[0], rate) + m.dc_gain * u[0] + 0.4 + 1e-3 * rng.standard_normal(u.size)
        segs.append((u, y, np.ones(u.size, bool)))
    num, den, info = vp_fit(segs, rate, span_s=30.0, f_excited_hz=5.0, max_order=3)
    assert info["order"] == 2 and info["nrmse_train"] < 0.01
    np.testing.assert_allclose(np.sort_complex(np.roots(den)), np.sort_complex(np.roots(m.den)), rtol=0.01)
    assert num[-1] / den[-1] == pytest.approx(1.2, rel=0.01)   # the 0.4 offset is not in the model


@pytest.mark.parametrize("segs,kw,msg", [
    ([(np.ones(50), np.ones(50), np.zeros(50, bool))], {}, "no training samples"),
    ([(np.ones(50), np.r_[np.ones(49), np.nan], np.ones(50, bool))], {}, "non-finite"),
    ([(np.ones(50), np.ones(40), np.ones(50, bool))], {}, "one length"),
    ([(np.arange(50.0), np.ones(50), np.ones(50, bool))], {}, "does not vary"),
    ([(np.arange(50.0), np.ones(50), np.ones(50, bool))], {"rate_hz": 0.0}, "positive rate"),
    ([(np.arange(50.0), np.ones(50), np.ones(50, bool))], {"shift": 2.0}, "within one sample"),
])
def test_unusable_input_is_one_line_of_bad_input(segs, kw, msg):
    args = {"rate_hz": 100.0, "span_s": 0.5, "f_excited_hz": 10.0, **kw}
    with pytest.raises(BadInputError, match=msg) as err:
        vp_fit(segs, args.pop("rate_hz"), **args)
    assert "\n" not in str(err.value)
