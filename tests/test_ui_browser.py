"""The report's figures and the live AFC, checked in a real browser (issue #29, part 4).

Needs Chromium (``chromium`` or ``chromium-browser`` on PATH; Debian: ``apt-get install
chromium``); skipped without it. One test, about a minute:

1. a Prefect server on the loopback (``prefect server start --host 127.0.0.1 --port P``, a
   subprocess with its own PREFECT_HOME and SQLite database under ``tmp_path``), always
   stopped at the end;
2. a short campaign on the simulated stand (the paper's strip, 21 steps, the 20 µs channel
   delay the loop finds) through ``vibid campaign`` in a subprocess with
   ``PREFECT_API_URL`` pointing at that server (the test process keeps its own Prefect
   settings: the suite's ``prefect_test_harness`` is never involved);
3. the run's ``<specimen>-report`` and ``<specimen>-live`` artifacts found through the
   server's REST API and their pages in the UI (``/artifacts/artifact/<id>``) screenshot by
   headless Chromium from the command line;
4. the screenshots must show the figures: a white figure area (the dark UI has none of its
   own) holding the model's line (matplotlib C1 orange in the report's AFC, C3 red in the
   live AFC) across hundreds of pixel columns and the measured points (C0 blue). A copy of
   the report artifact whose PNG data URIs are broken, shown by the same UI (its text is in
   the page's DOM), must fail the same check: the check sees the image, not the page.

``python tests/test_ui_browser.py [--docs DIR]`` (or ``python benchmarks/ui_screenshot.py``)
does the same outside pytest and writes the screenshots of docs/prefect-and-ui.md
(``docs/ui-report-artifact.png``, ``docs/ui-live-artifact.png``).

Every subprocess runs under a time-out; the server and Chromium are started in their own
process groups and those groups are ended, by id, when done.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

#: The test needs a Chromium on PATH (and runs about a minute: slow).
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="needs Chromium: no chromium or chromium-browser on PATH "
    "(Debian: apt-get install chromium)",
)
pytestmark = [needs_chromium, pytest.mark.slow]

SERVER_START_TIMEOUT_S = 180.0  # a fresh PREFECT_HOME copies the UI bundle first
SERVER_STOP_TIMEOUT_S = 30.0
CAMPAIGN_TIMEOUT_S = 400.0  # about 35 s on a 2-core machine (JAX compiles included)
CHROMIUM_TIMEOUT_S = 120.0
HTTP_TIMEOUT_S = 30.0

#: matplotlib's default colours as the figures draw them (report/plots.py's afc_figure,
#: flows/live.py's LiveAfc.render_png)
C0_BLUE = (0x1F, 0x77, 0xB4)  # measured points (report and live AFC)
C1_ORANGE = (0xFF, 0x7F, 0x0E)  # the identified model's line in the report's AFC
C3_RED = (0xD6, 0x27, 0x28)  # the identified model's line in the live AFC

#: the short campaign: the strip of setup_model.example_setup, 21 steps to 900 Hz
FREQUENCIES_HZ = (30.0,) + tuple(45.0 * k for k in range(1, 21))
TAU_S = 2e-5

DATA_URI = re.compile(r"data:image/png;base64,[A-Za-z0-9+/=]+")


# -- helpers: processes ------------------------------------------------------------------------
def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def prefect_env(home: Path, **extra: str) -> dict[str, str]:
    """This environment without any PREFECT_* setting (a user's profile, the suite's
    harness), with its own PREFECT_HOME and no telemetry, plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    env.update(PREFECT_HOME=os.fspath(home), PREFECT_SERVER_ANALYTICS_ENABLED="false", **extra)
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env


