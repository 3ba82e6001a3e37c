"""The flows end to end on small simulated sessions, under one Prefect test server.

`vibid replay` (the replay flow) gives the report of `vibid identify` on the same session,
valid against shared/spec/report-format.md, plus a report folder whose report.md links
non-empty PNGs; the stage tasks run as plain functions (`task.fn`); a batch over three
sessions on a two-worker local Dask cluster equals the single replays.

Sessions: the paper's strip, 21 short steps (the 30 Hz one too short to fit: flagged), the
full FE model at the identification's own accuracy (the flows are the point here, not the
model's independence). Session A has an undeclared channel delay for the loop to find.
"""

import dataclasses
import json
import math
import os

import numpy as np
import pytest

from vibid.cli import main
from vibid.errors import VibidError

pytestmark = pytest.mark.usefixtures("prefect_harness")

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
TAU_S = 2e-5
FREQUENCIES_HZ = (30.0,) + tuple(45.0 * k for k in range(1, 21))
SPECIMEN_KEY = "steel-strip-100x20x1"
LOOP_OPTIONS = ["--candidates", "channel_delay", "--restarts", "1"]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    from vibid.hardware_mocks.simulated_session import StandConditions, simulate_session
    from vibid.setup_model import example_setup

    s = example_setup()
    s = dataclasses.replace(
        s, excitation=dataclasses.replace(s.excitation, frequencies_hz=FREQUENCIES_HZ)
    )
    folder = tmp_path_factory.mktemp("flows")
    out = {}
    for name, params, seed in (
        ("A", TRUTH | {"tau_s": TAU_S}, 1),
        ("B", TRUTH, 2),
        ("C", TRUTH, 3),
    ):
        out[name] = simulate_session(
            folder / f"session-{name}.h5",
            s,
            params,
            seed=seed,
            conditions=StandConditions(record_s=0.05),
            accuracy="default",
        )
    return out


def _read(path):
    with open(path) as fh:
        return json.load(fh)


@pytest.fixture(scope="module")
def identified_cli(sessions, tmp_path_factory):
    path = tmp_path_factory.mktemp("identify") / "report.json"
    rc = main(["identify", sessions["A"], "--json", str(path), "--no-progress", *LOOP_OPTIONS])
    return rc, _read(path)


@pytest.fixture(scope="module")
def replayed_cli(sessions, tmp_path_factory):
    folder = tmp_path_factory.mktemp("replay")
    path, report_dir = folder / "report.json", folder / "report"
    rc = main(
        ["replay", sessions["A"], "--json", str(path), "--report", str(report_dir), *LOOP_OPTIONS]
    )
    return rc, _read(path), report_dir


@pytest.fixture(scope="module")
def stages_b(sessions, tmp_path_factory):
    """Session B through the three stage tasks' bodies (``task.fn``), no loop."""
    from vibid.flows.tasks import afc_task, identify_task, report_task

    data = afc_task.fn(sessions["B"])
    identified = identify_task.fn(data, loop=False, restarts=1)
    report, paths = report_task.fn(
        data, identified, report_dir=tmp_path_factory.mktemp("stages") / "B"
    )
    return data, identified, report, paths


# -- the report's format ----------------------------------------------------------------------
def _number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _check_value_std(block):
    assert set(block) >= {"value", "std"}
    assert _number(block["value"]) and (block["std"] is None or _number(block["std"]))


def check_report_format(report):
    """The keys and types of shared/spec/report-format.md (version 1)."""
    assert report["format"] == "vibid.report"
    assert type(report["format_version"]) is int and report["format_version"] == 1
    for key in ("session_id", "declared_model", "model"):
        assert isinstance(report[key], str) and report[key]
    afc = report["afc"]
    n = len(afc["frequency_hz"])
    assert n > 0 and all(len(afc[k]) == n for k in ("re", "im", "std"))
    assert all(_number(x) for k in ("frequency_hz", "re", "im") for x in afc[k])
    assert all(x is None or _number(x) for x in afc["std"])
    assert isinstance(report["parameters"], dict) and report["parameters"]
    for block in report["parameters"].values():
        _check_value_std(block)
    assert isinstance(report["effects"], list)
    for e in report["effects"]:
        assert isinstance(e["name"], str) and isinstance(e["parameters"], dict)
        for block in e["parameters"].values():
            _check_value_std(block)
    loop = report["loop"]
    assert isinstance(loop["unexplained_residual"], bool)
    assert loop["stages"] and loop["stages"][0]["added"] is None
    for st, e in zip(loop["stages"][1:], report["effects"]):
        assert st["added"] == e["name"]
    for st in loop["stages"]:
        assert _number(st["chi2_reduced"]) and _number(st["rel_rms_residual"])
        assert all(_number(v) for v in st["parameters"].values())


