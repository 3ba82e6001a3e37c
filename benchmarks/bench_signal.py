"""Signal stage: throughput and statistical efficiency.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_signal.py

1. Throughput: a session of 200 steps × 25 600 samples (5.12 M samples per channel), 5 Hz to
   4 kHz, clock offsets within ±200 ppm, -40 dB harmonics, DC, drift, noise; then the same
   with 2 048-sample records. Best of 5 runs of the whole stage (``afc_from_records``: fit,
   ratio, flags) and of the batched fit alone, side by side with the same fit called step by
   step.
2. Efficiency: 4000 Monte Carlo records; the variance of amplitude, phase (at the record
   centre) and frequency over the Cramér-Rao bound, and the reported standard uncertainty of H
   over the Monte Carlo scatter.
"""

from __future__ import annotations

import time

import numpy as np

from vibid.hardware_mocks.records import synthetic_step
from vibid.signal import StepRecord, afc_from_records, fit_harmonics
from vibid.signal.basis import Layout
from vibid.signal.harmonic import max_harmonics
from vibid.signal.ratio import phasor_ratio


def _best_of(fn, repeats=5):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def throughput(n=25_600):
    fs, n_steps = 25_600.0, 200
    rng = np.random.default_rng(0)
    freqs = np.geomspace(5.0, 4_000.0, n_steps)
    steps = []
    for k, f in enumerate(freqs):
        b, r = synthetic_step(
            f,
            1.0 / (1.0 - (f / 700.0) ** 2 + 0.01j),
            sample_rate_hz=fs,
            n_samples=n,
            clock_offset_ppm=rng.uniform(-200, 200),
            dc_m_s2=(0.05, 0.02),
            drift_m_s2_per_s=(0.01, 0.01),
            harmonics_db=(-40.0, -40.0),
            noise_std_m_s2=(1e-3, 1e-3),
            rng=k,
        )
        steps.append(StepRecord(f, fs, b, r))
    samples = n_steps * n
    stage, stage_med = _best_of(lambda: afc_from_records(steps))

    k = max_harmonics(freqs, fs)
    x = np.stack([np.stack([s.base, s.response]) for s in steps])
    groups = [k == v for v in np.unique(k)]
    batched, _ = _best_of(
        lambda: [fit_harmonics(x[g], freqs[g], fs, layout=Layout(1, int(k[g][0]))) for g in groups]
    )
    looped, _ = _best_of(
        lambda: [
            fit_harmonics(x[i], freqs[i], fs, layout=Layout(1, int(k[i]))) for i in range(n_steps)
        ],
        repeats=2,
    )
    print(f"session: {n_steps} steps x {n} samples = {samples / 1e6:.2f} M samples per channel")
    print(
        f"  whole stage (fit, ratio, flags): best {stage:.3f} s, median {stage_med:.3f} s, "
        f"{samples / stage / 1e6:.1f} M samples/s per channel"
    )
    print(
        f"  batched fit alone:               best {batched:.3f} s, {samples / batched / 1e6:.1f} M samples/s"
    )
    print(
        f"  same fit step by step:           best {looped:.3f} s  (batched is {looped / batched:.2f}x faster)"
    )


def efficiency():
    f, fs, n, m = 50.37, 1024.0, 1024, 4000
    h = 0.6 * np.exp(0.8j)
    sigma = np.array([0.05, 0.03])
    amp = np.array([1.0, abs(h)])
    clean = np.stack(
        synthetic_step(
            f,
            h,
            sample_rate_hz=fs,
            n_samples=n,
            clock_offset_ppm=120.0,
            dc_m_s2=(0.2, 0.1),
            drift_m_s2_per_s=(0.1, -0.2),
            harmonics_db=(-40.0, -40.0),
            rng=5,
        )
    )
    noisy = clean[None] + sigma[None, :, None] * np.random.default_rng(7).standard_normal((m, 2, n))
    print(
        f"efficiency: {m} records of {n} samples, {f * n / fs:.2f} cycles, SNR per sample "
        f"{(10 * np.log10(amp**2 / 2 / sigma**2)).round(1).tolist()} dB (base, response)"
    )
    print(
        "  bounds: var A >= 2 s^2/N; var phi >= 2 s^2/(N A^2) (phase at the record centre, also with the"
    )
    print(
        "  frequency estimated); var w >= 1 / sum_c A_c^2 N (N^2-1) / (24 s_c^2 fs^2) (shared frequency)"
    )
    for refine in (False, True):
        fit = fit_harmonics(
            noisy, f * (1 + 120e-6) if not refine else f, fs, refine_frequency=refine
        )
        x = fit.phasors_m_s2[:, :, 0]
        var_a = np.abs(x).var(axis=0, ddof=1) / (2 * sigma**2 / n)
        var_p = np.angle(x * np.exp(-1j * np.angle(x.mean(0)))).var(axis=0, ddof=1) / (
            2 * sigma**2 / (n * amp**2)
        )
        h_fit, cov = phasor_ratio(x[:, 0], x[:, 1], fit.fundamental_cov)
        cal_re = np.sqrt(cov[:, 0, 0]).mean() / h_fit.real.std(ddof=1)
        cal_im = np.sqrt(cov[:, 1, 1]).mean() / h_fit.imag.std(ddof=1)
        label = "refined frequency" if refine else "known frequency  "
        line = (
            f"  {label}: var/bound A {var_a[0]:.3f} {var_a[1]:.3f}, phi {var_p[0]:.3f} {var_p[1]:.3f}"
            f"; reported std / MC std of H: re {cal_re:.3f}, im {cal_im:.3f}"
        )
        if refine:
            crb_w = 1.0 / np.sum(amp**2 * n * (n**2 - 1) / (24 * sigma**2 * fs**2))
            line += f"; var/bound w {(2 * np.pi * fit.frequency_hz).var(ddof=1) / crb_w:.3f}"
        print(line)


if __name__ == "__main__":
    throughput(25_600)
    throughput(2_048)
    efficiency()
