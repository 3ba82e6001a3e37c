"""The plate model runs on the machinery it is handed, not on one it imports.

The model asks :mod:`vibid.identify.model.machinery` for its compiled functions, its numpy
section, its timing sections and the 64-bit check; :mod:`vibid.identify` hands the engine's.
Handed a stand-in that records what is asked and compiles with plain ``jax.jit``, the model
gives the same AFC to rounding, and every question went through the stand-in.
"""

import contextlib

import numpy as np
import pytest

import vibid.identify  # noqa: F401  (hands the engine's machinery to the model)
from vibid.errors import VibidError
from vibid.identify.model import assembly, machinery
from vibid.identify.model.plate import build_forward_model
from vibid.setup_model import example_setup

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
FREQS = np.linspace(7.5, 1500.0, 60)


class _Recorder:
    """A machinery that compiles the kernel with plain jax.jit and records each question."""

    def __init__(self):
        self.asked = []

    def compile(self, kernel):
        import jax

        self.asked.append("compile")
        jitted = jax.jit(kernel)

        class _Functions:
            afc = staticmethod(jitted)

        return _Functions()

    @contextlib.contextmanager
    def numpy_section(self):
        self.asked.append("numpy_section")
        yield

    @contextlib.contextmanager
    def section(self, name):
        self.asked.append(f"section:{name}")
        yield

    def require_x64(self):
        self.asked.append("require_x64")


@pytest.fixture
def engine_machinery():
    handed = machinery.handed()
    yield handed
    machinery.hand(handed)


def test_the_model_runs_on_a_handed_stand_in(engine_machinery):
    setup = example_setup()
    theta = np.array([TRUTH[n] for n in ("D", "nu", "beta")])
    reference = np.asarray(build_forward_model(setup, FREQS, theta0=TRUTH).afc(theta))

    recorder = _Recorder()
    machinery.hand(
        machinery.Machinery(
            compile=recorder.compile,
            numpy_section=recorder.numpy_section,
            section=recorder.section,
            require_x64=recorder.require_x64,
        )
    )
    assembly.assemble_all.cache_clear()  # assemble anew, under the stand-in
    assembly._model_matrices.cache_clear()
    fm = build_forward_model(setup, FREQS, theta0=TRUTH)
    got = np.asarray(fm.afc(theta))

    np.testing.assert_allclose(got, reference, rtol=1e-12, atol=0)
    assert "require_x64" in recorder.asked
    assert "compile" in recorder.asked
    assert "numpy_section" in recorder.asked  # the assembly ran in the handed section
    assert any(q.startswith("section:") for q in recorder.asked)


def test_a_model_handed_nothing_says_so(engine_machinery, monkeypatch):
    monkeypatch.setattr(machinery, "_handed", None)
    with pytest.raises(VibidError, match="handed no engine"):
        build_forward_model(example_setup(), FREQS, theta0=TRUTH)
