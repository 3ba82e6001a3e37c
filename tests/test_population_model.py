"""The population benchmark's generator (tests/population_model.py, a Ritz plate that shares
nothing with vibid) against independent references: the exact Rayleigh beam of
tests/beam_reference.py for a strip with nu = 0 and a centred sensor (frequencies, a clamp
spring, a rocking base, a point mass), the clamp spring's rigid limit, the orthotropic
moduli's isotropic special case, the two solution paths against each other, and the Ritz
order's convergence in the band."""

import math

import numpy as np
import pytest

import beam_reference as beam
import population_model as pm

L, W, H_M, RHO = 0.100, 0.020, 0.001, 7920.0
D = 17.97
#: no sensor: the beam and the plate agree exactly (a bare strip with nu = 0)
BARE = pm.Plate(L, W, H_M, RHO, 0.09, W / 2, 0.0, 1e-3)
NU0 = {"D": D, "nu": 0.0, "beta": 0.003}
ORDER = (16, 5)


def _beam_kw(**kw):
    return {
        "L": L,
        "EI": D * W * (1 + 0.003j),
        "rhoA": RHO * H_M * W,
        "rhoI": RHO * H_M**3 / 12 * W,
        "x_s": 0.09,
    } | kw


def test_cantilever_strip_frequencies_are_the_rayleigh_beams():
    f_plate = pm.natural_frequencies_hz(BARE, NU0, n=4, order=ORDER)
    kw = _beam_kw(EI=D * W)
    f_beam = beam.natural_frequencies_hz(3, **kw)
    # the bending modes (the third plate mode is the first torsion mode)
    bending = f_plate[[0, 1, 3]]
    np.testing.assert_allclose(bending, f_beam, rtol=1e-7)
    # and Euler-Bernoulli's (rotary inertia off) differ from Rayleigh's: the term matters
    eb = beam.natural_frequencies_hz(1, **(kw | {"rhoI": 0.0}))
    assert abs(eb[0] / f_beam[0] - 1) > 1e-7


def test_afc_of_the_strip_is_the_exact_beams():
    f = np.linspace(20.0, 2000.0, 40)
    H = pm.afc(f, BARE, NU0, order=ORDER)
    Hb = beam.afc(2 * math.pi * f, **_beam_kw())
    assert np.max(np.abs(H - Hb) / np.abs(Hb)) < 1e-6


def test_clamp_spring_against_the_beams_root_spring():
    f = np.linspace(20.0, 2000.0, 40)
    k = 300.0  # N m/rad per metre
    for beta_c in (0.0, 0.05):
        H = pm.afc(f, BARE, NU0, {"k_theta_N_per_rad": k, "beta_clamp": beta_c}, order=ORDER)
        Hb = beam.afc(2 * math.pi * f, **_beam_kw(k_root=k * W * (1 + 1j * beta_c)))
        assert np.max(np.abs(H - Hb) / np.abs(Hb)) < 1e-6
    # the clamp spring's loss factor defaults to the plate's
    H = pm.afc(f, BARE, NU0, {"k_theta_N_per_rad": k}, order=ORDER)
    Hb = beam.afc(2 * math.pi * f, **_beam_kw(k_root=k * W * (1 + 0.003j)))
    assert np.max(np.abs(H - Hb) / np.abs(Hb)) < 1e-6


def test_clamp_spring_rigid_limit_is_the_clamped_basis():
    plate = pm.Plate(L, W, H_M, RHO, 0.09, 0.013, 1e-3, 2e-3)
    mat = {"D": D, "nu": 0.3, "beta": 0.003}
    # the elastic basis x P_m (m < 20) held at zero slope spans x^2 P_m (m < 19)
    rigid = pm.natural_frequencies_hz(plate, mat, n=5, order=(19, 7))
    errors = []
    for k in (1e5, 1e6, 1e7):  # beyond 1e8 the stiff spring's rounding shows
        el = pm.natural_frequencies_hz(plate, mat, {"k_theta_N_per_rad": k}, n=5, order=(20, 7))
        errors.append(np.max(np.abs(el / rigid - 1)))
    assert errors[0] > 8 * errors[1] > 64 * errors[2]  # as 1 / k
    assert errors[2] < 5e-5
    assert np.all(el < rigid * (1 + 1e-9))  # a spring only softens


