"""The channel delay (effects/channel_delay.py): H times exp(-i ω τ) in every evaluator."""

import numpy as np

from plate_helpers import PAPER_THETA, strip_setup
from vibid.identify import build_forward_model

STRIP = dict(zip(("D", "nu", "beta"), PAPER_THETA))


def test_delay_turns_the_phase_and_vanishes_at_its_null_value():
    f = np.linspace(7.5, 1500.0, 40)
    plain = build_forward_model(strip_setup(), f, theta0=STRIP)
    delayed = build_forward_model(
        strip_setup(), f, effects=("channel_delay",), theta0=STRIP | {"tau_s": 0.0}
    )
    assert delayed.parameter_names == ("D", "nu", "beta", "tau_s")
    H = np.asarray(plain.afc(PAPER_THETA))
    tau = 2e-5
    th = np.append(PAPER_THETA, tau)
    expected = H * np.exp(-2j * np.pi * f * tau)
    np.testing.assert_allclose(np.asarray(delayed.afc(th)), expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(
        delayed.afc_full(th),
        plain.afc_full(PAPER_THETA) * np.exp(-2j * np.pi * f * tau),
        rtol=1e-12,
    )
    np.testing.assert_array_equal(np.asarray(delayed.afc(np.append(PAPER_THETA, 0.0))), H)


def test_the_delay_derivative_is_exact():
    import jax

    f = np.linspace(7.5, 1500.0, 40)
    fm = build_forward_model(
        strip_setup(), f, effects=("channel_delay",), theta0=STRIP | {"tau_s": 1e-5}
    )
    th = np.append(PAPER_THETA, 1e-5)
    J = np.asarray(jax.jacfwd(fm.afc)(th))[:, 3]
    H = np.asarray(fm.afc(th))
    np.testing.assert_allclose(J, -2j * np.pi * f * H, rtol=1e-12)
