"""A resonance whose top depends on its amplitude is left out of the fit, on data vibid did
not make: the exact beam of tests/beam_sessions.py (the paper's strip, nu = 0, its 1 g
sensor) on an FFT analyser's grid, its first mode slipping at large motion
(tests/modal_slip.py: a Jenkins joint on the mode's coordinate, harmonic balance). Where
the joint sticks, the AFC is the exact linear beam's.

The reference is vibid's own declared fit of the linear beam's AFC (the same noise): the
plate model and the beam differ in form (nu comes back about -0.05 on this grid, issue #26's
``NU_ON_BEAM_DATA``), so "the truth" for vibid is what it finds on the linear structure.
Fitted whole, the slipping top bends the loss factor 2.6-fold and D by 6 std of that
reference; with the top left out the fit is the linear structure's, within its std."""

import math

import numpy as np
import pytest

import beam_reference as beam
import beam_sessions as bs
import modal_slip
from loop_data import noisy
from vibid.identify.assess.linearity import linear_part
from vibid.identify.fit import Measurement, SearchOptions, identify

F = np.arange(40.0, 600.0, 0.05)  # two bending modes, 20 points per Hz


def _beam_kw():
    r = bs.setup().sensors.response
    return dict(
        L=bs.L,
        EI=bs.TRUTH["D"] * bs.W * (1 + 1j * bs.TRUTH["beta"]),
        rhoA=bs.RHO * bs.H_M * bs.W,
        rhoI=bs.RHO * bs.H_M**3 / 12 * bs.W,
        x_s=r.x_m,
        m=r.mass_kg,
        J=r.mass_kg * (r.radius_m**2 / 4 + bs.H_M**2 / 12),
    )


def _f1_hz():
    kw = _beam_kw()
    return beam.natural_frequencies_hz(1, **(kw | {"EI": kw["EI"].real}))[0]


@pytest.fixture(scope="module")
def afcs():
    """(linear beam H, std), (slipping beam H, std): the same noise draw."""
    omega = 2 * math.pi * F
    linear = noisy(beam.afc(omega, **_beam_kw()), 0)
    slipping = noisy(modal_slip.afc(omega, kappa=0.05, slip=0.1, f1_hz=_f1_hz(), **_beam_kw()), 0)
    return linear, slipping


def test_the_slipping_top_is_found_and_only_it_is_left_out(afcs):
    (H_lin, _), (H, sd) = afcs
    used, tests = linear_part(F, H, sd)
    first, second = tests
    f1 = _f1_hz()
    assert not first.linear and second.left_out_hz is None
    lo, hi = first.left_out_hz
    assert lo < f1 < hi and hi - lo < 0.2 * f1  # the top, not the resonance's band
    differs = np.abs(H - H_lin) > 1e-9 * np.abs(H_lin)  # where the joint slips
    assert not np.any(differs & used)  # every slipping point is left out
    assert (~used).sum() < 0.03 * F.size
    f_fl, q_fl, _ = first.flanks  # the flanks: the stuck (linear) mode
    assert f_fl == pytest.approx(f1, rel=5e-4)
    assert q_fl == pytest.approx(1 / bs.TRUTH["beta"], rel=0.05)
    assert first.top[1] < q_fl / 3  # the top: damped several times more
    assert "left out of the fit" in first.left_out_note


def test_a_fit_of_the_linear_part_is_the_linear_structures_and_the_whole_band_is_not(afcs):
    (H_lin, sd_lin), (H, sd) = afcs
    setup = bs.setup()
    reference = identify(
        setup, Measurement(F, H_lin, sd_lin), search=SearchOptions(restarts=1, seed=0)
    )
    used, _ = linear_part(F, H, sd)
    part = identify(
        setup, Measurement(F, H, sd, used=used), search=SearchOptions(restarts=1, seed=0)
    )
    whole = identify(setup, Measurement(F, H, sd), search=SearchOptions(restarts=1, seed=0))
    assert reference.chi2_reduced < 1.1 and part.chi2_reduced < 1.1
    assert whole.chi2_reduced > 100

    def off(result, name):  # in combined std of result and reference
        return abs(result.parameters[name] - reference.parameters[name]) / math.hypot(
            result.parameter_std[name], reference.parameter_std[name]
        )

    for name in ("D", "nu", "beta"):
        assert off(part, name) < 2.0, name
    assert part.parameters["beta"] == pytest.approx(bs.TRUTH["beta"], rel=0.01)
    assert whole.parameters["beta"] > 2 * bs.TRUTH["beta"]  # the slip's loss, read as the plate's
    assert off(whole, "D") > 5 and off(whole, "beta") > 100


def test_the_pipeline_leaves_the_top_out_and_says_so_unless_asked_not_to(afcs, tmp_path):
    from vibid.pipeline import SessionAfc, build_session_report, identify_afc
    from vibid.signal.imported import ImportedAfc

    _, (H, sd) = afcs
    data = SessionAfc(bs.setup(), "slipping-beam", ImportedAfc(F, H, sd, "slipping-beam"))
    found = identify_afc(data, loop=False, restarts=1)
    assert found.summary.startswith("left out of the fit: ")
    report = build_session_report(data, found)
    first = report["linearity"][0]
    lo, hi = first["left_out_hz"]
    assert lo < _f1_hz() < hi
    assert any(w.startswith("left out of the fit") for w in report["identification"]["warnings"])
    assert report["identification"]["chi2_reduced_data_weights"] < 1.1
    assert found.result.parameters["beta"] == pytest.approx(bs.TRUTH["beta"], rel=0.01)

    kept = identify_afc(data, loop=False, restarts=1, nonlinear_tops=True)
    assert "left out" not in kept.summary
    assert "left_out_hz" not in build_session_report(data, kept)["linearity"][0]
    assert kept.result.parameters["beta"] > 2 * bs.TRUTH["beta"]
    # a report built from the fit alone tests the resonances itself, and leaves nothing out
    from vibid.identify.assess import assess
    from vibid.report import build_report

    (alone, *_) = build_report(kept.result, assess(kept.result))["linearity"]
    assert not alone["linear"] and "left_out_hz" not in alone


def test_vibid_identify_writes_a_readable_report_that_shows_the_band_left_out(afcs, tmp_path):
    """`vibid identify --afc … --report DIR`: the console's first line, report.md's linearity
    note and the AFC figure (drawn) say which band was left out."""
    import dataclasses
    import json

    from vibid.cli import main

    _, (H, sd) = afcs
    csv = tmp_path / "afc.csv"
    np.savetxt(
        csv,
        np.column_stack([F, H.real, H.imag, sd]),
        delimiter=",",
        header="frequency_hz,re,im,std",
        comments="",
    )
    setup = dataclasses.replace(bs.setup(), excitation=None)  # the AFC was measured elsewhere
    (tmp_path / "setup.json").write_text(json.dumps(setup.to_dict()))
    out = tmp_path / "report"
    assert (
        main(
            [
                "identify",
                "--afc",
                str(csv),
                "--setup",
                str(tmp_path / "setup.json"),
                "--no-loop",
                "--restarts",
                "1",
                "--no-progress",
                "--report",
                str(out),
            ]
        )
        == 0
    )
    text = (out / "report.md").read_text()
    assert "Hz, is left out of the fit)" in text and "left out of the fit: " in text
    assert (out / "afc.png").stat().st_size > 10_000
    lo, hi = json.loads((out / "report.json").read_text())["linearity"][0]["left_out_hz"]
    assert lo < _f1_hz() < hi
