"""Steps recorded through the real drivers on the virtual stand, checked by the signal stage.

The reference is the virtual specimen's own H at the frequency the generator really plays
(the full FE model, independent of the harmonic fit); the signal stage's stated
uncertainty must cover the difference.
"""

import dataclasses
import itertools

import numpy as np
import pytest
from scipy.stats import chi2

from vibid.acquisition.generator import ScpiGenerator
from vibid.acquisition.stand import open_stand
from vibid.acquisition.stand_config import SimulatedConfig, StandConfig, StandConfigError
from vibid.hardware_mocks.simulated_session import true_afc
from vibid.hardware_mocks.virtual_stand import lookup_stand, open_simulated_stand
from vibid.setup_model import Excitation, example_setup
from vibid.signal import StepRecord, afc_from_records

FREQS = (40.0, 180.0, 300.0, 620.0, 1100.0)
N = 6400  # 0.25 s at 25.6 kHz
_names = itertools.count()


def setup_with(freqs=FREQS):
    return dataclasses.replace(example_setup(), excitation=Excitation(tuple(freqs), settle_s=0.5))


def stand_for(setup, ppm=40.0, **sim):
    name = f"vs{next(_names)}"
    config = StandConfig.from_dict(
        {
            "generator": {"url": f"vibidsim://{name}", "timeout_s": 0.1},
            "simulated": {"clock_offset_ppm": ppm, **sim},
        }
    )
    stand = open_simulated_stand(setup, config, accuracy="default")
    return stand, lookup_stand(name)


def play(stand, frequency_hz, *, settle_s, vpp=0.2, n=N, commanded_hz=None):
    """One step as a campaign plays it; returns the fitted AFC point (fitted at ``commanded_hz``,
    the step's frequency, default the one sent)."""
    stand.generator.amplitude_vpp = vpp
    stand.generator.frequency_hz = frequency_hz
    stand.generator.output_enabled = True
    stand.clock.sleep(settle_s)
    reading = stand.daq.acquire(n)
    step = StepRecord(
        commanded_hz or frequency_hz,
        reading.sample_rate_hz,
        reading.base_m_s2,
        reading.response_m_s2,
        status="overload" if reading.overloaded else "ok",
    )
    return afc_from_records([step]).points[0], reading


@pytest.mark.parametrize("ppm", [-200.0, 0.0, 200.0])
def test_recorded_afc_equals_the_specimens_h_within_its_uncertainty(ppm):
    setup = setup_with()
    stand, virtual = stand_for(setup, ppm=ppm)
    assert isinstance(stand.generator, ScpiGenerator)
    z, offsets = [], []
    with stand:
        for f in FREQS:
            # settle 60 s of virtual time: the Q≈330 first mode (74.9 Hz) has rung out
            point, reading = play(stand, f, settle_s=60.0)
            h = virtual.specimen.h(f * (1 + ppm * 1e-6))[0]
            assert point.flag_names == () and reading.overloaded == ()
            z += [(point.h - h).real / point.std_re, (point.h - h).imag / point.std_im]
            offsets.append((point.clock_offset_ppm - ppm) / (point.frequency_std_hz / f * 1e6))
            assert abs(point.h - h) / abs(h) < 2e-3
    z = np.array(z)
    assert np.max(np.abs(z)) < 4.5
    assert np.sum(z**2) < chi2.ppf(0.999, z.size)
    assert np.max(np.abs(offsets)) < 4.5  # the fitted clock offset is the generator's
    assert not virtual.instrument.output_on  # closed: output off


def test_the_virtual_specimen_is_the_simulated_sessions_truth():
    setup = setup_with()
    _, virtual = stand_for(setup)
    freqs = np.array([180.0, 620.0])
    np.testing.assert_array_equal(
        virtual.specimen.h(freqs), true_afc(setup, virtual.truth, [180.0, 620.0, 1.05 * 1100.0])[:2]
    )


