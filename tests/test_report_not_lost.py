"""A finished identification is never lost at a later step (issue 62, item 3).

Found: a stepped session of an isotropic metal strip whose loop ended in the orthotropic
material; ``vibid identify`` then exited 1 with ``no bounds given for D11, D12, D22, D66``,
and no report. The cause: the budget's model part judged the loop's models against the
setup's boxes, which hold none for a material the loop switched to
(:func:`vibid.identify.assess.budget.loop_box` now gives the loop's own). Whatever else fails after
the fit, the report is written, says what it could not do in one line (its ``not_done``),
and the command exits 0 when the identification converged."""

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from vibid.errors import VibidError
from vibid.identify.assess.budget import loop_box, model_spread
from vibid.identify.model.materials import Material
from vibid.identify.model.terms import PlateModel
from vibid.not_done import attempt, not_done_lines, reason
from vibid.setup_model import example_setup

TRUE = {"D": 17.97, "nu": 0.286, "beta": 0.003}
SETUP_JSON = "examples/strip_setup.json"


def _at_null(values: dict) -> dict:
    """The orthotropic plate that is the isotropic one (the anisotropy's null)."""
    D, nu = values["D"], values["nu"]
    return {"D11": D, "D12": nu * D, "D22": D, "D66": 0.5 * (1 - nu) * D, "beta": values["beta"]}


def test_the_loop_box_holds_the_box_the_loop_gave_a_material_it_switched_to():
    """The setup declares D, nu, beta; the loop's anisotropy fitted D11, D22 in D's box,
    D66 in (low/10, high/2), D12 in ±high/2. The model part of the budget is judged in
    them; with the setup's boxes alone it failed as the field run did."""
    s = example_setup()
    iso = PlateModel(Material("isotropic"))
    ortho = iso.with_material(Material("orthotropic"))

    def fit(model, values, chi2_red):
        return SimpleNamespace(
            plate_model=model,
            parameters=values,
            dof=57,
            parameter_names=tuple(values),
            values=np.array(list(values.values())),
            chi2_reduced_reported=chi2_red,
        )

    declared = fit(iso, TRUE, 9.0)
    final = fit(ortho, _at_null(TRUE) | {"D22": 16.0}, 3.0)
    loop = SimpleNamespace(
        unexplained_residual=True,
        final=final,
        alternatives=(),
        stages=[
            SimpleNamespace(added=None, result=declared, diagnosis=None),
            SimpleNamespace(added="anisotropy", result=final, diagnosis=None),
        ],
    )
    lo, hi = s.identification.bounds["D"]
    box = loop_box(s, loop)
    assert box == dict(s.identification.bounds) | {
        "D11": (lo, hi),
        "D22": (TRUE["D"] / 30, hi),
        "D66": (TRUE["D"] / 30, hi / 2),
        "D12": (-hi / 2, hi / 2),
    }
    assert loop_box(s, None) == dict(s.identification.bounds)
    with pytest.raises(VibidError, match="no bounds given for D11, D12, D22, D66"):
        model_spread(
            loop, "orthotropic", s.specimen.thickness_m, box=dict(s.identification.bounds)
        )  # the field run's failure
    spread = model_spread(loop, "orthotropic", s.specimen.thickness_m, box=box)
    assert set(spread) == {"E1_Pa", "E2_Pa", "G12_Pa", "nu12"}
    assert spread["E1_Pa"] == pytest.approx(0.0, abs=1e-6)  # one orthotropic model alone


@pytest.fixture(scope="module")
def strip():
    """The steel strip fitted (local, from the truth) to its own AFC with a 1 % ripple
    that no model explains: (setup, result)."""
    from vibid.identify import build_forward_model, configure
    from vibid.identify.fit import Measurement, SearchOptions, identify

    configure()
    s = example_setup()
    f = np.linspace(20.0, 1500.0, 60)
    fm = build_forward_model(s, f, theta0=TRUE)
    H = np.asarray(fm.afc(np.array(list(TRUE.values())))) * (1 + 0.01 * np.sin(f / 50))
    return s, identify(
        s,
        Measurement(f, H, 0.003 * np.abs(H) + 1e-4),
        search=SearchOptions(method="local", start=TRUE),
    )


