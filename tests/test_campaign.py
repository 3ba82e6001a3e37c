"""The campaign runner on tiny fakes of the stand (tests/campaign_fakes.py): the plan, the AFC
against the fake specimen's known H, the settle rule at a sharp resonance, the drive control,
the abort limit, Ctrl-C, faults, stop requests, resume and its refusals."""

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from campaign_fakes import fake_stand, fast_config, sdof_h, short_setup  # noqa: E402
from vibid.acquisition.campaign import CampaignError, amplitude_m_s2, run_campaign  # noqa: E402
from vibid.acquisition.plan import damping_settle_s, plan_summary, record_samples, stepped_sine  # noqa: E402
from vibid.acquisition.stand_config import TimingConfig  # noqa: E402
from vibid.cli import main  # noqa: E402
from vibid.errors import VibidError  # noqa: E402
from vibid.session import file_problems, read_session  # noqa: E402
from vibid.signal import afc_from_session  # noqa: E402


def test_record_is_whole_cycles_of_at_least_the_minimum_length():
    t = TimingConfig(min_record_s=0.25, min_cycles=20)
    # 7.5 Hz: 20 cycles (2.67 s) beat 0.25 s; 1000 Hz: 250 cycles make 0.25 s
    assert record_samples(7.5, 25600.0, t) == round(20 * 25600 / 7.5)
    assert record_samples(1000.0, 25600.0, t) == 6400
    n = record_samples(333.0, 25600.0, t)
    assert n / 25600.0 >= 0.25 - 0.5 / 25600 and abs(n * 333.0 / 25600.0 - 84) < 333.0 / 25600


def test_damping_settle_is_time_constants_of_q_capped():
    t = TimingConfig(expected_loss_factor=0.01, settle_time_constants=5.0, max_settle_s=3.0)
    assert damping_settle_s(80.0, t) == pytest.approx(5 * 100 / (math.pi * 80))  # 1.989 s
    assert damping_settle_s(10.0, t) == 3.0  # 15.9 s capped


def test_dry_run_lists_every_step_with_the_setup_settle():
    setup = short_setup(12)
    summary = plan_summary(setup, fast_config())
    assert [c.index for c in summary.commands] == list(range(12))
    assert [c.frequency_hz for c in summary.commands] == list(setup.excitation.frequencies_hz)
    assert all(c.settle_s == 0.05 for c in summary.commands)
    assert summary.settle_s == pytest.approx(12 * 0.05)
    assert summary.duration_s == pytest.approx(
        summary.settle_s + sum(c.n_samples for c in summary.commands) / 25600
    )
    with pytest.raises(VibidError, match="cannot start"):
        stepped_sine(setup, fast_config(), start=13)


def test_unsettled_record_is_recorded_again_at_multiples_of_the_damping_settle():
    from vibid.acquisition.plan import StepOutcome

    cfg = fast_config(max_settle_s=10.0)
    plan = stepped_sine(short_setup(3, 70.0, 90.0), cfg)
    first = next(plan)
    d = damping_settle_s(70.0, cfg.timing)  # 2.27 s
    waits = [first.settle_s + first.record_s]
    for k in (1, 2, 3, 4):
        cmd = plan.send(StepOutcome(settled=False))
        assert (cmd.index, cmd.attempt) == (0, k)
        assert waits[-1] + cmd.settle_s == pytest.approx(
            k * d
        )  # the k-th multiple since the change
        waits.append(k * d + cmd.record_s)
    cmd = plan.send(StepOutcome(settled=False))  # 5 d passes the 10 s cap: up to the cap
    assert waits[-1] + cmd.settle_s == pytest.approx(10.0)
    assert plan.send(StepOutcome(settled=False)).index == 1