def test_a_wrong_frequency_command_gives_a_wrong_record():
    setup = setup_with()
    stand, virtual = stand_for(setup, ppm=0.0)
    with stand:
        point, _ = play(stand, 310.0, settle_s=60.0, commanded_hz=300.0)  # the step is 300 Hz
    # no 300 Hz in the record: the frequency search finds nothing and the base amplitude
    # seen at 300 Hz is what leaks from 310 Hz, a fraction of the 5 m/s² played
    assert "fit" in point.flag_names and not point.used
    assert point.amplitude_m_s2[0] < 0.2 * 5.0
    assert virtual.instrument.frequency_hz == 310.0


def test_output_off_records_noise_only():
    stand, virtual = stand_for(setup_with(), noise=4e-4)
    with stand:
        point, _ = play(stand, 300.0, settle_s=60.0)
        stand.generator.output_enabled = False
        stand.clock.sleep(60.0)
        reading = stand.daq.acquire(N)
    base = reading.base_m_s2 - reading.base_m_s2.mean()
    # 4e-4 of the 5 m/s² target: 2 mm/s² of noise, plus the stand's small drift
    assert np.std(base) == pytest.approx(2e-3, rel=0.1)
    assert point.amplitude_m_s2[0] == pytest.approx(5.0, rel=1e-3)  # 25 m/s² per V × 0.2 V


def test_same_seed_same_records_on_a_reopened_stand():
    setup = setup_with((300.0,))
    records = []
    for _ in range(2):
        stand, _ = stand_for(setup, seed=7)
        with stand:
            records.append(play(stand, 300.0, settle_s=1.0)[1])
    np.testing.assert_array_equal(records[0].base_m_s2, records[1].base_m_s2)
    np.testing.assert_array_equal(records[0].response_m_s2, records[1].response_m_s2)
    stand, _ = stand_for(setup, seed=8)
    with stand:
        other = play(stand, 300.0, settle_s=1.0)[1]
    assert not np.array_equal(other.response_m_s2, records[0].response_m_s2)


def test_announced_steps_seed_the_records_from_their_index():
    setup = setup_with((300.0, 620.0))
    records = {}
    for order in ((0, 1), (1,)):  # uninterrupted, and resumed at step 1
        stand, _ = stand_for(setup, seed=3)
        with stand:
            for index in order:
                stand.begin_step(index)
                reading = play(stand, setup.excitation.frequencies_hz[index], settle_s=60.0)[1]
                records.setdefault(index, []).append(reading)
    first, resumed = records[1]
    np.testing.assert_array_equal(first.response_m_s2, resumed.response_m_s2)
    stand, _ = stand_for(setup, seed=3)
    with stand:
        stand.begin_step(0)
        other = play(stand, 620.0, settle_s=60.0)[1]  # same frequency, other step: other noise
    assert not np.array_equal(other.response_m_s2, first.response_m_s2)


def test_too_short_a_settle_at_a_q300_resonance_leaves_a_flagged_transient():
    setup = setup_with((70.0, 75.0))
    _, virtual = stand_for(setup)
    f_n, gamma = virtual.specimen.nearest_mode(75.0)
    assert np.pi * f_n / gamma == pytest.approx(333, rel=0.05)  # Q = 1/β of the plate
    results = {}
    for settle_s in (0.2, 60.0):
        stand, virtual = stand_for(setup, ppm=0.0)
        with stand:
            play(stand, 70.0, settle_s=60.0, vpp=0.01)
            point, reading = play(stand, round(f_n, 2), settle_s=settle_s, vpp=0.01)
        assert reading.overloaded == ()
        results[settle_s] = point
    assert "unsettled" in results[0.2].flag_names
    assert results[60.0].flag_names == ()


def test_a_resonance_driven_too_hard_overloads_the_response_channel():
    setup = setup_with((75.0,))
    stand, virtual = stand_for(setup)
    f_n, _ = virtual.specimen.nearest_mode(75.0)
    with stand:
        point, reading = play(stand, round(f_n, 2), settle_s=60.0, vpp=0.2)
    assert reading.overloaded == ("response",)
    assert "overload" in point.flag_names and not point.used


def test_open_stand_finds_the_simulated_stand_by_name():
    setup = setup_with((300.0,))
    stand = open_stand("simulated", setup, StandConfig())
    with stand:
        assert stand.generator.idn.startswith("vibid,SimGen")
    assert not lookup_stand("stand").instrument.output_on


