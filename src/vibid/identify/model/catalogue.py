"""Every parameter vibid knows, by name: the material models' and the effects'.

The one place to look a parameter up (its unit, transform, prior rule) when all one has is
its name: the setup's bounds, a command line's ``NAME=VALUE``, a parameter space.
"""

from __future__ import annotations

import functools

from vibid.identify.model.terms import Parameter


@functools.lru_cache(maxsize=1)
def catalogue() -> dict[str, Parameter]:
    from vibid.identify.effects import EFFECT_PARAMETERS
    from vibid.identify.model.materials import MODELS, Material

    out = {q.name: q for m in MODELS for pml in (False, True) for q in Material(m, pml).parameters}
    return out | EFFECT_PARAMETERS


def known_parameter(name: str) -> Parameter | None:
    """The declaration of parameter ``name``, or None if no term has it."""
    return catalogue().get(name)
