"""The closed loop: read the residual, then add the plainest effect that explains it.

Starting from the declared model's fit, each round over a frozen state (the stages so far
and their prior box, :mod:`~vibid.identify.loop.rounds`):

1. **Judge** the current fit with the one judge of "fits the data"
   (:func:`vibid.identify.fit.noise.explains`, which the report asks too): a fit that
   explains the data to the level of their noise ends the loop, so nothing is ever added
   to data the model already explains.
2. **Diagnose** its residual (:mod:`vibid.identify.diagnosis`): the ratio measured / model
   fitted with poles and residues, read as resonances where the plate has none (or none
   its sensor sees: a mode the model hides beside one is named), plate modes misplaced or
   damped wrongly, and smooth trends.
3. **Score** every candidate (:mod:`~vibid.identify.loop.candidates`: an effect or a new
   material, behind one protocol) that applies to the model and the diagnosis (a stand
   resonance needs a diagnosed pole, which also places its frequency and Q) with a score
   test at the current fit (:mod:`~vibid.identify.loop.scoring`). A new material also
   needs the modes' pattern to ask for it: more of the plate's modes in the band than the
   current material has stiffnesses (which place any fewer).
4. **Refit** the candidates whose score asks for it, best first, and the best one the
   diagnosis asks for where it is not among them, and each one without parameters of its
   own (one run; its secant score is no slope) (:mod:`~vibid.identify.loop.refit`), a
   new material after the effects: where their refits leave most of the misfit, search
   the best-scoring new material globally (its basin may lie far from the current
   fit's; an effect's new parameters start at their null or at the diagnosed feature, and
   a resonance the diagnosis placed is searched near its pole only: its frequency within
   10 %, its Q within 3 times the pole's; an effect that shows a mode the model hides
   also starts from the material moved to place that mode on the pole). Where the model's
   own error barely changes the current fit's chi2, every refit is weighed as the current
   fit is (that error is estimated again only for the one the round adds); elsewhere each
   weighs its own. A refit that takes a parameter out of its prior box for no more chi2
   than a parameter that explains nothing gains from the misfit is run again with it
   held at its current value (a strip's Poisson's ratio, which its bending modes barely
   determine).
5. **Judge** each refit (:class:`Verdict`): a placed resonance inside the spans around
   its pole, not on their faces; significant, away from its null, every parameter the
   current fit had inside its prior box still inside it (a refit that reaches the data
   only with a non-physical value explains nothing), and significant twice: against the
   noise, and against the misfit that remains (its likelihood ratio in units of that
   misfit's reduced chi2 times its autocorrelation time along frequency as the refit's
   own change of the model sees it, what a parameter that explains nothing removes from
   it; the final covariance is scaled by the reduced chi2 and the whole autocorrelation
   time); or bringing a parameter the declared model bent out of its prior box back
   inside it.
6. **Choose** among the passing refits one for the structure it explains: those that
   explain nearly all the misfit where there are any, else those that remove a diagnosed
   feature (a refit that only shaves a share off a misfit it leaves is ``no_structure``:
   any extra parameter does that); of them, those whose refit
   removes the most significant diagnosed feature compete, and of them the plainest
   explanation the data cannot tell from the best: an effect whose feature the diagnosis
   found before one without, an effect of the stand before a new material.

A round's scores and refits start from the same state, so the next ones run beside the
one the round is judging (on the machine's second core: :mod:`vibid.identify.threads`);
the round takes them in its own order, so it decides as it would one after the other.

The loop ends when the fit explains the data, when no candidate passes, or after
``max_rounds``. A residual that remains is reported (``unexplained_residual``) and the
final covariance is scaled by its reduced chi2 (the Birge ratio squared) and by the
residual's autocorrelation time along frequency (a smooth misfit spans many points, which
then count as one): the misfit then measures how far the model is from the data.
"""

from vibid.identify.loop.candidates import (MAX_INSTANCES, Candidate, EffectCandidate,
                                            MaterialCandidate, all_candidates)
from vibid.identify.loop.rounds import close_loop, scaled_by_misfit
from vibid.identify.loop.verdicts import LoopResult, Score, Stage, Verdict

__all__ = ["MAX_INSTANCES", "Candidate", "EffectCandidate", "LoopResult",
           "MaterialCandidate", "Score", "Stage", "Verdict", "all_candidates", "close_loop",
           "scaled_by_misfit"]
