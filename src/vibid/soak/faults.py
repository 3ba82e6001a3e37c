"""The faults a soak injects, the day's schedule of them, and the stand configuration that
injects them (``simulated.faults``: :mod:`vibid.hardware_mocks.virtual_stand`)."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

#: faults the soak knows: the virtual stand's (generator, DAQ) and SIGKILL of the process
KINDS = ("no_reply", "error", "drop", "overload", "kill")
#: a generator that stops answering loses this many replies (its shutdown's too)
NO_REPLY_COUNT = 5


@dataclass(frozen=True, order=True)
class Fault:
    """A fault of ``kind`` (:data:`KINDS`) at the campaign's step ``index`` (0-based)."""

    index: int
    kind: str


def fault_plan(
    n_steps: int, counts: dict[str, int], seed: int, *, gap: int = 4, first: int = 1
) -> tuple[Fault, ...]:
    """``counts`` faults by kind at distinct random steps (from ``seed``), sorted, at least
    ``gap`` steps apart, from step ``first`` on and at least ``gap`` steps before the end
    (a killed process may have written a step or two beyond its kill step)."""
    kinds = [k for k, c in counts.items() for _ in range(int(c))]
    for k in kinds:
        if k not in KINDS:
            raise ValueError(f"unknown fault kind {k!r}, expected one of {', '.join(KINDS)}")
    if not kinds:
        return ()
    rng = np.random.default_rng(seed)
    t = len(kinds)
    room = (n_steps - gap - first) - (t - 1) * (gap - 1)  # steps first .. n_steps-gap-1
    if room < t:
        raise ValueError(f"{t} faults at least {gap} steps apart do not fit in {n_steps} steps")
    picks = np.sort(rng.choice(room, size=t, replace=False))
    kinds = [str(k) for k in rng.permutation(kinds)]
    return tuple(
        Fault(int(first + y + i * (gap - 1)), k) for i, (y, k) in enumerate(zip(picks, kinds))
    )


def config_doc(config, name: str, faults) -> dict:
    """The stand configuration as a document, with this soak's stand name and faults."""
    doc = json.loads(json.dumps(config.to_dict()))
    doc["generator"]["url"] = f"vibidsim://{name}"
    doc["simulated"]["faults"] = [
        {
            "kind": f.kind,
            "at_index": f.index,
            **({"count": NO_REPLY_COUNT} if f.kind == "no_reply" else {}),
        }
        for f in faults
    ]
    return doc


def truth(config) -> dict[str, float]:
    """The virtual specimen's true parameters, for judging the identification."""
    from vibid.hardware_mocks.virtual_stand import true_parameters

    return true_parameters(config)