@pytest.mark.parametrize(
    "doc, match",
    [
        (
            {"generator": {"url": "/dev/ttyUSB0"}},
            "generator.url: the simulated stand needs vibidsim://NAME",
        ),
        (
            {"simulated": {"effects": {"glue": {"x": 1.0}}}},
            "simulated.effects.glue: unknown effect",
        ),
        (
            {"simulated": {"effects": {"stand_resonance": [{"f_hz": 660.0}]}}},
            "simulated.effects.stand_resonance: give f_hz, q, theta_rad_per_m, got f_hz",
        ),
        (
            {"simulated": {"effects": {"sensor_gain": [{"gain": 1.0}, {"gain": 1.1}]}}},
            "simulated.effects.sensor_gain: sensor_gain occurs once, given 2 times",
        ),
        ({"simulated": {"faults": [{"kind": "fire"}]}}, "simulated: unknown fault kind 'fire'"),
    ],
)
def test_bad_simulated_configuration_is_one_line(doc, match):
    with pytest.raises(StandConfigError, match=match):
        open_simulated_stand(setup_with((300.0,)), StandConfig.from_dict(doc), accuracy="default")


def test_two_stand_resonances_are_two_instances_of_the_truth():
    from vibid.hardware_mocks.virtual_stand import true_parameters

    doc = {
        "simulated": {
            "effects": {
                "stand_resonance": [
                    {"f_hz": 660.0, "q": 30.0, "theta_rad_per_m": 0.3},
                    {"f_hz": 300.0, "q": 10.0, "theta_rad_per_m": -0.2},
                ]
            }
        }
    }
    truth = true_parameters(StandConfig.from_dict(doc))
    assert truth["f_hz_1"] == 660.0 and truth["f_hz_2"] == 300.0
    assert truth["theta_rad_per_m_2"] == -0.2


def test_simulate_takes_an_effect_once_per_instance():
    from vibid.cli.simulate import _effects
    from vibid.errors import VibidError

    item = "stand_resonance:f_hz=660,q=30,theta_rad_per_m=0.3"
    values, names = _effects([item, item.replace("660", "300"), "channel_delay:tau_s=2e-5"])
    assert names == ("stand_resonance", "channel_delay")
    assert values["f_hz_1"] == 660.0 and values["f_hz_2"] == 300.0 and values["tau_s"] == 2e-5
    with pytest.raises(VibidError, match="--effect stand_resonance: give f_hz, q, theta"):
        _effects(["stand_resonance:f_hz=660"])


def test_undeclared_effect_is_in_the_specimen_not_the_setup():
    setup = setup_with((620.0,))
    _, plain = stand_for(setup)
    _, clamped = stand_for(setup, effects={"clamp_compliance": {"k_theta_N_per_rad": 50.0}})
    assert clamped.truth["k_theta_N_per_rad"] == 50.0
    assert abs(clamped.specimen.h(620.0)[0] - plain.specimen.h(620.0)[0]) > 1e-3
    assert SimulatedConfig().effects == {}


@pytest.mark.parametrize(
    "fault, error",
    [
        (
            {"kind": "error", "at_step": 1, "code": -310, "message": "Overheated"},
            "instrument error after 'FREQ 300': -310 Overheated",
        ),
        ({"kind": "no_reply", "at_step": 1}, r"no reply to 'SYST:ERR\?' within 0.1 s"),
        ({"kind": "drop", "at_step": 1}, "device disconnected"),
    ],
)
def test_faults_of_the_stand_configuration_fire_at_their_step(fault, error):
    from vibid.acquisition.generator import GeneratorError

    stand, virtual = stand_for(setup_with((180.0, 300.0)), faults=[fault])
    with stand:
        play(stand, 180.0, settle_s=1.0)
        with pytest.raises(GeneratorError, match=error):
            play(stand, 300.0, settle_s=1.0)
    assert not virtual.instrument.output_on or fault["kind"] == "drop"  # unplugged: unreachable
