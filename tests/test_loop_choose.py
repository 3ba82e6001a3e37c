"""The loop's one criterion (:mod:`vibid.identify.loop.evidence`) and its choice
(``choose.compare``), checked against independent references: the Laplace evidence of a
linear-Gaussian model against the evidence integrated numerically over its prior box; the
choice's model prior as a Bayes factor; the order of a round's refits on stand-in
candidates."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import integrate

from vibid.identify.loop import choose, fitting
from vibid.identify.loop.diagnosis import Feature
from vibid.identify.loop.evidence import Noise, log_evidence, probabilities
from vibid.identify.loop.policy import Policy
from vibid.identify.loop.verdicts import Judgement, Score, Verdict

CHI2, DOF = 2.25169e11, 233


# -- the evidence against numerical integration ------------------------------------------------
def _line_fit(a_true, b_true, sigma, n=40, seed=0):
    """A straight line y = a + b x with white noise ``sigma``: its least-squares fit, the
    covariance, chi2 in the noise's units, and the data (a linear-Gaussian model, whose
    evidence Laplace's approximation gives exactly inside a wide box)."""
    rng = np.random.default_rng(seed)
    x = np.linspace(-1.0, 1.0, n)
    y = a_true + b_true * x + sigma * rng.standard_normal(n)
    A = np.column_stack([np.ones(n), x]) / sigma
    theta, *_ = np.linalg.lstsq(A, y / sigma, rcond=None)
    C = np.linalg.inv(A.T @ A)
    chi2 = float(np.sum((A @ theta - y / sigma) ** 2))
    return theta, C, chi2, (x, y)


def _result(theta, C, chi2, box):
    """A stand-in fit of parameters a, b (linear priors over ``box``)."""
    model = SimpleNamespace(
        default_bounds=lambda b: {**box, **b},
        parameters=(
            SimpleNamespace(name="a", kind=("linear",)),
            SimpleNamespace(name="b", kind=("linear",)),
        ),
    )
    return SimpleNamespace(
        values=np.asarray(theta),
        covariance=np.asarray(C),
        chi2=chi2,
        parameter_names=("a", "b"),
        plate_model=model,
    )


def _exact_log_evidence(data, sigma, box, n):
    """log ∫ L(a, b) p(a, b) da db over the box, L the Gaussian likelihood in units of
    the noise (the constant the evidence module drops, -n/2 log 2π, left out too)."""
    x, y = data
    (a0, a1), (b0, b1) = box["a"], box["b"]

    def like(b, a):
        return math.exp(-0.5 * float(np.sum(((a + b * x) - y) ** 2)) / sigma**2)

    z, _ = integrate.dblquad(like, a0, a1, b0, b1, epsabs=0, epsrel=1e-9)
    return math.log(z / ((a1 - a0) * (b1 - b0)))


def test_the_laplace_evidence_of_a_linear_model_is_its_integral_over_the_prior_box():
    sigma = 0.05
    theta, C, chi2, data = _line_fit(0.3, -0.2, sigma)
    box = {"a": (-1.0, 1.0), "b": (-1.0, 1.0)}
    ev = log_evidence(_result(theta, C, chi2, box), {}, Noise(n=80))
    # chi2 below n: the noise's own scale (s = 1); the posterior far inside the box
    assert ev.log_z == pytest.approx(_exact_log_evidence(data, sigma, box, 40), abs=1e-6)
    assert ev.inside == pytest.approx(0.0, abs=1e-12)


def test_a_posterior_cut_by_its_box_loses_the_mass_outside():
    """The truth a = 0.3 on a box that ends at 0.3: half the posterior lies outside, and
    the evidence is the integral over the box to within the marginal approximation."""
    sigma = 0.05
    theta, C, chi2, data = _line_fit(0.3, -0.2, sigma)
    box = {"a": (-1.0, float(theta[0])), "b": (-1.0, 1.0)}
    ev = log_evidence(_result(theta, C, chi2, box), {}, Noise(n=80))
    assert ev.inside == pytest.approx(math.log(0.5), abs=1e-6)
    assert ev.log_z == pytest.approx(_exact_log_evidence(data, sigma, box, 40), abs=1e-3)


