"""A reduced basis that cannot reach the band is an error, not an endless fit (issue 62).

One AFC point at 126 kHz (above a DAQ's Nyquist frequency, where the reader now refuses
it) made the paper's strip's basis 96 modes wide, to 114 kHz only, and the identification
ran until killed.
"""

import re

import numpy as np
import pytest

from vibid.errors import VibidError
from vibid.identify.model.plate import build_forward_model
from vibid.setup_model import example_setup

THETA0 = {"D": 17.97, "nu": 0.286, "beta": 0.003}


def test_a_band_beyond_the_basis_is_refused_in_one_line():
    setup = example_setup()
    freqs = np.append(np.linspace(20.0, 1500.0, 40), 126491.0)
    with pytest.raises(VibidError) as err:
        build_forward_model(setup, freqs, theta0=THETA0)
    msg = str(err.value)
    assert "\n" not in msg and "126491 Hz" in msg and "narrower band" in msg
    reached = float(re.search(r"reach only (\d+) Hz", msg)[1])
    assert 1500.0 < reached < 126491.0


def test_the_papers_band_is_reached():
    fm = build_forward_model(example_setup(), np.linspace(20.0, 1500.0, 40), theta0=THETA0)
    assert fm.basis.f_top_hz >= 1500.0