def _end_group(proc: subprocess.Popen, timeout_s: float = SERVER_STOP_TIMEOUT_S) -> None:
    """Stop ``proc`` and its process group (started with ``start_new_session``)."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            pass
    # whatever the leader left in its group (it is gone or was just asked to go)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=10)


def _tail(path: Path, n: int = 3000) -> str:
    try:
        return path.read_text(errors="replace")[-n:]
    except OSError:
        return ""


@contextlib.contextmanager
def prefect_server(folder: Path, *, timeout_s: float = SERVER_START_TIMEOUT_S):
    """A Prefect server on 127.0.0.1 (a free port) with PREFECT_HOME and its SQLite
    database in ``folder``; yields its API URL (``http://127.0.0.1:P/api``) once
    ``/api/health`` answers, and always stops it.

    ``PREFECT_UI_API_URL`` is set to the same URL: ``prefect server start --port P`` does
    not tell the UI its port, and the UI would then ask port 4200 for its data (an empty
    page)."""
    folder.mkdir(parents=True, exist_ok=True)
    port = free_port()
    api_url = f"http://127.0.0.1:{port}/api"
    env = prefect_env(
        folder / "prefect-home",
        PREFECT_API_DATABASE_CONNECTION_URL=f"sqlite+aiosqlite:///{folder / 'prefect.db'}",
        PREFECT_UI_API_URL=api_url,
        PREFECT_SERVER_API_HOST="127.0.0.1",
        PREFECT_SERVER_API_PORT=str(port),
    )
    log = folder / "server.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "prefect",
                "server",
                "start",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
            ],
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            cwd=folder,
            start_new_session=True,
        )
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"the Prefect server exited ({proc.returncode}):\n{_tail(log)}")
            try:
                with urllib.request.urlopen(f"{api_url}/health", timeout=5) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"no Prefect server at {api_url} after {timeout_s:.0f} s:\n{_tail(log)}"
                )
            time.sleep(0.5)
        yield api_url
    finally:
        _end_group(proc)


def write_campaign_inputs(folder: Path) -> tuple[Path, Path]:
    """The short campaign's setup and simulated stand (as tests/test_flows_campaign.py's,
    without its fault)."""
    import dataclasses

    from vibid.setup_model import example_setup

    s = example_setup()
    s = dataclasses.replace(
        s, excitation=dataclasses.replace(s.excitation, frequencies_hz=FREQUENCIES_HZ)
    )
    setup = folder / "setup.json"
    setup.write_text(s.to_json())
    stand = folder / "stand.json"
    stand.write_text(
        json.dumps(
            {
                "generator": {"url": "vibidsim://ui-browser", "timeout_s": 0.2},
                "timing": {"min_record_s": 0.05, "min_cycles": 10, "max_settle_s": 40.0},
                "simulated": {
                    "seed": 3,
                    "noise": 0.003,
                    "effects": {"channel_delay": {"tau_s": TAU_S}},
                },
            }
        )
    )
    return setup, stand


def run_campaign(folder: Path, api_url: str, *, timeout_s: float = CAMPAIGN_TIMEOUT_S):
    """``vibid campaign`` on the simulated stand in a subprocess reporting to ``api_url``;
    returns (specimen name, completed process)."""
    folder.mkdir(parents=True, exist_ok=True)
    setup, stand = write_campaign_inputs(folder)
    env = prefect_env(folder / "client-home", PREFECT_API_URL=api_url)
    cmd = [
        sys.executable,
        "-m",
        "vibid",
        "campaign",
        os.fspath(setup),
        "--stand",
        "simulated",
        "--stand-config",
        os.fspath(stand),
        "--out",
        os.fspath(folder / "strip.h5"),
        "--report",
        os.fspath(folder / "report"),
        "--candidates",
        "channel_delay",
        "--restarts",
        "1",
    ]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        env=env,
        cwd=folder,
        text=True,
        start_new_session=True,
    )
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        _end_group(proc, 10)
        raise TimeoutError(f"the campaign took over {timeout_s:.0f} s") from None
    finally:
        _end_group(proc, 10)
    specimen = json.loads(setup.read_text())["specimen"]["name"]
    return specimen, subprocess.CompletedProcess(cmd, proc.returncode, out, None)


def artifact_key(specimen: str, suffix: str) -> str:
    """The key vibid publishes a specimen's artifacts under (docs/prefect-and-ui.md: ``<specimen>-report``,
    ``<specimen>-live``): the name in lowercase, runs of other characters as one dash."""
    slug = re.sub(r"[^a-z0-9]+", "-", specimen.lower()).strip("-")
    return f"{slug or 'specimen'}-{suffix}"


# -- helpers: the REST API ---------------------------------------------------------------------
def api_post(api_url: str, path: str, body: dict):
    req = urllib.request.Request(
        f"{api_url}{path}",
        data=json.dumps(body).encode(),
        headers={"Content-Type": "application/json"},
        method="POST",
    )
    with urllib.request.urlopen(req, timeout=HTTP_TIMEOUT_S) as r:
        return json.loads(r.read())


def latest_artifact(api_url: str, key: str) -> dict | None:
    """The newest version of the artifact ``key`` (``POST /api/artifacts/filter``)."""
    found = api_post(
        api_url,
        "/artifacts/filter",
        {"artifacts": {"key": {"any_": [key]}}, "sort": "CREATED_DESC", "limit": 1},
    )
    return found[0] if found else None


def create_markdown_artifact(api_url: str, key: str, markdown: str, *, flow_run_id=None) -> dict:
    """A markdown artifact made directly through the API (``POST /api/artifacts/``)."""
    return api_post(
        api_url,
        "/artifacts/",
        {
            "key": key,
            "type": "markdown",
            "data": markdown,
            "flow_run_id": flow_run_id,
            "description": "vibid UI test: figures broken",
        },
    )


def artifact_page(api_url: str, artifact_id: str) -> str:
    """The artifact's page in the UI (the server serves the UI beside its API)."""
    return f"{api_url.removesuffix('/api')}/artifacts/artifact/{artifact_id}"


