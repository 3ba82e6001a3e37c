"""The adaptive campaign: measure a little, fit, then measure where the fit says it learns most.

One batch at a time, as a plain generator of step commands
(:class:`~vibid.acquisition.plan.StepSource`; the runner plays them and writes each step):

1. **Coarse sweep.** ``coarse_steps`` frequencies spread geometrically over the band, each
   settled the setup's ``settle_s`` and recorded the stand's shortest record: enough of the
   AFC's shape for the global search to place the modes.
2. **Fit** what is measured, as the report does (:func:`~.fit.fit_steps`): the signal stage's AFC
   sorted by frequency, the declared model, the closed loop when the one judge of "fits
   the data" says the residual asks for it. A later fit starts from the last one (the
   model with the effects found so far; the declared model, and the loop, again when that
   no longer explains the data).
3. **Stop** when every targeted parameter's reported standard uncertainty is at or below
   its target (the same estimator as the report: a warm refit that claims it is checked by
   the report's own identification, global search and all), when the stand time reaches the cap, or
   when the last three batches lowered it by less than a quarter of what their information
   predicted (the model's own error or a residual the model cannot explain limits it, not
   the number of steps).
4. **Choose** the next batch (:func:`~.batch.next_batch`): draws from the current fit's posterior
   (its estimate and covariance), the Fisher information per step over them at candidate
   frequencies (a grid over the band and, for every mode of every draw, its half-power band
   evenly in phase: :mod:`vibid.planner.information`), greedily by expected gain per second of stand
   time (:mod:`vibid.planner.design`) starting from the information of the steps measured, aiming below
   the target by as much as the report's std is now wider than the information's (a Birge
   ratio, rival minima, the model's error: :func:`~.batch.calibration`), and spending at most as
   much stand time as all the steps before it. A resonance the residual's diagnosis finds
   where the model has none gets steps across its half-power band as well, and each
   minimum the fit could not tell from its estimate (its std includes their spread) a step
   where their AFCs differ most (:func:`~.batch.telling_apart`).
5. **Play** the batch in ascending frequency, each step settled as the current fit's modes
   require (:mod:`vibid.planner.settle`; the setup's ``settle_s`` the floor; a record still ringing is
   recorded again, :func:`~vibid.acquisition.plan.play_step`, waiting the fit's Q), then
   pause with the output off while the next fit runs: compute time is not stand time.

The session carries the options as its ``adaptive`` attribute (:meth:`~.options.AdaptiveOptions.attribute`),
so a resumed campaign reads its steps from the file and goes on from step 2.
"""

from vibid.planner.adaptive.batch import Batch, next_batch
from vibid.planner.adaptive.campaign import AdaptiveCampaign
from vibid.planner.adaptive.fit import CurrentFit, fit_steps, reached
from vibid.planner.adaptive.options import AdaptiveOptions, coarse_sweep

__all__ = [
    "AdaptiveCampaign",
    "AdaptiveOptions",
    "Batch",
    "CurrentFit",
    "coarse_sweep",
    "fit_steps",
    "next_batch",
    "reached",
]
