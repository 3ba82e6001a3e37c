"""The paper's strip against independent discretisations, and vibid's own refinement
family converging.

* scikit-fem's own ``ElementTriArgyris`` (basis in global coordinates) on uniform meshes:
  on one mesh it spans the space of vibid's local-coordinate Argyris (the frequencies agree
  to 3e-8 on 40 x 8 cells), but its corner singularity limits a uniform mesh to about
  second order, so its 40 x 8 mesh is about 3e-5 off, and Richardson's h^2 extrapolation
  of 40 x 8 and 80 x 16 (slow) converges it to a few 1e-6 only. The first torsion mode
  (790 Hz) converges at about h^1.5 there, and the global basis loses digits as the cells
  shrink (its monomials' conditioning grows as (x / h)^5: 2.6e-8 off vibid's basis on
  40 x 8 cells, 1.9e-6 on 80 x 16), so the extrapolation puts that mode 2.6e-6 to 4.4e-6
  (the rounding differs with the CPU's BLAS kernels) above a bound the exact one lies
  under (a conforming mesh's frequency; benchmarks/disc_error.py).
  Fitted, its AFC moves nu by -1.2e-5 and D by -1.2e-4: no reference for data that precise;
* the Morley element (a different, non-conforming, quadratic space) on uniform meshes,
  extrapolated the same way;
* vibid's family of corner-refined meshes (:func:`~vibid.identify.model.forward.
  finer_discretisation`): conforming, so each frequency bounds the exact one from above,
  converging at about h^6 (the order the model's error estimate measures).
"""

import numpy as np
import pytest

from plate_helpers import PAPER_THETA, strip_model, strip_setup
from vibid.identify.model.assembly import Geometry, assemble_plate
from vibid.identify.model.full import afc_full
from vibid.identify.model.mesh import Discretisation, coarser_discretisation, finer_discretisation
from vibid.identify.model.modal import complex_eigenvalues, frequencies_and_decays

GEOM = Geometry.from_setup(strip_setup())


def _frequencies(disc, n=6):
    model = strip_model()
    mats = assemble_plate(GEOM, disc)
    th = PAPER_THETA
    lam = complex_eigenvalues(mats, model.param.moduli(th), model.param.losses(th), n)
    return frequencies_and_decays(lam)[0]


@pytest.fixture(scope="module")
def default_frequencies():
    model = strip_model()
    return model.natural_frequencies(PAPER_THETA, 6)[0]


def test_against_scikit_fem_argyris(default_frequencies):
    ref = _frequencies(Discretisation("argyris-global", 40, 8))
    np.testing.assert_allclose(default_frequencies, ref, rtol=1e-4)
    # the reference lies above (conforming element, coarser near the corners)
    assert np.all(ref > default_frequencies)


def test_afc_against_scikit_fem_argyris_off_resonance(default_frequencies):
    """The AFC agrees where it is not dominated by a resonance's exact position."""
    model = strip_model()
    f = np.linspace(10.0, 1500.0, 60)
    far = f[np.all(np.abs(f[:, None] / default_frequencies[None, :] - 1) > 0.05, axis=1)]
    dc = model.param.complex_moduli(PAPER_THETA)
    ref = afc_full(assemble_plate(GEOM, Discretisation("argyris-global", 40, 8)), dc, far)
    H = afc_full(model.mats, dc, far)
    assert np.abs(H - ref).max() < 1e-3 * np.abs(ref).max()


def test_against_extrapolated_morley(default_frequencies):
    """Morley (h²) on 60 x 12 and 120 x 24, Richardson-extrapolated: within 1.5e-4."""
    coarse = _frequencies(Discretisation("morley", 60, 12))
    fine = _frequencies(Discretisation("morley", 120, 24))
    ratio = (default_frequencies - coarse) / (default_frequencies - fine)
    assert np.all((ratio > 3.0) & (ratio < 4.5))  # about h² convergence towards our values
    extrapolated = (4 * fine - coarse) / 3
    np.testing.assert_allclose(default_frequencies, extrapolated, rtol=1.5e-4)