# -- helpers: the browser ----------------------------------------------------------------------
def _chromium(args: list[str], folder: Path, *, timeout_s: float) -> subprocess.CompletedProcess:
    profile = Path(tempfile.mkdtemp(prefix="chromium-profile-", dir=folder))
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        "--no-first-run",
        "--disable-dev-shm-usage",
        "--disable-extensions",
        "--force-device-scale-factor=1",
        f"--user-data-dir={profile}",
        *args,
    ]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise TimeoutError(f"chromium took over {timeout_s:.0f} s: {' '.join(cmd)}") from None
    finally:
        _end_group(proc, 10)  # its renderer and GPU helpers too
        shutil.rmtree(profile, ignore_errors=True)
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def screenshot(
    url: str,
    path: Path,
    *,
    width: int = 1400,
    height: int = 2400,
    budget_ms: int = 15000,
    timeout_s: float = CHROMIUM_TIMEOUT_S,
) -> Path:
    """Headless Chromium's screenshot of ``url`` (the viewport, ``width`` x ``height``)
    after ``budget_ms`` of virtual time (the UI's scripts and API calls run first)."""
    path = Path(path)
    path.unlink(missing_ok=True)
    done = _chromium(
        [
            f"--window-size={width},{height}",
            f"--virtual-time-budget={budget_ms}",
            f"--screenshot={path}",
            url,
        ],
        path.parent,
        timeout_s=timeout_s,
    )
    if not path.is_file():
        raise RuntimeError(
            f"chromium wrote no screenshot (rc {done.returncode}):\n"
            f"{done.stderr.decode(errors='replace')[-2000:]}"
        )
    return path


def dump_dom(
    url: str, folder: Path, *, budget_ms: int = 15000, timeout_s: float = CHROMIUM_TIMEOUT_S
) -> str:
    """The page's DOM as headless Chromium has it after ``budget_ms`` of virtual time."""
    done = _chromium(
        [f"--virtual-time-budget={budget_ms}", "--dump-dom", url], folder, timeout_s=timeout_s
    )
    return done.stdout.decode(errors="replace")