def _orthotropic_copy(result):
    """``result`` (isotropic) as the orthotropic plate at its null, with the covariance
    carried through the map (D, nu, beta) -> (D11, D12, D22, D66, beta)."""
    D, nu = result.parameters["D"], result.parameters["nu"]
    G = np.array([[1, 0, 0], [nu, D, 0], [1, 0, 0], [0.5 * (1 - nu), -0.5 * D, 0], [0, 0, 1]])
    cov = G @ np.asarray(result.covariance) @ G.T
    std = np.sqrt(np.diag(cov))
    values = _at_null(result.parameters)
    return dataclasses.replace(
        result,
        model="orthotropic",
        parameter_names=tuple(values),
        values=np.array(list(values.values())),
        std=std,
        covariance=cov,
        correlation=cov / np.outer(std, std),
        model_error_bias=None,
        plate_model=result.plate_model.with_material(Material("orthotropic")),
    )


def test_an_orthotropic_end_of_an_isotropic_setup_has_its_report_and_budget(strip):
    """The field case: the loop ended in the orthotropic material, a residual remaining
    (so the budget weighs the models it compared, in their prior boxes). The report has
    its engineering constants with their whole budget, and nothing is left out."""
    from vibid.identify.assess import assess
    from vibid.identify.loop.verdicts import LoopResult, Stage
    from vibid.report import build_report

    s, iso = strip
    ortho = _orthotropic_copy(iso)
    loop = LoopResult((Stage.of(None, iso), Stage.of("anisotropy", ortho)), (), True)
    report = build_report(ortho, assess(ortho, loop, s), loop=loop)
    assert report["not_done"] == []
    eng = report["engineering"]
    E = 12 * iso.parameters["D"] * (1 - iso.parameters["nu"] ** 2) / s.specimen.thickness_m**3
    assert eng["E1_Pa"]["value"] == pytest.approx(E, rel=1e-9)  # the null is the strip
    assert {"fit", "model", "clamp_line"} <= set(eng["budget"]["E1_Pa"])
    assert report["model"] == "orthotropic" and "plausibility" in report


def test_a_stage_that_fails_is_one_line_and_the_rest_is_written(tmp_path, monkeypatch, capsys):
    """``vibid identify`` whose budget fails as the field run's did, whose AFC figure and
    reference calibration fail too: exit 0, report.json (both) and report.md written with
    the fit's values and the constants (the fit's std alone), each failure one line in
    the console and in the report."""
    from vibid.cli import main
    from vibid.identify import build_forward_model
    from vibid.pipeline import read_setup

    setup = read_setup(SETUP_JSON)
    f = np.linspace(20.0, 1500.0, 60)
    H = np.asarray(build_forward_model(setup, f, theta0=TRUE).afc(np.array(list(TRUE.values()))))
    afc = tmp_path / "afc.csv"
    afc.write_text(
        "frequency_hz,re,im,std\n"
        + "".join(
            f"{fi:.17g},{h.real:.17g},{h.imag:.17g},{0.003 * abs(h) + 1e-4:.17g}\n"
            for fi, h in zip(f, H)
        )
    )

    from vibid.identify import fit
    from vibid.identify.assess import budget, curve, reference

    real = fit.identify

    def local_from_truth(setup, measured, model=fit.ModelChoice(), search=fit.SearchOptions()):
        search = dataclasses.replace(search, method="local", start=TRUE)
        return real(setup, measured, model, search)

    monkeypatch.setattr(fit, "identify", local_from_truth)  # the global search's minutes saved

    def no_bounds(*a, **k):
        raise VibidError("no bounds given for D11, D12, D22, D66")

    def broken(*a, **k):
        raise KeyError("D11")

    monkeypatch.setattr(budget, "engineering_budget", no_bounds)
    monkeypatch.setattr(reference, "calibrate_free_length", broken)
    monkeypatch.setattr(curve, "model_curve", broken)
    out, folder = tmp_path / "r.json", tmp_path / "report"
    rc = main(
        [
            "identify",
            "--afc",
            str(afc),
            "--setup",
            SETUP_JSON,
            "--json",
            str(out),
            "--report",
            str(folder),
            "--no-loop",
            "--no-progress",
            "--reference-E",
            "2e11",
        ]
    )
    captured = capsys.readouterr()
    console = captured.out
    assert rc == 0, captured.err
    report = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(c))
    assert report == json.loads((folder / "report.json").read_text())
    assert report["not_done"] == [
        {"stage": "reference", "reason": "KeyError: 'D11'"},
        {"stage": "uncertainty budget", "reason": "no bounds given for D11, D12, D22, D66"},
        {"stage": "figures", "reason": "afc.png: KeyError: 'D11'"},
    ]
    assert report["identification"]["converged"] is True
    assert report["parameters"]["D"]["value"] == pytest.approx(TRUE["D"], rel=1e-3)
    eng = report["engineering"]  # the constants stay, with the fit's std
    assert "budget" not in eng and math.isfinite(eng["E_Pa"]["std"]) and eng["E_Pa"]["std"] > 0
    assert "plausibility" in report and "reference" not in report
    said = [line for line in console.splitlines() if line.startswith("not done:")]
    assert said == not_done_lines(report) and len(said) == 3
    assert (
        "not done: uncertainty budget (the engineering constants carry the fit's std "
        "alone): no bounds given for D11, D12, D22, D66"
    ) in said
    md = (folder / "report.md").read_text()
    assert all(line in md for line in said)
    assert (folder / "residuals.png").exists() and not (folder / "afc.png").exists()


