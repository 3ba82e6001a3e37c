"""identify: the plate model and the identification of its parameters from a measured AFC.

Three layers, one folder each:

* :mod:`vibid.identify.model`: the finite-element discretisation (mesh, elements, forms,
  sensor disc, assembly), the model terms (:mod:`~vibid.identify.model.terms`, the material
  laws in :mod:`~vibid.identify.model.materials`), and the solvers that read them: full
  sparse, modal, reduced JAX; :func:`build_forward_model` puts them together;
* :mod:`vibid.identify.effects`: one module per physical effect a declared model may lack;
* :mod:`vibid.identify.fit`: the inverse problem (data and weights, parameter space, local
  and global methods, uncertainty) and :func:`identify`, the strategy.

Nothing here changes the process on import: entry points call
:func:`vibid.identify.engine.runtime.configure` (64-bit JAX, compilation cache). The names below
load their modules on first use.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "ForwardModel": "vibid.identify.model.forward",
    "build_forward_model": "vibid.identify.model.forward",
    "natural_frequencies": "vibid.identify.model.forward",
    "plate_model": "vibid.identify.model.forward",
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