def test_base_rotation_is_the_exact_beams():
    f = np.linspace(20.0, 2000.0, 40)
    eff = {"f_hz_1": 700.0, "q_1": 20.0, "theta_rad_per_m_1": 0.3}
    H = pm.afc(f, BARE, NU0, eff, order=ORDER)
    theta = 0.3 / (1 - (f / 700.0) ** 2 + 1j * f / (700.0 * 20.0))
    Hb = beam.afc(2 * math.pi * f, **_beam_kw(), rotation_per_translation=theta)
    assert np.max(np.abs(H - Hb) / np.abs(Hb)) < 1e-6
    # the rotation alone, at low frequency, is the rigid field x_s theta
    lo = pm.afc(np.array([1e-3]), BARE, NU0, eff, order=ORDER)[0]
    assert abs(lo - (1 + 0.09 * 0.3)) < 1e-6


def test_point_mass_and_rotary_inertia_are_the_beams_body():
    f = np.linspace(20.0, 2000.0, 40)
    m, e = 5e-4, 4e-3
    # an added mass is a point mass at the sensor's centre (the report format's
    # added_mass): the beam's body of that mass and no rotary inertia, to within 1/200 of
    # what the mass does (measured 5e-4: a point on a plate against a section of a beam)
    small = pm.Plate(L, W, H_M, RHO, 0.09, W / 2, 1e-12, 1e-3)
    H = pm.afc(f, small, NU0, {"mass_kg": m}, order=(24, 5))
    Hb = beam.afc(2 * math.pi * f, **_beam_kw(m=m, J=0.0))
    Hb0 = beam.afc(2 * math.pi * f, **_beam_kw())
    assert np.max(np.abs(H - Hb) / np.abs(Hb)) < 5e-3 * np.max(np.abs(Hb0 - Hb) / np.abs(Hb))
    # a tall sensor: its rotary inertia m ((h/2 + e)^2 - (h/2)^2), spread over the disc,
    # against the beam's rigid body with that J (the disc bends with the strip under it:
    # a model-form difference, 10 times smaller than what the height itself does)
    sensor = pm.Plate(L, W, H_M, RHO, 0.09, W / 2, 1e-3, 1e-3)
    H = pm.afc(f, sensor, NU0, {"height_m": e}, order=(24, 5))
    J = 1e-3 * ((H_M / 2 + e) ** 2 - (H_M / 2) ** 2) + 1e-3 * H_M**2 / 12
    kw = _beam_kw(m=1e-3, J=J)
    Hb = beam.afc(2 * math.pi * f, **kw)
    Hb0 = beam.afc(2 * math.pi * f, **(kw | {"J": 1e-3 * H_M**2 / 12}))
    err = np.max(np.abs(H - Hb) / np.abs(Hb))
    assert err < 0.1 * np.max(np.abs(Hb0 - Hb) / np.abs(Hb))


def test_free_length_is_a_longer_beam():
    f = np.linspace(20.0, 2000.0, 30)
    H = pm.afc(f, BARE, NU0, {"dL_m": 0.002}, order=ORDER)
    Hb = beam.afc(2 * math.pi * f, **_beam_kw(L=L + 0.002, x_s=0.092))
    assert np.max(np.abs(H - Hb) / np.abs(Hb)) < 1e-6


def test_orthotropic_with_isotropic_moduli_is_the_isotropic_plate():
    plate = pm.Plate(0.15, 0.1, 0.002, 2700.0, 0.13, 0.07, 2e-3, 3e-3)
    D0, nu = 52.0, 0.33
    iso = {"D": D0, "nu": nu, "beta": 0.002}
    ortho = {"D11": D0, "D22": D0, "D12": nu * D0, "D66": (1 - nu) * D0 / 2, "beta": 0.002}
    f = np.linspace(10.0, 800.0, 50)
    np.testing.assert_allclose(
        pm.afc(f, plate, ortho, order=(10, 8)), pm.afc(f, plate, iso, order=(10, 8)), rtol=1e-12
    )
    # and D22 matters: a softer D22 lowers frequencies
    soft = ortho | {"D22": D0 / 4}
    assert np.all(
        pm.natural_frequencies_hz(plate, soft, n=4, order=(10, 8))
        <= pm.natural_frequencies_hz(plate, iso, n=4, order=(10, 8)) * (1 + 1e-12)
    )