def test_unsettled_record_is_recorded_again_after_the_damping_settle():
    from vibid.acquisition.plan import StepOutcome

    setup = short_setup(3, 70.0, 90.0)
    cfg = fast_config()
    plan = stepped_sine(setup, cfg)
    first = next(plan)
    again = plan.send(StepOutcome(settled=False))
    assert (again.index, again.attempt) == (0, 1)
    assert again.settle_s == pytest.approx(
        damping_settle_s(70.0, cfg.timing) - first.settle_s - first.record_s
    )
    nxt = plan.send(StepOutcome(settled=True))  # the neighbour starts with the damping settle
    d80 = damping_settle_s(80.0, cfg.timing)
    assert nxt.index == 1 and nxt.settle_s == pytest.approx(d80)
    # still unsettled: again at twice the damping settle (3.98 s) since the change, capped at 3 s
    again = plan.send(StepOutcome(settled=False))
    assert (again.index, again.attempt) == (1, 1)
    assert again.settle_s == pytest.approx(3.0 - d80 - nxt.record_s)
    last = plan.send(StepOutcome(settled=False))  # the cap is reached: on to the next step
    assert (last.index, last.settle_s) == (2, pytest.approx(damping_settle_s(90.0, cfg.timing)))


def _zscores(path, ppm=40.0, eta=0.01):
    with read_session(path) as s:
        table = afc_from_session(s)
    h = sdof_h(table.commanded_hz * (1 + 1e-6 * ppm), eta=eta)  # at the frequency played
    return table, (table.H.real - h.real) / table.std_re, (table.H.imag - h.imag) / table.std_im


def test_campaign_afc_equals_the_specimens_h_within_its_uncertainty(tmp_path):
    path = tmp_path / "s.h5"
    stand = fake_stand(seed=3, clock_offset_ppm=-150.0)
    result = run_campaign(
        short_setup(12), stand, path, fast_config(settle_time_constants=14.0, max_settle_s=10.0)
    )
    assert (result.run_status, result.reason, result.n_steps) == ("complete", "", 12)
    table, z_re, z_im = _zscores(path, ppm=-150.0)
    assert table.used.all(), table.flags
    z = np.concatenate([z_re, z_im])
    assert np.max(np.abs(z)) < 4.5 and 0.2 < np.mean(z**2) < 3.0, z
    assert file_problems(path) == []
    assert not stand.generator.output_enabled and stand.generator.log[0] == ("shutdown",)
    assert stand.generator.log[-1] == ("shutdown",)


def test_sharp_resonance_with_a_short_settle_is_flagged_and_the_q_based_settle_avoids_it(tmp_path):
    setup = short_setup(5, 60.0, 100.0, settle_s=0.02)  # 80 Hz, the resonance, is step 2
    eta = 1 / 300
    short = tmp_path / "short.h5"
    run_campaign(
        setup,
        fake_stand(seed=1, eta=eta),
        short,
        fast_config(expected_loss_factor=eta, max_settle_s=0.0),
    )
    table, *_ = _zscores(short, eta=eta)
    assert "unsettled" in table.flags[2]
    settled = tmp_path / "settled.h5"
    run_campaign(
        setup,
        fake_stand(seed=1, eta=eta),
        settled,
        fast_config(expected_loss_factor=eta, settle_time_constants=16.0, max_settle_s=30.0),
    )
    table, z_re, z_im = _zscores(settled, eta=eta)
    assert not any("unsettled" in f for f in table.flags), table.flags
    assert np.max(np.abs(np.concatenate([z_re, z_im]))) < 4.5
    with read_session(settled) as s:
        attrs = [s.step_attributes(i) for i in range(5)]
    # 70 Hz rang on: recorded again after 16 time constants; 80 Hz, its neighbour, settled as
    # long from the start
    assert attrs[1]["vibid_resettled"] and attrs[1]["vibid_settle_s"] == pytest.approx(
        16 * 300 / (math.pi * 70)
    )
    assert not attrs[2]["vibid_resettled"] and attrs[2]["vibid_settle_s"] == pytest.approx(
        16 * 300 / (math.pi * 80)
    )
    assert attrs[0]["vibid_settle_s"] == 0.02


