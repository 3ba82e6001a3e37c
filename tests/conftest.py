import os
import sys

# Tests run on the CPU in float64, whatever the machine has.
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see vibid.cli: small dense solves

from vibid.identify.engine.runtime import configure  # noqa: E402

# what every entry point does: 64-bit JAX and the compilation cache (importing vibid
# changes nothing in the process)
configure()


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def prefect_harness():
    """One Prefect test server (temporary database) for the whole test session; the flow
    tests ask for it, the others never start it."""
    from prefect.testing.utilities import prefect_test_harness

    _prefect_console_follows_stderr()
    with prefect_test_harness(server_startup_timeout=120):
        _prefect_console_follows_stderr()
        yield


class _CurrentStderr:
    """Whatever ``sys.stderr`` is when written to (each test's capture in turn)."""

    def write(self, text):
        return sys.stderr.write(text)

    def __getattr__(self, name):
        return getattr(sys.stderr, name)


def _prefect_console_follows_stderr() -> None:
    """Prefect's console handler keeps the ``sys.stderr`` it found when Prefect set up its
    logging, which in a test run is some earlier test's capture, closed since: its next
    line then fails with a 'Logging error' traceback. Point it at the current stderr."""
    import logging

    from prefect.logging.handlers import PrefectConsoleHandler

    for logger in [logging.getLogger()] + [
        logging.getLogger(n) for n in list(logging.root.manager.loggerDict)
    ]:
        for handler in getattr(logger, "handlers", []):
            if isinstance(handler, PrefectConsoleHandler):
                handler.stream = _CurrentStderr()  # not setStream: it flushes the closed one
                handler.console.file = _CurrentStderr()
