"""identify: the plate forward model and the identification of its stiffness.

The forward model (this package's plate half) maps a declared setup and material
parameters to the AFC at the response sensor; see :mod:`vibid.identify.forward`.
"""

import vibid.identify.jax_setup  # noqa: F401  (64-bit floats, compilation cache: first)
from vibid.identify.forward import ForwardModel, build_forward_model, natural_frequencies

__all__ = ["ForwardModel", "build_forward_model", "natural_frequencies"]