def _rel(a, b):
    return abs(a - b) / abs(b)


# -- replay ------------------------------------------------------------------------------------
def test_replay_writes_a_report_in_the_format_and_finds_the_delay(replayed_cli):
    rc, report, _ = replayed_cli
    assert rc == 0
    check_report_format(report)
    assert [e["name"] for e in report["effects"]] == ["channel_delay"]
    tau = report["effects"][0]["parameters"]["tau_s"]
    assert abs(tau["value"] - TAU_S) < 5 * tau["std"] + 1e-3 * TAU_S
    before, after = (st["chi2_reduced"] for st in report["loop"]["stages"])
    assert before > 1e3 and after < 2.0
    # the 30 Hz step is a cycle and a half: flagged, so not in the fitted AFC
    assert len(report["afc"]["frequency_hz"]) == len(FREQUENCIES_HZ) - 1


def test_replay_gives_the_report_of_identify(identified_cli, replayed_cli):
    rc_i, ident = identified_cli
    rc_r, replay, _ = replayed_cli
    assert rc_i == rc_r == 0
    assert replay["session_id"] == ident["session_id"]
    assert replay["afc"]["frequency_hz"] == ident["afc"]["frequency_hz"]
    assert replay["afc"]["re"] == ident["afc"]["re"] and replay["afc"]["im"] == ident["afc"]["im"]
    assert set(replay["parameters"]) == set(ident["parameters"])
    for name, p in ident["parameters"].items():
        assert _rel(replay["parameters"][name]["value"], p["value"]) <= 1e-12, name
        assert _rel(replay["parameters"][name]["std"], p["std"]) <= 1e-9, name
    assert [e["name"] for e in replay["effects"]] == [e["name"] for e in ident["effects"]]
    for a, b in zip(replay["loop"]["stages"], ident["loop"]["stages"]):
        assert a["added"] == b["added"]
        assert _rel(a["chi2_reduced"], b["chi2_reduced"]) <= 1e-9


def test_replay_calibrates_the_clamp_as_identify_does(sessions, tmp_path, capsys):
    """``--reference-E`` through the Prefect flow: the report's ``reference`` block is the
    one ``vibid identify --reference-E`` writes for the same session (the calibration
    itself is checked on an exact beam in test_reference_specimen.py). A bending resonance
    goes as sqrt(E) / L², so a reference modulus 4 % above the identified one asks a free
    length (206 / 198)^¼ = 1.0100 times the declared one (1.00985: the sensor's mass bends
    that law by 1e-4 here). A bad reference is one line, before Prefect starts."""
    from vibid.flows import replay_flow

    options = ["--no-loop", "--restarts", "1"]
    path = tmp_path / "identify.json"
    assert (
        main(
            [
                "identify",
                sessions["B"],
                "--json",
                str(path),
                "--no-progress",
                *options,
                "--reference-E",
                "206e9",
                "--reference-E-std",
                "4e9",
            ]
        )
        == 0
    )
    by_identify = _read(path)["reference"]
    report = replay_flow(
        sessions["B"], loop=False, restarts=1, reference_E_pa=206e9, reference_E_std_pa=4e9
    )
    block = report["reference"]
    assert set(block) == set(by_identify)
    for key in ("free_length_m", "free_length_std_m", "declared_length_m"):
        assert block[key] == pytest.approx(by_identify[key], rel=1e-9)
    E = report["engineering"]["E_Pa"]["value"]
    assert block["free_length_m"] / block["declared_length_m"] == pytest.approx(
        (206e9 / E) ** 0.25, rel=5e-4
    )
    capsys.readouterr()
    assert main(["replay", sessions["B"], "--reference-E=-5e9"]) == 1
    err = capsys.readouterr().err.strip()
    assert "the reference modulus must be a positive number of Pa" in err
    assert len(err.splitlines()) == 1
    with pytest.raises(VibidError, match="^reference_E_std_pa goes with reference_E_pa$"):
        replay_flow(sessions["B"], loop=False, restarts=1, reference_E_std_pa=4e9)


