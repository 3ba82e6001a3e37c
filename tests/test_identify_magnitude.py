"""Magnitude-only identification (``--magnitude-only``): the fit sees |H| alone.

References independent of vibid's plate model: the Ritz plate of ``ritz_toy`` (the
Monte Carlo of the magnitude fit's spread against its Fisher standard deviation, and of how
much the phase was worth), and the paper's strip from the full FE model on a finer mesh
than the fit's (``loop_data``) with an undeclared delay between the channels, which |H|
cannot see.
"""

import json

import numpy as np
import pytest

from ritz_toy import RitzPlateModel
from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.fit.trust_region import gauss_newton
from vibid.setup_model import example_setup

TRUE = np.array([17.97, 0.286, 0.003])
F_HZ = np.linspace(10.0, 600.0, 120)
#: Monte Carlo draws: the sample std of N draws is within 3/√(2N) ≈ 12 % of the true one
#: at three sigma.
DRAWS = 300


@pytest.fixture(scope="module")
def toy():
    setup = example_setup()
    fm = RitzPlateModel(setup, F_HZ)
    H0 = np.asarray(fm.afc(TRUE))
    sd = 0.005 * np.abs(H0) + 1e-3
    return setup, fm, H0, sd


def _noisy(H0, sd, rng):
    return H0 + sd * (rng.standard_normal(H0.size) + 1j * rng.standard_normal(H0.size))


def test_chi2_is_on_the_magnitudes_with_n_minus_p_degrees_of_freedom(toy):
    setup, fm, H0, sd = toy
    H = _noisy(H0, sd, np.random.default_rng(5)) * np.exp(-2j * np.pi * F_HZ * 3e-5)
    r = identify(
        setup,
        Measurement(F_HZ, H, sd, magnitude=True),
        ModelChoice(forward_model=fm),
        SearchOptions(method="local", start=TRUE, refresh=False),
    )
    assert r.converged and r.magnitude
    assert r.dof == F_HZ.size - 3
    by_hand = np.sum(((np.abs(np.asarray(fm.afc(r.values))) - np.abs(H)) / sd) ** 2)
    assert r.chi2 == pytest.approx(by_hand, rel=1e-9)
    # the delay turns the phase but not |H|: the fit does not see it
    assert np.all(np.abs(r.values - TRUE) < 3 * r.std)
    assert 0.6 < r.chi2_reduced < 1.5
    # the complex fit of the same points and weights knows more: no std shrinks
    assert all(v >= 1.0 for v in r.magnitude_only_std_ratio.values())


def test_monte_carlo_spread_is_the_magnitude_fits_fisher_std(toy):
    """The spread of magnitude-only estimates over noise draws is the reported std, and
    the ratio of the two fits' spreads is the reported magnitude_only_std_ratio."""
    setup, fm, H0, sd = toy
    reported = identify(
        setup,
        Measurement(F_HZ, H0, sd, magnitude=True),
        ModelChoice(forward_model=fm),
        SearchOptions(method="local", start=TRUE, refresh=False),
    )
    space = ParameterSpace.from_bounds(fm.parameter_names, setup.identification.bounds)
    problems = {
        mag: LeastSquaresProblem(fm, fit_data(F_HZ, H0, sd, magnitude=mag), space)
        for mag in (True, False)
    }
    rng = np.random.default_rng(11)
    est = {True: [], False: []}
    for _ in range(DRAWS):
        H = _noisy(H0, sd, rng)
        for mag, p in problems.items():
            run = gauss_newton(p.with_data(H, sd), space.to_u(TRUE))
            assert run.converged, run.message
            est[mag].append(run.theta)
    spread = {mag: np.std(np.array(e), axis=0, ddof=1) for mag, e in est.items()}
    np.testing.assert_allclose(spread[True] / reported.std, 1.0, atol=0.12)
    ratio = np.array([reported.magnitude_only_std_ratio[n] for n in fm.parameter_names])
    np.testing.assert_allclose(spread[True] / spread[False] / ratio, 1.0, atol=0.15)
    # on this plate the phase carries most of what the AFC says about the loss factor
    # (the magnitude alone sees it in the peak heights only), little of D and nu
    assert ratio[2] > 2.5 and ratio[0] < 1.2 and ratio[1] < 1.2
    # unbiased at this noise level: the mean within 4 standard errors of the truth
    mean = np.mean(np.array(est[True]), axis=0)
    assert np.all(np.abs(mean - TRUE) < 4 * spread[True] / np.sqrt(DRAWS))


@pytest.mark.slow
def test_an_undeclared_delay_needs_no_effect_on_the_magnitude(tmp_path):
    """`vibid identify --afc … --magnitude-only` on a strip whose channels are 20 µs apart:
    the closed loop adds nothing (a delay cannot be seen in |H| and is not tried) and D, ν,
    β come back within 3 std; the complex fit of the same data does not fit them."""
    from afc_files import write_afc_csv
    from loop_data import TRUTH, F, data, declared_fit, strip_on
    from vibid.cli import main
    from vibid.identify.fit.noise import explains

    H, sd = data({"tau_s": 2e-5}, 7)
    csv = write_afc_csv(tmp_path / "afc.csv", F, H, sd)
    setup = tmp_path / "setup.json"
    setup.write_text(strip_on().to_json())
    out = tmp_path / "report.json"
    assert (
        main(
            [
                "identify",
                "--afc",
                str(csv),
                "--setup",
                str(setup),
                "--magnitude-only",
                "--json",
                str(out),
                "--no-progress",
                "--restarts",
                "1",
            ]
        )
        == 0
    )
    doc = json.loads(out.read_text())
    ident = doc["identification"]
    assert ident["data"] == "magnitude"
    assert ident["dof"] == F.size - 3
    assert doc["effects"] == [] and len(doc["loop"]["stages"]) == 1
    assert doc["loop"]["unexplained_residual"] is False
    assert all("channel_delay" != r["candidate"] for rnd in doc["loop"]["rounds"] for r in rnd)
    for name, truth in TRUTH.items():
        p = doc["parameters"][name]
        assert abs(p["value"] - truth) < 3 * p["std"], (name, p)
    ratio = ident["magnitude_only_std_ratio"]
    assert set(ratio) == set(TRUTH) and all(v >= 1.0 for v in ratio.values())
    # the phase holds the delay: the declared complex fit leaves a residual
    assert explains(declared_fit({"tau_s": 2e-5}, 7)) is False