# -- helpers: what a screenshot shows ----------------------------------------------------------
def load_rgb(path):
    import numpy as np
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def colour_mask(rgb, colour, tol: int = 40):
    """Pixels within ``tol`` (per channel) of ``colour`` (the browser scales a figure down,
    and an antialiased line's pixels blend with the white around it)."""
    import numpy as np

    return np.abs(rgb.astype(int) - np.array(colour)).max(axis=2) <= tol


def white_areas(
    rgb, *, min_run: int = 40, min_row_white: int = 200, min_height: int = 120, max_gap: int = 6
):
    """The large white areas of a screenshot, as (top, bottom, left, right) boxes: bands of
    rows that hold at least ``min_row_white`` pixels in white runs of ``min_run`` or more
    (a figure's background; glyphs of text never make such runs), at least ``min_height``
    rows tall, gaps of up to ``max_gap`` rows bridged; their columns where the band is
    mostly white. The Prefect UI's own pages (dark theme) have none."""
    import numpy as np

    white = (rgb >= 245).all(axis=2)
    h, w = white.shape
    # per row: the pixels in white runs of min_run or more
    padded = np.zeros((h, w + 2), bool)
    padded[:, 1:-1] = white
    d = np.diff(padded.astype(np.int8), axis=1)
    long_white = np.zeros(h, int)
    for y in range(h):
        starts, ends = np.flatnonzero(d[y] == 1), np.flatnonzero(d[y] == -1)
        runs = ends - starts
        long_white[y] = runs[runs >= min_run].sum()
    rows = np.flatnonzero(long_white >= min_row_white)
    boxes = []
    if rows.size == 0:
        return boxes
    groups = np.split(rows, np.flatnonzero(np.diff(rows) > max_gap + 1) + 1)
    for g in groups:
        top, bottom = int(g[0]), int(g[-1]) + 1
        if bottom - top < min_height:
            continue
        cols = np.flatnonzero(white[top:bottom].mean(axis=0) > 0.5)
        if cols.size:
            boxes.append((top, bottom, int(cols[0]), int(cols[-1]) + 1))
    return boxes


def figure_evidence(rgb, line, points) -> list[dict]:
    """Per white area of the screenshot: its box, and the pixels of the ``line`` colour
    and of the ``points`` colour in it, with how many columns each spans."""
    import numpy as np

    out = []
    for top, bottom, left, right in white_areas(rgb):
        region = rgb[top:bottom, left:right]
        item = {"box": (top, bottom, left, right)}
        for name, colour in (("line", line), ("points", points)):
            m = colour_mask(region, colour)
            item[name] = int(m.sum())
            item[f"{name}_columns"] = int(np.count_nonzero(m.any(axis=0)))
        out.append(item)
    return out


def shows_figure(
    rgb,
    *,
    line,
    points,
    min_line_columns: int = 150,
    min_line_pixels: int = 200,
    min_points: int = 50,
) -> dict | None:
    """The first white area that holds a plot: the ``line`` colour over at least
    ``min_line_columns`` columns (a curve across the axes, not a glyph or a badge) and
    ``min_points`` pixels of the ``points`` colour; None if there is none. A broken image
    (its icon and alt text on the dark page) has no white area at all, and a light page
    without the figure no line of the figure's colours."""
    for item in figure_evidence(rgb, line, points):
        if (
            item["line_columns"] >= min_line_columns
            and item["line"] >= min_line_pixels
            and item["points"] >= min_points
        ):
            return item
    return None


