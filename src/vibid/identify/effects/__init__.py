"""Effects: physical terms a declared model may lack, one module each.

Each module of this package defines one :class:`~vibid.identify.model.terms.Term` as its
``EFFECT``, with its parameters (names and units as in the report format's "Effect names"
table), default prior box and a null value at which it vanishes exactly. Adding an effect
is adding a module here: it is found by name, and every evaluator (full, modal, reduced)
reads it through the term interface.
"""

from __future__ import annotations

import importlib
import pkgutil

from vibid import parameters as _catalogue


def _discover() -> dict:
    found = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        term = importlib.import_module(f"{__name__}.{info.name}").EFFECT
        found[term.name] = term
    return found


#: Every effect by its report name.
EFFECTS: dict = _discover()


def _all_parameters(term) -> tuple:
    """A term's parameters in every material's form (``transverse_shear`` has ``G13_Pa``
    on an orthotropic plate only)."""
    return getattr(term, "all_parameters", term.parameters)


#: Every effect parameter by name (the setup's bounds may name them): the catalogue's
#: (:data:`vibid.parameters.EFFECT_PARAMETERS`; an effect that may occur several times
#: under its unsuffixed names).
EFFECT_PARAMETERS: dict = dict(_catalogue.EFFECT_PARAMETERS)


def effects_for(names) -> tuple:
    """The effects whose parameters appear in ``names``, in :data:`EFFECTS` order (an
    instance's name, ``f_hz_2``, names its effect)."""
    names = {_catalogue.split_instance(n)[0] for n in names}
    return tuple(
        t
        for t in EFFECTS.values()
        if {_catalogue.split_instance(q.name)[0] for q in _all_parameters(t)} & names
    )


#: What ``anisotropy`` (the report's other effect name: a material, not a term) is, in a
#: lab's words; an effect's own is its term's ``meaning``.
ANISOTROPY_MEANING = "an orthotropic material instead of the declared isotropic one"


def meaning_of(name: str) -> str:
    """What an effect of the report is, in a lab's words (its name when unknown)."""
    if name == "anisotropy":
        return ANISOTROPY_MEANING
    return EFFECTS[name].meaning if name in EFFECTS else name


__all__ = ["EFFECTS", "EFFECT_PARAMETERS", "effects_for", "meaning_of"]
