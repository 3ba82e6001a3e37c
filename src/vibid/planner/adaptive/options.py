"""What an adaptive campaign aims at and may spend, as the session records it, and its
coarse sweep."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibid.errors import VibidError
from vibid.planner.prior import Target, check_stand_time_cap, parse_targets

__all__ = ["AdaptiveOptions", "coarse_sweep"]


@dataclass(frozen=True)
class AdaptiveOptions:
    """What an adaptive campaign aims at and may spend: ``targets`` (standard uncertainties
    of named parameters), the ``band_hz`` it measures in, the stand-time cap, steps per
    batch, the coarse sweep's step count and the seed of its posterior draws."""

    targets: tuple[Target, ...]
    band_hz: tuple[float, float]
    max_stand_time_s: float = 600.0
    batch_size: int = 4
    coarse_steps: int = 16
    seed: int = 0

    def attribute(self) -> dict:
        """The session's ``adaptive`` root attribute (session-format.md)."""
        return {
            "target": [str(t) for t in self.targets],
            "band_hz": [float(b) for b in self.band_hz],
            "max_stand_time_s": float(self.max_stand_time_s),
            "batch_size": int(self.batch_size),
            "coarse_steps": int(self.coarse_steps),
            "seed": int(self.seed),
        }

    @classmethod
    def from_attribute(cls, doc: dict, names) -> AdaptiveOptions:
        """The options a session's ``adaptive`` attribute records (one-line errors)."""
        try:
            return cls(
                parse_targets(doc["target"], names),
                tuple(float(b) for b in doc["band_hz"]),
                float(doc["max_stand_time_s"]),
                int(doc["batch_size"]),
                int(doc.get("coarse_steps", 16)),
                int(doc.get("seed", 0)),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise VibidError(f"the session's adaptive attribute cannot be read ({exc})") from None

    def check(self, setup) -> None:
        lo, hi = self.band_hz
        nyquist = setup.daq.sample_rate_hz / 2
        if not 0 < lo < hi < nyquist:
            raise VibidError(
                f"--band {lo:g}:{hi:g}: needs 0 < low < high < {nyquist:g} Hz (Nyquist)"
            )
        check_stand_time_cap(self.max_stand_time_s)
        if self.batch_size < 1 or self.coarse_steps < 4:
            raise VibidError("--batch must be at least 1 and the coarse sweep at least 4 steps")


def coarse_sweep(options: AdaptiveOptions) -> np.ndarray:
    """The first batch's frequencies, Hz: geometric over the band."""
    return np.round(np.geomspace(*options.band_hz, options.coarse_steps), 6)
