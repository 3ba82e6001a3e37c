"""The uncertainty budget of the engineering constants (vibid.identify.assess.budget) and the
plausibility of the constants in the report.

Analytic references: a Kirchhoff plate with a massless sensor has natural frequencies
ω ∝ √(D / ρh) whatever the mode, so a fit of its AFC returns D ∝ ρh: E = 12 D (1 − ν²)/h³
then goes as h⁻² (the conversion's h⁻³ times the fit's h) and as ρ¹, and ν does not move.
The model part is Burnham & Anderson's weighted spread, checked on two models of known
QAIC.
"""

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from vibid.identify.assess.budget import engineering_budget, model_spread
from vibid.setup_model import example_setup

TRUE = {"D": 17.97, "nu": 0.286, "beta": 0.003}
H_STD, RHO_STD = 1e-5, 40.0  # 1 % of the 1 mm thickness, 0.5 % of 7920 kg/m³


def _setup(**response):
    s = example_setup()
    return dataclasses.replace(
        s,
        specimen=dataclasses.replace(
            s.specimen, thickness_std_m=H_STD, density_std_kg_m3=RHO_STD, length_std_m=1e-4
        ),
        sensors=dataclasses.replace(
            s.sensors, response=dataclasses.replace(s.sensors.response, **response)
        ),
    )


@pytest.fixture(scope="module")
def massless():
    """The strip with a (nearly) massless sensor, fitted to its own noise-free AFC."""
    from vibid.identify import build_forward_model, configure
    from vibid.identify.fit import Measurement, SearchOptions, identify

    configure()
    s = _setup(mass_kg=1e-7)
    f = np.linspace(20.0, 1500.0, 60)
    fm = build_forward_model(s, f, theta0=TRUE)
    H = np.asarray(fm.afc(np.array(list(TRUE.values()))))
    result = identify(
        s,
        Measurement(f, H, 0.003 * np.abs(H) + 1e-4),
        search=SearchOptions(method="local", start=TRUE),
    )
    return s, result


def test_the_thickness_and_density_move_E_as_the_plate_scales(massless):
    s, result = massless
    block = engineering_budget(s, result)
    E = block["E_Pa"]["value"]
    parts = block["budget"]["E_Pa"]
    h, rho = s.specimen.thickness_m, s.specimen.density_kg_m3
    assert parts["thickness_m"] == pytest.approx(2 * E * H_STD / h, rel=0.01)  # not 3
    assert parts["density_kg_m3"] == pytest.approx(E * RHO_STD / rho, rel=0.01)
    # nu is fixed by ratios of frequencies, which neither changes
    nu = block["budget"]["nu"]
    assert nu["thickness_m"] < 0.1 * nu["fit"] and nu["density_kg_m3"] < 0.1 * nu["fit"]
    # the parts are independent: the combined std is their root sum of squares
    for k in ("E_Pa", "nu", "G_Pa"):
        rss = math.sqrt(sum(v**2 for v in block["budget"][k].values()))
        assert block[k]["std"] == pytest.approx(rss, rel=1e-12)
    assert "mostly the declared length" in " ".join(block["notes"])
    # what the setup gives no uncertainty for is said, not silently left at zero
    (unknown,) = [n for n in block["notes"] if n.startswith("the setup declares no")]
    assert (
        "for the width, sensor position (x), sensor position (y), sensor mass: the "
        "budget leaves them out"
    ) in unknown
    assert not {"thickness_m", "density_kg_m3", "length_m"} - set(parts)