def test_drive_control_holds_the_base_within_tolerance_and_never_above_max_drive(tmp_path):
    path = tmp_path / "s.h5"
    gain = lambda f: 25.0 * (f / 60.0) ** -1.5  # noqa: E731 - a shaker weaker with frequency
    stand = fake_stand(seed=2, gain=gain)
    cfg = fast_config(settle_time_constants=14.0, max_settle_s=10.0)
    run_campaign(short_setup(10), stand, path, cfg)
    with read_session(path) as s:
        base = np.array(
            [amplitude_m_s2(st.base, st.frequency_hz, st.sample_rate_hz) for st in s.steps()]
        )
        drives = np.array([s.step_attributes(i)["vibid_drive_vpp"] for i in range(len(s))])
    assert np.all(np.abs(base / 5.0 - 1) <= 0.05), base
    # the drive followed the shaker: 5 m/s² / gain(f)
    freqs = np.array(short_setup(10).excitation.frequencies_hz)
    np.testing.assert_allclose(drives, 5.0 / gain(freqs), rtol=0.05)
    assert stand.generator.max_vpp_seen <= cfg.drive.max_vpp

    capped = tmp_path / "capped.h5"
    stand = fake_stand(seed=2, gain=gain)
    cfg = replace(cfg, drive=replace(cfg.drive, max_vpp=0.3))
    result = run_campaign(short_setup(10), stand, capped, cfg)
    assert result.run_status == "complete"
    assert stand.generator.max_vpp_seen == pytest.approx(0.3)
    with read_session(capped) as s:
        notes = [s.step_attributes(i).get("vibid_note", "") for i in range(len(s))]
        assert s.statuses() == ["ok"] * 10
    reachable = 0.3 * gain(freqs) >= 5.0 * 0.95
    assert [bool(n) for n in notes] == list(~reachable)
    assert "maximum 0.3 Vpp" in notes[-1]


def test_abort_limit_switches_off_writes_the_step_aborted_and_closes_with_the_reason(tmp_path):
    path = tmp_path / "s.h5"
    stand = fake_stand(seed=4)
    cfg = fast_config(settle_time_constants=14.0, max_settle_s=10.0)
    cfg = replace(
        cfg, drive=replace(cfg.drive, abort_response_m_s2=100.0)
    )  # |H| 100 at 80 Hz: 500 m/s²
    result = run_campaign(short_setup(10), stand, path, cfg)
    assert (
        result.run_status == "aborted" and "abort limit 100 m/s2 at 80 Hz (step 4)" in result.reason
    )
    assert result.n_steps == 5
    assert not stand.generator.output_enabled
    assert ("freq", 90.0) not in stand.generator.log
    assert file_problems(path) == []
    with read_session(path) as s:
        assert s.statuses() == ["ok"] * 4 + ["aborted"]
        assert (s.run_status, s.run_status_reason) == ("aborted", result.reason)


def _reference(tmp_path, n=10):
    path = tmp_path / "reference.h5"
    run_campaign(short_setup(n), fake_stand(seed=7), path, fast_config())
    return path


def assert_same_steps(path, reference):
    """Samples and attributes equal, step by step (t0_utc aside)."""
    with read_session(path) as a, read_session(reference) as b:
        assert len(a) == len(b)
        for i in range(len(a)):
            sa, sb = a.step(i), b.step(i)
            np.testing.assert_array_equal(sa.base, sb.base)
            np.testing.assert_array_equal(sa.response, sb.response)
            attrs_a, attrs_b = a.step_attributes(i), b.step_attributes(i)
            attrs_a.pop("t0_utc"), attrs_b.pop("t0_utc")
            assert attrs_a == attrs_b, i


def test_ctrl_c_leaves_output_off_and_the_file_interrupted_then_resume_completes_it(tmp_path):
    reference = _reference(tmp_path)
    path = tmp_path / "s.h5"
    stand = fake_stand(seed=7, fail_at=(3, KeyboardInterrupt()))
    result = run_campaign(short_setup(), stand, path, fast_config())
    assert (result.run_status, result.n_steps) == ("interrupted", 3)
    assert "Ctrl-C" in result.reason
    assert not stand.generator.output_enabled and stand.generator.log[-1] == ("shutdown",)
    assert file_problems(path) == []
    with read_session(path) as s:
        assert len(s) == 3 and s.run_status == "interrupted"  # the partial step is not written
    stand = fake_stand(seed=7)
    result = run_campaign(short_setup(), stand, path, fast_config(), resume=True)
    assert (result.run_status, result.n_steps) == ("complete", 10)
    assert stand.generator.log[0] == ("shutdown",)  # output off first thing on resume too
    assert_same_steps(path, reference)


