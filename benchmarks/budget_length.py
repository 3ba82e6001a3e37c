"""A declared length's part of E's uncertainty against the refit at that length.

    python benchmarks/budget_length.py      (about two minutes)

The titanium strip in the clamp the steel strip calibrated
(``examples/real-steel/titanium_setup.json``: its free length declared to 0.62 mm) through
the whole loop, as ``vibid identify`` runs it; then the loop's final model refitted locally
at the length one standard uncertainty longer and shorter, with Poisson's ratio free and
held where the loop held it. The budget's length part of E
(:func:`vibid.identify.assess.budget.estimate_shifts`, first order) should match the refit with
the loop's held parameters held (BENCHMARKS.md, "The real strips' first resonances left
out, …").
"""

from __future__ import annotations

import os

HERE = os.path.dirname(os.path.abspath(__file__))
AFC = os.path.join(HERE, "..", "..", "shared", "data", "real-titanium", "afc.csv")
SETUP = os.path.join(HERE, "..", "examples", "real-steel", "titanium_setup.json")


def main() -> None:
    from vibid.identify.engine.runtime import configure

    configure()
    from vibid.identify.assess.budget import engineering_budget, with_declared
    from vibid.identify.assess.engineering import constants
    from vibid.identify.engine.threads import jax_turn
    from vibid.identify.fit.strategy import Measurement, ModelChoice, SearchOptions, identify
    from vibid.identify.model.plate import build_forward_model
    from vibid.pipeline import afc_file, identify_afc

    data = afc_file(AFC, SETUP)
    closed = identify_afc(data).loop
    final, setup = closed.final, data.setup
    h, sigma = setup.specimen.thickness_m, setup.specimen.length_std_m
    held = closed.stages[-1].held
    with jax_turn():
        parts = engineering_budget(setup, final, closed)["budget"]["E_Pa"]
        print(
            f"budget: E's length part {parts['length_m'] / 1e9:.3g} GPa "
            f"(held in the shift: {', '.join(held) or 'nothing'})"
        )
        E0 = constants("isotropic", final.parameters, h)["E_Pa"]
        model, f, used = final.plate_model, final.frequency_hz, final.used
        box = model.default_bounds(dict(setup.identification.bounds))
        for sign in (+1, -1):
            moved = with_declared(setup, "length_m", setup.specimen.length_m + sign * sigma)
            fm = build_forward_model(
                moved, f[used], model=model, theta0=final.parameters, bounds=box
            )
            for label, kinds in (
                ("free", None),
                (
                    "held",
                    {
                        n: ("logit", final.parameters[n] - 1e-7, final.parameters[n] + 1e-7)
                        for n in held
                    },
                ),
            ):
                r = identify(
                    moved,
                    Measurement(f, final.H, final.H_std, used=used, weights=final.weights),
                    ModelChoice(name=model.model, forward_model=fm, bounds=box, kinds=kinds),
                    SearchOptions(method="local", start=final.parameters),
                )
                c = constants("isotropic", r.parameters, h)
                print(
                    f"refit at L {'+' if sign > 0 else '-'} {sigma * 1e3:.2f} mm, "
                    f"{', '.join(held) or 'nothing'} {label}: E moves "
                    f"{(c['E_Pa'] - E0) / 1e9:+.3g} GPa, nu {c['nu']:.3g}, "
                    f"chi2_red {r.chi2_reduced:.4g}"
                )


if __name__ == "__main__":
    main()
