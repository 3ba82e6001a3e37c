"""No hidden global state: importing vibid changes nothing in the process; a model used
without 64-bit JAX fails loudly; the forward model covers the box the search explores."""

import os
import subprocess
import sys

import numpy as np
import pytest

from plate_helpers import PAPER_THETA, strip_model, strip_setup
from vibid.errors import VibidError
from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify

#: A script's lines that compile one function worth a cache entry and evaluate it (``value``).
COMPILE_ONE = (
    "f = jax.jit(lambda x: jnp.linalg.eigh(x @ x.T + jnp.eye(40))[0].sum())\n"
    "value = float(f(jnp.ones((40, 40))))\n"
)


def _run(code: str, tmp_path) -> subprocess.CompletedProcess:
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("JAX_", "VIBID_", "XLA_", "OPENBLAS_", "OMP_"))
    }
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300
    )


def test_importing_vibid_changes_nothing_and_a_32_bit_process_fails_loudly(tmp_path):
    code = (
        "import jax, matplotlib\n"
        "backend = matplotlib.get_backend()\n"
        "import vibid.identify, vibid.identify.fit, vibid.identify.model.forward, vibid.report\n"
        "from vibid.identify import build_forward_model\n"
        "from vibid.setup_model import example_setup\n"
        "print(jax.config.jax_enable_x64, matplotlib.get_backend() == backend)\n"
        "try:\n"
        "    build_forward_model(example_setup(), [100.0, 200.0])\n"
        "except Exception as exc:\n"
        "    print(type(exc).__name__, exc)\n"
    )
    out = _run(code, tmp_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "False True"
    assert lines[1].startswith("VibidError") and "64-bit JAX" in lines[1]
    assert not (tmp_path / "cache" / "vibid").exists()  # no cache folder made on import


def test_configure_switches_on_64_bits_and_the_cache(tmp_path):
    out = _run(
        "from vibid.identify import configure\nimport jax\n"
        "from threadpoolctl import threadpool_info\n"
        "print(configure(), jax.config.jax_enable_x64,\n"
        "      sorted({i['num_threads'] for i in threadpool_info()\n"
        "              if i['user_api'] == 'blas'}) == [1])",
        tmp_path,
    )
    assert out.returncode == 0, out.stderr
    folder, x64, one_thread = out.stdout.split()
    assert x64 == "True" and folder == str(tmp_path / "cache" / "vibid" / "jax")
    assert os.path.isdir(folder)
    assert one_thread == "True"  # every BLAS library of the process on one thread


def test_configure_adds_vibids_xla_flags_and_keeps_the_users(tmp_path, monkeypatch):
    from vibid.identify.engine.runtime import XLA_CPU_FLAGS, use_xla_flags

    out = _run(
        "import os\nfrom vibid.identify import configure\nconfigure()\n"
        "print(os.environ['XLA_FLAGS'])",
        tmp_path,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == list(XLA_CPU_FLAGS)
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_fusion_emitters=true --xla_dump_to=/x")
    use_xla_flags(("--xla_cpu_use_fusion_emitters=false", "--xla_cpu_enable_fast_math=false"))
    assert os.environ["XLA_FLAGS"].split() == [
        "--xla_cpu_use_fusion_emitters=true",
        "--xla_dump_to=/x",
        "--xla_cpu_enable_fast_math=false",
    ]


def test_the_compilation_cache_is_read_and_written_under_a_lock(tmp_path):
    """Two processes share the cache: one must not read an entry the other is still writing
    (a truncated entry crashed a test worker). JAX locks the cache only when it has a size
    limit; its lock file and its access times appear once an entry is written and read."""
    code = (
        "from vibid.identify import configure\nimport jax, jax.numpy as jnp\n"
        "folder = configure()\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        + COMPILE_ONE
        + "print(folder, jax.config.jax_compilation_cache_max_size, value)\n"
    )
    first = _run(code, tmp_path)
    assert first.returncode == 0, first.stderr
    folder, limit, _ = first.stdout.split()
    assert int(limit) > 0
    entries = [n for n in os.listdir(folder) if n.endswith("-cache")]
    assert entries and os.path.exists(os.path.join(folder, ".lockfile"))
    second = _run(code, tmp_path)  # a second process reads the entry
    assert second.returncode == 0, second.stderr
    assert all(os.path.exists(os.path.join(folder, n.replace("-cache", "-atime"))) for n in entries)


def test_the_forward_model_is_built_on_the_box_the_search_explores(monkeypatch):
    """identify(..., bounds=...) built its wide basis on the setup's box and searched the
    caller's, so the basis need not cover what was searched."""
    import vibid.identify.model.plate as plate

    built = []
    real = plate.build_forward_model

    def spy(*args, **kwargs):
        built.append(kwargs.get("bounds"))
        return real(*args, **kwargs)

    monkeypatch.setattr(plate, "build_forward_model", spy)
    setup = strip_setup()
    f = np.linspace(10.0, 600.0, 40)
    H = np.ones(f.size, complex)  # what is fitted does not matter here
    box = {"D": (5.0, 50.0), "nu": (0.1, 0.45), "beta": (1e-3, 1e-2)}
    identify(
        setup,
        Measurement(f, H),
        ModelChoice(bounds=box),
        SearchOptions(method="local", start={"D": 17.0, "nu": 0.3, "beta": 0.003}, refresh=False),
    )
    assert built == [box]


def test_a_wide_model_built_for_a_smaller_box_is_refused():
    fm = strip_model("wide", "fast", 200)
    f = fm.frequencies_hz
    H = np.asarray(fm.afc(PAPER_THETA))
    box = {"D": (0.5, 200.0), "nu": (0.0, 0.5), "beta": (1e-4, 0.1)}
    with pytest.raises(VibidError, match="does not cover the searched box"):
        identify(strip_setup(), Measurement(f, H), ModelChoice(forward_model=fm, bounds=box))
    # the box it was built for is fine
    res = identify(
        strip_setup(),
        Measurement(f, H),
        ModelChoice(forward_model=fm),
        SearchOptions(method="local", start={"D": 18.0, "nu": 0.29, "beta": 0.003}, refresh=False),
    )
    np.testing.assert_allclose(res.values, PAPER_THETA, rtol=1e-6)


def test_an_entry_without_an_access_time_does_not_stop_new_entries(tmp_path):
    """A cache written without a size limit (vibid before it had one) holds entries without
    an access time; JAX's eviction reads every entry's before it writes a new one, fails, and
    writes nothing ("Error writing persistent compilation cache entry", every compilation
    again in every process). configure() stamps them with their file's time first."""
    folder = tmp_path / "cache"
    folder.mkdir()
    (folder / "jit_old-0123-cache").write_bytes(b"an entry of the unlimited cache")
    os.utime(folder / "jit_old-0123-cache", ns=(0, 1_700_000_000_123_456_789))
    code = (
        "import os, warnings\nfrom vibid.identify import configure\n"
        "import jax, jax.numpy as jnp\n"
        f"os.environ['VIBID_JAX_CACHE'] = {str(folder)!r}\n"
        "folder = configure()\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "warnings.simplefilter('error')\n" + COMPILE_ONE
    )
    run = _run(code, tmp_path)
    assert run.returncode == 0, run.stderr
    assert "Error writing" not in run.stderr
    stamp = (folder / "jit_old-0123-atime").read_bytes()
    assert int.from_bytes(stamp, "little") == 1_700_000_000_123_456_789
    new = [n for n in os.listdir(folder) if n.endswith("-cache") and not n.startswith("jit_old")]
    assert new and all((folder / n.replace("-cache", "-atime")).exists() for n in new)
