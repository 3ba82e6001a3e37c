"""What the planner is told: the target uncertainties and the prior over the parameters.

``--target D=0.1% nu=0.002``: a standard uncertainty per named parameter, relative (``%``,
of the parameter's own value) or absolute (its unit). ``--prior D=17±30% nu=0.3±0.05``: a
normal prior per named parameter (mean ± std, std relative with ``%``); a parameter the
prior does not name is uniform over the setup's box (log-uniform when the box spans more
than a decade). Draws are a scrambled Sobol sequence, clipped to the box: the reduced model
is built for that box. ``--max-stand-time S``: the stand time the plan may spend, s.

Each is read whole or refused in one line (:class:`~vibid.errors.VibidError`): a number
that is not finite (``1e999`` is inf), a name given twice, a standard uncertainty that is
not positive.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from vibid.errors import VibidError

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class Target:
    """A standard uncertainty to reach: ``value`` (a fraction when ``relative``)."""

    name: str
    value: float
    relative: bool

    def std_of(self, theta_value: float) -> float:
        """The target as an absolute standard uncertainty at the parameter's value."""
        return self.value * abs(theta_value) if self.relative else self.value

    def __str__(self) -> str:
        return (
            f"{self.name}={self.value * 100:g}%" if self.relative else f"{self.name}={self.value:g}"
        )


@dataclass(frozen=True)
class NormalPrior:
    name: str
    mean: float
    std: float


def check_stand_time_cap(seconds: float, option: str = "--max-stand-time") -> None:
    """Refuse a stand-time cap (s) that is not a positive finite number: a cap of zero or
    less plans nothing, and one of nan or inf caps nothing."""
    if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
        raise VibidError(f"{option} {seconds!r}: must be a positive number of seconds")


def parse_targets(texts, names) -> tuple[Target, ...]:
    """``["D=0.1%", "nu=0.002"]`` → targets; a name outside ``names`` or given twice is an
    error."""
    out = []
    for text in texts:
        m = re.fullmatch(rf"\s*(\w+)\s*=\s*({_NUMBER})\s*(%?)\s*", text)
        if not m:
            raise VibidError(f"--target {text!r}: expected NAME=VALUE or NAME=VALUE% (e.g. D=0.1%)")
        name, value, pct = m.group(1), _finite(m.group(2), "--target", text), bool(m.group(3))
        _known(name, names, "--target")
        if any(t.name == name for t in out):
            raise VibidError(f"--target: {name} is given twice")
        if not value > 0:
            raise VibidError(f"--target {text!r}: the uncertainty must be positive")
        out.append(Target(name, value / 100 if pct else value, pct))
    if not out:
        raise VibidError("--target: name at least one parameter, e.g. --target D=0.1%")
    return tuple(out)


def parse_prior(texts, names) -> dict[str, NormalPrior]:
    """``["D=17±30%", "nu=0.3+-0.05"]`` → normal priors by name."""
    out = {}
    for text in texts:
        m = re.fullmatch(
            rf"\s*(\w+)\s*=\s*({_NUMBER})\s*(?:±|\+-|\+/-)\s*({_NUMBER})\s*(%?)\s*", text
        )
        if not m:
            raise VibidError(
                f"--prior {text!r}: expected NAME=MEAN±STD or NAME=MEAN±STD% "
                "(e.g. D=17±30%; +- for ±)"
            )
        name = m.group(1)
        mean, std = _finite(m.group(2), "--prior", text), _finite(m.group(3), "--prior", text)
        _known(name, names, "--prior")
        if name in out:
            raise VibidError(f"--prior: {name} is given twice")
        std = std / 100 * abs(mean) if m.group(4) else std
        if not (std > 0 and math.isfinite(std)):
            raise VibidError(
                f"--prior {text!r}: the standard deviation must be a positive finite number"
            )
        out[name] = NormalPrior(name, mean, std)
    return out


def _finite(number: str, option: str, text: str) -> float:
    """A number of ``text`` that must be finite (the pattern lets ``1e999`` through)."""
    value = float(number)
    if not math.isfinite(value):
        raise VibidError(f"{option} {text!r}: {number} is not a finite number")
    return value


def _known(name: str, names, option: str) -> None:
    if name not in names:
        raise VibidError(
            f"{option}: {name} is not a parameter of the model (its parameters: {', '.join(names)})"
        )


def check_priors_in_box(priors: dict[str, NormalPrior], box: dict) -> None:
    """Refuse a prior whose mean is outside the setup's box (the draws are clipped to it)."""
    for p in priors.values():
        lo, hi = box[p.name]
        if not lo < p.mean < hi:
            raise VibidError(
                f"--prior {p.name}: the mean {p.mean:g} is outside the setup's "
                f"bounds [{lo:g}, {hi:g}]"
            )


def prior_draws(
    names, box: dict, priors: dict[str, NormalPrior], n: int, seed: int = 0
) -> np.ndarray:
    """(n, p) parameter vectors drawn from the prior, inside ``box``."""
    from scipy.stats import norm, qmc

    check_priors_in_box(priors, box)
    u = qmc.Sobol(len(names), scramble=True, seed=seed).random(n)
    u = np.clip(u, 1e-6, 1 - 1e-6)
    out = np.empty_like(u)
    for j, name in enumerate(names):
        lo, hi = box[name]
        if name in priors:
            v = priors[name].mean + priors[name].std * norm.ppf(u[:, j])
        elif lo > 0 and hi / lo > 10:
            v = lo * (hi / lo) ** u[:, j]
        else:
            v = lo + (hi - lo) * u[:, j]
        span = hi - lo
        out[:, j] = np.clip(v, lo + 1e-6 * span, hi - 1e-6 * span)
    return out


def prior_std(names, box: dict, priors: dict[str, NormalPrior], centre: np.ndarray) -> np.ndarray:
    """(p,) a standard deviation per parameter: the normal prior's, else the box's
    (uniform: width/√12; log-uniform: value · ln(hi/lo)/√12)."""
    out = []
    for name, c in zip(names, centre):
        lo, hi = box[name]
        if name in priors:
            out.append(priors[name].std)
        elif lo > 0 and hi / lo > 10:
            out.append(abs(c) * math.log(hi / lo) / math.sqrt(12))
        else:
            out.append((hi - lo) / math.sqrt(12))
    return np.asarray(out)
