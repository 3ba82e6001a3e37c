"""Does the loop's diagnosis of a residual survive a perturbation of a part in 10⁹?

    python benchmarks/diagnosis_stability.py [--setup SETUP.json] [--draws 4]

Runs ``vibid identify`` on the real titanium AFC (``../shared/data/real-titanium``, or
``tests/data/titanium_afc.csv.gz`` and its setup where that is absent) and keeps the
arguments of every call of :func:`vibid.identify.loop.diagnosis.diagnose` (the declared fit's
residual, each passing refit's, the final one). Each is then diagnosed again ``--draws``
times with the model's AFC multiplied by ``1 + 1e-9 n`` (``n`` standard normal per point:
rounding-level, far below any model change the loop makes). Prints, per call, the features
(kind, Hz, Q) as diagnosed and how many of the draws say something else (:func:`agree`:
another kind, or a frequency more than 1 % away). A diagnosis is the loop's evidence for
which effect to try next; one that changes under rounding makes the loop's path depend on
it.
"""

import argparse
import gzip
import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.join(HERE, "..", "..", "shared", "data", "real-titanium")


def agree(a, b) -> bool:
    """Whether two diagnoses say the same to the loop: the same kinds, each feature of one
    with a feature of the same kind within 1 % in frequency in the other."""

    def covered(x, y):
        return all(
            any(
                f.kind == g.kind and (f.kind == "trend" or abs(np.log(f.f_hz / g.f_hz)) < 0.01)
                for g in y.features
            )
            for f in x.features
        )

    return (
        sorted(f.kind for f in a.features) == sorted(f.kind for f in b.features)
        and covered(a, b)
        and covered(b, a)
    )


def words(d) -> str:
    return "; ".join(
        x.kind if x.kind == "trend" else f"{x.kind} {x.f_hz:.1f} Hz Q {x.q:.3g}" for x in d.features
    )


def main() -> int:
    from vibid.identify.engine.runtime import configure

    configure()
    import vibid.identify.loop.diagnosis as diagnosis
    from vibid.cli import main as cli

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    shared_setup = os.path.join(SHARED, "setup.json")
    p.add_argument(
        "--setup",
        default=shared_setup
        if os.path.exists(shared_setup)
        else os.path.join(HERE, "..", "tests", "data", "titanium_setup.json"),
    )
    p.add_argument("--draws", type=int, default=4)
    args = p.parse_args()
    afc = os.path.join(SHARED, "afc.csv")
    tmp = tempfile.mkdtemp()
    if not os.path.exists(afc):
        afc = os.path.join(tmp, "afc.csv")
        with (
            gzip.open(
                os.path.join(HERE, "..", "tests", "data", "titanium_afc.csv.gz"), "rt"
            ) as src,
            open(afc, "w") as dst,
        ):
            dst.write(src.read())
    calls, original = [], diagnosis.diagnose

    def kept(*a, **k):
        calls.append((a, k))
        return original(*a, **k)

    diagnosis.diagnose = kept
    cli(
        [
            "identify",
            "--afc",
            afc,
            "--setup",
            args.setup,
            "--json",
            os.path.join(tmp, "report.json"),
            "--no-progress",
        ]
    )
    diagnosis.diagnose = original
    rng = np.random.default_rng(0)
    changed_calls = 0
    print(
        f"\n{len(calls)} diagnoses, each again {args.draws} times with the model's AFC "
        f"perturbed by 1e-9 (relative):"
    )
    for i, ((f, Hm, H0, sd), k) in enumerate(calls):
        d0 = original(f, Hm, H0, sd, **k)
        changed = 0
        for _ in range(args.draws):
            d = original(f, Hm, H0 * (1 + 1e-9 * rng.standard_normal(H0.shape)), sd, **k)
            changed += not agree(d, d0)
        changed_calls += changed > 0
        print(f"  {i}: {changed} of {args.draws} differ | {words(d0)}")
    print(f"{changed_calls} of {len(calls)} diagnoses change under a perturbation of 1e-9")
    return 0


if __name__ == "__main__":
    sys.exit(main())
