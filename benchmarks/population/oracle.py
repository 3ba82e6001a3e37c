"""What vibid's own model reaches with the truth's effects: the population's oracle fit.

    python -m benchmarks.population.oracle [--half calibration|measured|all] [--cases ...]

For each case, the model the truth says is right (its material model, its library effects;
an effect outside the library is left out: vibid has no term for it) is fitted locally from
the truth's own values (the setup's prior box, each effect's catalogue box widened to hold
the truth), with vibid's identification (trust-region Newton, the model's own error in the
weights). Its reduced chi2 beside the loop's final one separates two kinds of miss
(:func:`benchmarks.population.score.miss_kind`, by BIC):

* ``search``: the oracle fits strongly better: a better explanation was within the library
  and the loop did not reach it (a refit that stopped in another basin, a candidate not
  tried);
* ``data``: it does not: the data do not prefer the truth over what the loop chose
  (effects the band cannot tell apart at this noise, or vibid's model lacking the physics).

The fit starts at the truth, so it answers "is there a better minimum at the truth", not
"can the loop find it". Results are cached in ``results/<case>/oracle.json`` (gitignored),
keyed by the case's digest and vibid's source less the loop and the report
(:func:`fit_code_digest`: the oracle runs neither), so a change to the loop keeps them;
``run.py`` reads them into the table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
from benchmarks.population import cases as C
from benchmarks.population.run import RESULTS, select


def _truth(name):
    d = C.CASES_DIR / name
    truth = json.loads((d / "truth.json").read_text())
    flat = dict(truth["material"])
    for values in truth["effects"].values():
        flat.update(values)
    return d, truth, flat


def oracle_fit(name) -> dict:
    """The oracle fit of case ``name`` (module doc): its chi2_red, status and seconds."""
    import vibid.identify
    from vibid.identify import identify
    from vibid.identify.fit.inputs import Measurement, ModelChoice, SearchOptions
    from vibid.identify.model.plate import Plate, plate_model_for
    from vibid.parameters import known_effect_parameter
    from vibid.pipeline import read_setup

    vibid.identify.configure()
    d, truth, flat = _truth(name)
    afc = np.loadtxt(d / "afc.csv", delimiter=",", skiprows=1)
    f, H, std = afc[:, 0], afc[:, 1] + 1j * afc[:, 2], afc[:, 3]
    setup = read_setup(d / "setup.json")
    effects = tuple(truth["effects"])
    model = plate_model_for(tuple(flat), effects)
    box = dict(setup.identification.bounds)
    for n, v in flat.items():  # every box widened to hold the truth
        q = known_effect_parameter(n)
        if q is not None and q.bounds is not None:
            lo, hi = q.bounds
        elif n in box:
            lo, hi = box[n]
        else:  # an orthotropic truth declared isotropic: its moduli have no box of their own
            lo, hi = sorted((v / 3, 3 * v))
        box[n] = (min(lo, v), max(hi, v))
    box = model.default_bounds(box)
    t0 = time.monotonic()
    fm = Plate(setup).forward_model(f, model=model, theta0=flat, bounds=box)
    res = identify(
        setup,
        Measurement(f, H, std),
        ModelChoice(name=model.material.model, forward_model=fm, bounds=box),
        SearchOptions(method="local", start=flat),
    )
    return {
        "case": name,
        "effects": list(effects),
        "chi2_reduced": float(res.chi2_reduced),
        "status": res.status.value,
        "parameters": {k: float(v) for k, v in res.parameters.items()},
        "seconds": round(time.monotonic() - t0, 2),
    }


def fit_code_digest() -> str:
    """A hash of vibid's source that the oracle fit runs: all of it but ``identify/loop/``
    and ``report/``."""
    import hashlib
    import importlib.util
    import pathlib

    root = pathlib.Path(importlib.util.find_spec("vibid").origin).parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        rel = f.relative_to(root).as_posix()
        if not rel.startswith(("identify/loop/", "report/")):
            h.update(rel.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def cached_oracle(name) -> dict | None:
    """The cached oracle fit of ``name`` for this case and this vibid, or None."""
    p = RESULTS / name / "oracle.json"
    if not p.exists():
        return None
    got = json.loads(p.read_text())
    if got.get("digest") != C.digest(name) or got.get("code") != fit_code_digest():
        return None
    return got


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--half", choices=("calibration", "measured", "all"), default="all")
    ap.add_argument("--cases", help="the first N cases of the half, or names (prefixes)")
    args = ap.parse_args(argv)
    _, names = select(args.half, args.cases)
    for i, name in enumerate(names):
        got = cached_oracle(name)
        if got is None:
            try:
                got = oracle_fit(name)
            except Exception as exc:  # noqa: BLE001 - one case's failure is its row
                got = {"case": name, "chi2_reduced": math.nan, "status": f"error: {exc}"}
            got |= {"digest": C.digest(name), "code": fit_code_digest()}
            (RESULTS / name).mkdir(parents=True, exist_ok=True)
            (RESULTS / name / "oracle.json").write_text(json.dumps(got, indent=1) + "\n")
        print(
            f"[{i + 1}/{len(names)}] {name}: chi2_red {got['chi2_reduced']:.4g} ({got['status']})",
            file=sys.stderr,
            flush=True,
        )


if __name__ == "__main__":
    main()
