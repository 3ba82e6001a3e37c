"""The loop's last test of its own additions (:func:`vibid.identify.loop.withdraw.at_the_end`),
on data from the independent Ritz stand of tests/population_model.py.

Each round tests the effects added before it from the new fit; the last addition was never
tested from a later estimate. On the population benchmark an isotropic plate's orthotropic
refit stopped in a wrong basin (chi2_red 191) and the next round's free length only moved
the fit out of it (1.2; the orthotropic model alone, fitted from the truth, 1.198). Here: a
strip whose AFC carries a channel delay and nothing else, and a loop state whose last
stage added a sensor gain on top of the delay. The gain explains nothing there and goes; the
delay, whose model without it is far from the data, stays.
"""

import math

import numpy as np
import pytest

import population_model as pm
from test_loop_mechanisms import PLATE, TRUTH, _setup
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.inputs import Measurement, ModelChoice, SearchOptions
from vibid.identify.fit.strategy import identify
from vibid.identify.loop.candidates import all_candidates
from vibid.identify.loop.evidence import with_prior
from vibid.identify.loop.examine import diagnosed
from vibid.identify.loop.rounds import finish
from vibid.identify.loop.state import Inputs, State
from vibid.identify.loop.verdicts import Stage, Verdict
from vibid.identify.loop.withdraw import at_the_end
from vibid.identify.model.plate import Plate

TAU_S = 4e-5  # the response channel 40 us late: 0.06 rad at the top of the band


def _fit(setup, f, H, std, effects, start):
    plate = Plate(setup)
    box = dict(setup.identification.bounds)
    candidates = {c.name: c for c in all_candidates()}
    for e in effects:
        box |= candidates[e].bounds(box, start, None)
    fm = plate.forward_model(f, effects=effects, theta0=start, bounds=box)
    names = fm.parameter_names
    return identify(
        setup,
        Measurement(f, H, std),
        ModelChoice(forward_model=fm, bounds={n: box[n] for n in names}),
        SearchOptions(method="local", start={n: start[n] for n in names}),
    )


@pytest.mark.slow
def test_the_last_addition_that_explains_nothing_is_withdrawn_at_the_end():
    f = np.linspace(20.0, 2400.0, 150)
    H = pm.afc(f, PLATE, TRUTH, {"tau_s": TAU_S}, pm.STRIP_ORDER)
    std = pm.noise_std(H, 0.003, 1e-4)
    H = pm.noisy(H, std, 11)
    setup = _setup(f)
    declared = identify(setup, Measurement(f, H, std), search=SearchOptions(restarts=1, seed=0))
    # the declared model cannot explain the delay
    assert declared.chi2_reduced > 5, declared.chi2_reduced
    start = dict(declared.parameters) | {"tau_s": 0.0}
    delay = _fit(setup, f, H, std, ("channel_delay",), start)
    assert delay.parameters["tau_s"] == pytest.approx(TAU_S, rel=0.05)
    gain = _fit(
        setup, f, H, std, ("channel_delay", "sensor_gain"), delay.parameters | {"gain": 1.0}
    )
    assert gain.chi2 <= delay.chi2  # the gain lowers chi2 a little, as any parameter does

    inputs = Inputs(Plate(setup), fit_data(f, H, std), all_candidates(), "newton")
    candidates = {c.name: c for c in inputs.pool}
    box = dict(setup.identification.bounds)
    prior = with_prior(box, candidates["channel_delay"], declared.parameters)
    prior = with_prior(prior, candidates["sensor_gain"], delay.parameters)
    stages = tuple(
        diagnosed(inputs, Stage.of(added, r))
        for added, r in ((None, declared), ("channel_delay", delay), ("sensor_gain", gain))
    )
    state = State(stages, box | {"tau_s": prior["tau_s"], "gain": prior["gain"]}, prior, ((),))

    ended = at_the_end(inputs, state)

    assert [s.added for s in ended.stages] == [None, "channel_delay"]
    final = ended.stages[-1].result
    assert "gain" not in final.parameters
    assert final.parameters["tau_s"] == pytest.approx(TAU_S, rel=0.05)
    (gone,) = ended.rounds[-1]
    assert gone.name == "sensor_gain" and gone.verdict is Verdict.WITHDRAWN
    assert gone.log_evidence > 0 and math.isfinite(gone.log_evidence)
    assert "withdrawn at the end" in gone.note
    # the loop's result says what is left
    assert finish(ended, 0.0).effects == ("channel_delay",)
