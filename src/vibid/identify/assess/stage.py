"""The assess stage: everything judged of an identified result, between the loop and the
report (pipeline: identify → closed loop → assess → report).

:func:`assess` computes, of one result (the loop's final stage where the loop ran):

* whether its residual is above the noise (the loop's own word where the loop ran);
* how much of the bending stiffness's variance a fitted free length carries;
* the linearity tests of the measured resonances (:mod:`~vibid.identify.assess.linearity`);
* with the declared setup, the engineering constants with their uncertainty budget
  (:mod:`~vibid.identify.assess.budget`; JAX: the caller holds the JAX turn), or, where the
  budget cannot be made, with the fit's covariance alone
  (:mod:`~vibid.identify.assess.engineering`); their plausibility
  (:mod:`~vibid.identify.assess.plausibility`); and, with a reference specimen, the clamp's
  calibration (:mod:`~vibid.identify.assess.reference`).

Each part that fails is one entry of :attr:`Assessment.not_done`
(:mod:`vibid.not_done`), the rest assessed: the report
(:func:`vibid.report.build_report`) only turns the :class:`Assessment` into its blocks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vibid.errors import VibidError
from vibid.not_done import attempt


@dataclass(frozen=True)
class FreeLengthShare:
    """How much of the bending stiffness's (and so E's) variance a fitted free length
    carries: ``stiffness`` its name (``D`` or ``D11``), ``share`` of its variance, and its
    std with the free length known (``known_std``) and as fitted (``std``), N m."""

    stiffness: str
    share: float
    known_std: float
    std: float


@dataclass(frozen=True)
class Assessment:
    """What :func:`assess` judged of one result (module doc); what a part could not judge
    is its default, with its entry in ``not_done``.

    ``unexplained_residual``: the fit leaves a residual above the noise; ``free_length``:
    a :class:`FreeLengthShare` or None; ``linearity``: the
    :class:`~vibid.identify.assess.linearity.Linearity` tests the report gives;
    ``constants``: the engineering constants (``{name: {"value", "std"}}``), None where
    none were made; ``budget``: their uncertainty budget (``{name: {part: std}}``) or None;
    ``notes``: the budget in words; ``plausibility``: the
    :class:`~vibid.identify.assess.plausibility.Plausibility` or None; ``reference``: the
    report's ``reference`` block or None; ``not_done``: the stages that could not be done
    (those given to :func:`assess`, then its own)."""

    unexplained_residual: bool = False
    free_length: FreeLengthShare | None = None
    linearity: tuple = ()
    constants: dict | None = None
    budget: dict | None = None
    notes: tuple[str, ...] = ()
    plausibility: object = None
    reference: dict | None = None
    not_done: tuple[dict, ...] = ()


def unexplained(result) -> bool:
    """Whether the fit leaves a residual above the noise (the one judge,
    :func:`vibid.identify.fit.noise.explains`, as the loop's). Without a known noise level
    nothing can be said, and the answer is False (with a warning in the result)."""
    from vibid.identify.fit.noise import explains

    return explains(result) is False


def free_length_share(result) -> FreeLengthShare | None:
    """How much of the bending stiffness's uncertainty a fitted free length carries: a
    longer span is a softer plate, and the two are nearly collinear. None when the model
    has no ``dL_m`` (or the covariance says nothing of it)."""
    names = list(result.parameter_names)
    stiff = "D" if "D" in names else "D11" if "D11" in names else None
    if "dL_m" not in names or stiff is None:
        return None
    C = np.asarray(result.covariance, float)
    i, j = names.index(stiff), names.index("dL_m")
    if not (np.isfinite(C[i, i]) and np.isfinite(C[j, j]) and C[i, i] > 0 and C[j, j] > 0):
        return None
    share = C[i, j] ** 2 / (C[i, i] * C[j, j])
    known = math.sqrt(max(C[i, i] * (1.0 - share), 0.0))
    return FreeLengthShare(stiff, share, known, math.sqrt(C[i, i]))


def linearity_tests(result, tests=None) -> tuple:
    """Whether each measured resonance the grid resolves is the response of a linear
    structure (:mod:`vibid.identify.assess.linearity`; the measured AFC alone, complex data
    only); empty where no resonance is resolved. ``tests``: the tests made before the fit
    (:func:`vibid.pipeline.identify_afc`), whose points the fit's own no longer hold."""
    from vibid.identify.assess.linearity import linear_part

    if tests is None:  # tested here, after a fit that left nothing out
        if result.magnitude:
            return ()
        std = None if result.H_std is None else np.asarray(result.H_std)
        tests = [
            replace(t, left_out_hz=None)
            for t in linear_part(result.frequency_hz, result.H, std, result.used)[1]
        ]
    return tuple(tests)


def fit_constants(setup, result) -> dict:
    """The engineering constants with the fit's covariance and the declared thickness's
    uncertainty through the conversion alone (:func:`vibid.identify.assess.engineering.
    engineering_constants`): the report's block where the budget could not be made."""
    from vibid.identify.assess.engineering import engineering_constants

    model = getattr(result.plate_model, "model", None) or result.model
    sp = setup.specimen
    return engineering_constants(
        model,
        result.parameter_names,
        result.values,
        result.covariance,
        sp.thickness_m,
        getattr(sp, "thickness_std_m", None) or 0.0,
    )


def judge_plausibility(model: str, result, constants: dict, setup):
    """Constants no material allows, and the comparison with the handbook range of the
    specimen's material class (:mod:`vibid.identify.assess.plausibility`)."""
    from vibid.identify.assess.plausibility import plausibility

    sp = setup.specimen
    return plausibility(
        model,
        result.parameters,
        result.parameter_std,
        constants,
        specimen_name=sp.name,
        material=sp.material,
        specimen=sp,
        sensor=setup.sensors.response,
    )


def reference_block(setup, result, reference, loop=None) -> dict | None:
    """The report's ``reference`` block: the clamp's effective free length that the
    specimen's known modulus gives (:mod:`vibid.identify.assess.reference`), in the boxes
    of the loop's models, or why there is none; None without a reference."""
    if reference is None:
        return None
    from vibid.identify.assess.budget import loop_box
    from vibid.identify.assess.reference import calibrate_free_length

    box = loop_box(setup, loop)
    try:
        return calibrate_free_length(setup, result, reference, box=box).as_report()
    except VibidError as exc:  # the report stays: it says why there is no calibration
        return {"note": f"reference specimen: {exc}"}


def _engineering(setup, result, loop, not_done: list) -> tuple[dict, dict]:
    """(the engineering constants' fields of an :class:`Assessment`, the constants the
    plausibility judges): with the budget, else with the fit's std alone, else none."""
    from vibid.identify.assess.budget import engineering_budget

    block = attempt("uncertainty budget", not_done, engineering_budget, setup, result, loop)
    if block is None:  # the constants with the fit's std alone
        block = attempt("engineering constants", not_done, fit_constants, setup, result, default={})
    made = bool(block)
    budget, notes = block.pop("budget", None), block.pop("notes", [])
    fields = {"constants": block if made else None, "budget": budget, "notes": tuple(notes)}
    return fields, block


def assess(result, loop=None, setup=None, *, linearity=None, reference=None, not_done=()):
    """The :class:`Assessment` of ``result`` (``loop.final`` where ``loop``, a
    :class:`~vibid.identify.loop.LoopResult`, is given). ``setup``: the declared setup;
    without it, no engineering constants, plausibility or reference. ``linearity``: the
    tests made before the fit (:func:`linearity_tests`); ``reference``: the specimen's known
    modulus (:class:`~vibid.identify.assess.reference.Reference`) or None; ``not_done``: the
    stages an earlier step could not do. The budget differentiates with JAX: hold the JAX
    turn (:func:`vibid.identify.engine.threads.jax_turn`)."""
    if loop is not None:
        result = loop.final
    not_done = list(not_done)
    fields = {
        "unexplained_residual": bool(loop.unexplained_residual)
        if loop is not None
        else unexplained(result),
        "free_length": free_length_share(result),
    }
    if setup is not None:
        fields["reference"] = attempt(
            "reference", not_done, reference_block, setup, result, reference, loop
        )
    fields["linearity"] = attempt(
        "linearity", not_done, linearity_tests, result, linearity, default=()
    )
    if setup is not None:
        engineering, constants = _engineering(setup, result, loop, not_done)
        model = getattr(getattr(result, "plate_model", None), "model", None) or result.model
        fields |= engineering
        fields["plausibility"] = attempt(
            "plausibility", not_done, judge_plausibility, model, result, constants, setup
        )
    return Assessment(**fields, not_done=tuple(not_done))