def test_a_misfit_larger_than_the_noise_is_the_noise_of_every_explanation():
    """Gaussian noise of unknown scale no smaller than the measured one: the profile
    likelihood, and a parameter that removes a share of a large misfit gains only the log
    of the ratio, times the independent points."""
    noise = Noise(n=200, tau=4.0)
    assert noise.log_likelihood(100.0) == pytest.approx(-100.0 / 8.0)  # s = 1
    assert noise.log_likelihood(2000.0) == pytest.approx(-(200 + 200 * math.log(10)) / 8)
    gain = noise.log_likelihood(0.95 * 2e5) - noise.log_likelihood(2e5)
    assert gain == pytest.approx(200 / 8 * math.log(1 / 0.95))  # 1.3 nats for 5 %


def test_a_candidate_must_beat_stopping_by_the_size_of_the_library():
    """Half the prior on "the model is complete", half over the k candidates: with k = 9
    and equal evidence, stopping is 9 times as probable as each candidate."""
    log_z = {None: 0.0} | {f"c{k}": 0.0 for k in range(9)}
    prior = {None: 0.5} | {f"c{k}": 0.5 / 9 for k in range(9)}
    p = probabilities(log_z, prior)
    assert p[None] == pytest.approx(0.5) and p["c0"] == pytest.approx(0.5 / 9)
    assert sum(p.values()) == pytest.approx(1.0)
    log_z["c0"] = math.log(9.0)  # a Bayes factor of 9: as probable as stopping
    p = probabilities(log_z, prior)
    assert p["c0"] == pytest.approx(p[None])


def _refit(gain, log_z):
    return Judgement(Verdict.COMPARED, (), SimpleNamespace(gain=gain), evidence=log_z)


def test_the_most_probable_fitted_explanation_is_chosen_and_listed_first():
    scores = [
        Score(n, 1e3, 1, 0.0, 0.1, log_evidence=z, estimated=True)
        for n, z in (("a", 0.0), ("b", 0.0), ("c", 50.0))
    ]
    judged = {"a": _refit(1e3, 10.0), "b": _refit(2e3, 12.0), "c": Judgement(Verdict.NOT_REFITTED)}
    out, chosen, shares = choose.compare(scores, judged, 0.0, Policy())
    assert chosen == "b"  # c's estimate is higher, but only a fit is a model
    assert [a["added"] for a in shares] == ["b", "a", None]  # the fits and stopping
    assert sum(a["probability"] for a in shares) == pytest.approx(1.0)
    # priors 1/6 each candidate, 1/2 stopping: b against a by e^2, against stopping by e^12/3
    assert shares[0]["probability"] == pytest.approx(1 / (1 + math.exp(-2) + 3 * math.exp(-12)))
    assert {s.name: s.estimated for s in out}["c"] is True
    verdicts = {s.name: s.verdict for s in out}
    assert verdicts == {"a": Verdict.LESS_PROBABLE, "b": Verdict.CHOSEN, "c": Verdict.NOT_REFITTED}
    # against a round where stopping is more probable than every fit
    out, chosen, shares = choose.compare(scores, {"a": _refit(1.0, -3.0)}, 0.0, Policy())
    assert chosen is None and shares[0]["added"] is None


