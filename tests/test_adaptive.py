"""The adaptive campaign (issue #28, part 3): its session, its steps, its decisions.

References that are not the campaign's own: a one-mode response worked by hand (where the
steps across a half-power band fall), the virtual specimen's true parameters and the
stand time of the setup's own uniform sweep on the same stand (what the campaign must beat),
and the order and content of what the runner was told to play (the file must hold exactly
that, in acquisition order).
"""

import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from campaign_fakes import fake_stand, fast_config, short_setup  # noqa: E402
from vibid.acquisition.campaign import CampaignError, run_campaign  # noqa: E402
from vibid.acquisition.plan import Pause, StepCommand, record_samples  # noqa: E402
from vibid.cli import main  # noqa: E402
from vibid.planner.information import PHASES_DEG, across_mode  # noqa: E402
from vibid.session import SessionWriter, file_problems, read_session  # noqa: E402

EXAMPLES = Path(__file__).parent.parent / "examples"


def test_steps_across_a_mode_are_evenly_spaced_in_its_phase():
    f_n, beta = 496.5, 0.003
    f = across_mode(f_n, beta)
    h = 1.0 / (f_n**2 * (1 + 1j * beta) - f**2)  # the one-mode response
    h_n = 1.0 / (f_n**2 * (1 + 1j * beta) - f_n**2)
    offset = np.degrees(np.angle(h / h_n))
    np.testing.assert_allclose(offset, PHASES_DEG, atol=1e-9)  # φ > 0 below f_n
    half = np.isclose(np.abs(PHASES_DEG), 45.0)
    np.testing.assert_allclose(np.abs(h[half]) ** 2 / np.abs(h_n) ** 2, 0.5, rtol=1e-12)
    assert f.min() > f_n * (1 - 2 * beta) and f.max() < f_n * (1 + 2 * beta)


def test_the_campaign_stalls_only_where_steps_stop_buying_what_their_information_promised():

    from vibid.planner.adaptive.campaign import stalled

    # slow but as promised: each batch of N steps on N lowers the std by sqrt(N / (N + b))
    n = np.array([100.0, 108.0, 116.0, 124.0])
    steady = list(1.0 / np.sqrt(n))
    promised = [0.5 * math.log(n[k + 1] / n[k]) for k in range(3)]
    assert not stalled(steady, promised)
    # a floor: the same promises, the std no longer moves (the model's error limits it)
    assert stalled([0.1, 0.0995, 0.099, 0.0985], promised)
    assert not stalled([0.1, 0.0995, 0.099], promised[:2])  # too few batches to tell


class Scripted:
    """A chooser that plays given batches (Hz) with a pause after each, then stops."""

    def __init__(self, batches, attribute=None):
        self.batches = batches
        self.attribute = attribute or {
            "target": ["D=1%"],
            "band_hz": [40.0, 130.0],
            "max_stand_time_s": 60.0,
            "batch_size": 2,
            "seed": 0,
        }
        self.starts = []

    def plan(self, session_path, start):
        self.starts.append((session_path, start))
        index = start
        for batch in self.batches[1 if start else 0 :]:
            for f in batch:
                yield StepCommand(
                    index,
                    index + 1,
                    f,
                    0.05,
                    record_samples(f, 25600.0, fast_config().timing),
                    25600.0,
                )
                index += 1
            yield Pause()
        return "scripted batches played"


