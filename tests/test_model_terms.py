"""The model-terms layer carries every kind of contribution through every evaluator: a
frequency law on the loss and an inertia term, declared by terms written here (the shape of
the closed loop's frequency_dependent_loss and added_mass), reduced against full."""

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from plate_helpers import PAPER_THETA, strip_setup

from vibid.identify import build_forward_model
from vibid.identify.model.materials import Material
from vibid.identify.model.terms import Parameter, PlateModel, Term

STRIP = dict(zip(("D", "nu", "beta"), PAPER_THETA))
F = np.linspace(7.5, 1500.0, 60)


@dataclass(frozen=True)
class PowerLawLoss(Term):
    """beta(f) = beta (f / 1 kHz)^alpha."""

    name = "test_power_law_loss"
    parameters = (Parameter("alpha", "1", ("linear",), bounds=(-1.0, 1.0), null=0.0),)

    def loss_law(self, p, omega, xp):
        return (omega / (2 * math.pi * 1000.0)) ** p["alpha"]


@dataclass(frozen=True)
class PointMass(Term):
    """A point mass at the sensor centre: M += m c cᵀ."""

    name = "test_point_mass"
    parameters = (Parameter("mass_kg", "kg", ("log",), bounds=(1e-5, 1e-2), null=0.0),)
    inertia_matrices = ("point_mass",)

    def inertia(self, p, xp):
        return {"point_mass": p["mass_kg"]}

    def assemble(self, ctx):
        c = sp.csr_matrix(ctx.probe)
        return {"point_mass": (c.T @ c).tocsr()}


def _model(term, value):
    model = PlateModel(Material("isotropic"), (term,))
    name = term.parameters[0].name
    fm = build_forward_model(strip_setup(), F, model=model, theta0=STRIP | {name: value})
    return fm, np.append(PAPER_THETA, value)


def test_a_loss_law_reaches_the_reduced_and_the_full_model():
    fm, th = _model(PowerLawLoss(), 0.5)
    H, Hf = np.asarray(fm.afc(th)), fm.afc_full(th)
    assert np.abs(H - Hf).max() < 1e-6 * np.abs(Hf).max()
    # the null value alpha = 0 is the plain model
    plain = build_forward_model(strip_setup(), F, theta0=STRIP)
    np.testing.assert_allclose(np.asarray(fm.afc(np.append(PAPER_THETA, 0.0))),
                               np.asarray(plain.afc(PAPER_THETA)), rtol=1e-12, atol=1e-14)
    # the modal solver applies the law at each mode's frequency: decay ~ pi f beta L(f)
    # (to O(beta^2))
    f, decay = fm.natural_frequencies(th, 1)
    f0, decay0 = plain.natural_frequencies(PAPER_THETA, 1)
    assert abs(f[0] / f0[0] - 1) < 1e-5  # Re sqrt(1 + i beta L) = 1 + O(beta^2)
    assert abs(decay[0] / decay0[0] / math.sqrt(f0[0] / 1000.0) - 1) < 1e-4


def test_an_inertia_term_reaches_the_reduced_and_the_full_model():
    fm, th = _model(PointMass(), 5e-4)
    H, Hf = np.asarray(fm.afc(th)), fm.afc_full(th)
    assert np.abs(H - Hf).max() < 1e-6 * np.abs(Hf).max()
    # half a gram at the tip lowers the first resonance (Rayleigh: by about
    # m phi_s^2 / 2 m_modal); it moves by far more than the reduced model's error
    f, _ = fm.natural_frequencies(th, 1)
    plain = build_forward_model(strip_setup(), F, theta0=STRIP)
    f0, _ = plain.natural_frequencies(PAPER_THETA, 1)
    assert 0.8 * f0[0] < f[0] < 0.99 * f0[0]
    # its exact derivative against a central difference of the full model
    import jax

    J = np.asarray(jax.jacfwd(fm.afc)(th))[:, 3]
    h = 1e-7
    Jfd = (fm.afc_full(th + [0, 0, 0, h]) - fm.afc_full(th - [0, 0, 0, h])) / (2 * h)
    assert np.abs(J - Jfd).max() < 1e-4 * np.abs(Jfd).max()
