"""identify: the plate forward model and the identification of its stiffness.

The forward model (this package's plate half) maps a declared setup and material
parameters to the AFC at the response sensor; see :mod:`vibid.identify.forward`.
"""

from vibid.identify.forward import ForwardModel, build_forward_model, natural_frequencies

__all__ = ["ForwardModel", "build_forward_model", "natural_frequencies"]
