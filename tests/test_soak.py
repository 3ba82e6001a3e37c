"""A campaign that stays up (#28, part 4): the soak on the simulated stand, short versions
(the setup's stepped sine, and an adaptive campaign).

The paper's strip (every other step of ``examples/strip_setup.json``: 40 steps, 18.75-1481 Hz),
a clean virtual specimen at the stand configuration's default noise, and eight faults at
random steps (seeded): a generator that stops answering, a dropped serial link, a knock on
the table that overloads the response channel, twice each, and two SIGKILLs of the campaign
process followed by a resume. Every step is in the file once and in order, the output is off
after every fault, and the identification is within 3 std of the truth and as clean as an
uninterrupted run's. ``benchmarks/soak.py`` is the long version (a few hundred steps).

The mock faults it needs are checked on their own first: a fault at a campaign step
(``at_index``), the DAQ overload, and a generator left playing by a dropped link.
"""

import dataclasses
import logging
import math
import signal
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from vibid.acquisition.generator import GeneratorError
from vibid.acquisition.stand_config import StandConfig
from vibid.hardware_mocks.virtual_stand import lookup_stand, open_simulated_stand
from vibid.session import load_setup
from vibid.setup_model import Excitation, example_setup
from vibid.soak import Fault, SoakOptions, fault_plan, soak

EXAMPLES = Path(__file__).parent.parent / "examples"
#: the example stand's drive (|H| reaches a few hundred: 1 m/s² of base keeps the response in
#: range) and settle cap, on a clean specimen at the default noise
STAND = {
    "drive": {"target_base_m_s2": 1.0, "initial_vpp": 0.04},
    "timing": {"max_settle_s": 30.0},
    "simulated": {"seed": 0},
}


def test_a_fault_plan_is_spaced_seeded_and_inside_the_campaign():
    counts = {"no_reply": 2, "drop": 2, "overload": 2, "kill": 2}
    plan = fault_plan(40, counts, seed=3)
    assert plan == fault_plan(40, counts, seed=3) and plan != fault_plan(40, counts, seed=4)
    steps = [f.index for f in plan]
    assert steps == sorted(steps) and min(np.diff(steps)) >= 4
    assert steps[0] >= 1 and steps[-1] <= 40 - 4 - 1
    assert sorted(f.kind for f in plan) == sorted(k for k, c in counts.items() for _ in range(c))
    with pytest.raises(ValueError, match="do not fit"):
        fault_plan(20, counts, seed=0)


def _stand(name, faults):
    setup = dataclasses.replace(example_setup(), excitation=Excitation((180.0, 300.0, 420.0), 0.5))
    config = StandConfig.from_dict(
        {
            "generator": {"url": f"vibidsim://{name}", "timeout_s": 0.1},
            "simulated": {"faults": faults},
        }
    )
    return setup, config


def test_an_overload_at_a_campaign_step_clips_that_steps_first_record_once():
    setup, config = _stand("soak-overload", [{"kind": "overload", "at_index": 1}])
    with open_simulated_stand(setup, config, accuracy="default") as stand:
        stand.generator.amplitude_vpp = 0.2
        stand.generator.output_enabled = True
        overloaded = []
        for index, f in enumerate((180.0, 300.0, 300.0)):
            stand.begin_step(min(index, 1))
            stand.generator.frequency_hz = f
            stand.clock.sleep(0.5)
            overloaded.append(stand.daq.acquire(6400).overloaded)
    assert overloaded == [(), ("response",), ()]  # step 1's first record; not its next one
    assert lookup_stand("soak-overload").instrument.sim_fired == {0}


