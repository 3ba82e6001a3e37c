"""The readable report's pieces without an identification: numbers with units and
uncertainty, figures whose axes name their units, the batch summary table, the task-runner
setting and the replay command's input checks."""

import csv
import io
import re

import numpy as np
import pytest

from vibid import parameters, report
from vibid.report import plots, values


def test_values_are_rounded_to_the_second_significant_digit_of_their_std():
    assert values.with_std(17.969987, 2.0e-5) == "17.969987 ± 0.000020"
    assert values.with_std(0.2861180, 1.3e-6) == "0.2861180 ± 0.0000013"
    assert values.with_std(1.9800156e11, 1.2e5) == "(1.9800156 ± 0.0000012)e+11"
    assert values.with_std(2.0e-5, 1.5e-9) == "(2.00000 ± 0.00015)e-5"
    assert values.with_std(3.0, None) == "3"


def test_units_come_from_the_model_terms():
    assert values.unit_of("D") == "N m"
    assert values.unit_of("D11") == "N m"
    assert values.unit_of("tau_s") == "s"
    assert values.unit_of("nu") == "1"
    assert values.unit_of("E_Pa") == "Pa"


def test_measured_phase_is_drawn_within_half_a_turn_of_the_unwrapped_model():
    # a model unwrapped to -540 deg; the measurement's angle() says +180 deg: same phasor
    ph = plots.phase_near(np.radians([180.0, -170.0]), np.radians([-540.0, -190.0]))
    assert np.allclose(np.degrees(ph), [-540.0, -170.0])


def _synthetic_afc():
    f = np.linspace(10, 200, 40)
    f0, zeta = 100.0, 0.01
    H = 1 / (1 - (f / f0) ** 2 + 2j * zeta * f / f0)
    fine = np.linspace(10, 200, 2000)
    Hf = 1 / (1 - (fine / f0) ** 2 + 2j * zeta * fine / f0)
    return f, H, fine, Hf


def _units_in(label):
    return label.count("(") >= 1 and label.rstrip().endswith(")")


def test_every_figure_names_the_unit_of_every_axis(tmp_path):
    f, H, fine, Hf = _synthetic_afc()
    figs = {
        "afc": plots.afc_figure(
            f,
            H,
            np.full(f.size, 1e-3),
            model_frequency_hz=fine,
            model_H=Hf,
            natural_hz=[100.0],
            flagged=[plots.Flagged(12.0, 1.0 + 0j, "few_cycles")],
            values_text="D = 1 ± 0.1 N·m",
        ),
        "residuals": plots.residual_figure(
            [
                plots.StageResidual(
                    "declared model",
                    f,
                    300 * np.sin(f),
                    np.cos(f),
                    1e4,
                    features=((100.0, "extra_pole 100 Hz"),),
                    trend="phase falls linearly by 11° across the band",
                ),
                plots.StageResidual("+ channel_delay", f, np.sin(f), np.cos(f), 1.0),
            ]
        ),
        "convergence": plots.convergence_figure(
            [("declared model", [[1e3, 10, 1], [1e3, 5]]), ("+ channel_delay", [[1e2, 1]])]
        ),
    }
    for name, fig in figs.items():
        labels = plots.axis_labels(fig)
        assert labels, name
        assert all(_units_in(t) for t in labels), (name, labels)
        path = plots.save_png(fig, tmp_path / f"{name}.png")
        data = open(path, "rb").read()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    # one panel per loop stage, side by side; the first marks its diagnosed features
    assert len(figs["residuals"].axes) == 2
    first = figs["residuals"].axes[0]
    texts = [t.get_text() for t in first.texts]
    assert "extra_pole 100 Hz" in texts and any(t.startswith("trend: phase") for t in texts)
    assert any(list(line.get_xdata()) == [100.0, 100.0] for line in first.lines)
    assert not figs["residuals"].axes[1].texts
    # the AFC figure: |H| and phase against frequency
    ax_mag, ax_ph = figs["afc"].axes[:2]
    assert ax_ph.get_xlabel() == "frequency (Hz)"
    assert ax_mag.get_yscale() == "log"


