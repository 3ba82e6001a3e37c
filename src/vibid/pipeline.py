"""The stages of one identification job, as plain functions: session → AFC → identified
model (with the closed loop) → assessed (:func:`assess_session`: the engineering
constants, their budget, the plausibility, the reference specimen) → the JSON report of
shared/spec/report-format.md (:func:`build_session_report`, which only formats).

``vibid identify`` (:mod:`vibid.cli.identify`) and the Prefect flows (:mod:`vibid.flows`)
both call these, so a replay of a session gives the same report as ``vibid identify`` on
it. Nothing here imports Prefect or prints: each stage returns what it found, and the
console text (:attr:`Identified.summary`) is the caller's to show.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from vibid.errors import VibidError
from vibid.identify.engine.threads import jax_turn
from vibid.not_done import NOT_DONE, attempt

# One compiled JAX program at a time per process: two identifications running in two
# threads of one process (a thread-pool task runner, an in-process Dask cluster)
# deadlocked inside XLA's CPU executions on the project's 2-core machine (both threads
# waiting in ``chi2_batch``, with one BLAS thread and XLA's single-threaded Eigen alike).
# The stages that run the model hold the JAX turn (:mod:`vibid.identify.engine.threads`); the
# signal stage, file writing and the model's numpy-only work (assembly, reduced bases)
# run beside them.

#: Default options of the identification stage (those of ``vibid identify``).
RESTARTS = 5
SEED = 0


@dataclass(frozen=True)
class SessionAfc:
    """The signal stage's result: the declared setup, the session id and its AFC
    (:class:`vibid.signal.afc.AfcTable`, or an imported AFC with the same attributes)."""

    setup: Any
    session_id: str
    afc: Any


@dataclass(frozen=True)
class Identified:
    """The identification stage's result: ``result`` the final
    :class:`~vibid.identify.fit.result.IdentificationResult` (the loop's last stage when
    the loop ran), ``loop`` the :class:`~vibid.identify.loop.LoopResult` or None, and
    ``summary`` the lines for the console; ``linearity`` the tests of the measured
    resonances made before the fit (:func:`vibid.identify.assess.linearity.linear_part`), some of
    whose tops the fit may have left out."""

    result: Any
    loop: Any
    summary: str
    linearity: tuple = ()

    @property
    def converged(self) -> bool:
        return bool(self.result.converged)


def parse_candidates(candidates) -> tuple[str, ...] | None:
    """The closed loop's candidate names from ``"A,B"`` or a list; None for all of them.
    An unknown name is a :class:`~vibid.errors.VibidError` that lists the known ones."""
    if candidates is None:
        return None
    if isinstance(candidates, str):
        candidates = candidates.split(",")
    names = tuple(c.strip() for c in candidates if c and c.strip())
    if not names:
        return None
    from vibid.identify.loop import all_candidates

    known = {c.name for c in all_candidates()}
    if unknown := sorted(set(names) - known):
        raise VibidError(
            f"--candidates: unknown {', '.join(unknown)}; expected some of "
            f"{', '.join(sorted(known))}"
        )
    return names


def session_afc(session_path: str | os.PathLike) -> SessionAfc:
    """Read a session file and fit the AFC of every step (:func:`vibid.signal.afc_from_session`),
    sorted by frequency (the file keeps the order acquired: an adaptive campaign's is not)."""
    from vibid.identify.engine.profile import section
    from vibid.session import read_session
    from vibid.signal import afc_from_session

    with read_session(session_path) as s, section("signal stage"):
        setup, session_id = s.setup, s.session_id
        afc = afc_from_session(s).by_frequency()
    return SessionAfc(setup, session_id, afc)


def afc_file(afc_path: str | os.PathLike, setup_path: str | os.PathLike) -> SessionAfc:
    """An AFC measured elsewhere (CSV or UFF58, told apart by content:
    :func:`vibid.signal.imported.read_afc`) with its declared setup (a setup JSON file, or
    a session file whose setup it is). Where the two meet, every frequency of the AFC must
    lie below the Nyquist frequency of the setup's DAQ
    (:func:`vibid.signal.imported.refuse_beyond_nyquist`: one line naming the row)."""
    from vibid.signal.imported import read_afc, refuse_beyond_nyquist

    afc = read_afc(os.fspath(afc_path))
    path = os.fspath(setup_path)
    if path.lower().endswith((".h5", ".hdf5")):
        from vibid.session import read_session

        with read_session(path) as session:
            setup = session.setup
    else:
        setup = read_setup(path)
    refuse_beyond_nyquist(afc, setup.daq.sample_rate_hz, shown=os.fspath(afc_path))
    return SessionAfc(setup, afc.session_id, afc)


def write_afc_uff(data: SessionAfc, path: str | os.PathLike) -> int:
    """Write the AFC the identification uses (the used points, at their frequencies: for a
    session, the refined ones on the DAQ clock) as UFF58, its std as a second record
    (:mod:`vibid.signal.uff`). Returns the number of points written."""
    from vibid.signal.uff import write_afc_uff as write

    afc = data.afc
    if afc.std is None:
        raise VibidError(f"{os.fspath(path)}: this AFC has no std to write beside it")
    used = np.asarray(afc.used, bool)
    write(
        os.fspath(path),
        np.asarray(afc.frequency_hz)[used],
        np.asarray(afc.H)[used],
        np.asarray(afc.std)[used],
        session_id=data.session_id,
    )
    return int(used.sum())


def fit_points(afc, *, magnitude_only: bool = False, nonlinear_tops: bool = False):
    """(the points to fit, the linearity tests): ``afc.used`` less the tops of resonances
    whose response depends on their amplitude (:func:`vibid.identify.assess.linearity.linear_part`),
    unless ``nonlinear_tops``; |H| alone is not tested (the test needs the complex AFC)."""
    if magnitude_only:
        return afc.used, ()
    from vibid.identify.assess.linearity import linear_part

    kept, tests = linear_part(afc.frequency_hz, afc.H, afc.std, afc.used)
    if not any(t.left_out_hz is not None for t in tests):
        return afc.used, tests
    if nonlinear_tops:
        return afc.used, tuple(replace(t, left_out_hz=None) for t in tests)
    return kept, tests


def identify_afc(
    data: SessionAfc,
    *,
    loop: bool = True,
    candidates=None,
    method: str = "global",
    local: str = "newton",
    restarts: int = RESTARTS,
    seed: int = SEED,
    progress=None,
    magnitude_only: bool = False,
    nonlinear_tops: bool = False,
) -> Identified:
    """Identify the declared model from ``data.afc`` (global search, then the local polish),
    then, with ``loop``, close the loop (:func:`vibid.identify.loop.close_loop`): the
    effects the residual asks for, among ``candidates`` (names; default all).

    The loop needs the AFC's uncertainty (to test the residual against the noise): without
    it, or when the declared fit did not converge, the declared model's result is final.
    ``progress`` is the search's ``progress(label, done, total, best)`` callback.
    ``magnitude_only``: fit |H| alone (stands whose channels are not synchronised or whose
    phase is not trusted); the loop then tries the candidates |H| can see.

    A resonance whose top is shown to depend on its amplitude (on an FFT analyser's dense
    grid: :func:`vibid.identify.assess.linearity.linear_part`) has its top left out of every fit,
    unless ``nonlinear_tops``: the plate model is linear, and the flanks hold the structure
    at small motion.
    """
    from vibid.identify import configure
    from vibid.identify.fit import Measurement, SearchOptions, identify

    if restarts < 1:
        raise VibidError("--restarts must be at least 1")
    names = parse_candidates(candidates)
    configure()
    setup, afc = data.setup, data.afc
    used, tests = fit_points(afc, magnitude_only=magnitude_only, nonlinear_tops=nonlinear_tops)
    said = "".join(t.left_out_note + "\n" for t in tests if t.left_out_hz is not None)
    with jax_turn():
        result = identify(
            setup,
            Measurement(afc.frequency_hz, afc.H, afc.std, used=used, magnitude=magnitude_only),
            search=SearchOptions(
                method=method, local=local, restarts=restarts, seed=seed, progress=progress
            ),
        )
        if loop and result.converged and afc.std is None:
            return Identified(
                result,
                None,
                said + "no loop: the AFC has no std column, so the "
                "residual cannot be tested against the noise\n" + result.summary(),
                tests,
            )
        if loop and result.converged:
            from vibid.identify.loop import close_loop

            closed = close_loop(
                setup,
                afc.frequency_hz,
                afc.H,
                afc.std,
                used=used,
                candidates=names,
                local=local,
                declared=result,
                magnitude=magnitude_only,
                left_out_hz=tuple(t.left_out_hz for t in tests if t.left_out_hz is not None),
            )
            return Identified(closed.final, closed, said + closed.summary(), tests)
    return Identified(result, None, said + result.summary(), tests)


def assess_session(data: SessionAfc, identified: Identified, reference=None, not_done=()) -> Any:
    """The assess stage of one identified session (:func:`vibid.identify.assess.assess`):
    the engineering constants with their budget, the plausibility, the linearity tests
    and, with ``reference`` (the specimen's known modulus), the clamp's calibration;
    ``not_done``: the stages that could not be done before it (:mod:`vibid.not_done`).
    The budget differentiates with JAX: hold the JAX turn."""
    from vibid.identify.assess import assess

    return assess(
        identified.result,
        identified.loop,
        data.setup,
        linearity=identified.linearity,
        reference=reference,
        not_done=not_done,
    )


def build_session_report(
    data: SessionAfc, identified: Identified, assessment=None
) -> dict[str, Any]:
    """The JSON report (:func:`vibid.report.build_report`) of one identified session and
    its ``assessment`` (:func:`assess_session`; assessed here where None)."""
    from vibid.report import build_report

    if assessment is None:
        with jax_turn():
            assessment = assess_session(data, identified)
    return build_report(
        identified.result,
        assessment,
        session_id=data.session_id,
        declared_model=data.setup.identification.model,
        afc=data.afc.to_report_block(),
        loop=identified.loop,
    )


def require_converged(identified: Identified) -> None:
    """Raise the job's failure once its report is written (the report says why)."""
    if not identified.converged:
        raise VibidError(f"the identification did not converge: {identified.result.message}")


def write_outputs(
    data: SessionAfc,
    identified: Identified,
    *,
    json_path=None,
    report_dir=None,
    session_path=None,
    reference=None,
) -> tuple[dict[str, Any], dict[str, str]]:
    """The assess and report stages: assess the result (:func:`assess_session`), build
    the JSON report, write the readable report folder
    (``report.md``, ``report.json``, PNG figures: :func:`vibid.report.write_lab_report`) to
    ``report_dir`` (if given) and the JSON report to ``json_path`` (if given). Returns the
    report and the paths written, by file name (``"json"`` for ``json_path``).
    ``reference``: the specimen's known modulus, a reference specimen that calibrates the
    clamp (:mod:`vibid.identify.assess.reference`).

    The fit's result is never lost here: a stage after it that fails (the reference, the
    budget, the figures, ...) is left out, in one line of the report's ``not_done``
    (:mod:`vibid.not_done`), and the rest is written. Only writing the files
    themselves may fail the job (a :class:`~vibid.errors.VibidError` naming the path)."""
    from vibid.report import write_report

    with jax_turn():  # the assess stage: the engineering constants differentiate with JAX
        assessment = assess_session(data, identified, reference)
    report = build_session_report(data, identified, assessment)
    paths: dict[str, str] = {}
    if report_dir is not None:  # first: what its figures could not do is in both files
        from vibid.identify.assess.curve import model_curve
        from vibid.report import write_lab_report

        with jax_turn():  # the AFC figure's model on a fine grid (JAX)
            curve = attempt(
                "figures",
                report.setdefault(NOT_DONE, []),
                model_curve,
                data.setup,
                identified.result,
                about="afc.png",
            )
        paths |= write_lab_report(
            report_dir,
            data,
            identified,
            report,
            session_path=None if session_path is None else os.fspath(session_path),
            curve=curve,
        )
    if json_path is not None:
        write_report(report, json_path)
        paths["json"] = os.fspath(json_path)
    return report, paths


def read_setup(path: str | os.PathLike):
    """The declared setup of a setup JSON file (one-line errors naming the file)."""
    from vibid.setup_model import parse_setup

    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except OSError as exc:
        raise VibidError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        return parse_setup(text)
    except VibidError as exc:
        raise VibidError(f"{path}: {exc}") from None
