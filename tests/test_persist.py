"""Traced programs kept on disk (vibid.identify.engine.persist): a second process runs the kept
program without tracing the model's code, to the same numbers; anything that changes the
program (the code, the shapes, the function) gets a program of its own; a damaged artefact
is traced again."""

import dataclasses
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vibid.identify.engine import persist
from vibid.identify.engine.persist import Persisted, identity_of

#: A script that builds the paper's strip problem, counts how often the reduced model's code
#: is traced while its Hessian is computed, and prints the count and the Hessian.
HESSIAN = """
import numpy as np
from vibid.identify.engine.runtime import configure

def main():
    configure()
    import sys
    sys.path.insert(0, {tests!r})
    from plate_helpers import PAPER_THETA, strip_model
    from vibid.identify.fit.data import fit_data
    from vibid.identify.fit.problem import LeastSquaresProblem
    from vibid.identify.fit.space import ParameterSpace
    from vibid.identify.model import reduced

    fm = strip_model(nf=60)
    H = np.asarray(fm.afc(PAPER_THETA)) * 1.02
    space = ParameterSpace.from_bounds(fm.parameter_names, fm.bounds)
    problem = LeastSquaresProblem(fm, fit_data(fm.frequencies_hz, H, np.abs(H) * 0.01), space)
    traced = []
    original = reduced.ReducedKernel.__call__
    reduced.ReducedKernel.__call__ = lambda self, a, t: traced.append(1) or original(self, a, t)
    u = space.to_u(PAPER_THETA * np.array([1.01, 0.98, 1.3]))
    B = problem.hessian(u)
    print(len(traced))
    print(" ".join(repr(float(b)) for b in B.ravel()))
    plain = problem._fn.hessian.fn(problem._padded(u), *problem._args(), problem._space)
    print(" ".join(repr(float(b)) for b in np.asarray(plain)[:3, :3].ravel()))

if __name__ == "__main__":
    main()
"""