def test_the_local_basis_spans_scikit_fem_argyris_space():
    """On one uniform mesh (40 x 8 cells, no corner refinement) vibid's local-coordinate
    Argyris and scikit-fem's own give the same six frequencies to 1e-7 (measured 3e-8):
    one finite element space, so a finer mesh of vibid's is an independent discretisation
    of the same plate, not another model."""
    ours = _frequencies(Discretisation("argyris", 40, 8))
    theirs = _frequencies(Discretisation("argyris-global", 40, 8))
    np.testing.assert_allclose(ours, theirs, rtol=1e-7)


def test_the_refinement_family_converges_from_above_at_about_h6():
    """The model's error estimate's three meshes (20 x 4 cells and 3 corner levels, the
    default 30 x 6 and 4, 45 x 9 and 5) and the "fine" mesh (60 x 12 and 6) bound each of
    the four frequencies below 1500 Hz (the fits' band) from above (conforming elements,
    exact quadrature), downwards along the family; the order measured from the three,
    mode by mode, is 5 to 9 (measured 5.4 for the torsion mode to 8.4, about h^6 as the
    model's estimate finds on the AFC), and their Richardson value meets the fine mesh's
    within 3e-8 (measured 1.9e-8), where the default is 3.4e-7 off and its finer mesh
    2.2e-8."""
    d0 = Discretisation("argyris", 30, 6, 4)
    coarse, fine = coarser_discretisation(d0), finer_discretisation(d0)
    assert finer_discretisation(coarse) == d0
    fc, f0, f1, ref = (
        _frequencies(d, 4) for d in (coarse, d0, fine, Discretisation("argyris", 60, 12, 6))
    )
    assert np.all((fc > f0) & (f0 > f1) & (f1 > ref))
    q = (f0 - f1) / (fc - f0)  # (2/3)^p for cells 2/3 as large per level
    order = np.log(q) / np.log(2 / 3)
    assert np.all((order > 5.0) & (order < 9.0)), order
    extrapolated = f1 - (f0 - f1) * q / (1 - q)
    np.testing.assert_allclose(extrapolated, ref, rtol=3e-8)
    assert np.max(np.abs(f0 / ref - 1)) > 3e-7 and np.max(np.abs(f1 / ref - 1)) > 1.5e-8


@pytest.mark.slow
def test_against_extrapolated_scikit_fem_argyris_fine(default_frequencies):
    """scikit-fem's Argyris on 40 x 8 and 80 x 16 (12 000 dof): its own convergence is
    about h² (the torsion mode's nearer h^1.5) and its extrapolation meets the default
    discretisation within 5e-6; its torsion mode lies above the fine mesh's, a bound the
    exact one lies under, by more than 1e-6: no reference at 1e-6. Measured 2.6e-6 and 4.4e-6
    on two CPUs: part of it is the global basis's rounding, which the BLAS kernels set, so the
    bar is the claim (1e-6), not a measurement."""
    coarse = _frequencies(Discretisation("argyris-global", 40, 8))
    fine = _frequencies(Discretisation("argyris-global", 80, 16))
    rate = np.log2((coarse - default_frequencies) / (fine - default_frequencies))
    assert np.all((rate > 1.5) & (rate < 2.6))
    extrapolated = (4 * fine - coarse) / 3
    np.testing.assert_allclose(default_frequencies, extrapolated, rtol=5e-6)
    bound = _frequencies(Discretisation("argyris", 60, 12, 6))
    assert extrapolated[2] / bound[2] - 1 > 1e-6


def test_default_discretisation_converged(default_frequencies):
    """Against a finer corner-refined mesh: first six frequencies within 1e-5 (issue: 1e-4)."""
    finer = _frequencies(Discretisation("argyris", 60, 12, 6))
    np.testing.assert_allclose(default_frequencies, finer, rtol=1e-5)
