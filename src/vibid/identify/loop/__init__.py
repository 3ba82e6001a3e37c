"""The closed loop: read the residual, then add the most probable explanation of it.

Starting from the declared model's fit, each round over a frozen state
(:mod:`~vibid.identify.loop.rounds`) does four things:

1. **Propose** (:func:`~vibid.identify.loop.propose.propose`): every candidate of the
   library (:mod:`~vibid.identify.loop.candidates`: an effect or a new material, behind
   one protocol) that applies to the current model, a structural fact (the effect it
   refines is there, it may share the model, an instance is left). The diagnosis
   (:mod:`~vibid.identify.loop.diagnosis`: the ratio measured / model fitted with poles
   and residues) proposes where a resonance starts, never which candidates are tried: a
   resonance of the stand or fixture is tried at every diagnosed pole, whatever the
   diagnosis read it as, and at the residual's largest maxima along the band.
2. **Fit**: each proposal's score test at the current fit gives its approximate
   evidence (:func:`~vibid.identify.loop.evidence.approximate`; of a resonance's places
   the best); the most promising are refitted (:mod:`~vibid.identify.loop.refit`), a
   compute budget of the :class:`~vibid.identify.loop.policy.Policy`. Two guards state
   facts: too few points for the parameters, and a new material needs more of the
   plate's modes in the band than the current one has stiffnesses.
3. **Compare** every explanation, stopping here included, by one criterion: its
   Bayesian evidence under one noise model for the round
   (:mod:`~vibid.identify.loop.evidence`: Laplace's approximation, Gaussian noise no
   smaller than the measured one with the misfit's correlation along frequency, uniform
   priors over each parameter's physical box), and the model prior of the policy (half on
   "the model is complete").
4. **Choose** the most probable; an effect added earlier that the new one makes
   redundant is withdrawn where the model without it is the more probable.

The loop ends when the fit explains the data to the level of their noise (the one judge,
:func:`vibid.identify.fit.noise.explains`, which the report asks too), when stopping is
the most probable explanation, or after ``max_rounds``; then its last addition, which no
round tested from a later fit, is tested as the others were, from the final estimate
(:func:`~vibid.identify.loop.withdraw.at_the_end`). Each stage keeps the
explanations it compared with their probabilities (the report's
``loop.stages[].alternatives``). A residual that remains is reported
(``unexplained_residual``) and the final covariance is scaled by its reduced chi2 (the
Birge ratio squared) and by the residual's autocorrelation time along frequency: the misfit
then measures how far the model is from the data.

A round's scores and refits start from the same state, so the next ones run beside the
one the round is weighing (on the machine's second core: :mod:`vibid.identify.engine.threads`);
the round takes them in its own order, so it decides as it would one after the other.
"""

from vibid.identify.loop.candidates import (
    Candidate,
    EffectCandidate,
    MaterialCandidate,
    all_candidates,
)
from vibid.identify.loop.policy import DEFAULT, Policy
from vibid.identify.loop.rounds import close_loop, scaled_by_misfit
from vibid.identify.loop.verdicts import LoopResult, Score, Stage, Verdict

__all__ = [
    "DEFAULT",
    "Candidate",
    "EffectCandidate",
    "LoopResult",
    "Policy",
    "MaterialCandidate",
    "Score",
    "Stage",
    "Verdict",
    "all_candidates",
    "close_loop",
    "scaled_by_misfit",
]