# -- where a resonance is tried -------------------------------------------------------------
def test_a_resonance_is_proposed_at_every_pole_whatever_the_diagnosis_read_it_as():
    """A stand resonance beside a model's antiresonance may be read as a misplaced mode:
    it is tried there all the same, and at the residual's largest maxima, once per span."""
    from vibid.identify.loop.candidates import EffectCandidate, Place

    shift = Feature("mode_shift", f_hz=664.0, q=80.0, significance=50.0)
    pole = Feature("extra_pole", f_hz=1300.0, q=40.0, significance=10.0)
    diagnosis = SimpleNamespace(features=(shift, pole), extra_poles=lambda: (pole,))
    peaks = (Place(670.0, 30.0, "residual_peak"), Place(2100.0, 30.0, "residual_peak"))
    places = EffectCandidate("stand_resonance").placements(diagnosis, peaks)
    assert [round(c.at.f_hz) for c in places] == [1300, 664, 2100]
    assert EffectCandidate("stand_resonance").placements(None, ()) == ()
    assert EffectCandidate("sensor_gain").placements(None, ()) == (EffectCandidate("sensor_gain"),)


def test_a_resonance_placed_at_a_pole_is_refitted_within_its_span():
    """The refit of a stand resonance placed at a diagnosed pole searches its frequency
    within 10 % of the pole only, its Q within 3 times the pole's: a logit over each span,
    which no step can leave (the titanium strip's slid from 661 Hz to 1755 Hz, and within
    10 % of the pole widened to Q 1: judged elsewhere than at the pole it was added
    for)."""
    from vibid.identify.fit.space import ParameterSpace
    from vibid.identify.loop.candidates import EffectCandidate, MaterialCandidate

    pole = Feature("extra_pole", f_hz=661.0, q=50.0, significance=900.0)
    diagnosis = SimpleNamespace(features=(pole,))
    cand = EffectCandidate("stand_resonance")
    current = {"D": 216.0, "nu": 0.3, "beta": 0.009}
    box = cand.bounds({}, current, diagnosis)
    assert box["f_hz_1"] == pytest.approx((661.0 / 1.1, 661.0 * 1.1))
    assert box["q_1"] == pytest.approx((50.0 / 3, 150.0))  # Q within 3x the pole's
    held = cand.held(current, diagnosis)
    assert held == {"f_hz_1": ("logit", *box["f_hz_1"]), "q_1": ("logit", *box["q_1"])}
    space = ParameterSpace.from_bounds(["f_hz_1"], box, held)
    f = space.theta([[-40.0], [0.0], [40.0]])[:, 0]  # far beyond the box's faces u = ±1
    lo, hi = box["f_hz_1"]
    assert lo <= f[0] < lo + 0.2 and hi - 0.2 < f[2] <= hi and f[1] == pytest.approx(664.0, abs=0.1)
    # without a diagnosed pole, the catalogue's box; a material holds nothing
    assert cand.bounds({}, current)["f_hz_1"] == (5.0, 5000.0)
    assert cand.held(current, None) == {} and MaterialCandidate().held(current, diagnosis) == {}


# -- the order of the refits (``fitting.fit_and_weigh``) ---------------------------------------
def _round(monkeypatch, gains, fits_noise=()):
    """Refit a round of stand-in candidates (``gains``: name -> the chi2 its refit removes;
    the material ``anisotropy`` has the highest approximate evidence of all) and return
    the refits run, in order, as (name, searched). On one thread: on two the next refit
    starts early, so the order in which refits start is a race."""
    monkeypatch.setenv("VIBID_THREADS", "1")
    calls = []

    def refit(
        plate, data, res, cand, box, diagnosis, local, search=False, extended=None, policy=None
    ):
        calls.append((cand.name, search))
        return SimpleNamespace(gain=gains[cand.name], result=cand.name, searched=search)

    def weigh(cand, fit, res, state, noise):
        return Judgement(Verdict.COMPARED, (), fit, evidence=fit.gain)

    monkeypatch.setattr(fitting.refits, "refit", refit)
    monkeypatch.setattr(fitting, "weigh", weigh)
    monkeypatch.setattr(fitting, "outside_prior", lambda res, box: [])
    monkeypatch.setattr(
        fitting.Stage,
        "of",
        classmethod(lambda cls, added, result: SimpleNamespace(fits_noise=result in fits_noise)),
    )
    cands = {
        n: SimpleNamespace(
            name=n,
            label=n,
            moves_basin=n == "anisotropy",
            modes_needed=lambda m: 0,
            extend=lambda m: SimpleNamespace(names=("D", "nu", "x")),
        )
        for n in gains
    }
    scores = [
        Score(n, 1e9, 1, 0.0, 0.1, log_evidence=1e9 if n == "anisotropy" else 1e8 - k)
        for k, n in enumerate(gains)
    ]
    res = SimpleNamespace(chi2=CHI2, dof=DOF, plate_model=None, parameter_names=("D", "nu"))
    state = SimpleNamespace(current=SimpleNamespace(result=res, diagnosis=None), box={}, prior={})
    inputs = SimpleNamespace(
        plate=None,
        data=SimpleNamespace(n_residuals=2 * DOF),
        local="newton",
        left_out_hz=(),
        policy=Policy(),
    )
    judged = fitting.fit_and_weigh(inputs, state, cands, scores, {}, Noise(2 * DOF))
    return calls, judged


