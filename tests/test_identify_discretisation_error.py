"""The discretisation part of the reported std (issue 62), against data from a converged
model: the paper's steel strip (D 17.97 N m, nu 0.286, beta 0.003) on the loop tests' 60
steps to 1500 Hz, its AFC the full FE model on the "fine" mesh (60 x 12 cells, 6 corner
levels: the virtual stand's specimen, tests/loop_data.py), whose first six frequencies lie
within 1e-8 of a mesh with 90 x 18 cells and 8 corner levels (the fit's default: 7e-7,
benchmarks/disc_error.py); vibid's Argyris spans scikit-fem's own Argyris space
(tests/test_plate_reference.py).

The data are noise-free and weighted as a stand ten times more precise than the issue's
sessions (std 3e-6 |H| + 1e-6, nu's noise part about 1e-7): the estimate's offset from
the truth is then the fit model's discretisation error, about seven times its noise part,
which the std must cover on its own.
"""

import numpy as np
import pytest

from loop_data import TRUTH, F, fine_afc, strip_on
from vibid.identify import build_forward_model
from vibid.identify.fit import Measurement, SearchOptions, identify

THETA = np.array([TRUTH[n] for n in ("D", "nu", "beta")])


@pytest.fixture(scope="module")
def converged():
    """(H, std): the converged AFC and the precise stand's std."""
    H = fine_afc({})
    return H, 3e-6 * np.abs(H) + 1e-6


def test_the_extrapolated_error_meets_a_converged_mesh(converged):
    """At the truth, the model's error H_inf - H against the converged AFC's H_fine - H
    (full models both, relative to |H| at each point): within 9 % (measured 7.1 %; the
    extrapolation's order 5.9 from the meshes with 20 x 4, 30 x 6 and 45 x 9 cells), where
    the finer step alone misses 11.5 % (its mesh's own error, about a tenth of the
    model's, and the part of the difference that the extrapolation's factor does not
    reach: the steps differ in shape as well)."""
    H_conv, _ = converged
    fm = build_forward_model(strip_on(), F, theta0=TRUTH)
    err = fm.discretisation_error(THETA)
    truth = H_conv - np.asarray(fm.afc_full(THETA))  # the default mesh's own error

    def off(d):
        return np.linalg.norm((d - truth) / np.abs(H_conv)) / np.linalg.norm(truth / np.abs(H_conv))

    assert 4.0 < err.extrapolation.order < 8.0 and not err.extrapolation.limited
    assert off(err.d) < 0.09
    assert off(err.finer) > 0.1  # what the estimate missed before
    assert err.meshes == (
        "argyris 20x4 +3 corner levels",
        "argyris 30x6 +4 corner levels",
        "argyris 45x9 +5 corner levels",
    )


@pytest.mark.parametrize("magnitude", [False, True], ids=["complex", "magnitude"])
def test_truth_within_two_std_on_data_from_a_converged_model(converged, magnitude):
    """Every declared constant within 2 reported std of the truth (measured 0.2 to 0.95
    std), the discretisation part carrying it: the noise part alone would leave nu more
    than 5 std out (6.9 complex, 5.8 |H|), and the part the report gives agrees with the
    estimate's real offset within 25 % (complex: D 4.0e-6 for an offset of 3.7e-6, nu
    6.7e-7 for 6.4e-7; |H|: D 1.4e-6 for 1.2e-6, nu 5.7e-7 for 5.4e-7; the finer step
    alone gave 5 to 9 % less than the extrapolation, nu 5 % below its offset)."""
    H, sd = converged
    r = identify(
        strip_on(),
        Measurement(F, H, sd, magnitude=magnitude),
        search=SearchOptions(method="local", start=TRUTH),
    )
    assert r.converged, r.message
    bias = np.abs(r.model_error_bias)
    noise_std = np.sqrt(np.diag(r.covariance) - bias**2)
    for i, name in enumerate(r.parameter_names):
        offset = r.values[i] - TRUTH[name]
        assert abs(offset) < 2 * r.std[i], (name, r.values[i], r.std[i])
        if name in ("D", "nu"):
            assert bias[i] == pytest.approx(abs(offset), rel=0.25), (name, offset, bias[i])
    i = r.parameter_names.index("nu")
    assert abs(r.values[i] - TRUTH["nu"]) > 5 * noise_std[i]
