"""The measured AFC a fit uses: the points kept, their standard uncertainties, what was dropped."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vibid.errors import VibidError


@dataclass(frozen=True)
class FitData:
    """The measured AFC the fit uses: points kept, their weights, and what was dropped.

    Attributes
    ----------
    frequency_hz: (n,) frequencies of all points given.
    H: (n,) complex measured AFC (dimensionless acceleration ratio).
    std: (n,) standard uncertainty of Re H and Im H, or None when not known.
    used: (n,) bool, points that enter the fit (finite, and not excluded by the caller).
    warnings: sentences about points dropped or uncertainties repaired.
    magnitude: the fit sees |H| alone (phase not trusted): ``H`` then holds |H| (real, in
        a complex array) and ``std`` the standard uncertainty of |H|, which for a point
        well above its noise equals that of Re H and of Im H (first order: circular noise
        of std s per part has std s along any direction, the radial one included).
    """

    frequency_hz: np.ndarray
    H: np.ndarray
    std: np.ndarray | None
    used: np.ndarray
    warnings: tuple[str, ...] = field(default=())
    magnitude: bool = False

    @property
    def n_used(self) -> int:
        return int(self.used.sum())

    @property
    def n_residuals(self) -> int:
        """Real numbers the fit sees: |H| per point, or Re H and Im H per point."""
        return self.n_used * (1 if self.magnitude else 2)

    @property
    def noise_known(self) -> bool:
        return self.std is not None


def fit_data(frequency_hz, H, std=None, used=None, *, magnitude: bool = False) -> FitData:
    """Check and clean a measured AFC; raise :class:`VibidError` when nothing usable is left.
    With ``magnitude`` the fit sees |H| alone (:class:`FitData`); |H| of |H| is |H|, so data
    that are already magnitudes may be passed again."""
    f = np.asarray(frequency_hz, dtype=float).ravel()
    H = np.asarray(H).astype(complex).ravel()
    if f.shape != H.shape:
        raise VibidError(
            f"frequency_hz has {f.size} points but H has {H.size}: give one H per frequency"
        )
    mask = np.ones(f.shape, bool) if used is None else np.asarray(used, bool).ravel().copy()
    if mask.shape != f.shape:
        raise VibidError(f"'used' has {mask.size} entries for {f.size} points")
    warnings = []
    bad = ~(np.isfinite(f) & np.isfinite(H.real) & np.isfinite(H.imag)) & mask
    s = None
    if std is not None:
        s = np.asarray(std, dtype=float).ravel()
        if s.shape != f.shape:
            raise VibidError(f"std has {s.size} entries for {f.size} points")
        bad |= ~np.isfinite(s) & mask
    if bad.any():
        warnings.append(
            f"{int(bad.sum())} of {f.size} AFC points are not finite (NaN/inf in frequency, H "
            "or std) and were left out of the fit"
        )
    mask &= ~bad
    if s is not None:
        pos = s[mask] > 0
        if not pos.any():
            warnings.append(
                "every standard uncertainty of the AFC is zero: fitting without weights, "
                "the noise level is estimated from the residual"
            )
            s = None
        elif not pos.all():
            floor = float(np.min(s[mask][pos]))
            warnings.append(
                f"{int((~pos).sum())} AFC points had a zero standard uncertainty; "
                f"the smallest positive one ({floor:.3g}) was used for them"
            )
            s = np.where(s > 0, s, floor)
    if mask.sum() == 0:
        raise VibidError("no usable AFC point: every point is NaN or excluded")
    if magnitude:
        if s is not None and (low := int(np.count_nonzero(np.abs(H[mask]) < 3 * s[mask]))):
            warnings.append(
                f"{low} AFC points have |H| below 3 std: a magnitude that close to the noise "
                "reads high (by about std²/(2|H|)), which a fit of |H| alone does not correct"
            )
        H = np.abs(H).astype(complex)
    return FitData(f, H, s, mask, tuple(warnings), magnitude)