def test_a_new_material_is_searched_at_once_where_the_effects_leave_most_of_the_misfit(monkeypatch):
    """The effects' refits explain under half the misfit, so the material, though its
    approximate evidence is the highest, comes last and is searched over its box."""
    gains = {
        "anisotropy": CHI2 - 3.5e4,
        "stand_resonance": 0.18 * CHI2,
        "sensor_position": 0.13 * CHI2,
    }
    calls, judged = _round(monkeypatch, gains)
    assert calls == [("stand_resonance", False), ("sensor_position", False), ("anisotropy", True)]
    assert judged["anisotropy"].fit.searched


def test_a_new_material_is_refitted_locally_where_an_effect_explains_most_of_the_misfit(
    monkeypatch,
):
    gains = {"anisotropy": 0.3 * CHI2, "clamp_compliance": 0.8 * CHI2}
    calls, _ = _round(monkeypatch, gains)
    assert calls == [("clamp_compliance", False), ("anisotropy", False)]


def test_a_new_material_is_not_refitted_once_an_effect_fits_the_noise(monkeypatch):
    gains = {"anisotropy": 0.3 * CHI2, "added_mass": CHI2 - DOF}
    calls, judged = _round(monkeypatch, gains, fits_noise=("added_mass",))
    assert calls == [("added_mass", False)]
    assert judged["anisotropy"].verdict is Verdict.NOT_REFITTED


def test_only_the_most_promising_refits_run_beyond_the_budget(monkeypatch):
    gains = {f"e{k}": 1e3 * (k + 1) for k in range(6)}
    calls, judged = _round(monkeypatch, gains)
    assert [c for c, _ in calls] == ["e0", "e1", "e2", "e3"]  # Policy.refits_per_round
    assert judged["e5"].verdict is Verdict.NOT_REFITTED


# -- how a refit is weighed (``refit.model_error_weighs_in``) ------------------------------------
def test_refits_weigh_their_own_model_error_only_where_it_changes_chi2():
    """Titanium's declared fit: chi2_red 9175 under the data's weights, 8963 with the
    model's error (2.3 %): refits are weighed as the current fit is. The simulated CFRP
    plate once orthotropic: 27.3 against 2.0: each refit weighs its own (without it, the
    error's systematic part missing, three spurious effects stood 3 std from their nulls)."""
    from vibid.identify.loop.refit import model_error_weighs_in

    def fit(data, weighted):
        return SimpleNamespace(chi2_reduced_data_weights=data, chi2_reduced=weighted)

    assert not model_error_weighs_in(fit(9175.0, 8963.0))
    assert model_error_weighs_in(fit(27.3, 2.0))
    assert model_error_weighs_in(fit(1.12, 1.0))  # 12 %: near the noise it weighs in
