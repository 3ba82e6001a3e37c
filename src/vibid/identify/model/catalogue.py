"""Every parameter vibid knows, by name: the material models' and the effects'.

The one place to look a parameter up (its unit, transform, prior rule) when all one has is
its name: the setup's bounds, a command line's ``NAME=VALUE``, a parameter space. The
catalogue itself is :mod:`vibid.parameters` (no numerical import); this module keeps its
historical names.
"""

from __future__ import annotations

from vibid.parameters import Parameter, catalogue, known_parameter

__all__ = ["Parameter", "catalogue", "known_parameter"]
