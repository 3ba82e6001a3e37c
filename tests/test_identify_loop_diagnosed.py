"""The closed loop choosing from the residual's diagnosis, on sessions vibid did not
simulate (tests/beam_sessions.py: the exact beam of tests/beam_reference.py), with every
default candidate in play: a stand resonance is named at its frequency, started from the
pole the diagnosis found; alone and together with an elastic clamp; an elastic clamp
alone; a frictional clamp is named with its own loss; clean beam data are left
untouched."""

import dataclasses

import beam_sessions as bs
import pytest

from vibid.identify.loop import close_loop
from vibid.report import build_report

RESONANCE = {"f_hz_1": 660.0, "q_1": 30.0, "theta_rad_per_m_1": 0.3}


def _nu_boxed(setup):
    """``setup`` with the declared box of nu the lab's knowledge of its material (near 0,
    as the beam's): an elastic clamp softens every mode of a beam, which a free nu mimics
    (the declared fit bends nu to 0.19 and the clamp's score drops below its test)."""
    return dataclasses.replace(setup, identification=dataclasses.replace(
        setup.identification, bounds=dict(setup.identification.bounds) | {"nu": (-0.05, 0.05)}))


def test_clean_beam_data_get_nothing_added():
    H, sd = bs.data({}, seed=3)
    loop = close_loop(bs.setup(), bs.F, H, sd, seed=0, restarts=1)
    assert loop.effects == () and not loop.unexplained_residual
    assert loop.stages[0].diagnosis is not None and loop.stages[0].diagnosis.features == ()


@pytest.mark.slow
def test_a_stand_resonance_is_named_at_its_frequency_among_every_candidate():
    H, sd = bs.data(RESONANCE, seed=0)
    loop = close_loop(bs.setup(), bs.F, H, sd, seed=0, restarts=1)
    poles = loop.stages[0].diagnosis.extra_poles()
    assert poles and abs(poles[0].f_hz - 660.0) < 25.0  # within a step of the grid
    assert loop.effects == ("stand_resonance",)
    assert not loop.unexplained_residual
    bs.named_with_truth(loop, RESONANCE)
    doc = build_report(loop.final, session_id="beam-stand", loop=loop, setup=bs.setup())
    first = doc["loop"]["diagnosis"][0]
    assert any(f["kind"] == "extra_pole" and abs(f["f_hz"] - 660) < 25 for f in first)


@pytest.mark.slow
@pytest.mark.parametrize("k_theta", [
    8e3,
    pytest.param(1.6e4, marks=pytest.mark.xfail(strict=True, reason=(
        "known defect of the loop (issue #25): the clamped beam's first resonance, 74.6 Hz "
        "(half-power bandwidth 0.22 Hz), lies 0.4 Hz from the 75 Hz step, which then "
        "decides the fit; the declared fit bends nu to 0.19, outside its box; the clamp's "
        "refit stays at its null (k_theta infinite) and a sensor gain, then an added mass "
        "of 4.6 mg, are named instead (chi2_red 2.91 -> 0.80)"))),
])
def test_an_elastic_clamp_alone_is_named(k_theta):
    """A root spring that loses as the plate does: the clamp alone, k_theta and the
    plate's D and beta within 3 std. At 8e3 N/rad the declared fit bends nu to -0.26 and
    the clamp is named in round 0 (k_theta 8029 +- 35); at 1.6e4 N/rad (the stiffness the
    tests with a stand resonance or a clamp loss use) it is not (the mark): a defect on the
    code before and after this test was written."""
    effects = {"k_theta_N_per_rad": k_theta}
    H, sd = bs.data(effects, seed=1)
    loop = close_loop(_nu_boxed(bs.setup()), bs.F, H, sd, seed=0, restarts=1)
    assert not loop.stages[0].fits_noise
    assert loop.effects == ("clamp_compliance",), loop.effects
    assert not loop.unexplained_residual
    bs.named_with_truth(loop, effects, but=("nu",))
    assert abs(loop.final.parameters["nu"]) < bs.NU_ON_BEAM_DATA


@pytest.mark.slow
def test_a_stand_resonance_and_an_elastic_clamp_are_both_named():
    effects = RESONANCE | {"k_theta_N_per_rad": 1.6e4}
    H, sd = bs.data(effects, seed=1)
    loop = close_loop(_nu_boxed(bs.setup()), bs.F, H, sd, seed=0, restarts=1)
    assert set(loop.effects) == {"stand_resonance", "clamp_compliance"}, loop.effects
    assert not loop.unexplained_residual
    bs.named_with_truth(loop, effects, but=("nu",))
    assert abs(loop.final.parameters["nu"]) < bs.NU_ON_BEAM_DATA


@pytest.mark.slow
def test_a_frictional_clamp_is_named_with_its_own_loss():
    """A clamp spring that loses 100 times what the plate does: the clamp, then its loss;
    the plate's beta comes back (the declared fit had bent it to 4.6 times the truth)."""
    effects = {"k_theta_N_per_rad": 1.6e4, "beta_clamp": 0.3}
    H, sd = bs.data(effects, seed=1)
    loop = close_loop(_nu_boxed(bs.setup()), bs.F, H, sd, seed=0, restarts=1)
    assert loop.effects == ("clamp_compliance", "clamp_loss")
    assert not loop.unexplained_residual
    assert loop.stages[0].result.parameters["beta"] > 3 * bs.TRUTH["beta"]
    bs.named_with_truth(loop, effects, but=("nu",))
    assert abs(loop.final.parameters["nu"]) < bs.NU_ON_BEAM_DATA
