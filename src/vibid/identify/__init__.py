"""identify: the plate model and the identification of its parameters from a measured AFC.

Three layers, one folder each:

* :mod:`vibid.identify.model`: the finite-element discretisation (mesh, elements, forms,
  sensor disc, assembly), the model terms (:mod:`~vibid.identify.model.terms`, the material
  laws in :mod:`~vibid.identify.model.materials`), and the solvers that read them: full
  sparse, modal, reduced JAX; :func:`build_forward_model` puts them together;
* :mod:`vibid.identify.effects`: one module per physical effect a declared model may lack;
* :mod:`vibid.identify.fit`: the inverse problem (data and weights, parameter space, local
  and global methods, uncertainty) and :func:`identify`, the strategy.

* :mod:`vibid.identify.engine`: the machinery that runs the model (compiled functions and
  their caches, threads, profile, 64-bit JAX); the model does not import it: it is handed the
  engine's functions here, on import (:mod:`vibid.identify.model.machinery`).

Nothing here changes the process on import: entry points call
:func:`vibid.identify.engine.runtime.configure` (64-bit JAX, compilation cache). The names below
load their modules on first use.
"""

from __future__ import annotations

import importlib

from vibid.identify.engine import compiled, profile, runtime, threads
from vibid.identify.model import machinery

# The model's machinery is the engine's. Each is looked up when called, so what a test
# puts in the engine's place (a watched numpy section) is what the model runs in.
machinery.hand(
    machinery.Machinery(
        compile=lambda kernel: compiled.kernel_functions(kernel),
        numpy_section=lambda: threads.numpy_section(),
        section=lambda name: profile.section(name),
        require_x64=lambda: runtime.require_x64(),
    )
)

_EXPORTS = {
    "ForwardModel": "vibid.identify.model.forward",
    "build_forward_model": "vibid.identify.model.plate",
    "natural_frequencies": "vibid.identify.model.plate",
    "plate_model": "vibid.identify.model.plate",
    "PlateModel": "vibid.identify.model.terms",
    "identify": "vibid.identify.fit.strategy",
    "IdentificationResult": "vibid.identify.fit.result",
    "EFFECTS": "vibid.identify.effects",
    "configure": "vibid.identify.engine.runtime",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'vibid.identify' has no attribute {name!r}")
