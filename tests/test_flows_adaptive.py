"""`vibid campaign --adaptive` through campaign_flow (issues #28 and #29): the adaptive
campaign on the simulated stand under the Prefect test server, its live AFC showing each
batch's fit, and its report.

The virtual strip (0.3 % noise, no undeclared effect); a target loose enough that the coarse
sweep and at most a batch or two reach it. The references: the virtual specimen's true
parameters, and what the flow was told to publish.
"""

import contextlib
import io
import json
from pathlib import Path

import pytest

from vibid.cli import main

pytestmark = pytest.mark.usefixtures("prefect_harness")
EXAMPLES = Path(__file__).parent.parent / "examples"


@pytest.fixture(scope="module")
def adaptive(tmp_path_factory):
    import vibid.flows.live as live

    folder = tmp_path_factory.mktemp("adaptive")
    stand = folder / "stand.json"
    stand.write_text(
        json.dumps(
            {
                "generator": {"url": "vibidsim://flow-adaptive"},
                "drive": {"target_base_m_s2": 1.0, "initial_vpp": 0.04},
                "timing": {"max_settle_s": 30.0},
                "simulated": {"seed": 2, "noise": 0.003},
            }
        )
    )
    out, report_dir = folder / "a.h5", folder / "report"
    published = []
    real = live.prefect_publish

    def spy(key, markdown):
        published.append((key, markdown))
        real(key, markdown)

    stdout = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(stdout):
        mp.setattr(live, "prefect_publish", spy)
        rc = main(
            [
                "campaign",
                str(EXAMPLES / "strip_setup.json"),
                "--stand",
                "simulated",
                "--stand-config",
                str(stand),
                "--out",
                str(out),
                "--report",
                str(report_dir),
                "--adaptive",
                "--target",
                "D=0.002%",
                "--max-stand-time",
                "120",
                "--no-loop",
                "--restarts",
                "1",
            ]
        )
    return {
        "rc": rc,
        "out": out,
        "stdout": stdout.getvalue(),
        "published": published,
        "report": json.loads((report_dir / "report.json").read_text()),
    }


def test_the_adaptive_flow_records_an_adaptive_session_and_reports_the_truth(adaptive):
    from vibid.session import file_problems, read_session

    assert adaptive["rc"] == 0, adaptive["stdout"]
    assert file_problems(adaptive["out"]) == []
    with read_session(adaptive["out"]) as s:
        assert s.adaptive["target"] == ["D=0.002%"] and s.adaptive["max_stand_time_s"] == 120.0
        assert s.run_status == "complete" and len(s) >= 16
        assert s.stand_time_s < 120.0
    truth = {"D": 17.97, "nu": 0.286, "beta": 0.003}  # the stand configuration's defaults
    params = adaptive["report"]["parameters"]
    for name, value in truth.items():
        assert abs(params[name]["value"] - value) < 3 * params[name]["std"], name
    assert params["D"]["std"] / params["D"]["value"] <= 2e-5


def test_the_live_afc_shows_each_batchs_fit_and_how_the_campaign_ended(adaptive):
    from prefect.artifacts import Artifact

    versions = [md for key, md in adaptive["published"] if key == "steel-strip-100x20x1-live"]
    assert versions, [key for key, _ in adaptive["published"]]
    assert all("adaptive: until D=0.002% or 120 s of stand time" in md for md in versions)
    fits = [md for md in versions if "drawn over the points: fit of 16 steps" in md]
    assert fits and "after 16 steps: D " in fits[0]
    last = versions[-1]
    assert "campaign complete" in last and "target reached" in last
    assert "drawn over the points: identified model" in last
    artifact = Artifact.get("steel-strip-100x20x1-live")
    assert artifact is not None and "target reached" in artifact.data