def test_attempt_returns_the_default_and_says_why_in_one_line():
    not_done = []
    assert attempt("plausibility", not_done, lambda: 1 / 0, default={}) == {}
    assert attempt("linearity", not_done, lambda x: x + 1, 1) == 2
    assert not_done == [{"stage": "plausibility", "reason": "ZeroDivisionError: division by zero"}]
    assert reason(VibidError("two\n  lines")) == "two lines"
    with pytest.raises(ValueError, match="unknown report stage"):
        attempt("nonsense", [], lambda: None)
    with pytest.raises(KeyboardInterrupt):  # an interrupt still stops the job
        attempt("figures", [], lambda: (_ for _ in ()).throw(KeyboardInterrupt()))


def test_the_report_says_how_sure_the_loop_is(strip):
    """The criterion and, per stage, the explanations compared with their probabilities,
    the chosen first, in report.json (the format's ``loop.criterion`` and
    ``loop.stages[].alternatives``) and in report.md."""
    from dataclasses import replace

    from vibid.identify.assess import assess
    from vibid.identify.loop.verdicts import LoopResult, Stage
    from vibid.report import build_report
    from vibid.report.markdown import summary_markdown

    s, iso = strip
    alts = (
        {"added": "stand_resonance", "criterion": 120.0, "probability": 0.97, "f_hz": 664.0},
        {"added": "clamp_loss", "criterion": 116.5, "probability": 0.02},
        {"added": None, "criterion": 0.0, "probability": 0.01},
    )
    stop = (
        {"added": None, "criterion": 3.0, "probability": 0.9},
        {"added": "sensor_gain", "criterion": 1.0, "probability": 0.1, "estimated": True},
    )
    loop = LoopResult(
        (
            replace(Stage.of(None, iso), alternatives=alts),
            replace(Stage.of("stand_resonance", iso), alternatives=stop),
        ),
        (),
        True,
    )
    report = build_report(iso, assess(iso, loop, s), loop=loop)
    assert report["loop"]["criterion"]["name"] == "log_evidence"
    first, last = (st["alternatives"] for st in report["loop"]["stages"])
    assert [a["added"] for a in first] == ["stand_resonance", "clamp_loss", None]
    assert sum(a["probability"] for a in first) == pytest.approx(1.0)
    assert last[0]["added"] is None and last[1]["estimated"] is True
    text = summary_markdown(report)
    assert (
        "after the declared model: stand resonance at 664 Hz: 0.97; clamp loss: 0.02; "
        "stop here: 0.01" in text
    )
    assert "after + stand_resonance: stop here: 0.9; sensor gain: 0.1 (estimated)" in text
