"""``transverse_shear`` against Timoshenko's beam, the independent reference: on a narrow
strip with nu = 0 (a plate that bends like a beam) the relative frequency shift that the
shear field adds to the Kirchhoff plate equals the closed-form Timoshenko/Rayleigh cantilever
ratio (Huang 1961): the field is Timoshenko's theory on a beam (the forced response and a
sensor's: tests/test_transverse_shear_vs_timoshenko.py)."""

import numpy as np
import pytest

import huang_cantilever as huang
from plate_helpers import plate_setup
from vibid.identify.model.materials import flexural_rigidity
from vibid.identify.model.plate import natural_frequencies

# the real titanium strip of shared/data/real-titanium (h/L = 0.03), no sensor mass
L, B, H, RHO, E, KAPPA = 0.0996, 0.020, 0.003, 4550.0, 110e9, 5 / 6


def cantilever(shear: bool, n: int = 2):
    """The strip's clamped-free frequencies, Hz (Huang 1961: tests/huang_cantilever.py)."""
    return huang.frequencies_hz(n, L=L, B=B, H=H, rho=RHO, E=E, kappa=KAPPA, shear=shear)


@pytest.mark.slow
def test_shear_shift_matches_timoshenko_on_a_narrow_strip():
    setup = plate_setup(L, B, H, density=RHO, mass_kg=0.0, radius_m=0.002)
    p = {"D": flexural_rigidity(E, 0.0, H), "nu": 0.0, "beta": 0.0}
    f_k, _ = natural_frequencies(setup, p, 4)
    f_s, _ = natural_frequencies(setup, p, 4, effects=("transverse_shear",))
    bending = [0, 1]  # the third mode of the strip is its first torsion
    plate_shift = (f_s / f_k - 1)[bending]
    beam_shift = cantilever(True) / cantilever(False) - 1
    # the shift itself: -4.2e-4 and -2.9e-3 (far above the data's resolution)
    assert beam_shift[0] == pytest.approx(-4.21e-4, rel=0.01)
    assert beam_shift[1] == pytest.approx(-2.92e-3, rel=0.01)
    # measured 5e-11 and 3e-12 (the first-order inertia it replaced: 2e-7 and 3e-6)
    assert abs(plate_shift[0] - beam_shift[0]) < 1e-9
    assert abs(plate_shift[1] - beam_shift[1]) < 1e-9
    # the Kirchhoff plate itself is the Rayleigh beam (the mesh converged well below that)
    assert np.max(np.abs(f_k[bending] / cantilever(False) - 1)) < 1e-6


def test_orthotropic_form_equals_isotropic_form_at_the_isotropic_shear_modulus():
    """D11/(kappa G13 h) with G13 = E/2(1+nu) is h²/(6 kappa (1-nu)): both forms give the same
    frequencies for an isotropic material written as orthotropic."""
    setup = plate_setup(L, B, H, density=RHO, mass_kg=0.0, radius_m=0.002)
    nu = 0.33
    D = flexural_rigidity(E, nu, H)
    iso, _ = natural_frequencies(
        setup, {"D": D, "nu": nu, "beta": 0.0}, 3, effects=("transverse_shear",)
    )
    ortho = {
        "D11": D,
        "D12": nu * D,
        "D22": D,
        "D66": (1 - nu) * D / 2,
        "beta": 0.0,
        "G13_Pa": E / (2 * (1 + nu)),
    }
    f_o, _ = natural_frequencies(setup, ortho, 3)
    np.testing.assert_allclose(f_o, iso, rtol=1e-10)


def test_the_shear_field_shares_no_model_with_a_stretched_mesh_or_a_moved_sensor():
    """Their matrices move mass on the bending deflection alone; the field's coupling is the
    declared mass: such a model is refused with one line, and the loop does not try it."""
    from vibid.errors import VibidError
    from vibid.identify.loop.candidates import all_candidates
    from vibid.identify.model.assembly import Geometry, model_matrices
    from vibid.identify.model.mesh import discretisation
    from vibid.identify.model.plate import plate_model

    setup = plate_setup(L, B, H, density=RHO, mass_kg=1e-3, radius_m=0.002)
    g = Geometry.from_setup(setup)
    both = plate_model("isotropic", effects=("sensor_position", "transverse_shear"))
    with pytest.raises(VibidError, match="cannot share a model"):
        model_matrices(g, discretisation(g), both.effects)
    shear = {c.name: c for c in all_candidates()}
    with_position = plate_model("isotropic", effects=("sensor_position",))
    with_shear = plate_model("isotropic", effects=("transverse_shear",))
    assert not shear["transverse_shear"].applies(with_position)
    assert not shear["free_length"].applies(with_shear)
    assert shear["clamp_compliance"].applies(with_shear)