def test_the_discretisation_part_is_the_bias_through_the_conversion_and_keeps_the_total(massless):
    """The fit's covariance C holds the discretisation's bias b as b bᵀ: the budget splits
    it into ``fit`` √(gᵀ (C − b bᵀ) g) and ``discretisation`` |gᵀ b|, g the constant's
    gradient, which add in quadrature to the std C alone gave before the split. g here is
    the closed form's: E = 12 D (1 − ν²) / h³, G = 6 D (1 − ν) / h³."""
    from vibid.identify.assess.budget import fit_parts
    from vibid.identify.assess.engineering import sensitivities

    s, result = massless
    b = np.asarray(result.model_error_bias, float)
    assert result.parameter_names == ("D", "nu", "beta") and np.all(np.abs(b[:2]) > 0)
    block = engineering_budget(s, result)
    D, nu = result.parameters["D"], result.parameters["nu"]
    h = s.specimen.thickness_m
    g = {
        "E_Pa": [12 * (1 - nu**2) / h**3, -24 * D * nu / h**3, 0.0],
        "nu": [0.0, 1.0, 0.0],
        "G_Pa": [6 * (1 - nu) / h**3, -6 * D / h**3, 0.0],
    }
    keys, J, _ = sensitivities("isotropic", result.parameter_names, result.values, h)
    C = np.asarray(result.covariance, float)
    for i, k in enumerate(keys):
        parts = block["budget"][k]
        assert parts["discretisation"] == pytest.approx(abs(np.dot(g[k], b)), rel=1e-6)
        assert parts["discretisation"] > 0
        # the total as before the split: the fit's part gᵀ C g and the declared ones
        before = J[i] @ C @ J[i] + sum(
            v**2 for n, v in parts.items() if n not in ("fit", "discretisation")
        )
        assert block[k]["std"] == pytest.approx(math.sqrt(before), rel=1e-12)
        assert math.hypot(parts["fit"], parts["discretisation"]) == pytest.approx(
            math.sqrt(J[i] @ C @ J[i]), rel=1e-12
        )
    # without a bias (no signed model error) the fit's part is gᵀ C g, as before: to the
    # rounding of two orders of summation (einsum and two matrix products differ by up to
    # ~8 ulp on a covariance whose terms cancel; 1e-15 failed here on 26b04c8 alone)
    plain = fit_parts(keys, J, C)
    assert all(set(p) == {"fit"} for p in plain.values())
    assert [plain[k]["fit"] for k in keys] == pytest.approx(
        [math.sqrt(J[i] @ C @ J[i]) for i in range(len(keys))], rel=1e-13
    )


def test_the_fit_part_is_the_covariance_less_the_bias_term():
    """A covariance A + b bᵀ: ``fit`` is √(gᵀ A g), ``discretisation`` |gᵀ b|, whatever
    their sizes; a bias that is all of C leaves the fit's part at 0, never NaN."""
    from vibid.identify.assess.budget import fit_parts

    rng = np.random.default_rng(0)
    M = rng.normal(size=(3, 3))
    A, b, g = M @ M.T, rng.normal(size=3), rng.normal(size=(2, 3))
    parts = fit_parts(["a", "c"], g, A + np.outer(b, b), b)
    for i, k in enumerate(("a", "c")):
        assert parts[k]["fit"] == pytest.approx(math.sqrt(g[i] @ A @ g[i]), rel=1e-12)
        assert parts[k]["discretisation"] == pytest.approx(abs(g[i] @ b), rel=1e-15)
    only = fit_parts(["a"], g[:1], np.outer(b, b), b)["a"]
    assert only["fit"] == pytest.approx(0.0, abs=1e-7 * only["discretisation"])
    assert only["discretisation"] == pytest.approx(abs(g[0] @ b), rel=1e-15)


def test_the_model_part_is_the_weighted_spread_of_the_compared_models():
    """Two isotropic models 2 ln 3 apart in QAIC weigh 3 : 1; their E differ by ΔE, so the
    spread is √(w₁ w₂) ΔE = √3/4 ΔE."""

    def fit(D, chi2_red, p):
        return SimpleNamespace(
            plate_model=SimpleNamespace(model="isotropic"),
            dof=100,
            chi2_reduced_reported=chi2_red,
            parameters={"D": D, "nu": 0.3},
            parameter_names=("D", "nu", "beta") + ("x",) * (p - 3),
        )

    final = fit(18.0, 4.0, 4)
    # QAIC = chi2/c + 2p, c = 4: 100 + 8 for the final, 100 + 8 + 2 ln 3 for the other
    other = fit(17.0, 4.0 + 4 * 2 * math.log(3) / 100, 4)
    loop = SimpleNamespace(
        unexplained_residual=True,
        final=final,
        stages=[SimpleNamespace(result=final)],
        alternatives=(other,),
    )
    h = 0.001
    E = [12 * D * (1 - 0.09) / h**3 for D in (18.0, 17.0)]
    spread = model_spread(loop, "isotropic", h)
    assert spread["E_Pa"] == pytest.approx(math.sqrt(3) / 4 * abs(E[0] - E[1]), rel=1e-9)
    assert spread["nu"] == pytest.approx(0.0, abs=1e-15)
    # a loop whose final model explains the data has no model part
    explained = SimpleNamespace(**{**vars(loop), "unexplained_residual": False})
    assert model_spread(explained, "isotropic", h) == {}


