"""Figures in the Prefect UI: the report's PNGs embedded in its markdown artifact, and the
live AFC a campaign publishes as ``<specimen>-live`` while it runs (issue #29, parts 2, 3)."""

import base64
import logging
import re

import numpy as np
import pytest

from vibid.acquisition.campaign import StepProgress

pytestmark = pytest.mark.usefixtures("prefect_harness")

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
DATA_URI = re.compile(r"\]\(data:image/png;base64,([A-Za-z0-9+/=]+)\)")


def _write_png(path, color):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1))
    FigureCanvasAgg(fig)
    fig.add_subplot().plot([0, 1], [0, 1], color=color)
    fig.savefig(path, format="png", dpi=40)
    return path.read_bytes()


def _steps(n):
    return [
        StepProgress(
            index=i,
            n_steps=n,
            frequency_hz=50.0 + 10 * i,
            h_abs=1.0 + i,
            phase_deg=-20.0 * i,
            eta_s=float(n - i - 1),
        )
        for i in range(n)
    ]


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _decoded_pngs(markdown):
    return [base64.b64decode(m) for m in DATA_URI.findall(markdown)]


# -- part 2: the report's figures -----------------------------------------------------------
def test_figures_markdown_embeds_the_report_figures_in_order(tmp_path):
    from vibid.flows.tasks import figures_markdown

    residuals = _write_png(tmp_path / "residuals.png", "C1")
    afc = _write_png(tmp_path / "afc.png", "C0")
    (tmp_path / "other.png").write_bytes(afc)  # not a report figure: left out
    text = figures_markdown(tmp_path)
    assert _decoded_pngs(text) == [afc, residuals]  # AFC first, convergence missing
    assert "convergence.png" not in text
    assert figures_markdown(tmp_path / "nothing-here") == ""


def test_figures_markdown_links_a_too_large_figure(tmp_path, monkeypatch):
    from vibid.flows import tasks

    _write_png(tmp_path / "afc.png", "C0")
    monkeypatch.setattr(tasks, "MAX_EMBEDDED_PNG_BYTES", 10)
    text = tasks.figures_markdown(tmp_path)
    assert "data:image" not in text and str(tmp_path / "afc.png") in text


# -- part 3: the live AFC ---------------------------------------------------------------------
def test_live_afc_publishes_every_update_without_a_throttle():
    from vibid.flows.live import LiveAfc

    published = []
    live = LiveAfc(
        "Steel strip",
        5,
        min_interval_s=0.0,
        clock=_Clock(),
        publish=lambda key, md: published.append((key, md)),
    )
    for p in _steps(5):
        live.update(p)
    assert len(published) == 5
    key, md = published[-1]
    assert key == "steel-strip-live"
    assert "steps done 5 of 5" in md
    (png,) = _decoded_pngs(md)
    assert png.startswith(PNG_MAGIC)
    assert "steps done 2 of 5 (3 to go)" in published[1][1]


def test_live_afc_throttle_publishes_the_first_and_the_last_step():
    from vibid.flows.live import LiveAfc

    clock = _Clock()
    published = []
    live = LiveAfc(
        "s", 6, min_interval_s=1e6, clock=clock, publish=lambda key, md: published.append(md)
    )
    for p in _steps(6):
        clock.t += 1.0
        live.update(p)
    assert len(published) == 2
    assert "steps done 1 of 6" in published[0] and "steps done 6 of 6" in published[1]
    assert not live.close()  # nothing new since
    # the identified model drawn over the points: one more version
    live.set_model([50.0, 100.0], [1 + 1j, 2 - 1j], label="identified model")
    assert live.close(note="campaign complete")
    assert "identified model" in published[-1] and _decoded_pngs(published[-1])


def test_live_afc_waits_by_its_own_cost():
    """A publication that took c seconds delays the next by c / 2 % at least."""
    from vibid.flows.live import LiveAfc

    clock = _Clock()
    published = []

    def slow_publish(key, md):
        clock.t += 0.1
        published.append(md)

    live = LiveAfc("s", 30, min_interval_s=0.0, clock=clock, publish=slow_publish)
    for p in _steps(30):
        live.update(p)
        clock.t += 1.0
    # 0.1 s per publication: the first two (the first does not count), then one per 5 s
    # at most, and the last step's
    assert 6 <= len(published) <= 2 + 5 + 1  # (the fake clock sums floats)
    assert sum(live.costs[1:-1]) / clock.t <= 0.02 + 0.1 / clock.t


