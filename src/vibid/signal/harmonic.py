"""Joint harmonic fit of the channels of one step, sharing one refined frequency.

Model of channel ``c`` (``u`` the centred, normalised time of :mod:`vibid.signal.basis`)::

    x_c(u) = Σ_j p_cj u^j + Σ_{k=1..K} [a_ck cos(kνu) + b_ck sin(kνu)] + e_c,

with white noise ``e_c`` of variance ``σ_c²`` per channel and one normalised frequency ``ν``
shared by every channel: the base and the response are driven by the same generator. This is
the four-parameter sine fit of IEEE Std 1057 (amplitude, phase, offset, frequency), extended
to several channels, a polynomial drift and harmonics 2..K as nuisance terms.

Estimation is maximum likelihood by variable projection (Golub & Pereyra 1973): for a given
``ν`` the linear parameters are least squares; ``ν`` follows Gauss-Newton steps on the
reduced problem, each channel weighted by ``1/σ_c²``, from the commanded frequency (or from a
coarse segment-phase estimate when the clock tolerance exceeds a fraction of a bin). Every
sum over a record is a Gram product on the half grid (see :mod:`vibid.signal.basis`), so one
iteration costs about one matrix product per sample and steps of equal length are solved
together.

The phasor of harmonic ``k`` is ``X_ck = a_ck - i b_ck`` (``x = Re(X e^{+ikνu})``) at the
record centre. Its covariance is the inverse Fisher information of the whole joint model,
frequency included (Schur complement), with ``σ_c²`` the residual variance.

Cramér-Rao bounds (Rife & Boorstyn 1974; Kay, *Fundamentals of Statistical Signal
Processing I*, ex. 3.14), one sinusoid of amplitude ``A`` in white noise, ``N`` samples, many
cycles: ``var A ≥ 2σ²/N``; ``var φ ≥ 2σ²/(N A²)`` for a known frequency and equally for an
estimated one when, as here, the phase is referred to the record centre (the frequency and
the centre phase are uncorrelated); ``var ω ≥ 24 σ² fs² / (A² N (N² - 1))`` in (rad/s)², whose
Fisher information adds over channels sharing the frequency.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from vibid.signal.basis import (
    Layout,
    columns,
    half_grid,
    normalised_frequency,
    split_halves,
    unit_phasors,
)
from vibid.signal.basis import (
    frequency_hz as _frequency_hz,
)

log = logging.getLogger(__name__)

__all__ = ["HarmonicFit", "Layout", "fit_harmonics", "max_harmonics"]

#: Steps per batch are limited so that S·N stays below this: the working set then stays in
#: cache (measured: 2^16 beats 2^13 by ~20 % and 2^20 by ~40 % on 25 600-sample records).
_CHUNK_SAMPLES = 1 << 16
#: Bound on the quadratic convergence constant of the Gauss-Newton step, 1/rad.
_KAPPA = 1.0
#: A Gauss-Newton step is limited to a quarter of a DFT bin (Δν = π per bin).
_MAX_STEP = np.pi / 4
#: Segments of the coarse frequency estimate (its range is ±n_segments/2 bins).
_N_SEGMENTS = 16


@dataclass(frozen=True)
class HarmonicFit:
    """Fit of ``S`` steps of ``C`` channels each (shapes in brackets). Phasors at record centre.

    Attributes
    ----------
    frequency_hz : (S,) refined frequency on the sample clock, Hz.
    frequency_std_hz : (S,) its standard uncertainty, Hz (0 when not refined).
    phasors_m_s2 : (S, C, K) complex harmonic phasors; ``[..., 0]`` is the fundamental.
    phasor_var : (S, C, K) variance per real component of each phasor, (m/s²)².
    fundamental_cov : (S, 2C, 2C) covariance of (Re X_0, Im X_0, Re X_1, Im X_1, ...) of the
        fundamentals, the frequency's uncertainty included.
    offset_m_s2 : (S, C) offset at the record centre.
    drift_m_s2_per_s : (S, C) linear drift rate (0 when the layout has no drift term).
    noise_std_m_s2 : (S, C) residual standard deviation.
    half_phasors_m_s2 : (S, C, 2) fundamental fitted on the first and on the second half, the
        frequency held at the whole record's.
    half_cov : (S, 2, 2C, 2C) covariance of (Re X_0, Im X_0, Re X_1, ...) on each half.
    residual_ss_halves : (S, C, 2) the whole record's fit's residual sum of squares over its
        first and over its second half (the centre sample of an odd record in neither).
    iterations : (S,) Gauss-Newton iterations.
    converged : (S,) the frequency search converged; where it did not, the step is fitted at the
        commanded frequency (taken as known) instead.
    """

    frequency_hz: np.ndarray
    frequency_std_hz: np.ndarray
    phasors_m_s2: np.ndarray
    phasor_var: np.ndarray
    fundamental_cov: np.ndarray
    offset_m_s2: np.ndarray
    drift_m_s2_per_s: np.ndarray
    noise_std_m_s2: np.ndarray
    half_phasors_m_s2: np.ndarray
    half_cov: np.ndarray
    residual_ss_halves: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray


def max_harmonics(frequency_hz, sample_rate_hz, n_harmonics: int = 3) -> np.ndarray:
    """Highest harmonic order (≤ ``n_harmonics``, ≥ 1) that stays below 0.49·fs."""
    ratio = 0.49 * np.asarray(sample_rate_hz, float) / np.asarray(frequency_hz, float)
    return np.clip(np.floor(ratio), 1, n_harmonics).astype(int)


def fit_harmonics(
    records: np.ndarray,
    frequency_hz,
    sample_rate_hz,
    *,
    layout: Layout = Layout(),
    refine_frequency: bool = True,
    max_offset_ppm: float = 200.0,
    max_iterations: int = 20,
) -> HarmonicFit:
    """Fit records ``(S, C, N)`` (or ``(C, N)``, one step), m/s², sharing ``N``.

    Parameters
    ----------
    records : samples of ``C`` channels at ``S`` steps.
    frequency_hz : (S,) or scalar, commanded frequency, Hz: the starting point.
    sample_rate_hz : (S,) or scalar, sample clock, Hz.
    layout : polynomial degree and number of harmonics (``K·f`` must stay below fs/2).
    refine_frequency : estimate the frequency (else it is taken as known).
    max_offset_ppm : clock tolerance; beyond 0.2 bin a coarse estimate seeds the search.
    max_iterations : Gauss-Newton iterations at most.
    """
    x = np.asarray(records, dtype=np.float64)
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3:
        raise ValueError(f"records must have shape (S, C, N), got {x.shape}")
    s, _, n = x.shape
    f0 = np.broadcast_to(np.asarray(frequency_hz, dtype=np.float64), (s,))
    fs = np.broadcast_to(np.asarray(sample_rate_hz, dtype=np.float64), (s,))
    if np.any(layout.n_harmonics * f0 >= 0.5 * fs):
        raise ValueError("harmonic order times frequency reaches fs/2; lower n_harmonics")
    if n < 2 * layout.n_model + 2:
        raise ValueError(f"records of {n} samples are too short for {layout.n_model} parameters")
    step = max(1, _CHUNK_SAMPLES // n)
    parts = [
        _fit_chunk(
            x[i : i + step],
            normalised_frequency(f0[i : i + step], fs[i : i + step], n),
            layout,
            refine_frequency,
            max_offset_ppm,
            max_iterations,
        )
        for i in range(0, s, step)
    ]
    out = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    nu, nu_std = out.pop("nu"), out.pop("nu_std")
    theta = out.pop("theta")
    two_fs = 2.0 * fs[:, None] / (n - 1)
    return HarmonicFit(
        frequency_hz=_frequency_hz(nu, fs, n) if refine_frequency else np.array(f0),
        frequency_std_hz=_frequency_hz(nu_std, fs, n),
        offset_m_s2=theta[..., 0] + out.pop("mean"),
        drift_m_s2_per_s=theta[..., 1] * two_fs
        if layout.degree >= 1
        else np.zeros(theta.shape[:2]),
        **out,
    )


def coarse_frequency(x: np.ndarray, nu0: np.ndarray, n_segments: int = _N_SEGMENTS) -> np.ndarray:
    """Normalised frequency from the phase advance between segments of the demodulated record.

    ``x`` (S, C, N) without its mean, ``nu0`` (S,) the demodulation frequency. The phase of
    ``Σ_c Σ_m Z_{m+1} conj(Z_m)``, ``Z_m`` the segment sums of ``x e^{-iν0 u}``, is the advance
    over one segment (Kay 1989 weighting: strong channels count most). Unambiguous within
    ±n_segments/2 bins when each segment holds several cycles.
    """
    _, _, n = x.shape
    length = n // n_segments
    used = length * n_segments
    demod = unit_phasors(nu0, -2.0 * nu0 / (n - 1), used)  # exp(-iν0 u_m), u_0 = -1
    z = (x[..., :used] * demod[:, None, :]).reshape(*x.shape[:2], n_segments, length).sum(-1)
    advance = np.angle((z[..., 1:] * z[..., :-1].conj()).sum(axis=(-1, -2)))
    return nu0 + advance * (n - 1) / (2.0 * length)


@dataclass(frozen=True)
class _Records:
    """One batch of records without their means, split about the centre (basis.split_halves)."""

    mean: np.ndarray  # (S, C)
    xx: np.ndarray  # (S, C) sum of squares
    after: np.ndarray  # (S, C, H)
    before: np.ndarray  # (S, C, H), mirrored
    centre: np.ndarray | None  # (S, C) when N is odd
    x_even: np.ndarray  # after + before
    x_odd: np.ndarray  # after - before
    u: np.ndarray  # (H,)
    n: int

    def subset(self, idx) -> _Records:
        pick = lambda a: None if a is None else a[idx]  # noqa: E731
        return _Records(
            self.mean[idx],
            self.xx[idx],
            self.after[idx],
            self.before[idx],
            pick(self.centre),
            self.x_even[idx],
            self.x_odd[idx],
            self.u,
            self.n,
        )

    @classmethod
    def of(cls, x: np.ndarray) -> _Records:
        mean = x.mean(-1)
        x = x - mean[..., None]
        after, before, centre = split_halves(x)
        after, before = np.ascontiguousarray(after), np.ascontiguousarray(before)
        return cls(
            mean,
            np.einsum("scn,scn->sc", x, x),
            after,
            before,
            centre,
            after + before,
            after - before,
            half_grid(x.shape[-1]),
            x.shape[-1],
        )


def _fit_chunk(x, nu0, layout: Layout, refine: bool, max_offset_ppm: float, max_iterations: int):
    rec = _Records.of(x)
    nu = np.array(nu0, dtype=np.float64)
    if refine:
        seed = nu * 1.5e-6 * max_offset_ppm > 0.2 * np.pi
        if np.any(seed):
            nu[seed] = coarse_frequency(x[seed] - rec.mean[seed, :, None], nu[seed])
        if layout.n_harmonics > 1:  # converge on the fundamental alone first: a third of the cost
            nu = _solve(rec, nu, Layout(layout.degree, 1), True, max_iterations, final=False).nu
    store = _solve(rec, nu, layout, refine, max_iterations)
    if refine and not np.all(store.converged):
        # an undetermined frequency (too few cycles, no signal): fall back to the commanded one
        bad = np.flatnonzero(~store.converged)
        log.debug("frequency refinement did not converge at %d step(s)", bad.size)
        store.take(bad, _solve(rec.subset(bad), np.asarray(nu0)[bad], layout, False, 1))
    return store.finish(rec.mean, rec.n)


def _solve(
    rec: _Records, nu, layout: Layout, refine: bool, max_iterations: int, final: bool = True
) -> _Store:
    """Variable-projection Gauss-Newton on ν for every record of the batch.

    Each iteration projects the active records at their ν (:func:`_iterate`); a record whose
    step is small enough (or undetermined, or out of iterations) is kept (:func:`_keep`) and
    leaves the batch, the others step on. ``final=False`` only refines ν (no residuals,
    halves or covariances are kept).
    """
    s, n_channels, _ = rec.after.shape
    dof = rec.n - layout.n_model - (1.0 / n_channels if refine else 0.0)
    floor = 1e-28 * rec.xx + 1e-300
    store = _Store(nu, n_channels, layout, dof, refine)
    buffer = np.empty((s, layout.n_model, rec.u.size))
    active = np.arange(s)
    for it in range(1, max_iterations + 1):
        x = _iterate(rec, active, store.nu[active], layout, buffer[: active.size], floor, dof)
        bad = ~np.isfinite(x.dnu) | (x.den <= 0)
        done = (x.last | bad | (it == max_iterations)) if refine else np.ones_like(bad)
        take = np.where(x.last & ~bad, x.dnu, 0.0) if refine else np.zeros_like(x.dnu)
        if not final:
            store.nu[active[done]] += take[done]
        elif np.any(done):
            d = slice(None) if np.all(done) else done
            converged = ~bad[d] & (x.last[d] | (not refine))
            _keep(store, x, rec, active[d], d, take[d], layout, floor, it, converged)
        step = np.clip(x.dnu[~done], -_MAX_STEP, _MAX_STEP)
        active = active[~done]
        store.nu[active] += step
        if active.size == 0:
            break
    return store


@dataclass(frozen=True)
class _Iterate:
    """One Gauss-Newton iterate of the active records (shapes of :func:`_solve`'s batch):
    the columns ``m`` at ν and the halves they project, their Gram products (``gp`` the
    half's, ``pp``/``qn`` the records' after/before), the linear fit (``ddi`` the inverse
    normal matrix, ``theta``), the derivative's projections (``dg_even``/``dg_odd``, ``v``
    = ``ddi`` times them, ``gg`` the reduced curvature), and the step ``dnu`` with its
    curvature ``den`` and whether it is the last (``last``)."""

    m: np.ndarray
    after: np.ndarray
    before: np.ndarray
    gp: np.ndarray
    pp: np.ndarray
    qn: np.ndarray
    ddi: np.ndarray
    theta: np.ndarray
    dg_even: np.ndarray
    dg_odd: np.ndarray
    v: np.ndarray
    gg: np.ndarray
    dnu: np.ndarray
    den: np.ndarray
    last: np.ndarray


def _iterate(rec: _Records, active, nu, layout: Layout, buffer, floor, dof: float) -> _Iterate:
    """The linear least squares of the records ``active`` at ``nu`` and the Gauss-Newton
    step on ν of the reduced problem (each channel weighted by its residual variance)."""
    par = layout.parity
    m = columns(nu, rec.u, layout, out=buffer)
    mt = m.transpose(0, 2, 1)
    after, before = rec.after[active], rec.before[active]
    gp, pp, qn = m @ mt, after @ mt, before @ mt
    dd = gp * (1.0 + np.outer(par, par))
    pf = pp + qn * par
    if rec.centre is not None:
        dd += np.outer(layout.centre_row, layout.centre_row)
        pf += rec.centre[active][..., None] * layout.centre_row
    ddi = np.linalg.inv(dd)
    theta = np.einsum("sij,scj->sci", ddi, pf)
    rss = np.maximum(rec.xx[active] - np.einsum("sci,sci->sc", theta, pf), floor[active])
    # g_c = ∂(model_c)/∂ν = g_even + g_odd on the half grid, g(-u) = g_even - g_odd
    g_even, g_odd = _derivative_halves(theta, m, rec.u, layout)
    dg_even, dg_odd = g_even @ mt, g_odd @ mt
    dg = 2.0 * np.where(par > 0, dg_even, dg_odd)  # Σ over the record of D g_c
    gx = np.einsum("scn,scn->sc", g_even, rec.x_even[active]) + np.einsum(
        "scn,scn->sc", g_odd, rec.x_odd[active]
    )
    gg = 2.0 * (np.einsum("scn,scn->sc", g_even, g_even) + np.einsum("scn,scn->sc", g_odd, g_odd))
    v = np.einsum("sij,scj->sci", ddi, dg)
    gr = gx - np.einsum("sci,sci->sc", theta, dg)
    gg = gg - np.einsum("sci,sci->sc", dg, v)
    sig2 = rss / dof
    num, den = (gr / sig2).sum(-1), (gg / sig2).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        dnu = num / den
        # Gauss-Newton is quadratic here: after a step Δ the error is about κΔ² with
        # κ ≲ 1/rad (κ ≈ 0.3 measured). Once that is 1 % of std(ν), take the step to first
        # order, θ(ν + Δ) = θ(ν) - vΔ (halves likewise), and stop.
        last = _KAPPA * dnu**2 * np.sqrt(den) <= 0.01
    return _Iterate(
        m, after, before, gp, pp, qn, ddi, theta, dg_even, dg_odd, v, gg, dnu, den, last
    )


def _keep(store: _Store, x: _Iterate, rec: _Records, idx, d, take, layout, floor, it, converged):
    """Keep the records ``idx`` (``d`` of the iterate ``x``) in ``store``, their last step
    ``take`` taken to first order in θ and in the halves' projections."""
    t = take[:, None, None]
    store.put(
        idx,
        theta=x.theta[d] - x.v[d] * t,
        ddi=x.ddi[d],
        v=x.v[d],
        gg=x.gg[d],
        gp=x.gp[d],
        pp=x.pp[d] - (x.dg_even[d] + x.dg_odd[d]) * t,
        qn=x.qn[d] - (x.dg_even[d] - x.dg_odd[d]) * t,
        **_residual_ss(
            x.theta[d],
            x.m[d],
            x.after[d],
            x.before[d],
            None if rec.centre is None else rec.centre[idx],
            layout,
            floor[idx],
        ),
        iterations=it,
        converged=converged,
    )
    store.nu[idx] += take