def test_stand_fault_aborts_with_its_message_and_output_off(tmp_path):
    from vibid.acquisition.generator import GeneratorError

    path = tmp_path / "s.h5"
    stand = fake_stand(seed=7, fail_at=(2, GeneratorError("generator: no reply to 'FREQ 60'")))
    result = run_campaign(short_setup(), stand, path, fast_config())
    assert (
        result.run_status == "aborted"
        and result.reason == "stand fault: generator: no reply to 'FREQ 60'"
    )
    assert result.n_steps == 2 and not stand.generator.output_enabled
    with read_session(path) as s:
        assert s.run_status_reason == result.reason


def test_unexpected_error_closes_interrupted_and_is_raised(tmp_path):
    path = tmp_path / "s.h5"
    stand = fake_stand(seed=7, fail_at=(1, ZeroDivisionError("bug")))
    with pytest.raises(ZeroDivisionError):
        run_campaign(short_setup(), stand, path, fast_config())
    assert not stand.generator.output_enabled
    with read_session(path) as s:
        assert (len(s), s.run_status) == (
            1,
            "interrupted",
        ) and "ZeroDivisionError" in s.run_status_reason


def test_stop_request_ends_cleanly_between_steps(tmp_path):
    import threading

    path = tmp_path / "s.h5"
    event = threading.Event()
    seen = []

    def progress(p):
        seen.append(p)
        if p.index == 1:
            event.set()

    stand = fake_stand(seed=7, transient_scale=0.0)  # no re-records: one record a step
    result = run_campaign(short_setup(), stand, path, fast_config(), progress=progress, stop=event)
    # step 1 is written and reported while step 2 settles; step 2, measured, is written at the
    # stop, and nothing more is played
    assert (result.run_status, result.reason, result.n_steps) == (
        "interrupted",
        "stopped on request",
        3,
    )
    assert [p.index for p in seen] == [0, 1, 2] and seen[0].n_steps == 10
    assert {a[0] for a in stand.daq.acquisitions} == {0, 1, 2}
    assert seen[1].eta_s > 0 and math.isfinite(seen[1].h_abs)


def test_progress_reports_the_steps_h_and_phase(tmp_path):
    seen = []
    run_campaign(
        short_setup(),
        fake_stand(seed=7),
        tmp_path / "s.h5",
        fast_config(settle_time_constants=14.0, max_settle_s=10.0),
        progress=seen.append,
    )
    h = sdof_h(np.array([p.frequency_hz for p in seen]) * (1 + 40e-6))
    np.testing.assert_allclose([p.h_abs for p in seen], np.abs(h), rtol=2e-3)
    np.testing.assert_allclose([p.phase_deg for p in seen], np.degrees(np.angle(h)), atol=0.2)
    assert seen[-1].eta_s == 0.0 and [p.index for p in seen] == list(range(10))


def test_optional_fields_are_written_and_the_session_validates(tmp_path, capsys):
    path = tmp_path / "s.h5"
    run_campaign(
        short_setup(),
        fake_stand(seed=7),
        path,
        fast_config(),
        operator="A. Tester",
        notes="clamp torque 5 N m",
        temperature_c=21.5,
    )
    with read_session(path) as s:
        assert (s.operator, s.notes) == ("A. Tester", "clamp torque 5 N m")
        assert {st.temperature_c for st in s.steps()} == {21.5}
    assert main(["validate", str(path)]) == 0
    assert "10 steps (10 ok)" in capsys.readouterr().out


def test_resume_refuses_a_complete_file_another_setup_and_a_missing_file(tmp_path):
    reference = _reference(tmp_path)
    with pytest.raises(CampaignError, match="already complete"):
        run_campaign(short_setup(), fake_stand(), reference, fast_config(), resume=True)
    with pytest.raises(CampaignError, match="setup differs"):
        run_campaign(short_setup(11), fake_stand(), reference, fast_config(), resume=True)
    with pytest.raises(CampaignError, match="no such session file"):
        run_campaign(short_setup(), fake_stand(), tmp_path / "none.h5", fast_config(), resume=True)
    stand = fake_stand()
    with pytest.raises(CampaignError, match="already exists"):
        run_campaign(short_setup(), stand, reference, fast_config())
    assert not stand.generator.output_enabled and stand.daq.acquisitions == []
    with read_session(reference) as s:
        assert len(s) == 10 and s.run_status == "complete"


