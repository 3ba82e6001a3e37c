"""The structure a model's compiled code is written for: its material with every effect.

Compiling the reduced model's functions (the AFC, chi2, its gradient and Hessian, the
batched chi2 of a global search) takes a few tenths of a second each, while evaluating them
takes milliseconds. The closed loop tries one extended model per candidate effect, each
scored, refitted and sometimes searched; compiled once per model, most of its minutes were
compilation. So every model of one material shares the code of one *structure*: the
material with every effect of the library (:mod:`vibid.identify.effects`).

A model of that material runs the structure's code with

* the structure's parameter vector filled from the model's (:func:`embedding`): the
  model's parameters where it has them, each absent effect's parameter at its null value
  (a delay of 0 s, a gain of 1, a mass of 0 kg: the map or coefficient is then exactly the
  identity or zero) or, where the null is not a number the code can use (a rigid clamp,
  ``k_θ = ∞``; ``G13`` of a shear term that is absent), any finite stand-in;
* the projected matrices, loads and probes of the terms it lacks set to zero
  (:func:`~vibid.identify.model.reduced.padded_arrays`), which removes those terms exactly
  whatever their coefficient (the clamp's spring, the shear term's inertia).

The model's AFC is thus the structure's, to rounding. The code depends on the structure and
on the arrays' shapes only, and JAX compiles it once per shape: a model with one more
parameter or a larger basis compiles again, an effect of the same size does not.

Some terms cost the structure's code something even where they are absent: a clamp with
a loss of its own makes the modes complex (the direct solve per frequency instead of the
modal sum), a stand resonance adds the base rotation's load, and a stretch of the free
length is bound to its plate's length. The structure holds those only where the model
does (each instance of a stand resonance the model has), so a model without them runs the
plain code.

A model with a term outside the library (a test's own term) is its own structure.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from vibid.identify.model.terms import PlateModel

#: The stand-in value of an absent parameter whose null is not finite (or not given).
STAND_IN = 1.0


@functools.lru_cache(maxsize=32)
def structure_of(model: PlateModel) -> PlateModel:
    """The structure whose compiled code ``model`` runs (see the module docstring)."""
    from vibid.identify.effects import EFFECTS

    material = model.material
    library = tuple(t.for_material(material) for t in EFFECTS.values())
    optional = {t.name for t in library if not t.in_every_structure}
    if not all(t in library or t.name in optional for t in model.effects):
        return model
    terms = []
    for t in library:
        if t.in_every_structure:
            terms.append(t)
        else:
            terms += sorted(
                (e for e in model.effects if e.name == t.name), key=lambda e: e.instance or 0
            )
    return PlateModel(material, tuple(terms))


def absent_value(parameter) -> float:
    """The value an absent effect's parameter takes in the structure (its null if finite)."""
    null = parameter.null
    return float(null) if null is not None and math.isfinite(null) else STAND_IN


@functools.lru_cache(maxsize=64)
def _embedding(model: PlateModel, structure: PlateModel) -> tuple[tuple, tuple]:
    names = structure.names
    index = tuple(names.index(n) for n in model.names)
    own = set(model.names)
    base = tuple(0.0 if q.name in own else absent_value(q) for q in structure.parameters)
    return base, index


def embedding(model: PlateModel, structure: PlateModel) -> tuple[np.ndarray, np.ndarray]:
    """``(base (p_s,), index (p,))``: the structure's parameter vector of ``model``'s
    ``theta`` is ``base`` with ``theta`` written at ``index``."""
    base, index = _embedding(model, structure)
    return np.array(base, float), np.array(index, int)


def slots(names_of_model, names_of_structure) -> list[int | None]:
    """For each of the structure's matrix (or probe) names, its position among the
    model's, or None where the model lacks it."""
    where = {n: i for i, n in enumerate(names_of_model)}
    return [where.get(n) for n in names_of_structure]


def embed(embedding_: tuple[np.ndarray, np.ndarray], theta):
    """The structure's parameter vector(s) of a model's ``theta`` (last axis: the model's
    parameters; numpy stays numpy, JAX arrays and tracers stay JAX)."""
    base, index = embedding_
    if isinstance(theta, np.ndarray) or not hasattr(theta, "at"):
        theta = np.asarray(theta, float)
        out = np.broadcast_to(base, theta.shape[:-1] + base.shape).copy()
        out[..., index] = theta
        return out
    import jax.numpy as jnp

    out = jnp.broadcast_to(jnp.asarray(base), theta.shape[:-1] + base.shape)
    return out.at[..., index].set(theta)
