"""The declared plate as one object (:class:`vibid.identify.model.plate.Plate`): what the
loop asks of a fitted stage (its modes, their Q, those in the band) answered by one call,
equal to the separate questions, and Q checked against the proportional-loss limit."""

import numpy as np

from vibid.identify.model.plate import Plate, natural_frequencies, natural_mode_heights
from vibid.setup_model import example_setup

PARAMS = {"D": 17.97, "nu": 0.286, "beta": 0.003}


def test_the_plates_modes_are_the_separate_questions_answered_at_once():
    setup = example_setup()
    modes = Plate(setup).modes(PARAMS, 8)
    f_hz, decay = natural_frequencies(setup, PARAMS, 8)
    f2, height = natural_mode_heights(setup, PARAMS, 8)
    np.testing.assert_allclose(modes.frequency_hz, f_hz, rtol=1e-12)
    np.testing.assert_allclose(modes.decay_1_per_s, decay, rtol=1e-12)
    np.testing.assert_allclose(modes.height, height, rtol=1e-9)
    # the real modes, in the same order: √λ against √((1 + iβ) λ)'s real part
    np.testing.assert_allclose(f2 * np.sqrt(1 + 1j * PARAMS["beta"]).real, f_hz, rtol=1e-9)


def test_q_is_one_over_the_loss_factor_for_proportional_loss():
    """``Λ = (1 + iβ) λ``: ``√Λ = √λ √(1 + iβ) = 2π f + iγ``, so ``Q = π f / γ =
    Re √(1+iβ) / (2 Im √(1+iβ))`` for every mode, whatever its shape (about 1/β)."""
    modes = Plate(example_setup()).modes(PARAMS, 6)
    root = np.sqrt(1 + 1j * PARAMS["beta"])
    np.testing.assert_allclose(modes.q, root.real / (2 * root.imag), rtol=1e-9)
    assert abs(modes.q[0] * PARAMS["beta"] - 1) < 1e-5


def test_the_modes_in_a_band_count_the_closed_interval():
    modes = Plate(example_setup()).modes(PARAMS, 6)
    f = modes.frequency_hz
    assert modes.in_band(0.0, np.inf) == 6
    assert modes.in_band(f[1], f[3]) == 3  # both ends inside
    assert modes.in_band(f[1] * (1 + 1e-9), f[3] * (1 - 1e-9)) == 1