def test_bad_stand_configuration_is_refused_before_any_file_or_drive(tmp_path):
    path = tmp_path / "s.h5"
    cfg = fast_config()
    for bad in (
        replace(cfg, drive=replace(cfg.drive, initial_vpp=6.0)),  # above max_vpp 5
        replace(cfg, timing=replace(cfg.timing, min_record_s=0.0)),
    ):
        stand = fake_stand()
        with pytest.raises(VibidError, match="stand configuration"):
            run_campaign(short_setup(), stand, path, bad)
        assert (
            not path.exists()
            and stand.daq.acquisitions == []
            and not stand.generator.output_enabled
        )


def test_a_file_that_cannot_be_written_aborts_with_output_off(tmp_path, monkeypatch):
    from vibid.session import SessionWriter

    path = tmp_path / "s.h5"
    real = SessionWriter.append

    def full_disk(self, **kw):
        if self.n_steps == 2:
            raise VibidError(
                f"{self.path}: cannot write the session file (No space left on device)"
            )
        return real(self, **kw)

    monkeypatch.setattr(SessionWriter, "append", full_disk)
    stand = fake_stand(seed=7)
    result = run_campaign(short_setup(), stand, path, fast_config())
    assert result.run_status == "aborted" and result.reason.endswith("(No space left on device)")
    assert not result.reason.startswith("stand fault") and result.n_steps == 2
    assert not stand.generator.output_enabled
    with read_session(path) as s:
        assert (len(s), s.run_status) == (2, "aborted")


def test_a_planned_setup_settles_and_records_each_step_as_listed():
    """issue #28: per-step ``settle_s`` and minimum ``record_s`` reach the commands; a record
    is never shorter than the stand's own minimum."""
    setup = short_setup(3, 70.0, 90.0)
    exc = replace(setup.excitation, settle_s=(0.2, 1.5, 0.0), record_s=(0.01, 1.0, 2.0))
    cfg = fast_config()
    commands = plan_summary(replace(setup, excitation=exc), cfg).commands
    assert [c.settle_s for c in commands] == [0.2, 1.5, 0.0]
    fs = setup.daq.sample_rate_hz
    assert commands[0].n_samples == record_samples(70.0, fs, cfg.timing)  # the stand's minimum
    for c, wanted_s in zip(commands[1:], (1.0, 2.0)):
        cycles = c.n_samples * c.frequency_hz / fs
        assert (
            c.record_s >= wanted_s - 0.5 / fs and abs(cycles - round(cycles)) < c.frequency_hz / fs
        )
        assert c.record_s < wanted_s + 1.0 / c.frequency_hz + 1.0 / fs  # the least whole cycles


def test_the_drive_controls_amplitude_is_right_on_a_long_record_with_a_clock_offset():
    # 8.75 s at 1427.5 Hz, the DAQ's clock 40 ppm off the generator's: the phase drifts by
    # 2π·1427.5·40e-6·8.75 = 3.14 rad over the record, so one fit at the commanded
    # frequency reads sinc-reduced 2/π = 0.64 of the amplitude; by blocks it reads 1
    fs, f, t_s, ppm = 25600.0, 1427.5, 8.75, 40.0
    t = np.arange(int(fs * t_s)) / fs
    x = 1.0 * np.cos(2 * np.pi * f * (1 + ppm * 1e-6) * t + 0.3) + 0.02
    one_fit = np.linalg.lstsq(
        np.stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones_like(t)], 1),
        x,
        rcond=None,
    )[0]
    assert np.hypot(*one_fit[:2]) == pytest.approx(2 / np.pi, abs=0.01)  # the old reading
    assert amplitude_m_s2(x, f, fs) == pytest.approx(1.0, abs=2e-3)
    # a short record at a low frequency still fits whole cycles (4 at least)
    t = np.arange(int(fs * 0.4)) / fs
    assert amplitude_m_s2(0.5 * np.sin(2 * np.pi * 12.5 * t), 12.5, fs) == pytest.approx(
        0.5, rel=1e-6
    )