def test_an_adaptive_session_keeps_acquisition_order_and_lists_what_it_recorded(tmp_path):
    from vibid.pipeline import session_afc

    setup, out = short_setup(), tmp_path / "a.h5"
    stand = fake_stand()
    played = [[120.0, 60.0], [90.0, 60.0]]  # not sorted, one frequency twice
    result = run_campaign(setup, stand, out, fast_config(), chooser=Scripted(played))
    assert (result.run_status, result.n_steps) == ("complete", 4)
    assert result.stopped_because == "scripted batches played"
    assert file_problems(out) == []
    with read_session(out) as s:
        assert list(s.frequencies_hz()) == [120.0, 60.0, 90.0, 60.0]
        assert s.setup.excitation.frequencies_hz == (120.0, 60.0, 90.0, 60.0)
        assert s.setup.excitation.settle_s == setup.excitation.settle_s  # the floor
        assert s.adaptive == Scripted([]).attribute
        assert s.run_status == "complete" and s.stand_time_s > 0
        steps_written = [s.step_attributes(i)["settle_s"] for i in range(len(s))]
    assert all(v >= 0.05 for v in steps_written)
    # the output was off while the plan thought (between the batches)
    log = [c for c, *_ in stand.generator.log]
    assert log.count("shutdown") == 4  # at the start, at each pause, at the end
    # the identification reads it sorted by frequency; the step indices stay the file's
    afc = session_afc(out).afc
    assert list(afc.commanded_hz) == [60.0, 60.0, 90.0, 120.0]
    assert [p.index for p in afc.points] == [1, 3, 2, 0]


def test_an_adaptive_session_is_created_with_its_first_step_and_reads_interrupted_unclosed(
    tmp_path,
):
    setup, out = short_setup(), tmp_path / "a.h5"
    w = SessionWriter(out, setup, adaptive={"batch_size": 2})
    assert not out.exists()  # a setup lists at least one frequency: no file without a step
    w.append(frequency_hz=70.0, sample_rate_hz=25600.0, base=np.ones(64), response=np.ones(64))
    with read_session(out) as s:
        assert s.setup.excitation.frequencies_hz == (70.0,)
        # no run_status, and the setup lists as many frequencies as steps: for a campaign of
        # fixed steps that reads complete, for an adaptive one interrupted
        assert s.run_status == "interrupted"
    empty = SessionWriter(tmp_path / "never.h5", setup, adaptive={})
    empty.close("interrupted", "stopped before the first step")
    assert not (tmp_path / "never.h5").exists()


def test_an_adaptive_campaign_resumes_from_its_steps_with_its_own_options_only(tmp_path):
    setup, out = short_setup(), tmp_path / "a.h5"
    first = Scripted([[120.0, 60.0], [90.0]])
    run_campaign(setup, fake_stand(), out, fast_config(), chooser=first)
    with read_session(out) as s:
        attribute = s.adaptive
    # its status says complete, but a resume is allowed: the chooser decides (here: one more batch)
    more = Scripted([[120.0, 60.0], [95.0]], attribute)
    other_excitation = dataclasses.replace(
        setup, excitation=dataclasses.replace(setup.excitation, frequencies_hz=(10.0, 20.0))
    )
    result = run_campaign(
        other_excitation, fake_stand(), out, fast_config(), resume=True, chooser=more
    )
    assert more.starts == [(str(out), 3)] and result.n_steps == 4
    with read_session(out) as s:
        assert list(s.frequencies_hz()) == [120.0, 60.0, 90.0, 95.0]
    with pytest.raises(CampaignError, match="other adaptive options"):
        run_campaign(
            setup,
            fake_stand(),
            out,
            fast_config(),
            resume=True,
            chooser=Scripted([], {**attribute, "batch_size": 9}),
        )
    other_specimen = dataclasses.replace(
        setup, specimen=dataclasses.replace(setup.specimen, thickness_m=0.002)
    )
    with pytest.raises(CampaignError, match="declared setup differs"):
        run_campaign(other_specimen, fake_stand(), out, fast_config(), resume=True, chooser=more)
    uniform = tmp_path / "u.h5"
    run_campaign(setup, fake_stand(), uniform, fast_config())
    with pytest.raises(CampaignError, match="not an adaptive campaign"):
        run_campaign(setup, fake_stand(), uniform, fast_config(), resume=True, chooser=more)


def test_a_plan_that_cannot_go_on_aborts_without_a_retry_and_keeps_its_steps(tmp_path):
    from vibid.acquisition.plan import PlanError

    class Failing(Scripted):
        def plan(self, session_path, start):
            yield StepCommand(0, 1, 80.0, 0.05, 2560, 25600.0)
            yield Pause()
            raise PlanError("the fit of 1 steps failed: too few AFC points")

    stand = fake_stand()
    result = run_campaign(
        short_setup(), stand, tmp_path / "a.h5", fast_config(), chooser=Failing([])
    )
    assert result.run_status == "aborted" and result.n_steps == 1
    assert result.reason.startswith("the plan could not go on: ")  # not "stand fault:"
    assert not stand.generator.output_enabled