def test_the_clamp_line_part_is_the_refit_at_a_longer_span_times_the_box(massless):
    """Where a residual remains and the setup does not declare the free length's
    uncertainty, the clamp's line is a part: |∂E/∂L| (E refitted with the free end and the
    sensor 0.1 mm further from the clamp, the definition) times the standard uncertainty
    of a rectangular distribution over the free length's box. Without a loop's residual,
    or with the length's uncertainty declared, there is none."""
    from vibid.identify.assess.budget import clamp_line, with_declared
    from vibid.identify.assess.engineering import constants
    from vibid.identify.fit import Measurement, SearchOptions, identify

    declared, result = massless
    s = dataclasses.replace(
        declared, specimen=dataclasses.replace(declared.specimen, length_std_m=None)
    )
    L, x, h = s.specimen.length_m, s.sensors.response.x_m, s.specimen.thickness_m
    d = 1e-4
    longer = with_declared(with_declared(s, "length_m", L + d), "sensor_x_m", x + d)
    refit = identify(
        longer,
        Measurement(result.frequency_hz, result.H, result.H_std),
        search=SearchOptions(method="local", start=result.parameters),
    )
    dE = (
        constants("isotropic", refit.parameters, h)["E_Pa"]
        - constants("isotropic", result.parameters, h)["E_Pa"]
    ) / d
    loop = SimpleNamespace(
        unexplained_residual=True,
        final=result,
        stages=[SimpleNamespace(result=result, held=())],
        alternatives=(),
    )
    box = dict(s.identification.bounds)
    for lo, hi in ((-5e-3, 5e-3), (0.0, 2e-3)):
        part = clamp_line(s, loop, box | {"dL_m": (lo, hi)})["E_Pa"]
        assert part == pytest.approx(abs(dE) * (hi - lo) / math.sqrt(12), rel=0.03)
    assert clamp_line(declared, loop, box) == {}  # length_std_m declared
    explained = SimpleNamespace(**{**vars(loop), "unexplained_residual": False})
    assert clamp_line(s, explained, box) == {}


@pytest.mark.slow
def test_the_clamp_line_part_covers_a_free_span_the_data_cannot_name():
    """An exact Rayleigh beam (tests/beam_reference.py, a model vibid did not write) of a
    100 x 20 x 3 mm titanium-like strip (E 110 GPa, nu 0), its 1.7 g sensor near the tip,
    whose clamp's line lies 3 mm inside the jaws, and a 2 % crosstalk that no candidate
    explains: the loop leaves a residual and does not name the free length, and its E
    comes out 14 % low, 15 GPa, four times the fit's and model's parts together. With the
    clamp's line counted, E ± 2 std reaches the beam's modulus; the data's own first-order
    information on the line (0.60 mm) did not."""
    import beam_reference as beam
    from loop_data import noisy
    from plate_helpers import plate_setup
    from vibid.identify import configure
    from vibid.identify.loop import close_loop
    from vibid.setup_model import Identification

    configure()
    L, W, h, rho, E, dL = 0.1, 0.02, 0.003, 4550.0, 110e9, 3e-3
    f = np.linspace(60.0, 1600.0, 80)
    s = plate_setup(L, W, h, rho, x_m=0.096, y_m=W / 2, mass_kg=0.0017, radius_m=0.0038)
    s = dataclasses.replace(
        s,
        identification=Identification(
            "isotropic", {"D": (10.0, 1000.0), "nu": (-0.3, 0.5), "beta": (1e-4, 0.1)}
        ),
    )
    r = s.sensors.response
    H = (
        beam.afc(
            2 * math.pi * f,
            L=L + dL,
            EI=E * h**3 / 12 * W * (1 + 0.005j),
            rhoA=rho * h * W,
            rhoI=rho * h**3 / 12 * W,
            x_s=r.x_m + dL,
            m=r.mass_kg,
            J=r.mass_kg * (r.radius_m**2 / 4 + h**2 / 12),
        )
        + 0.02
    )
    H, sd = noisy(H, 2)
    loop = close_loop(s, f, H, sd, seed=0, restarts=1)
    assert loop.unexplained_residual and "free_length" not in loop.effects
    block = engineering_budget(s, loop.final, loop)
    value, parts = block["E_Pa"]["value"], block["budget"]["E_Pa"]
    assert E - value > 4 * math.hypot(
        parts["fit"], parts.get("discretisation", 0.0), parts.get("model", 0.0)
    )
    assert E - value < 2 * block["E_Pa"]["std"]


