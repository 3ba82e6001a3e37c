"""The Prefect UI screenshots of docs/prefect-and-ui.md, reproduced with one command:

    python benchmarks/ui_screenshot.py [--docs DIR] [--keep DIR]

Starts a Prefect server on the loopback (its own temporary PREFECT_HOME and database), runs
a 21-step campaign on the simulated stand against it (``vibid campaign`` in a subprocess),
opens the ``<specimen>-report`` and ``<specimen>-live`` artifacts' pages in headless
Chromium, checks that the figures show, and writes ``docs/ui-report-artifact.png`` and
``docs/ui-live-artifact.png``; then stops the server. About a minute; needs ``chromium``
(or ``chromium-browser``) on PATH. The work is ``tests/test_ui_browser.py``'s (its
``check_in_browser``); ``--keep DIR`` keeps the full screenshots, the session, the report
and the server's log.
"""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from test_ui_browser import main  # noqa: E402

if __name__ == "__main__":
    argv = sys.argv[1:]
    if not any(a == "--docs" or a.startswith("--docs=") for a in argv):
        argv = ["--docs", os.path.join(HERE, "..", "docs"), *argv]
    sys.exit(main(argv))
