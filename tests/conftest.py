import os

# Tests run on the CPU in float64, whatever the machine has.
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see vibid.cli: small dense solves

from vibid.identify.runtime import configure  # noqa: E402

# what every entry point does: 64-bit JAX and the compilation cache (importing vibid
# changes nothing in the process)
configure()


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def prefect_harness():
    """One Prefect test server (temporary database) for the whole test session; the flow
    tests ask for it, the others never start it."""
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=120):
        yield
