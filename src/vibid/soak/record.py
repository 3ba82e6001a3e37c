"""The soak's record: what became of each fault, the steps and runs, and the
identification of the soaked (and an uninterrupted) session against the truth."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from vibid.soak.faults import Fault


@dataclass
class FaultOutcome:
    """What became of one fault: ``fired`` (it struck), ``ended_run`` (it stopped the
    campaign run it struck), ``output_off`` (the output was off after it: True/False, None
    where the fault does not stop the drive, an overload), ``survived`` (it fired and the
    campaign went on to complete with every check passed)."""

    fault: Fault
    fired: bool = False
    ended_run: bool = False
    output_off: bool | None = None
    survived: bool = False
    note: str = ""


@dataclass(frozen=True)
class Identification:
    """The identification of a session: chi2/dof (the final model's, as reported), whether
    a residual above the noise remains, and per declared parameter (value, std, truth)."""

    chi2_dof: float
    unexplained: bool
    parameters: dict[str, tuple[float, float, float]]
    effects: tuple[str, ...] = ()
    seconds: float = math.nan

    def error_std(self) -> dict[str, float]:
        """|value − truth| / std per parameter."""
        return {n: abs(v - t) / s for n, (v, s, t) in self.parameters.items()}


@dataclass
class SoakResult:
    """The soak's record: each fault's outcome, the steps, the runs, the identification."""

    path: str
    outcomes: list[FaultOutcome]
    n_steps: int
    duplicates: int
    runs: int
    seconds: float
    stand_time_s: float | None = None
    orphans: int = 0  #: server processes a killed campaign process left behind (removed)
    identification: Identification | None = None
    reference: Identification | None = None
    reference_stand_time_s: float | None = None
    log: list[str] = field(default_factory=list)

    @property
    def survived(self) -> int:
        return sum(o.survived for o in self.outcomes)

    def summary(self) -> str:
        """The soak in a few lines: faults survived by kind, steps, chi2/dof, errors."""
        kinds = {}
        for o in self.outcomes:
            got, total = kinds.get(o.fault.kind, (0, 0))
            kinds[o.fault.kind] = (got + o.survived, total + 1)
        by_kind = ", ".join(f"{k} {a}/{b}" for k, (a, b) in kinds.items())
        lines = [
            f"faults survived: {self.survived} of {len(self.outcomes)} ({by_kind})",
            f"steps: {self.n_steps} in the file, duplicates {self.duplicates}, "
            f"campaign runs {self.runs}, orphaned processes removed {self.orphans}, stand time "
            + (f"{self.stand_time_s:.1f} s" if self.stand_time_s is not None else "?")
            + (
                f" (without faults {self.reference_stand_time_s:.1f} s)"
                if self.reference_stand_time_s is not None
                else ""
            ),
        ]
        for label, ident in (("soaked", self.identification), ("without faults", self.reference)):
            if ident is None:
                continue
            errors = ", ".join(f"{n} {e:.2f}" for n, e in ident.error_std().items())
            lines.append(
                f"{label}: chi2/dof {ident.chi2_dof:.3f}, unexplained_residual "
                f"{str(ident.unexplained).lower()}, effects "
                f"{', '.join(ident.effects) or 'none'}; |error|/std {errors}"
            )
        ident_s = sum(i.seconds for i in (self.identification, self.reference) if i is not None)
        lines.append(f"run time {self.seconds:.1f} s (identification {ident_s:.1f} s of it)")
        return "\n".join(lines)


def identify_session(
    path, truth: dict[str, float], *, restarts: int = 2, seed: int = 0
) -> Identification:
    """The identification the report would give (the closed loop included), against ``truth``."""
    from vibid.pipeline import identify_afc, session_afc

    t = time.perf_counter()
    found = identify_afc(session_afc(path), loop=True, restarts=restarts, seed=seed)
    r = found.result
    if found.loop is not None:
        unexplained = bool(found.loop.unexplained_residual)
        effects = tuple(found.loop.effects)
    else:
        from vibid.identify.fit.noise import explains

        unexplained, effects = explains(r) is False, ()
    params = {
        n: (float(v), float(s), float(truth[n]))
        for n, v, s in zip(r.parameter_names, r.values, r.std)
        if n in truth
    }
    return Identification(
        float(r.chi2_reduced_reported), unexplained, params, effects, time.perf_counter() - t
    )
