"""The loop's policy: every number its rounds use, in one frozen object passed in.

None of them chooses between explanations (the evidence does,
:mod:`~vibid.identify.loop.evidence`). Each is a model prior, a compute budget (how many
refits a round can afford, where a resonance without a diagnosed pole is tried), or a
statement of physics (how far a placed resonance may slide and still be the pole it was
placed on, how many instances of an effect a stand plausibly has).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Policy:
    #: the prior probability that the current model is complete ("stop here"); the rest is
    #: spread evenly over the round's explanations
    stop_prior: float = 0.5
    #: refits a round runs, the explanations of highest approximate evidence first (the
    #: score test's, :func:`~vibid.identify.loop.evidence.approximate`); every one while
    #: the estimate lies outside its prior box, where the score at a bent point says little
    refits_per_round: int = 4
    #: where a resonance of the stand or fixture is tried beyond the diagnosed poles: the
    #: frequencies of this many of the residual's largest local maxima along the band
    band_trials: int = 4
    #: the quality factor a resonance tried at a residual's maximum starts from (the
    #: diagnosis gives a pole's own)
    trial_q: float = 30.0
    #: a resonance placed on a pole is fitted within this factor of its frequency ...
    pole_span: float = 1.1
    #: ... and of its Q (beyond, it would be another structure than the pole)
    q_span: float = 3.0
    #: instances of an effect that may occur more than once (two stand resonances)
    max_instances: int = 2
    #: a new material's refit is searched globally over its box when the local refits of
    #: the round leave more than this share of the misfit above the noise (its basin may
    #: lie far from the current fit's)
    search_share: float = 0.5
    #: a refit's starts along its new parameters, in the coordinates u of their box
    #: (u = ±1 its faces) ...
    starts_u: tuple = (-0.75, -0.25, 0.25, 0.75)
    #: ... and where it restarts a current parameter found outside its box
    inside_u: float = 0.9
    #: where the model's own error changes the current fit's chi2 by less than this share,
    #: a refit is polished under the current fit's weights and only the one the round adds
    #: weighs its own (a compute budget: estimating that error costs each refit a solve)
    model_error_share: float = 0.1
    #: an orthotropic plate's weak stiffnesses (D22, D66) may lie this many times below the
    #: stiffness the isotropic fit found: a unidirectional carbon laminate has E2 / E1 about
    #: 1/15 and G12 / E1 about 1/30 (a statement of physics: the new material's prior)
    orthotropy_divisor: float = 30.0


DEFAULT = Policy()