# -- the campaign on the virtual strip -------------------------------------------------------
STAND = {
    "drive": {"target_base_m_s2": 1.0, "initial_vpp": 0.04},
    "timing": {"max_settle_s": 30.0},
    "simulated": {"seed": 0, "noise": 0.003},
}


def _strip_stand(name, **simulated):
    from vibid.acquisition.stand_config import StandConfig
    from vibid.session import load_setup

    doc = json.loads(json.dumps(STAND))
    doc["generator"] = {"url": f"vibidsim://{name}"}
    doc["simulated"].update(simulated)
    return load_setup(EXAMPLES / "strip_setup.json"), StandConfig.from_dict(doc)


def _adaptive(setup, config, out, targets, *, loop=False, cap=120.0, lines=None):
    from vibid.acquisition.stand import open_stand
    from vibid.planner.adaptive import AdaptiveCampaign, AdaptiveOptions
    from vibid.planner.prior import parse_targets

    options = AdaptiveOptions(parse_targets(targets, ("D", "nu", "beta")), (18.75, 1500.0), cap)
    chooser = AdaptiveCampaign(
        setup, config, options, loop=loop, say=(lines.append if lines is not None else None)
    )
    with open_stand("simulated", setup, config) as stand:
        return run_campaign(setup, stand, out, config, chooser=chooser), chooser


@pytest.mark.slow
def test_the_adaptive_campaign_reaches_the_uniform_sweeps_certainty_in_far_less_stand_time(
    tmp_path,
):
    """On the virtual strip (0.3 % noise, Q 333): the setup's uniform sweep (80 steps,
    18.75-1500 Hz) and the adaptive campaign told to reach the uniform sweep's standard
    uncertainties; both identified as the report does."""
    from vibid.acquisition.stand import open_stand
    from vibid.hardware_mocks.virtual_stand import true_parameters
    from vibid.pipeline import identify_afc, session_afc

    setup, config = _strip_stand("adaptive-strip")
    with open_stand("simulated", setup, config) as stand:
        uniform = run_campaign(setup, stand, tmp_path / "u.h5", config)
    u = identify_afc(session_afc(tmp_path / "u.h5"), loop=False, restarts=2).result
    targets = [f"{n}={s:.6g}" for n, s in zip(u.parameter_names, u.std)]
    lines = []
    result, chooser = _adaptive(setup, config, tmp_path / "a.h5", targets, lines=lines)
    print("\n".join(lines))
    assert result.run_status == "complete" and result.stopped_because.startswith("target reached")
    a = identify_afc(session_afc(tmp_path / "a.h5"), loop=False, restarts=2).result
    truth = true_parameters(config)
    ratio = result.stand_time_s / uniform.stand_time_s
    print(
        f"stand time adaptive {result.stand_time_s:.1f} s / uniform {uniform.stand_time_s:.1f} s "
        f"= {ratio:.2f}; std ratio {np.asarray(a.std) / np.asarray(u.std)}"
    )
    assert ratio < 1 / 3
    for name, value, std, u_std in zip(a.parameter_names, a.values, a.std, u.std):
        assert abs(value - truth[name]) < 3 * std, name
        assert std <= u_std * 1.0001, name  # the report's own estimator: at the target
    # steps across the modes' half-power bands, not only the coarse sweep
    with read_session(tmp_path / "a.h5") as s:
        f = s.frequencies_hz()
    assert len(f) > chooser.options.coarse_steps
    assert np.any(np.abs(f / 790.0 - 1) < 0.003) and np.any(np.abs(f / 1427.5 - 1) < 0.003)