def _derivative_halves(theta, m, u, layout: Layout):
    """Even and odd parts of ``∂model/∂ν = Σ_k k u (b_k cos kνu - a_k sin kνu)`` on the half grid.

    ``u sin`` is even and ``u cos`` odd; shapes (S, C, H).
    """
    k = np.arange(1, layout.n_harmonics + 1)
    a, b = theta[..., layout.cos_columns] * k, theta[..., layout.sin_columns] * k
    g_even = (a @ m[:, layout.sin_columns]) * (-u)
    g_odd = (b @ m[:, layout.cos_columns]) * u
    return g_even, g_odd


def _residual_ss(theta, d_half, after, before, centre, layout: Layout, floor) -> dict:
    """Explicit residual sums of squares per channel (no cancellation at high SNR): ``rss``
    over the record (at least ``floor``) and ``rss_halves`` (S, C, 2) over its first half
    (``before``, mirrored) and its second (``after``)."""
    par = layout.parity[: layout.n_model]
    r_after = after - theta @ d_half
    r_before = before - (theta * par) @ d_half
    halves = np.stack(
        [np.einsum("scn,scn->sc", r_before, r_before), np.einsum("scn,scn->sc", r_after, r_after)],
        axis=-1,
    )
    ss = halves.sum(-1)
    if centre is not None:
        ss += (centre - theta @ layout.centre_row) ** 2
    return {"rss": np.maximum(ss, floor), "rss_halves": halves}