def _run(tmp_path) -> tuple[int, np.ndarray]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_", "VIBID_"))}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    script = tmp_path / "hessian.py"
    script.write_text(HESSIAN.format(tests=os.path.dirname(__file__)))
    out = subprocess.run(
        [sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr
    count, kept, plain = out.stdout.splitlines()[-3:]
    kept, plain = (np.array([float(v) for v in line.split()]) for line in (kept, plain))
    np.testing.assert_allclose(kept, plain, rtol=1e-12, atol=0)  # the program jit traces
    return int(count), kept


def test_a_second_process_runs_the_kept_hessian_without_tracing_the_model(tmp_path):
    traced_first, first = _run(tmp_path)
    kept = os.listdir(tmp_path / "cache" / "vibid" / "jax" / "exported")
    assert traced_first > 0 and any(n.endswith(".jaxexport") for n in kept)
    traced_again, again = _run(tmp_path)
    assert traced_again == 0  # the model's Python code never ran: the program came from disk
    assert np.all(np.isfinite(first)) and np.abs(first).max() > 0
    np.testing.assert_allclose(again, first, rtol=1e-12, atol=0)


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setattr(persist, "folder", lambda: str(tmp_path))
    return tmp_path


def _counted():
    """A jitted function and the list its tracing appends to."""
    traces = []

    def f(x, y):
        traces.append(1)
        return jnp.sin(x) @ y

    return jax.jit(f), traces


def _artefacts(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".jaxexport"))


def test_a_kept_program_is_found_by_its_identity_and_shapes_only(folder, monkeypatch):
    x, y = np.linspace(0.0, 1.0, 6).reshape(2, 3), np.arange(3.0)
    f, traces = _counted()
    expected = np.sin(x) @ y
    np.testing.assert_allclose(Persisted(f, "toy", "v1")(x, y), expected, rtol=1e-15)
    assert len(traces) == 1 and len(_artefacts(folder)) == 1

    g, traces_g = _counted()  # another process's function of the same identity
    np.testing.assert_allclose(Persisted(g, "toy", "v1")(x, y), expected, rtol=1e-15)
    assert traces_g == []

    h, traces_h = _counted()
    kept = Persisted(h, "toy", "v1")
    kept(np.ones((4, 3)), y)  # other shapes: a program of their own
    kept(x, y)
    kept(x, y)
    assert len(traces_h) == 1 and len(_artefacts(folder)) == 2

    other, traces_other = _counted()
    Persisted(other, "other", "v1")(x, y)  # another function
    structure, traces_structure = _counted()
    Persisted(structure, "toy", "v2")(x, y)  # the same function of another model structure
    monkeypatch.setattr(persist, "code_digest", lambda: "edited")
    edited, traces_edited = _counted()
    Persisted(edited, "toy", "v1")(x, y)  # the same function after an edit of vibid
    assert len(traces_other) == len(traces_structure) == len(traces_edited) == 1
    assert len(_artefacts(folder)) == 5


def test_a_damaged_artefact_is_traced_again_and_rewritten(folder):
    x, y = np.eye(3), np.ones(3)
    f, traces = _counted()
    Persisted(f, "toy", "v1")(x, y)
    (path,) = folder.glob("*.jaxexport")
    path.write_bytes(path.read_bytes()[:100])
    g, traces_g = _counted()
    np.testing.assert_allclose(Persisted(g, "toy", "v1")(x, y), np.sin(x) @ y, rtol=1e-15)
    assert len(traces_g) == 1 and path.stat().st_size > 100


def test_without_an_identity_a_folder_or_vibids_source_the_function_is_traced_as_usual(
    tmp_path, monkeypatch
):
    monkeypatch.setattr(persist, "folder", lambda: None)
    f, traces = _counted()
    Persisted(f, "toy", "v1")(np.eye(2), np.ones(2))
    monkeypatch.setattr(persist, "folder", lambda: str(tmp_path))
    Persisted(f, "toy", None)(np.eye(2), np.ones(2))
    monkeypatch.setattr(persist, "code_digest", lambda: None)  # vibid in a zip archive
    Persisted(f, "toy", "v1")(np.eye(2), np.ones(2))
    assert list(tmp_path.iterdir()) == []


@dataclasses.dataclass(frozen=True)
class Outside:
    """A structure vibid's source does not hold."""

    name: str = "own term"


def test_identity_only_for_what_vibids_code_determines():
    from vibid.identify.model.plate import plate_model
    from vibid.identify.model.reduced import ReducedKernel

    kernel = ReducedKernel(plate_model("isotropic"))
    text = identity_of(kernel)
    assert text is not None and "isotropic" in text and identity_of(kernel) == text
    assert identity_of(ReducedKernel(plate_model("orthotropic"))) != text
    assert identity_of(lambda x: x) is None
    assert identity_of(Outside()) is None  # a class outside vibid (a test's own term)
    assert identity_of(ReducedKernel(Outside())) is None


def test_the_folder_keeps_the_most_recently_used(tmp_path):
    for k in range(5):
        p = tmp_path / f"{k}.jaxexport"
        p.write_bytes(b"x")
        os.utime(p, (1000 + k, 1000 + k))
    persist._evict(str(tmp_path), keep=2)
    assert _artefacts(tmp_path) == ["3.jaxexport", "4.jaxexport"]


def test_inside_a_transformation_it_is_the_function_itself(folder):
    f, traces = _counted()
    kept = Persisted(f, "toy", "v1")
    x, y = np.eye(2), np.array([1.0, 2.0])
    J = jax.jacfwd(lambda x: kept(x, y))(x)  # a kept program has no derivative rule
    expected = jax.jacfwd(lambda x: jnp.sin(x) @ y)(x)
    np.testing.assert_allclose(J, expected, rtol=1e-15)
    assert _artefacts(folder) == []