@pytest.mark.slow
def test_a_resonance_where_the_model_has_none_gets_steps_across_it(tmp_path):
    """A table mode (the stand resonance of the virtual specimen, 660 Hz, Q 30) that the
    declared plate does not have, and no loop to name it: the residual's diagnosis finds a
    resonance where the model has none, and the next batch measures across it."""
    setup, config = _strip_stand(
        "adaptive-stand-mode",
        effects={"stand_resonance": {"f_hz": 660.0, "q": 30.0, "theta_rad_per_m": 0.3}},
    )
    lines = []
    result, chooser = _adaptive(
        setup, config, tmp_path / "a.h5", ["D=1e-5%", "nu=1e-4%"], cap=30.0, lines=lines
    )
    print("\n".join(lines))
    found = [d for d in chooser.history if d["unexpected"]]
    assert found and any(line.startswith("resonance where the model has none") for line in lines)
    f_hz, q = found[0]["unexpected"][0]
    assert 500.0 < f_hz < 800.0  # the coarse sweep's 576 and 792 Hz steps see it between them
    half_width = f_hz / q / 2
    across = [x for x in found[0]["batch_hz"] if abs(x - f_hz) <= 2 * half_width]
    assert len(across) >= 3, found[0]
    assert min(across) < f_hz < max(across)  # on both sides of it


@pytest.mark.slow
def test_an_effect_the_loop_finds_between_batches_is_in_the_model_the_next_steps_are_chosen_on(
    tmp_path,
):
    """The undeclared 20 µs channel delay of the quick start's stand: the coarse sweep's fit
    does not explain the data, the loop adds the delay, and every later batch is chosen on
    (and every later fit starts from) the model with it."""
    from vibid.acquisition.stand import open_stand
    from vibid.planner.adaptive import AdaptiveCampaign, AdaptiveOptions
    from vibid.planner.prior import parse_targets

    setup, config = _strip_stand("adaptive-delay", effects={"channel_delay": {"tau_s": 2e-5}})
    options = AdaptiveOptions(
        parse_targets(["D=0.0005%"], ("D", "nu", "beta")), (18.75, 1500.0), 60.0
    )
    lines = []
    chooser = AdaptiveCampaign(
        setup, config, options, candidates=("channel_delay",), restarts=2, say=lines.append
    )
    with open_stand("simulated", setup, config) as stand:
        result = run_campaign(setup, stand, tmp_path / "a.h5", config, chooser=chooser)
    print("\n".join(lines))
    assert result.run_status == "complete"
    assert chooser.history and all(d["effects"] == ("channel_delay",) for d in chooser.history)
    r = chooser.fit.result
    tau = r.parameters["tau_s"]
    assert abs(tau - 2e-5) < 3 * r.std[list(r.parameter_names).index("tau_s")]


def test_campaign_options_that_do_not_go_together_are_refused_in_one_line(tmp_path, capsys):
    setup = str(EXAMPLES / "strip_setup.json")
    base = ["campaign", setup, "--stand", "simulated", "--out", str(tmp_path / "x.h5")]
    for extra, message in (
        (["--adaptive", "--target", "D=0.1%", "--record-only"], "--record-only with --adaptive"),
        (["--target", "D=0.1%"], "--target goes with --adaptive"),
        (["--adaptive"], "--adaptive needs --target"),
        (["--adaptive", "--target", "D=0.1%", "--band", "5:20000"], "Nyquist"),
    ):
        assert main(base + extra) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "x.h5").exists()


def test_the_dry_run_prints_the_coarse_sweep_and_the_rule(capsys):
    rc = main(
        [
            "campaign",
            str(EXAMPLES / "strip_setup.json"),
            "--stand",
            "simulated",
            "--adaptive",
            "--target",
            "D=0.1%",
            "nu=0.002",
            "--band",
            "20:1000",
            "--dry-run",
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0
    first = out.splitlines()[0]
    assert "coarse sweep of 16 steps 20-1000 Hz" in first
    f = np.array([float(x) for x in out.splitlines()[1].split()])
    np.testing.assert_allclose(f, np.geomspace(20, 1000, 16), rtol=1e-3)
    assert "until D=0.1%, nu=0.002" in out and "600 s of stand time" in out