def crop_for_docs(
    rgb,
    box,
    path: Path,
    *,
    header_rows: int = 70,
    above: int = 60,
    below: int = 50,
    near_top: int = 1000,
    max_width: int = 1000,
    max_bytes: int = 300_000,
) -> Path:
    """The docs' picture: the page from its top down to the figure area ``box`` (plus
    ``below`` rows) where the figure starts within ``near_top`` rows; else the UI's header
    (the artifact's key and id), a grey cut, and the page from ``above`` rows over the
    figure, cropped on the right past the figure and the header's text. Downscaled to
    ``max_width`` pixels (smaller again until the PNG is under ``max_bytes``)."""
    import numpy as np
    from PIL import Image

    top, bottom, _, fig_right = box
    h, w, _ = rgb.shape
    # the header's text (the artifact's key / id), left of the menu button at the far right
    header = rgb[:header_rows, : w - 100].astype(int).mean(axis=2) > 150
    text_cols = np.flatnonzero(header.any(axis=0))
    right = min(w, max(fig_right + 60, (int(text_cols[-1]) + 30) if text_cols.size else 0))
    lum = rgb.astype(int).mean(axis=2)
    end, blank = bottom, 0
    while end < min(h, bottom + 4 * below) and (end < bottom + below or blank < 14):
        blank = blank + 1 if np.ptp(lum[end, :right]) <= 12 else 0
        end += 1  # on to a gap between paragraphs: not within the caption
    if top <= near_top:
        parts = [rgb[:end]]  # the whole page's width: the run's details beside the figure
    else:
        start = top - above
        while start < top and np.ptp(lum[start, :right]) > 12:
            start += 1  # not from the middle of a line of text: from the blank row after it
        parts = [
            rgb[:header_rows, :right],
            np.full((3, right, 3), 90, np.uint8),
            rgb[start:end, :right],
        ]
    im = Image.fromarray(np.ascontiguousarray(np.concatenate(parts, axis=0)))
    width = min(max_width, im.width)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        small = im.resize((width, round(im.height * width / im.width)), Image.LANCZOS)
        small.save(path, optimize=True)
        if path.stat().st_size < max_bytes or width < 400:
            return path
        width = int(width * 0.85)


# -- the whole check ----------------------------------------------------------------------------
REPORT_WINDOW = (1400, 5200)  # tall: the report's figures come after its tables
LIVE_WINDOW = (1400, 1400)
BUDGETS_MS = (15000, 45000)  # a second, longer look where the first found no figure


def screenshot_showing(url: str, path: Path, window, *, line, points, min_line_columns):
    """The page's screenshot and the figure it shows (None: none), looked at again with a
    longer virtual-time budget if the first look finds none (a busy machine's UI may not
    have its data yet)."""
    for budget_ms in BUDGETS_MS:
        rgb = load_rgb(
            screenshot(url, path, width=window[0], height=window[1], budget_ms=budget_ms)
        )
        hit = shows_figure(rgb, line=line, points=points, min_line_columns=min_line_columns)
        if hit is not None:
            break
    return rgb, hit


