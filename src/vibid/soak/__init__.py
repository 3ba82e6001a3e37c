"""soak: a day of faulted campaigns on the simulated stand, each fault survived.

:func:`soak` plays a whole campaign on the virtual stand while faults strike at chosen steps
(:func:`fault_plan` draws them from a seed), and checks what a lab needs from a campaign
that must stay up for hours:

* ``no_reply`` (the generator stops answering), ``error`` (it reports a fault), ``drop``
  (its serial link is unplugged) and ``overload`` (a knock on the table clips the response
  channel) are injected through the stand configuration (``simulated.faults``, fired at the
  step's index: :mod:`vibid.hardware_mocks.virtual_stand`). A fault that ends the campaign
  (``aborted``, ``stand fault: ...``) is retried as a resume on a reopened stand, as the
  campaign flow does;
* ``kill``: the run that reaches it is a separate process (``python -m vibid campaign ...
  --record-only``, given the overloads on its way), sent SIGKILL at a random instant within
  a step's time after it reported the step; the next run resumes the file, as ``--resume``.

Checked on the way and at the end (a failed check raises :class:`SoakError`):

* every step reported done is in the file, no step is in it twice, and the file's steps are
  the setup's frequencies in acquisition order (``complete`` at the end);
* the generator output is off after every fault that ends a run: at the run's end where
  the link still works, and by the first command of the next run where it does not (a
  dropped link, a killed process), before any frequency is played;
* the identification of the soaked session is then compared with the truth (each declared
  parameter's error in its std) and, with ``reference=True``, with an uninterrupted run of
  the same stand (chi2/dof, ``unexplained_residual``).

The campaign is an option (:class:`SoakOptions`): the setup's stepped sine by default
(in-process runs of :func:`vibid.acquisition.campaign.run_campaign`, process runs of
``vibid campaign --record-only``), or with ``adaptive`` an adaptive campaign
(:mod:`vibid.planner.adaptive`: in process with its chooser, as a process ``vibid campaign
--adaptive`` with the same options, which runs the Prefect flow). An adaptive campaign's
steps are not known in advance: the file must then hold every step reported, once, in the
order acquired, and end ``complete`` when the campaign decided to stop. What a SIGKILLed
process leaves running after a grace of a few seconds (Prefect's temporary server would
be, were it not tied to its parent: :mod:`vibid.flows.server`) is removed with the process
group and counted (``orphans``).

The modules, one idea each:

* :mod:`~vibid.soak.faults` — the faults and the day's schedule of them (:func:`fault_plan`),
  and the stand configuration that injects them;
* :mod:`~vibid.soak.runs` — one campaign run: in process on a reopened stand, or a process
  killed with SIGKILL;
* :mod:`~vibid.soak.checks` — what the file must hold after each run and at the end;
* :mod:`~vibid.soak.record` — what became of each fault, and the soak's record;
* :mod:`~vibid.soak.harness` — :func:`soak`: runs until the campaign is complete, then the
  record and the identification.

It sits above the mocks, the campaign, the planner and the pipeline; ``hardware_mocks/``
imports none of it.
"""

from vibid.soak.checks import SoakError
from vibid.soak.faults import KINDS, NO_REPLY_COUNT, Fault, fault_plan
from vibid.soak.harness import SoakOptions, soak
from vibid.soak.record import FaultOutcome, Identification, SoakResult, identify_session

__all__ = [
    "KINDS",
    "NO_REPLY_COUNT",
    "Fault",
    "FaultOutcome",
    "SoakError",
    "SoakOptions",
    "SoakResult",
    "Identification",
    "fault_plan",
    "identify_session",
    "soak",
]