def test_a_reopened_stand_finds_the_generator_a_dropped_link_left_playing():
    setup, config = _stand("soak-drop", [{"kind": "drop", "at_index": 1}])
    stand = open_simulated_stand(setup, config, accuracy="default")
    stand.generator.amplitude_vpp = 0.2
    stand.begin_step(0)
    stand.generator.frequency_hz = 180.0
    stand.generator.output_enabled = True
    stand.begin_step(1)
    with pytest.raises(GeneratorError, match="disconnected"):
        stand.generator.frequency_hz = 300.0
    stand.close()  # cannot reach it: the output stays on
    left = lookup_stand("soak-drop").instrument
    assert left.output_on and not left.connected
    with open_simulated_stand(setup, config, accuracy="default") as again:
        now = lookup_stand("soak-drop").instrument
        assert now is not left and now.output_on and now.frequency_hz == 300.0
        again.generator.shutdown()
        assert not now.output_on
    assert now.sim_fired == {0}  # not again on the reopened stand


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL (POSIX)")
def test_a_campaign_survives_faults_at_random_steps_and_identifies_as_without_them(tmp_path):
    logging.getLogger("vibid.acquisition.generator").setLevel(logging.ERROR)  # the lost links
    setup = load_setup(EXAMPLES / "strip_setup.json")
    freqs = setup.excitation.frequencies_hz[::2]
    setup = dataclasses.replace(
        setup, excitation=dataclasses.replace(setup.excitation, frequencies_hz=freqs)
    )
    config = StandConfig.from_dict(STAND)
    # seed 0: two overloads on the way to the second SIGKILL (the killed process injects them)
    plan = fault_plan(len(freqs), {"no_reply": 2, "drop": 2, "overload": 2, "kill": 2}, seed=0)
    result = soak(setup, config, tmp_path / "soak.h5", plan, SoakOptions(reference=True, seed=1))
    print("\n" + "\n".join(result.log) + "\n" + result.summary())
    assert result.survived == len(plan), result.outcomes
    for o in result.outcomes:
        assert o.fired
        assert o.output_off is (None if o.fault.kind == "overload" else True), o
        assert o.ended_run == (o.fault.kind != "overload")
    assert (result.n_steps, result.duplicates) == (len(freqs), 0)
    assert result.runs == 1 + sum(o.ended_run for o in result.outcomes)
    ident, ref = result.identification, result.reference
    dof = 2 * len(freqs) - len(ident.parameters)
    assert set(ident.parameters) == {"D", "nu", "beta"}
    assert max(ident.error_std().values()) < 3.0, ident
    # as clean as without faults: at the noise (the clean run too), and close to it
    limit = chi2.ppf(0.99, dof) / dof
    assert ident.chi2_dof < limit and ref.chi2_dof < limit, (ident.chi2_dof, ref.chi2_dof)
    assert abs(ident.chi2_dof - ref.chi2_dof) < 0.15
    assert not ident.unexplained and not ref.unexplained
    assert ident.effects == ref.effects == ()
    assert math.isclose(result.stand_time_s, result.reference_stand_time_s, rel_tol=0.2)


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL (POSIX)")
def test_an_adaptive_campaign_survives_faults_and_identifies_as_without_them(tmp_path):
    """The soak the issue asks for, short: an adaptive campaign (coarse sweep, batches of 4,
    a target it cannot reach, so that the 60 s stand-time cap ends it) through a dropped
    link, a generator that stops answering, an overload and a SIGKILL of the `vibid campaign
    --adaptive` process (the Prefect flow) followed by a resume, all in its first 24 steps."""
    from vibid.planner.adaptive import AdaptiveOptions
    from vibid.planner.prior import parse_targets

    logging.getLogger("vibid.acquisition.generator").setLevel(logging.ERROR)
    setup = load_setup(EXAMPLES / "strip_setup.json")
    config = StandConfig.from_dict(STAND)
    options = AdaptiveOptions(
        parse_targets(["D=1e-7%"], ("D", "nu", "beta")), (18.75, 1500.0), 60.0
    )
    plan = fault_plan(24, {"no_reply": 1, "drop": 1, "overload": 1, "kill": 1}, seed=0)
    result = soak(
        setup,
        config,
        tmp_path / "soak.h5",
        plan,
        SoakOptions(adaptive=options, reference=True, seed=1),
    )
    print("\n" + "\n".join(result.log) + "\n" + result.summary())
    assert result.survived == len(plan), result.outcomes
    for o in result.outcomes:
        assert o.fired and o.ended_run == (o.fault.kind != "overload")
        assert o.output_off is (None if o.fault.kind == "overload" else True), o
    assert result.duplicates == 0 and result.n_steps > max(f.index for f in plan)
    assert result.runs == 1 + sum(o.ended_run for o in result.outcomes)
    assert result.orphans == 0  # the killed flow's Prefect server ended with it
    ident, ref = result.identification, result.reference
    for i in (ident, ref):
        assert max(i.error_std().values()) < 3.0, i
        assert not i.unexplained and i.effects == ()
    # both stopped at the cap: the faults cost no stand time beyond a re-measured step or two
    assert result.stand_time_s == pytest.approx(result.reference_stand_time_s, rel=0.15)


def test_two_faults_at_one_step_are_refused(tmp_path):
    from vibid.soak import SoakError

    setup, config = _stand("soak-two", [])
    with pytest.raises(SoakError, match="two faults at one step"):
        soak(
            setup,
            config,
            tmp_path / "s.h5",
            [Fault(1, "drop"), Fault(1, "kill")],
            SoakOptions(identify=False),
        )
