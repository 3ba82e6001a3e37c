import os

# Tests run on the CPU in float64, whatever the machine has.
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see vibid.cli: small dense solves

from vibid.identify.runtime import configure  # noqa: E402

# what every entry point does: 64-bit JAX and the compilation cache (importing vibid
# changes nothing in the process)
configure()
