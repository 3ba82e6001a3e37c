"""The one cache of compiled functions: bounded, keyed by what the code depends on.

A reduced model splits into a hashable kernel (the code of its structure: its material with
every effect of the library, :mod:`vibid.identify.model.structure`) and arrays (its
projected matrices), :class:`~vibid.identify.model.reduced.ReducedKernel`. Every model of
one structure (the declared model, each candidate of the loop, a model rebuilt around a new
estimate, another restart's, another session's) shares the compiled functions built here,
passing its own arrays; JAX compiles each once per array shape. The caches are LRUs of a
few entries: a long-running worker that replays hundreds of sessions keeps only the code of
the last few structures, and an evicted entry frees its compiled code. Each function also
keeps the programs it traces on disk (:mod:`vibid.identify.engine.persist`), so that another
process does not trace them again.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

#: How many model structures (kernels) keep their compiled code.
MAX_KERNELS = 8


@dataclass(frozen=True)
class KernelFunctions:
    """jit-compiled evaluations of one kernel, each ``f(arrays, theta or thetas)``."""

    afc: Callable
    afc_batch: Callable
    modes_batch: Callable
    modes_afc_batch: Callable


@functools.lru_cache(maxsize=MAX_KERNELS)
def kernel_functions(kernel) -> KernelFunctions:
    import jax

    from vibid.identify.engine.persist import Persisted, identity_of
    from vibid.identify.engine.runtime import over_population

    identity = identity_of(kernel)

    def kept(name, fn):
        return Persisted(jax.jit(fn), f"kernel.{name}", identity)

    return KernelFunctions(
        afc=kept("afc", kernel),
        afc_batch=kept("afc_batch", over_population(kernel)),
        modes_batch=kept("modes_batch", over_population(kernel.modes)),
        modes_afc_batch=kept("modes_afc_batch", over_population(kernel.modes_and_afc)),
    )
