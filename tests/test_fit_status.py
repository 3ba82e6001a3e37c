"""No meaningless "converged" (issue 62, item 10): an estimate that is not finite, or one
at the end of a parameter's physical range (the catalogue's rule: a positive stiffness at
~0, Poisson's ratio at −1 or 0.5), is never ``converged``, whatever the optimiser said; the
prior box's edge is another matter (a warning), and an estimate there may be converged.

Found: an all-zero AFC "converged" (D 3e-12 N m, nu −1, beta 8.7e5)."""

import sys
from pathlib import Path

import numpy as np
import pytest

from vibid.identify.fit.result import LocalResult, Status, final_status, physical_end
from vibid.identify.fit.space import ParameterSpace
from vibid.parameters import K_THETA, NU, D
from vibid.setup_model import example_setup

BOUNDS = {"D": (1.0, 100.0), "nu": (0.0, 0.5), "beta": (1e-4, 0.1)}  # the strip's setup
SPACE = ParameterSpace.from_bounds(tuple(BOUNDS), BOUNDS)


def _run(theta, status=Status.CONVERGED):
    return LocalResult(
        "trust-region-newton",
        np.zeros(3),
        np.asarray(theta, float),
        57.0,
        status,
        "converged (the step became negligible)",
        12,
        13,
    )


def _status(D=17.97, nu=0.286, beta=0.003, chi2=57.0, status=Status.CONVERGED):
    theta = np.array([D, nu, beta])
    return final_status(_run(theta, status), SPACE, theta, chi2)


def test_an_estimate_inside_the_physical_range_keeps_the_optimisers_word():
    assert _status(nu=0.3) == (
        Status.CONVERGED,
        "trust-region-newton converged (the step became negligible)",
    )
    # the prior box's edges are not the physical range's ends: nu = 0 (the box's low) and
    # a D below the box are warnings of their own, and may be converged
    assert _status(nu=0.0)[0] is Status.CONVERGED
    assert _status(D=0.5)[0] is Status.CONVERGED
    assert _status(nu=0.4999)[0] is Status.CONVERGED
    assert _status(beta=0.0)[0] is Status.CONVERGED  # a loss factor may be 0


def test_an_estimate_at_the_end_of_its_physical_range_is_not_converged():
    status, message = _status(nu=-1 + 1e-12)
    assert status is Status.AT_PHYSICAL_LIMIT and not status.ok
    assert "nu = -1 at -1" in message and "end of a parameter's physical range" in message
    assert _status(nu=0.5 - 1e-7)[0] is Status.AT_PHYSICAL_LIMIT
    status, message = _status(D=3e-12, nu=-1 + 1e-13, beta=8.7e5)  # the all-zero AFC's
    assert status is Status.AT_PHYSICAL_LIMIT
    assert "D = 3e-12 at 0" in message and "nu = -1 at -1" in message
    # an optimiser that did not converge keeps its own status
    assert _status(nu=-1 + 1e-12, status=Status.MAX_ITERATIONS)[0] is Status.MAX_ITERATIONS


def test_a_loss_that_is_not_finite_is_not_converged():
    status, message = _status(chi2=float("nan"))
    assert status is Status.NOT_FINITE and "chi2 = nan" in message


def test_the_ends_follow_the_catalogues_rule():
    assert physical_end(NU.rule, -1 + 1e-12, 0.0, 0.5) == -1.0
    assert physical_end(NU.rule, 0.5, 0.0, 0.5) == 0.5
    assert physical_end(NU.rule, 0.3, 0.0, 0.5) is None
    assert physical_end(D.rule, 3e-12, 1.0, 100.0) == 0.0
    assert physical_end(D.rule, 17.97, 1.0, 100.0) is None
    # a clamp at 1e3 N/rad in a box of 1e2-1e9 is a soft clamp, not no clamp
    assert physical_end(K_THETA.rule, 1e3, *K_THETA.bounds) is None
    assert physical_end("non-negative", 0.0, 0.0, 5e-3) is None


def test_an_afc_without_the_plates_response_is_not_converged():
    """A flat AFC of 1e-3 (the plate's response absent: a disconnected sensor) fitted from
    the truth: the optimiser stops, converged in its own terms, with D three decades below
    its box and nu at 0.5. Not converged: the report says so, the job fails after it. The
    strip's own AFC converges."""
    sys.path.insert(0, str(Path(__file__).parent))
    from ritz_toy import RitzPlateModel
    from vibid.errors import VibidError
    from vibid.identify import configure
    from vibid.identify.assess import assess
    from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify
    from vibid.pipeline import Identified, require_converged
    from vibid.report import build_report

    configure()
    setup = example_setup()
    f = np.linspace(20.0, 1500.0, 60)
    fm = RitzPlateModel(setup, f)
    start = {"D": 17.97, "nu": 0.286, "beta": 0.003}
    flat = identify(
        setup,
        Measurement(f, np.full(f.size, 1e-3 + 0j), np.full(f.size, 1e-3)),
        ModelChoice(forward_model=fm),
        SearchOptions(method="local", start=start),
    )
    assert flat.local_results[0].status is Status.CONVERGED  # the optimiser's own word
    assert flat.status is Status.AT_PHYSICAL_LIMIT and not flat.converged
    assert flat.parameters["D"] < 1e-3 * BOUNDS["D"][0]
    ident = build_report(flat, assess(flat), session_id="flat")["identification"]
    assert ident["status"] == "at_physical_limit" and ident["converged"] is False
    with pytest.raises(VibidError, match="did not converge.*physical range"):
        require_converged(Identified(flat, None, ""))
    H = np.asarray(fm.afc(np.array(list(start.values()))))
    own = identify(
        setup,
        Measurement(f, H, 0.003 * np.abs(H) + 1e-4),
        ModelChoice(forward_model=fm),
        SearchOptions(method="local", start={"D": 20.0, "nu": 0.3, "beta": 0.004}),
    )
    assert own.status is Status.CONVERGED
    assert own.parameters["nu"] == pytest.approx(0.286, rel=1e-6)