def test_replay_report_folder_links_its_figures(replayed_cli):
    _, report, folder = replayed_cli
    text = (folder / "report.md").read_text()
    for name in ("afc.png", "residuals.png", "convergence.png"):
        assert f"]({name})" in text, name
        data = (folder / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    assert _read(folder / "report.json")["parameters"] == report["parameters"]
    # the lab's language: values with units and std, the effect and what it changed
    assert "| D | bending stiffness |" in text and "N·m" in text and " ± " in text
    assert "**channel_delay**" in text and "χ²/dof went from" in text
    assert "## Details" in text


def test_replay_publishes_artifacts_keyed_by_specimen(replayed_cli):
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterKey

    _, report, _ = replayed_cli
    with get_client(sync_client=True) as client:
        found = client.read_artifacts(
            artifact_filter=ArtifactFilter(
                key=ArtifactFilterKey(any_=[f"{SPECIMEN_KEY}-report", f"{SPECIMEN_KEY}-parameters"])
            )
        )
    # other replays in this Prefect server publish under the same specimen's keys: this
    # run's are the ones of its session and its identified D
    reports = [
        a for a in found if a.key == f"{SPECIMEN_KEY}-report" and report["session_id"] in a.data
    ]
    assert reports and all(a.type == "markdown" for a in reports)
    assert any("channel_delay" in a.data for a in reports)
    tables = [a for a in found if a.key == f"{SPECIMEN_KEY}-parameters"]
    assert tables and all(a.type == "table" for a in tables)
    rows = [
        next(
            r
            for r in (json.loads(a.data) if isinstance(a.data, str) else a.data)
            if r["quantity"] == "D"
        )
        for a in tables
    ]
    assert any(
        d["value"] == report["parameters"]["D"]["value"] and d["unit"] == "N m" for d in rows
    )


# -- the stages as plain functions ------------------------------------------------------------
def test_stage_tasks_write_figures_whose_axes_carry_units(stages_b):
    from vibid.identify.assess.curve import model_curve
    from vibid.report import draw_figures, plots

    data, identified, report, paths = stages_b
    check_report_format(report)
    curve = model_curve(data.setup, identified.result)
    figs = draw_figures(data, identified, report, curve=curve)
    assert set(figs) == {"afc.png", "residuals.png", "convergence.png"}
    for name, fig in figs.items():
        labels = plots.axis_labels(fig)
        assert labels and all("(" in t and t.endswith(")") for t in labels), (name, labels)
    assert os.path.getsize(paths["afc.png"]) > 10_000
    assert "](afc.png)" in open(paths["report.md"]).read()


def test_the_model_is_drawn_on_a_fine_grid_through_its_resonances(stages_b):
    from vibid.identify import natural_frequencies
    from vibid.identify.assess.curve import model_curve as fine_model

    data, identified, _, _ = stages_b
    result = identified.result
    grid, H, natural = fine_model(data.setup, result)
    assert grid.size >= 2000 and np.all(np.diff(grid) > 0)
    fn, _ = natural_frequencies(data.setup, result.parameters, 6)
    assert np.allclose(natural, fn[(fn >= grid[0]) & (fn <= grid[-1])])
    # the first resonance (about 75 Hz) lies between two steps: the fine grid draws its
    # peak far above every measured point
    u = result.used
    near = np.abs(grid - natural[0]) < 1.0
    steps_near = np.abs(result.frequency_hz[u] - natural[0]) < 30.0
    assert steps_near.sum() >= 2
    assert np.abs(H[near]).max() > 20 * np.abs(result.H[u][steps_near]).max()
    # away from the resonances the fine model is the fitted one
    f_used = result.frequency_hz[u]
    away = np.min(np.abs(f_used[:, None] - natural[None, :]), axis=1) > 30
    on = np.interp(f_used[away], grid, H.real) + 1j * np.interp(f_used[away], grid, H.imag)
    fitted = result.model_afc[u][away]
    assert np.max(np.abs(on - fitted) / np.abs(fitted)) < 1e-3


def test_the_live_afc_draws_the_identified_model_on_the_report_s_fine_grid(stages_b, monkeypatch):
    """The live AFC's last version: the identified model on fine_model's grid (its
    resonance peaks at their height, not straight lines between the steps), computed once
    by set_identified; drawing it computes nothing more."""
    from vibid.flows.live import LiveAfc
    from vibid.identify.assess.curve import model_curve as fine_model

    data, identified, _, _ = stages_b
    result = identified.result
    live = LiveAfc("s", 1, min_interval_s=0.0, publish=lambda key, md: None)
    u = np.asarray(result.used, bool)
    for i, (f, H) in enumerate(zip(result.frequency_hz[u], result.H[u])):
        live.points[i] = (float(f), float(abs(H)), float(np.degrees(np.angle(H))), None)
    live.set_identified(result, data.setup)
    assert not live.failed
    grid, H, natural = fine_model(data.setup, result)
    f, mag, phase, label = live.model
    assert np.array_equal(f, grid) and np.allclose(mag, np.abs(H)) and label == "identified model"
    assert np.abs(np.diff(phase)).max() < 90  # unwrapped along the grid
    near = np.abs(grid - natural[0]) < 1.0
    assert (
        mag[near].max()
        > 20 * np.abs(result.H[u][np.abs(result.frequency_hz[u] - natural[0]) < 30]).max()
    )
    # drawing it computes nothing more (no wall clock: the suite runs under load)
    import vibid.identify.assess.curve as curve

    def no_model(*a, **k):
        raise AssertionError("render_png computed the model again")

    monkeypatch.setattr(curve, "model_curve", no_model)
    assert live.render_png().startswith(b"\x89PNG")


# -- batch on Dask -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def single_replays(sessions, stages_b):
    from vibid.flows import replay_flow

    out = {"B": stages_b[2]}
    for name in ("A", "C"):
        out[name] = replay_flow(sessions[name], loop=False, restarts=1)
    return out


@pytest.fixture(scope="module")
def batch(sessions, tmp_path_factory):
    from distributed import LocalCluster

    from vibid.flows import batch_replay_flow

    folder = tmp_path_factory.mktemp("batch")
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        result = batch_replay_flow(
            [sessions[k] for k in "ABC"],
            report_dir=folder,
            task_runner=cluster,
            loop=False,
            restarts=1,
        )
    return result, folder


def test_batch_on_a_dask_cluster_equals_single_replays(batch, single_replays):
    result, folder = batch
    assert result.errors == ("", "", "")
    for name, report in zip("ABC", result.reports):
        check_report_format(report)
        single = single_replays[name]
        assert report["session_id"] == single["session_id"]
        for p, block in single["parameters"].items():
            assert _rel(report["parameters"][p]["value"], block["value"]) <= 1e-12, (name, p)
        assert (folder / f"session-{name}" / "report.md").exists()


def test_batch_summary_table(batch):
    import csv

    result, folder = batch
    with open(folder / "summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["session"] for r in rows] == ["session-A", "session-B", "session-C"]
    for row, report in zip(rows, result.reports):
        assert float(row["D"]) == report["parameters"]["D"]["value"]
        assert float(row["D_std"]) == report["parameters"]["D"]["std"]
        assert float(row["chi2_reduced_after"]) == report["loop"]["stages"][-1]["chi2_reduced"]
    md = (folder / "summary.md").read_text()
    assert md.count("| session-") == 3 and "D (N·m)" in md


# -- UFF58 and |H| alone through the replay flow --------------------------------------------------
def test_replay_flow_writes_and_reads_uff58_and_fits_the_magnitude(sessions, tmp_path):
    """The replay flow writes the AFC it identifies as UFF58, and identifies that file (an
    AFC from elsewhere, with the session's setup) to the same parameters; both fits on
    |H| alone. Session A's undeclared delay is in the phase, so |H| needs no effect."""
    from vibid.flows import replay_flow

    uff = tmp_path / "A.uff"
    first = replay_flow(
        sessions["A"], uff_path=uff, magnitude_only=True, restarts=1, candidates="sensor_gain"
    )
    again = replay_flow(
        afc_path=uff,
        setup_path=sessions["A"],
        magnitude_only=True,
        restarts=1,
        candidates="sensor_gain",
    )
    for report in (first, again):
        check_report_format(report)
        assert report["identification"]["data"] == "magnitude"
        assert report["effects"] == [] and report["loop"]["unexplained_residual"] is False
    n = len(first["afc"]["frequency_hz"])
    assert first["identification"]["dof"] == n - 3 == again["identification"]["dof"]
    for p, block in first["parameters"].items():
        assert _rel(again["parameters"][p]["value"], block["value"]) <= 1e-6, p
        assert abs(block["value"] - TRUTH[p]) < 3 * block["std"], p
    with pytest.raises(Exception, match="session file, or an AFC file"):
        replay_flow(afc_path=uff, restarts=1)