def test_the_report_carries_the_budget_and_is_never_silent_on_a_non_physical_value(massless):
    from vibid.identify.assess import assess
    from vibid.report import build_report, console_summary, summary_markdown

    s, result = massless
    report = build_report(result, assess(result, setup=s))
    eng = report["engineering"]
    assert set(eng["budget"]["E_Pa"]) == {
        "fit",
        "discretisation",
        "thickness_m",
        "density_kg_m3",
        "length_m",
    }
    assert report["plausibility"]["material_class"] == "steel"  # "steel strip 100x20x1"
    assert not report["plausibility"]["violations"]
    md = summary_markdown(report)
    assert "| constant | fit | discretisation | thickness_m |" in md
    assert "discretisation: the mesh's error, Richardson-extrapolated" in md
    assert "Plausibility (the specimen is steel)" in md
    # how the discretisation error was estimated, and the bias it causes, signed
    disc = report["identification"]["discretisation"]
    assert len(disc["meshes"]) == 3 and len(set(disc["meshes"])) == 3
    assert disc["meshes"][1] == result.discretisation.meshes[1]
    assert disc["order"] > 1 and disc["factor"] >= 1 and disc["limited"] is False
    assert disc["bias"] == pytest.approx(
        dict(zip(result.parameter_names, result.model_error_bias)), rel=1e-15
    )
    assert report["identification"]["model_error_std"] == pytest.approx(
        {n: abs(b) for n, b in disc["bias"].items()}, rel=1e-15
    )
    # the same fit with nu pushed past 0.5: a warning in the report, report.md and console
    bent = dataclasses.replace(result, values=np.array([17.97, 0.55, 0.003]))
    report = build_report(bent, assess(bent, setup=s))
    said = report["plausibility"]["violations"]
    assert len(said) == 1 and "0.5" in said[0] and "the closed loop did not run" in said[0]
    assert said[0] in report["identification"]["warnings"]
    assert "**not physical**" in summary_markdown(report)
    assert "NOT PHYSICAL" in console_summary(report)


def test_the_model_part_counts_correlated_residuals_once_and_only_defensible_models(monkeypatch):
    """A residual whose autocorrelation time is tau makes tau points one: the same two
    models, tau = 5 and a chi2 gap five times wider, weigh 3 : 1 again. A model that leaves
    a parameter outside its prior box is no defensible model: it has no weight."""
    from vibid.identify.loop import evidence

    def fit(D, chi2_red, name):
        return SimpleNamespace(
            plate_model=SimpleNamespace(model="isotropic"),
            dof=100,
            chi2_reduced_reported=chi2_red,
            parameters={"D": D, "nu": 0.3},
            parameter_names=("D", "nu", "beta", "x"),
            name=name,
        )

    final = fit(18.0, 4.0, "final")
    other = fit(17.0, 4.0 + 5 * 4 * 2 * math.log(3) / 100, "other")
    loop = SimpleNamespace(
        unexplained_residual=True,
        final=final,
        stages=[SimpleNamespace(result=final)],
        alternatives=(other,),
    )
    h = 0.001
    E = [12 * D * (1 - 0.09) / h**3 for D in (18.0, 17.0)]
    spread = model_spread(loop, "isotropic", h, tau=5.0)
    assert spread["E_Pa"] == pytest.approx(math.sqrt(3) / 4 * abs(E[0] - E[1]), rel=1e-9)
    # without tau the gap is five times wider in QAIC: the other weighs 3^-5 of the final
    w = 3.0**-5 / (1 + 3.0**-5)
    assert model_spread(loop, "isotropic", h)["E_Pa"] == pytest.approx(
        math.sqrt(w * (1 - w)) * abs(E[0] - E[1]), rel=1e-9
    )
    monkeypatch.setattr(
        evidence, "outside_prior", lambda r, box: ["nu"] if r.name == "other" else []
    )
    assert model_spread(loop, "isotropic", h, tau=5.0, box={})["E_Pa"] == 0.0
    # where the final model is outside the box too, the box tells none from another: the
    # spread is over every model compared (not zero: the final's alone)
    monkeypatch.setattr(evidence, "outside_prior", lambda r, box: ["nu"])
    assert model_spread(loop, "isotropic", h, tau=5.0, box={})["E_Pa"] == pytest.approx(
        math.sqrt(3) / 4 * abs(E[0] - E[1]), rel=1e-9
    )