def test_direct_and_modal_paths_agree():
    """A uniform loss goes through the real modes, alpha = 0 through the direct solve."""
    plate = pm.Plate(L, W, H_M, RHO, 0.09, 0.013, 1e-3, 2e-3)
    mat = {"D": D, "nu": 0.3, "beta": 0.003}
    f = np.linspace(20.0, 2500.0, 40)
    a = pm.afc(f, plate, mat, {"k_theta_N_per_rad": 500.0}, order=(14, 6))
    b = pm.afc(
        f,
        plate,
        mat,
        {"k_theta_N_per_rad": 500.0, "alpha": 0.0, "air_gamma_per_s": 0.0},
        order=(14, 6),
    )
    np.testing.assert_allclose(a, b, rtol=1e-9)


def test_air_damping_loss_falls_as_one_over_f():
    """Viscous air damping gamma: a mode's extra loss factor is gamma / omega_n."""
    mat = {"D": D, "nu": 0.0, "beta": 1e-6}
    f1, f2 = pm.natural_frequencies_hz(BARE, mat, n=2, order=ORDER)
    gamma = 2.0
    for fn in (f1, f2):
        f = fn * (1 + np.linspace(-0.02, 0.02, 4001))
        H = np.abs(pm.afc(f, BARE, mat, {"air_gamma_per_s": gamma}, order=ORDER))
        top = H.argmax()
        half = f[H >= H[top] / math.sqrt(2)]
        loss = (half[-1] - half[0]) / f[top]
        assert loss == pytest.approx(gamma / (2 * math.pi * fn), rel=0.02)


@pytest.mark.parametrize(
    "plate, mat, order, higher, f_max",
    [
        (
            pm.Plate(0.1, 0.02, 0.001, 7920.0, 0.09, 0.013, 1e-3, 2e-3),
            {"D": D, "nu": 0.3, "beta": 0.003},
            pm.STRIP_ORDER,
            (48, 19),
            3000.0,
        ),
        (
            pm.Plate(0.2, 0.15, 0.002, 2700.0, 0.18, 0.1, 2e-3, 3e-3),
            {"D": 52.0, "nu": 0.33, "beta": 0.002},
            pm.PLATE_ORDER,
            (38, 36),
            700.0,
        ),
    ],
)
def test_truth_order_converges_the_band(plate, mat, order, higher, f_max):
    """The truth's Ritz order against a higher one. The band's frequencies agree within
    5e-6 (the convergence is algebraic, not spectral: the clamped edge meets the free ones
    in corners whose field is singular for nu > 0), and the AFC on a grid that samples
    every peak's top (9 points within +-2 beta of each mode) differs by 0.25 of a 0.3 %
    noise's std in RMS, under one std at its worst point (a top)."""
    a = pm.natural_frequencies_hz(plate, mat, n=8, order=order)
    b = pm.natural_frequencies_hz(plate, mat, n=8, order=higher)
    band = b < f_max
    assert band.sum() >= 3
    assert np.max(np.abs(a[band] / b[band] - 1)) < 5e-6
    tops = (b[band][:, None] * (1 + mat["beta"] * np.linspace(-2, 2, 9))).ravel()
    f = np.sort(np.concatenate([np.linspace(10.0, f_max, 150), tops]))
    Ha, Hb = pm.afc(f, plate, mat, order=order), pm.afc(f, plate, mat, order=higher)
    z = np.abs(Ha - Hb) / pm.noise_std(Hb, 0.003, 1e-4)
    assert np.sqrt(np.mean(z**2)) < 0.25
    assert z.max() < 1.0