def _report(name="s", D=17.97, tau=None):
    effects = (
        []
        if tau is None
        else [{"name": "channel_delay", "parameters": {"tau_s": {"value": tau, "std": 1e-9}}}]
    )
    stages = [
        {
            "added": None,
            "chi2_reduced": 812.0,
            "rel_rms_residual": 0.07,
            "parameters": {"D": D * 0.99, "nu": 0.3, "beta": 0.005},
        }
    ]
    if tau is not None:
        stages.append(
            {
                "added": "channel_delay",
                "chi2_reduced": 1.04,
                "rel_rms_residual": 0.002,
                "parameters": {"D": D, "nu": 0.286, "beta": 0.003, "tau_s": tau},
            }
        )
    return {
        "format": "vibid.report",
        "format_version": 1,
        "session_id": f"id-{name}",
        "declared_model": "isotropic",
        "model": "isotropic",
        "afc": {"frequency_hz": [1.0], "re": [1.0], "im": [0.0], "std": [0.1]},
        "parameters": {
            "D": {"value": D, "std": 0.01},
            "nu": {"value": 0.286, "std": 0.004},
            "beta": {"value": 0.003, "std": 2e-5},
        },
        "effects": effects,
        "loop": {"stages": stages, "unexplained_residual": False, "rounds": [[]]},
    }


def test_batch_summary_has_one_row_per_session_and_reads_back_exactly():
    reports = [_report("a", 17.97, 2e-5), _report("b", 18.0123456789), None]
    rows = [
        report.summary_row("a", reports[0]),
        report.summary_row("b", reports[1]),
        report.summary_row("c", None, error="VibidError: broken file"),
    ]
    back = list(csv.DictReader(io.StringIO(report.summary_csv(rows))))
    assert [r["session"] for r in back] == ["a", "b", "c"]
    assert float(back[1]["D"]) == 18.0123456789  # repr: exact
    assert float(back[0]["tau_s"]) == 2e-5 and back[1]["tau_s"] == ""
    assert back[0]["effects"] == "channel_delay" and back[1]["effects"] == "none"
    assert float(back[0]["chi2_reduced_before"]) == 812.0
    assert float(back[0]["chi2_reduced_after"]) == 1.04
    assert back[2]["status"] == "failed: VibidError: broken file"
    md = report.summary_table_markdown(rows)
    lines = md.strip().splitlines()
    assert len(lines) == 2 + 3
    assert "D (N·m)" in lines[0] and "tau_s (s)" in lines[0]
    assert "17.970 ± 0.010" in lines[2] and "812 → 1.04" in lines[2]


def test_summary_markdown_speaks_of_the_effect_and_what_it_changed():
    text = report.summary_markdown(_report("a", 17.97, 2e-5), figures=["afc.png"])
    assert "**channel_delay**" in text and "time skew" in text
    assert "from 812 to 1.04" in text
    assert "D +1.01 %" in text  # 17.97 against the declared fit's 17.97 * 0.99
    assert "![" in text and "(afc.png)" in text
    assert text.index("## Details") > text.index("## Identified values")


def test_markdown_console_and_ui_table_show_the_json_values_alike():
    r = _report("a", 17.97, 2e-5)
    r["engineering"] = {
        "E_Pa": {"value": 1.9800156e11, "std": 1.2e5},
        "nu": {"value": 0.2861180, "std": 1.3e-6},
        "budget": {},
    }
    md, console = report.summary_markdown(r), report.console_summary(r)
    table = {(row["quantity"], row["source"]): row for row in report.parameter_table(r)}
    json_values = (
        [(n, p, "model") for n, p in r["parameters"].items()]
        + [(n, p, "channel_delay") for n, p in r["effects"][0]["parameters"].items()]
        + [(n, p, "engineering") for n, p in r["engineering"].items() if n != "budget"]
    )
    assert len(table) == len(json_values) == 6
    for name, p, source in json_values:
        said = values.with_std(p["value"], p["std"])  # from the JSON, not through the rows
        row = table[name, source]
        assert (row["value"], row["std"], row["value ± std"]) == (p["value"], p["std"], said)
        if source != "channel_delay":
            assert f"| {name} | {parameters.describe(name)} | {said} |" in md, name
        if source != "engineering":
            line = next(t for t in console.splitlines() if t.split()[:1] == [name])
            assert said + values.unit_text(values.unit_of(name)) in line, name
    assert "(1.9800156 ± 0.0000012)e+11" in md and "(2.00000 ± 0.00010)e-5 s" in console


def test_the_budget_table_says_what_its_fit_and_discretisation_columns_hold():
    r = _report("a", 17.97, 2e-5)
    r["engineering"] = {
        "E_Pa": {"value": 1.98e11, "std": 5e9},
        "budget": {"E_Pa": {"fit": 3e9, "discretisation": 4e9}},
    }
    r["identification"] = {"uncertainty_notes": ["E_Pa's uncertainty is mostly the mesh"]}
    md = report.summary_markdown(r)
    assert "| constant | fit | discretisation |" in md and "| E_Pa | 3e+09 | 4e+09 |" in md
    (legend,) = [t for t in md.splitlines() if t.startswith("- columns: ")]
    assert legend == (
        "- columns: fit: the data's noise and the model's misfit; "
        "discretisation: the mesh's error, Richardson-extrapolated over three "
        "meshes (the shift of the estimate it causes)"
    )
    # a budget of declared quantities alone needs no legend: their columns are setup fields
    r["engineering"]["budget"] = {"E_Pa": {"thickness_m": 5e9}}
    assert "- columns:" not in report.summary_markdown(r)