class _Store:
    """Per-step results gathered as steps converge, then turned into the fit's arrays."""

    _PER_STEP = (
        "nu",
        "dof",
        "refined",
        "theta",
        "ddi",
        "v",
        "gg",
        "gp",
        "pp",
        "qn",
        "rss",
        "rss_halves",
        "iterations",
    )

    def __init__(self, nu, c: int, layout: Layout, dof: float, refined: bool):
        s, p = len(nu), layout.n_model
        self.layout, self.nu = layout, np.array(nu, dtype=np.float64)
        self.dof = np.full(s, dof)
        self.refined = np.full(s, refined)
        self.theta = np.zeros((s, c, p))
        self.ddi = np.zeros((s, p, p))
        self.v = np.zeros((s, c, p))
        self.gg = np.zeros((s, c))
        self.gp = np.zeros((s, p, p))
        self.pp = np.zeros((s, c, p))
        self.qn = np.zeros((s, c, p))
        self.rss = np.zeros((s, c))
        self.rss_halves = np.zeros((s, c, 2))
        self.iterations = np.zeros(s, dtype=int)
        self.converged = np.zeros(s, dtype=bool)

    def put(self, idx, **values):
        for key, value in values.items():
            getattr(self, key)[idx] = value

    def take(self, idx, other: _Store) -> None:
        """Replace steps ``idx`` by ``other``'s results (``converged`` is kept)."""
        for key in self._PER_STEP:
            getattr(self, key)[idx] = getattr(other, key)

    def finish(self, mean, n: int) -> dict:
        with np.errstate(divide="ignore", invalid="ignore"):  # an undetermined ν gives inf/NaN
            return self._finish(mean, n)

    def _finish(self, mean, n: int) -> dict:
        lay, nu = self.layout, self.nu
        s, c = self.rss.shape
        sig2 = self.rss / self.dof[:, None]
        den = (self.gg / sig2).sum(-1)
        inv_den = np.where(self.refined, np.where(den > 0, 1.0 / den, np.inf), 0.0)
        cos_idx = np.arange(lay.n_model)[lay.cos_columns]
        sin_idx = np.arange(lay.n_model)[lay.sin_columns]
        phasors = self.theta[..., cos_idx] - 1j * self.theta[..., sin_idx]
        # Cov(θ_c, θ_c') = σ_c² (DᵀD)⁻¹ δ_cc' + v_c v_c'ᵀ var(ν)   (block inverse, Schur complement)
        diag = np.diagonal(self.ddi, axis1=-2, axis2=-1)
        var_lin = sig2[..., None] * diag[:, None, :] + self.v**2 * inv_den[:, None, None]
        phasor_var = 0.5 * (var_lin[..., cos_idx] + var_lin[..., sin_idx])

        fund = np.array([cos_idx[0], sin_idx[0]])
        flip = np.array([1.0, -1.0])  # (a, b) -> (Re X, Im X) = (a, -b)
        blk = self.ddi[:, fund[:, None], fund[None, :]] * np.outer(flip, flip)
        cov = np.zeros((s, 2 * c, 2 * c))
        for i in range(c):
            cov[:, 2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = sig2[:, i, None, None] * blk
        vv = (self.v[..., fund] * flip).reshape(s, 2 * c)
        cov += vv[:, :, None] * vv[:, None, :] * inv_den[:, None, None]

        half_phasors, half_cov = self._halves(sig2, fund, n)
        return {
            "nu": nu,
            "nu_std": np.sqrt(inv_den),
            "theta": self.theta,
            "mean": mean,
            "phasors_m_s2": phasors,
            "phasor_var": phasor_var,
            "fundamental_cov": cov,
            "noise_std_m_s2": np.sqrt(sig2),
            "half_phasors_m_s2": half_phasors,
            "half_cov": half_cov,
            "residual_ss_halves": self.rss_halves,
            "iterations": self.iterations,
            "converged": self.converged,
        }

    def _halves(self, sig2, fund, n: int):
        """Fundamental fitted on each half alone (frequency fixed at the whole record's).

        The half before the centre has the Gram ``S G S`` of the half after (``S`` the column
        parities), so one inverse serves both. Returns phasors (S, C, 2) (before, after) and
        covariances (S, 2, 2C, 2C) of (Re X_0, Im X_0, Re X_1, ...) per half; within a half the
        channels are independent.
        """
        par = self.layout.parity
        s, c = sig2.shape
        if n // 2 < 2 * self.layout.n_model:
            return np.full((s, c, 2), np.nan + 0j), np.full((s, 2, 2 * c, 2 * c), np.nan)
        ddpi = np.linalg.inv(self.gp)
        after = np.einsum("sij,scj->sci", ddpi, self.pp)[..., fund]
        before = (np.einsum("sij,scj->sci", ddpi, self.qn) * par)[..., fund]
        flip = np.array([1.0, -1.0])  # (a, b) -> (Re X, Im X)
        blk_after = ddpi[:, fund[:, None], fund[None, :]] * np.outer(flip, flip)
        blk_before = blk_after * np.outer(par[fund], par[fund])
        cov = np.zeros((s, 2, 2 * c, 2 * c))
        for i in range(c):
            cov[:, 0, 2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = sig2[:, i, None, None] * blk_before
            cov[:, 1, 2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = sig2[:, i, None, None] * blk_after
        to_phasor = np.array([1.0, -1j])
        return np.stack([before @ to_phasor, after @ to_phasor], -1), cov
