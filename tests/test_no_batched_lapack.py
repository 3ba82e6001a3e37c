"""No compiled function of the fit calls LAPACK on a batch of matrices.

jaxlib 0.10's LAPACK kernels split a batch of matrices over XLA's intra-op thread pool and
block until it is done; two such calls side by side on a two-thread pool deadlock (every
thread in ``absl::BlockingCounter::Wait`` under ``jax::ParallelBatchMap``; issue 62). A call
on one matrix runs inline, on the calling thread. So the guarantee is structural: every
LAPACK custom call in the compiled code of the model's AFC, the population's loop, and the
fit's Jacobian, gradient, Hessian and batched chi2 sees one matrix, on both of the reduced
model's paths (proportional loss: Cholesky and eigh; a lossy clamp or a stand resonance: the
complex LU solve). The check reads XLA's own compiled HLO, so it fails on the code before
the fix (``jnp.linalg.solve`` over (nf, m, m): ``lapack_zgetrf_ffi`` on c128[120,16,16]).
"""

import re

import numpy as np
import pytest

from test_identify_compiled import _problem  # the paper strip, 120 frequencies
from vibid.identify.engine.compiled import kernel_functions
from vibid.identify.model.structure import embed

CALL = re.compile(
    r'custom_call_target="(?P<target>lapack_\w+)".*?'
    r"operand_layout_constraints=\{(?P<operands>.*?)\}, "
    r'.*?num_batch_dims="(?P<n>\d+)"'
)
SHAPE = re.compile(r"\b[a-z]+\d*\[(?P<dims>[\d,]*)\]")


def lapack_batches(hlo: str) -> list[tuple[str, int, str]]:
    """``(target, batch, operands)`` of every LAPACK custom call in compiled HLO text; the
    batch is the product of the first operand's batch dimensions (XLA's
    ``num_batch_dims``)."""
    calls = []
    for line in hlo.splitlines():
        m = CALL.search(line)
        if m is None:
            assert "lapack_" not in line.split("custom_call_target=")[-1][:9], line[:300]
            continue
        first = SHAPE.search(m["operands"])
        dims = [int(d) for d in first["dims"].split(",") if d]
        calls.append((m["target"], int(np.prod(dims[: int(m["n"])])), m["operands"]))
    return calls


def test_the_parser_sees_a_batched_solve():
    """The check itself can fail: a batched solve's HLO has a batch it reads."""
    import jax
    import jax.numpy as jnp

    from vibid.identify.engine.runtime import configure

    configure(cache=False)
    A = jnp.eye(3, dtype=complex)[None] * jnp.ones((5, 1, 1))
    hlo = jax.jit(jnp.linalg.solve).lower(A, jnp.ones((5, 3, 1), complex)).compile().as_text()
    batches = lapack_batches(hlo)
    assert batches and max(b for _, b, _ in batches) == 5
    one = jax.jit(jnp.linalg.solve).lower(A[0], jnp.ones((3, 1), complex)).compile().as_text()
    assert {b for _, b, _ in lapack_batches(one)} == {1}


def _compiled(jitted, *args) -> str:
    return jitted.lower(*args).compile().as_text()


@pytest.mark.parametrize(
    "effects, extra, proportional",
    [
        ((), {}, True),
        (("clamp_compliance", "clamp_loss"), {"k_theta_N_per_rad": 2e4, "beta_clamp": 0.05}, False),
        (
            ("clamp_compliance", "clamp_loss", "stand_resonance"),
            {
                "k_theta_N_per_rad": 2e4,
                "beta_clamp": 0.05,
                "f_hz_1": 700.0,
                "q_1": 30.0,
                "theta_rad_per_m_1": 0.05,
            },
            False,
        ),
    ],
)
def test_every_lapack_call_of_the_fit_sees_one_matrix(effects, extra, proportional):
    from vibid.identify.engine.runtime import configure

    configure(cache=False)
    problem, theta = _problem(effects, extra)
    assert problem.model.kernel.model.proportional == proportional
    fn, args = problem._fn, problem._args()
    u = problem._padded(problem.space.to_u(theta))
    th = problem._padded(theta)
    texts = {
        "jacobian_and_residuals": _compiled(fn.jacobian_and_residuals.fn, th, *args),
        "value_and_grad": _compiled(fn.value_and_grad.fn, u, *args, problem._space),
        "hessian": _compiled(fn.hessian.fn, u, *args, problem._space),
        "chi2_batch": _compiled(fn.chi2_batch.fn, np.stack([u, u, u]), *args, problem._space),
    }
    kernel = problem.model.kernel
    arrays = problem.model.arrays
    ks = kernel_functions(kernel)
    theta_s = np.asarray(embed(problem.model.embedding, theta))
    texts["afc"] = _compiled(ks.afc.fn, arrays, theta_s)
    texts["afc_batch"] = _compiled(ks.afc_batch.fn, arrays, np.stack([theta_s] * 3))
    seen = set()
    for name, hlo in texts.items():
        calls = lapack_batches(hlo)
        seen |= {t for t, _, _ in calls}
        batched = [(t, b, ops) for t, b, ops in calls if b > 1]
        assert not batched, (name, batched[:3])
    # the paths' own kernels are there to be checked: LU on the direct path, eigh on the modal
    assert any(("getrf" if not proportional else "syevd") in t for t in seen), seen