def test_the_report_says_how_the_discretisation_error_was_estimated():
    """``identification.discretisation``: the three meshes, the measured order and factor
    and the signed bias per parameter, from the result; null where the fit estimated none."""
    from types import SimpleNamespace

    from vibid.identify.fit.result import DiscretisationInfo
    from vibid.report.document import discretisation_block

    info = DiscretisationInfo.of(
        SimpleNamespace(
            meshes=("20x4c3", "30x6c4", "45x9c5"),
            extrapolation=SimpleNamespace(order=5.9, factor=1.11, limited=False),
        )
    )
    result = SimpleNamespace(
        discretisation=info,
        parameter_names=("D", "nu", "beta"),
        model_error_bias=np.array([-2e-3, 4e-4, float("nan")]),
    )
    assert discretisation_block(result) == {
        "meshes": ["20x4c3", "30x6c4", "45x9c5"],
        "order": 5.9,
        "factor": 1.11,
        "limited": False,
        "bias": {"D": -2e-3, "nu": 4e-4, "beta": None},
    }
    assert discretisation_block(SimpleNamespace(discretisation=None, model_error_bias=None)) is None
    assert discretisation_block(SimpleNamespace(discretisation=info, model_error_bias=None)) is None


def test_the_figure_list_drives_the_png_files_report_md_and_the_ui(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from matplotlib.figure import Figure

    from vibid.flows.tasks import figures_markdown
    from vibid.report import figures

    def draw_extra(source):
        fig = Figure(figsize=(2, 2))
        fig.subplots().plot([0, 1], [0, source.report["parameters"]["D"]["value"]])
        return fig

    monkeypatch.setattr(
        figures,
        "FIGURES",
        (
            figures.ReportFigure("extra.png", "An extra figure", draw_extra),
            figures.ReportFigure(
                "never.png",
                "Never drawn",
                lambda _: None,
                absent="(No never figure: nothing to draw.)",
            ),
        ),
    )
    data = SimpleNamespace(setup=SimpleNamespace(specimen=SimpleNamespace(name="strip")))
    r = _report("a", 17.97, 2e-5)
    paths = report.write_lab_report(tmp_path, data, None, r)
    assert set(paths) == {"extra.png", "report.md", "report.json"}
    md = open(paths["report.md"], encoding="utf-8").read()
    assert "![An extra figure](extra.png)\n\n*An extra figure*" in md
    assert "(No never figure: nothing to draw.)" in md and "never.png" not in md
    ui = figures_markdown(tmp_path)
    assert "![An extra figure](data:image/png;base64," in ui and "*An extra figure*" in ui
    assert "Never drawn" not in ui


def _html(markdown_text):
    markdown_it = pytest.importorskip("markdown_it")
    return markdown_it.MarkdownIt("commonmark").enable("table").render(markdown_text)


def test_where_a_residual_remains_the_report_names_what_came_closest_and_why_not():
    """A real strip's report whose loop left a residual: of the refits it compared and did
    not choose, the one that took most of the misfit is named first, its share from the
    stage's chi2; a candidate not refitted, or from a report of the earlier loop's rule
    verdicts, is none; and the report says how many points a left-out top took from the
    fit."""
    r = _report("a", 17.97)
    r["loop"]["unexplained_residual"] = True
    r["identification"] = {"dof": 1000}
    tried = {"score": 1e5, "p_value": 0.0, "kept": False}
    r["loop"]["rounds"] = [
        [
            tried
            | {
                "candidate": "stand_resonance",
                "delta_chi2": 1.0e5,
                "verdict": "less_probable",
                "note": "compared: probability 0.01, against 0.98 for stopping here",
            },
            tried
            | {
                "candidate": "fixture_resonance",
                "delta_chi2": 4.06e5,
                "verdict": "less_probable",
                "note": "compared: probability 0.01, against 0.98 for stopping here",
            },
            tried
            | {
                "candidate": "anisotropy",
                "delta_chi2": None,
                "verdict": "no_mode_pattern",
                "note": "not refitted",
            },
            # a report written by the earlier loop: its rule verdicts are no close call
            tried
            | {
                "candidate": "clamp_compliance",
                "delta_chi2": 9e5,
                "verdict": "at_null",
                "note": "the refit takes it to its null value",
            },
        ]
    ]
    r["afc"]["frequency_hz"] = [150.0, 190.0, 200.0, 300.0]
    r["linearity"] = [{"left_out_hz": [178.1, 216.3], "note": "..."}]
    text = report.summary_markdown(r)
    closest = text[text.index("What came closest") : text.index("## Fit quality")]
    assert closest.index("fixture_resonance") < closest.index("stand_resonance")
    assert "(χ² −4.06e+05, 50 % of the misfit): compared: probability 0.01" in closest
    assert "anisotropy" not in closest and "clamp_compliance" not in closest
    assert "AFC points used: 2 of 4 (178.1-216.3 Hz left out" in text
    r["loop"]["unexplained_residual"] = False  # a fit to the noise: nothing to name
    assert "What came closest" not in report.summary_markdown(r)


def test_the_residual_diagnosis_is_one_list_with_one_bullet_per_stage():
    r = _report("a", 17.97, 2e-5)
    r["loop"]["diagnosis"] = [
        [{"kind": "trend", "f_hz": None, "note": "phase falls linearly by 11° across the band"}],
        [],
    ]
    html = _html(report.summary_markdown(r))
    start = html.index("What the residual showed")
    items = html[start : html.index("</ul>", start)]
    # "- + channel_delay: ..." would be a list inside the list: two bullets
    assert items.count("<li>") == 2 and items.count("<ul>") == 1
    assert "channel_delay</strong>: nothing beyond the noise</li>" in items


def test_a_figure_s_alt_text_is_plain_and_its_caption_stays_visible():
    from vibid.report import figures

    captions = [fig.caption for fig in figures.FIGURES] + ["Tom's <b>bold</b> & [x] *y*"]
    assert any("'" in c for c in captions)  # the convergence figure's "optimiser's"
    for caption in captions:
        html = _html("\n".join(figures.figure_markdown(caption, "f.png")))
        (alt,) = re.findall(r'alt="([^"]*)"', html)
        assert not set(alt) & set("'\"&<>[]*_`\\"), alt  # nothing HTML would escape
        assert alt.replace("’", "'").split()[0] == caption.split()[0]
    md = "\n".join(figures.figure_markdown(figures.FIGURES[-1].caption, "convergence.png"))
    assert "*The local optimiser's χ² per iteration*" in md


def test_artifact_keys_are_stable_per_specimen():
    assert report.artifact_key("steel strip 100x20x1", "report") == "steel-strip-100x20x1-report"
    assert report.artifact_key("", "parameters") == "specimen-parameters"


def test_task_runner_setting():
    from prefect.task_runners import ThreadPoolTaskRunner
    from prefect_dask import DaskTaskRunner

    from vibid.errors import VibidError
    from vibid.flows.runners import make_task_runner

    assert isinstance(make_task_runner(None), ThreadPoolTaskRunner)
    assert isinstance(make_task_runner("threads"), ThreadPoolTaskRunner)
    r = make_task_runner("tcp://10.0.0.5:8786")
    assert isinstance(r, DaskTaskRunner) and r.address == "tcp://10.0.0.5:8786"
    with pytest.raises(VibidError, match="scheduler address"):
        make_task_runner("cluster-please")


def test_replay_command_rejects_bad_input_in_one_line(tmp_path, capsys):
    from vibid.cli import main

    assert main(["replay", str(tmp_path / "missing.h5")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("vibid replay: error:") and "no such file" in err and "\n" not in err
    assert main(["replay", str(tmp_path / "missing.h5"), "--candidates", "warp_drive"]) == 1
    assert "unknown warp_drive" in capsys.readouterr().err
    junk = tmp_path / "junk.h5"
    junk.write_text("not a session")
    assert main(["replay", str(junk)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("vibid replay: error:") and "junk.h5" in err and "\n" not in err


def test_artifacts_that_cannot_be_published_are_one_warning_and_the_flow_goes_on(monkeypatch):
    """The report is written before its Prefect artifacts: an artifact that cannot be made
    is one warning of the run's log, never the job's failure (issue 62)."""
    from types import SimpleNamespace

    from vibid.flows import tasks

    def broken(*a, **k):
        raise KeyError("E_Pa")

    said = []
    monkeypatch.setattr(tasks, "_publish", broken)
    monkeypatch.setattr(
        tasks,
        "run_logger",
        lambda: SimpleNamespace(warning=lambda fmt, *args: said.append(fmt % args)),
    )
    assert tasks.publish_artifacts({"session_id": "s"}, specimen="strip") is None
    assert said == ["the report's Prefect artifacts could not be published: KeyError: 'E_Pa'"]