def test_live_afc_failing_publish_warns_once_and_goes_on(caplog):
    from vibid.flows.live import LiveAfc

    calls = []

    def broken(key, md):
        calls.append(key)
        raise RuntimeError("server gone")

    logger = logging.getLogger("vibid.test-live")
    live = LiveAfc("s", 4, min_interval_s=0.0, clock=_Clock(), publish=broken, logger=logger)
    with caplog.at_level(logging.WARNING, logger="vibid.test-live"):
        for p in _steps(4):
            assert live.update(p) is False
        assert live.close(note="end") is False
    assert len(calls) == 5 and live.failed
    warnings = [r for r in caplog.records if r.name == "vibid.test-live"]
    assert len(warnings) == 1 and "server gone" in warnings[0].getMessage()


def test_live_afc_in_a_flow_reaches_the_prefect_api():
    from prefect import flow
    from prefect.artifacts import Artifact

    from vibid.flows.live import LiveAfc

    @flow(name="live-afc-test")
    def live_flow():
        live = LiveAfc("Live test plate", 3, min_interval_s=0.0, max_share=None)
        for p in _steps(3):
            live.update(p)
        return live.published

    assert live_flow() == 3
    artifact = Artifact.get("live-test-plate-live")
    assert artifact is not None and artifact.type == "markdown"
    assert "steps done 3 of 3" in artifact.data
    assert _decoded_pngs(artifact.data)[0].startswith(PNG_MAGIC)


def test_live_afc_phase_is_unwrapped_as_in_the_report():
    """The model's phase unwrapped along its grid; each measured phase within half a turn
    of it (no ±180° jump where nothing happens); without a model, the measured phases
    unwrapped along frequency. The |H| axis names the report's unit."""
    from vibid.flows.live import LiveAfc
    from vibid.report.plots import H_UNIT

    tau = 4e-3  # a pure delay: the phase falls by 1.44 turns over the band
    steps = [
        StepProgress(
            index=i,
            n_steps=9,
            frequency_hz=f,
            h_abs=1.0,
            phase_deg=float(np.degrees(np.angle(np.exp(-2j * np.pi * f * tau)))),
            eta_s=0.0,
        )
        for i, f in enumerate(np.linspace(50.0, 410.0, 9))
    ]

    def fed():
        live = LiveAfc("s", 9, min_interval_s=1e6, clock=_Clock(), publish=lambda k, md: None)
        for p in steps:
            live.update(p)
        return live

    with_model = fed()
    fine = np.linspace(50.0, 410.0, 400)
    with_model.set_model(fine, np.exp(-2j * np.pi * fine * tau))
    model_phase = with_model.model[2]
    assert np.all(np.diff(model_phase) < 0) and model_phase[-1] < -360.0
    measured, model = with_model.figure().axes[1].lines
    f, ph = measured.get_xdata(), measured.get_ydata()
    assert np.allclose(ph, np.interp(f, model.get_xdata(), model.get_ydata()), atol=1e-6)

    ax_mag, ax_ph = fed().figure().axes
    assert ax_mag.get_ylabel() == f"|H| ({H_UNIT})"
    (measured,) = ax_ph.lines
    assert np.all(np.diff(measured.get_ydata()) < 0)  # falling, never a jump up by 360


def test_a_resumed_campaigns_live_afc_starts_from_the_steps_its_file_holds():
    """The steps recorded before a crash (their AFC, as the signal stage read them from the
    file) are drawn with this process's steps, and the stand time goes on from theirs."""
    from vibid.flows.live import LiveAfc
    from vibid.hardware_mocks.records import synthetic_step
    from vibid.signal import StepRecord, afc_from_records

    fs, h = 25600.0, (2.0 + 1.0j, 3.0 - 1.0j, -1.0j)
    afc = afc_from_records(
        [
            StepRecord(
                f,
                fs,
                *synthetic_step(
                    f, hk, sample_rate_hz=fs, n_samples=6400, noise_std_m_s2=(1e-4, 1e-4), rng=i
                ),
                index=i,
            )
            for i, (f, hk) in enumerate(zip((50.0, 60.0, 70.0), h))
        ]
    )
    published = []
    live = LiveAfc(
        "s", 5, min_interval_s=1e6, clock=_Clock(), publish=lambda k, md: published.append(md)
    )
    live.add_recorded(afc, stand_time_s=7.5)
    assert sorted(live.points) == [0, 1, 2]
    for i, hk in enumerate(h):
        f, mag, phase, std = live.points[i]
        assert mag == pytest.approx(abs(hk), rel=1e-3)
        assert phase == pytest.approx(np.degrees(np.angle(hk)), abs=0.1) and 0 < std < 1e-3
    live.update(
        StepProgress(
            index=3,
            n_steps=5,
            frequency_hz=80.0,
            h_abs=1.0,
            phase_deg=0.0,
            eta_s=1.0,
            settle_s=0.5,
            record_s=0.25,
        )
    )
    assert "steps done 4 of 5 (1 to go)" in published[-1]
    assert "stand time so far: 8.2 s" in published[-1]  # 7.5 + 0.5 + 0.25
    assert len(live.figure().axes[0].lines[0].get_xdata()) == 4
