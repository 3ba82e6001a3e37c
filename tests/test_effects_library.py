"""Every effect of the library (identify/effects/), through the term interface: its null
value is the plain model, the reduced JAX model matches the full FE model with it, and its
exact derivative matches the full model's finite difference. A new effect module gets these
checks by adding its typical size below."""

import numpy as np
import pytest

from plate_helpers import PAPER_THETA, strip_setup
from vibid.identify import build_forward_model
from vibid.identify.effects import EFFECTS

STRIP = dict(zip(("D", "nu", "beta"), PAPER_THETA))
F = np.linspace(10.0, 1500.0, 30)
#: A size a lab meets, per effect (issue #11): 20 us delay, 2 % gain, a clamp that lowers
#: the first frequency by about 3 %, 0.3 g of glue, alpha = 0.3, a sensor 2 mm off its
#: declared place across the width; (issue #24) a stand resonance at 660 Hz, a clamp that
#: loses 0.05, a free span 2 mm longer, a sensor's centre of mass 5 mm above the plate;
#: (issue #26) a fixture resonance at 660 Hz of which the clamp carries 5 %.
TYPICAL = {
    "added_mass": {"mass_kg": 3e-4},
    "channel_delay": {"tau_s": 2e-5},
    "clamp_compliance": {"k_theta_N_per_rad": 1.6e4},
    "clamp_loss": {"beta_clamp": 0.05},
    "fixture_resonance": {"f_fixture_hz": 660.0, "q_fixture": 30.0, "a_fixture": 0.05},
    "free_length": {"dL_m": 2e-3},
    "frequency_dependent_loss": {"alpha": 0.3},
    "sensor_gain": {"gain": 1.02},
    "sensor_inertia": {"height_m": 5e-3},
    "sensor_position": {"sensor_dy_m": -2e-3},
    "stand_resonance": {"f_hz_1": 660.0, "q_1": 30.0, "theta_rad_per_m_1": 0.3},
    "transverse_shear": None,  # no parameter of its own on an isotropic plate
}
#: What an effect goes with (its values as above): a clamp's own loss needs the clamp.
REQUIRES = {"clamp_loss": "clamp_compliance"}


def test_every_effect_has_a_typical_size_and_declares_its_parameters():
    assert set(TYPICAL) == set(EFFECTS)
    for term in EFFECTS.values():
        assert term.meaning and term.meaning != term.name  # the report's words for it
        if TYPICAL[term.name] is None:
            assert term.parameters == ()
            continue
        assert set(term.names) == set(TYPICAL[term.name])
        for q in term.parameters:
            assert q.unit and q.bounds is not None
        # a null value for every parameter, but a resonance's frequency and quality factor,
        # which have none once its size is null (a clamp's loss: the plate's)
        nulls = term.null_values(STRIP)
        assert nulls and set(term.names) - set(nulls) <= {
            "f_hz_1",
            "q_1",
            "f_fixture_hz",
            "q_fixture",
        }


@pytest.fixture(scope="module")
def plain():
    fm = build_forward_model(strip_setup(), F, theta0=STRIP)
    return fm, fm.afc_full(PAPER_THETA)


@pytest.mark.parametrize("name", sorted(TYPICAL))
def test_effect_in_every_evaluator(name, plain):
    import jax

    if TYPICAL[name] is None:
        return _parameterless(name, plain)
    needs = REQUIRES.get(name)
    extra = TYPICAL[needs] if needs else {}
    own = TYPICAL[name]
    values = STRIP | extra | own
    fm = build_forward_model(
        strip_setup(), F, effects=((needs,) if needs else ()) + (name,), theta0=values
    )
    names = fm.parameter_names
    th = np.array([values[n] for n in names])
    H, Hf = np.asarray(fm.afc(th)), fm.afc_full(th)
    scale = np.abs(Hf).max()
    # the model it extends: the plain one, or the one with what it goes with
    if needs:
        base = build_forward_model(strip_setup(), F, effects=(needs,), theta0=STRIP | extra)
        reference = base.afc_full(np.array([(STRIP | extra)[n] for n in base.parameter_names]))
    else:
        reference = plain[1]
    # reduced against full, and the effect is far above that difference
    assert np.abs(H - Hf).max() < 1e-6 * scale
    assert np.abs(Hf - reference).max() > 1e-3 * scale
    # the null value is the model it extends (a rigid clamp: k = 1e11 N/rad, compliance 2e-9)
    term = next(t for t in fm.param.effects if t.name == name)
    nulls = term.null_values(values)
    at_null = values | {n: (1e11 if np.isinf(v) else v) for n, v in nulls.items()}
    H0 = fm.afc_full(np.array([at_null[n] for n in names]))
    infinite = any(np.isinf(v) for v in nulls.values())
    assert np.abs(H0 - reference).max() < (1e-6 if infinite else 1e-12) * scale
    # the exact derivative along each of its parameters: against a central difference of
    # the reduced model itself, and of the full model (which differs by the reduced model's
    # error, larger in relative terms for a derivative that is small away from the
    # resonances)
    J = np.asarray(jax.jacfwd(fm.afc)(th))
    for n, value in own.items():
        i = names.index(n)
        # central differences with steps h and 2h, Richardson-extrapolated (truncation
        # O(h⁴)), so that h can be large enough for round-off (~1e-13 of H near a peak, over
        # h) to stay small: one plain difference with h = 1e-5 left round-off at 1e-6 of the
        # moved sensor's derivative, and one with 1e-4 truncation at 1e-6 of the clamp's
        h = 1e-4 * abs(value)
        step = np.zeros(len(names))
        step[i] = h

        def central(k):
            return (np.asarray(fm.afc(th + k * step)) - np.asarray(fm.afc(th - k * step))) / (
                2 * k * h
            )

        Jr = (4 * central(1) - central(2)) / 3
        Jfd = (fm.afc_full(th + step) - fm.afc_full(th - step)) / (2 * h)
        assert np.abs(J[:, i] - Jr).max() < 1e-6 * np.abs(Jr).max(), n
        assert np.abs(J[:, i] - Jfd).max() < 1e-2 * np.abs(Jfd).max(), n


def _parameterless(name, plain):
    """A term without a parameter: reduced against full, a visible effect, and the exact
    derivative along the material's parameters (which set its coefficients)."""
    import jax

    fm = build_forward_model(strip_setup(), F, effects=(name,), theta0=STRIP)
    H, Hf = np.asarray(fm.afc(PAPER_THETA)), fm.afc_full(PAPER_THETA)
    scale = np.abs(Hf).max()
    assert np.abs(H - Hf).max() < 1e-6 * scale
    assert np.abs(Hf - plain[1]).max() > 1e-3 * scale
    J = np.asarray(jax.jacfwd(fm.afc)(PAPER_THETA))[:, 1]  # along nu
    h = 1e-6
    step = np.array([0, h, 0])
    Jr = (np.asarray(fm.afc(PAPER_THETA + step)) - np.asarray(fm.afc(PAPER_THETA - step))) / (2 * h)
    assert np.abs(J - Jr).max() < 1e-6 * np.abs(Jr).max()