def check_in_browser(folder: Path, *, docs: Path | None = None, log=print) -> dict:
    """Server, campaign, artifacts, screenshots and their checks (see the module's text);
    with ``docs``, docs/prefect-and-ui.md's two pictures written there. Returns what it found; raises
    AssertionError where the UI does not show a figure."""
    folder = Path(folder)
    t0 = time.monotonic()
    found: dict = {}
    with prefect_server(folder / "server") as api_url:
        log(f"server up at {api_url} ({time.monotonic() - t0:.0f} s)")
        t1 = time.monotonic()
        specimen, done = run_campaign(folder / "campaign", api_url)
        assert done.returncode == 0, done.stdout[-4000:]
        log(f"campaign done ({time.monotonic() - t1:.0f} s)")

        # the report: its figures in the artifact, then on the screen
        report = latest_artifact(api_url, artifact_key(specimen, "report"))
        assert report is not None, f"no {artifact_key(specimen, 'report')} artifact"
        assert report["type"] == "markdown" and DATA_URI.search(report["data"]), (
            "the report artifact embeds no PNG"
        )
        shot = folder / "report.png"
        rgb, hit = screenshot_showing(
            artifact_page(api_url, report["id"]),
            shot,
            REPORT_WINDOW,
            line=C1_ORANGE,
            points=C0_BLUE,
            min_line_columns=200,
        )
        assert hit is not None, (
            "the report artifact's page shows no AFC figure: "
            f"{figure_evidence(rgb, C1_ORANGE, C0_BLUE)} ({shot})"
        )
        found["report"] = {"id": report["id"], "screenshot": shot, "figure": hit}
        if docs is not None:
            found["report"]["docs"] = crop_for_docs(
                rgb, hit["box"], Path(docs) / "ui-report-artifact.png"
            )

        # the same page with its figures' data broken: the UI shows the text, the check
        # must see no figure
        broken_md = DATA_URI.sub("data:image/png;base64,AAAA", report["data"])
        broken = create_markdown_artifact(
            api_url,
            artifact_key(specimen, "broken-figures"),
            broken_md,
            flow_run_id=report["flow_run_id"],
        )
        url = artifact_page(api_url, broken["id"])
        dom = dump_dom(url, folder)
        assert "identification report" in dom and "data:image/png;base64,AAAA" in dom, (
            "the UI did not render the broken copy's markdown: the control proves nothing"
        )
        rgb_broken = load_rgb(
            screenshot(
                url, folder / "report-broken.png", width=REPORT_WINDOW[0], height=REPORT_WINDOW[1]
            )
        )
        miss = shows_figure(rgb_broken, line=C1_ORANGE, points=C0_BLUE, min_line_columns=200)
        assert miss is None, f"the check sees a figure where the image is broken: {miss}"

        # the live AFC: its last version, the points with the identified model over them
        live = latest_artifact(api_url, artifact_key(specimen, "live"))
        assert live is not None, f"no {artifact_key(specimen, 'live')} artifact"
        assert DATA_URI.search(live["data"]), "the live artifact embeds no PNG"
        shot = folder / "live.png"
        rgb, hit = screenshot_showing(
            artifact_page(api_url, live["id"]),
            shot,
            LIVE_WINDOW,
            line=C3_RED,
            points=C0_BLUE,
            min_line_columns=150,
        )
        assert hit is not None, (
            "the live artifact's page shows no AFC figure: "
            f"{figure_evidence(rgb, C3_RED, C0_BLUE)} ({shot})"
        )
        found["live"] = {"id": live["id"], "screenshot": shot, "figure": hit}
        if docs is not None:
            found["live"]["docs"] = crop_for_docs(
                rgb, hit["box"], Path(docs) / "ui-live-artifact.png"
            )
    log(f"checked in {time.monotonic() - t0:.0f} s")
    return found


def test_report_and_live_figures_show_in_the_prefect_ui(tmp_path):
    found = check_in_browser(tmp_path)  # its progress lines show with a failure
    assert set(found) == {"report", "live"}


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(
        description="Run a short campaign against a temporary Prefect "
        "server, screenshot its report and live AFC artifacts in "
        "headless Chromium, check that they show the figures, and "
        "write the pictures of docs/prefect-and-ui.md."
    )
    p.add_argument(
        "--docs",
        default=os.path.join(os.path.dirname(__file__), "..", "docs"),
        help="where to write ui-report-artifact.png and ui-live-artifact.png",
    )
    p.add_argument("--keep", metavar="DIR", help="work in DIR (kept) instead of a temporary one")
    args = p.parse_args(argv)
    if CHROMIUM is None:
        print("no chromium or chromium-browser on PATH", file=sys.stderr)
        return 1
    with contextlib.ExitStack() as stack:
        folder = args.keep or stack.enter_context(tempfile.TemporaryDirectory(prefix="vibid-ui-"))
        found = check_in_browser(Path(folder), docs=Path(args.docs))
        for name, item in found.items():
            print(
                f"{name}: artifact {item['id']}, figure at {item['figure']['box']} "
                f"-> {os.path.normpath(item['docs'])}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