@pytest.mark.slow
def test_a_declared_length_moves_E_as_the_refit_at_that_length_does_where_a_misfit_remains():
    """The real steel strip under its declared model (chi2_red 1.2e4: the misfit is far
    above the noise), its length declared to 0.5 mm: the budget's length part of E is the
    change of E when the model is refitted at the length 0.5 mm longer (the definition the
    first order approximates). The Gauss-Newton shift -J⁺Δr, which drops the Jacobian's
    change times this residual, gave 9.4 GPa where the refit moves E by 2.0 GPa (now 1.8);
    with nu held in both, 2.39 GPa against the refit's 2.41."""
    from pathlib import Path

    from vibid.identify import configure
    from vibid.identify.assess.budget import with_declared
    from vibid.identify.assess.engineering import constants
    from vibid.identify.assess.linearity import linear_part
    from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify
    from vibid.setup_model import parse_setup

    configure()
    here = Path(__file__).parents[1] / "examples" / "real-steel"
    f, re, im, std = np.loadtxt(here / "afc.csv", delimiter=",", skiprows=1, unpack=True)
    H = re + 1j * im
    used, _ = linear_part(f, H, std)  # the first resonance's top left out, as the CLI does
    s = parse_setup((here / "setup.json").read_text())
    s = dataclasses.replace(s, specimen=dataclasses.replace(s.specimen, length_std_m=5e-4))
    start = {"D": 127.14, "nu": -0.326, "beta": 0.01073}  # the declared fit's estimate
    fitted = identify(
        s, Measurement(f, H, std, used=used), search=SearchOptions(method="local", start=start)
    )
    part = engineering_budget(s, fitted)["budget"]["E_Pa"]["length_m"]
    longer = identify(
        with_declared(s, "length_m", s.specimen.length_m + 5e-4),
        Measurement(f, H, std, used=used),
        search=SearchOptions(method="local", start=fitted.parameters),
    )
    h = s.specimen.thickness_m
    moved = (
        constants("isotropic", longer.parameters, h)["E_Pa"]
        - constants("isotropic", fitted.parameters, h)["E_Pa"]
    )
    assert fitted.chi2_reduced > 1e3 and moved == pytest.approx(2.0e9, rel=0.1)
    assert part == pytest.approx(abs(moved), rel=0.2)
    # nu held (as the loop holds a parameter it kept inside its box): the shift moves the
    # others alone, as the refit with nu held does
    from vibid.identify.assess.budget import estimate_shifts
    from vibid.identify.assess.engineering import sensitivities

    nu = fitted.parameters["nu"]
    (shift,) = estimate_shifts(s, fitted, ["length_m"], held=("nu",)).values()
    assert shift[list(fitted.parameter_names).index("nu")] == 0.0
    keys, g, _ = sensitivities("isotropic", list(fitted.parameter_names), fitted.values, h)
    part_held = abs(g[keys.index("E_Pa")] @ shift)
    longer_held = identify(
        with_declared(s, "length_m", s.specimen.length_m + 5e-4),
        Measurement(f, H, std, used=used),
        ModelChoice(
            bounds=dict(s.identification.bounds) | {"nu": (nu - 1e-6, nu + 1e-6)},
            kinds={"nu": ("logit", nu - 1e-7, nu + 1e-7)},
        ),
        SearchOptions(method="local", start=fitted.parameters),
    )
    moved_held = (
        constants("isotropic", longer_held.parameters, h)["E_Pa"]
        - constants("isotropic", fitted.parameters, h)["E_Pa"]
    )
    assert part_held == pytest.approx(abs(moved_held), rel=0.2)
