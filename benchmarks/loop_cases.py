"""The cases of ``benchmarks/loop.py``: what is in the data, what the loop should find, and
how each case's data are made and read.

Four kinds:

* ``strip`` (the eight original cases): the paper's steel strip (``example_setup()``) on
  the virtual stand (``simulate_session``, the full FE model on the "fine" mesh), with one
  or two effects that the declared setup does not name;
* ``plate``: the paper's subject, a 150 x 100 x 2 mm CFRP plate, orthotropic in the data
  (:data:`PLATE_ENGINEERING`), declared isotropic; 120 stepped-sine steps up to 800 Hz
  (five modes in the band), clamped on a short edge like the strip;
* ``titanium`` and ``steel``: the real measured AFCs of ``../shared/data/real-titanium`` and
  ``examples/real-steel`` (no truth), read as ``vibid identify --afc afc.csv --setup
  setup.json`` reads them;
* ``table2-<noise>-<f_max>``: the rows of the paper's Table 2 as ``benchmarks/paper_table.py``
  defines them (its setup, frequencies, full-model data, noise and seeds): the data come
  from the full FE model of the declared discretisation plus white noise, so there is
  nothing for the loop to find (and on the noiseless rows, which have no std, it cannot
  look: the loop needs the AFC's uncertainty).
"""

from __future__ import annotations

import dataclasses
import os
import sys
from dataclasses import dataclass, field

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:  # paper_table.py sits beside this file
    sys.path.insert(0, _HERE)

# -- the strip cases (the original eight) ----------------------------------------------------
TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
#: case -> (effects in the data, what the loop should add)
CASES = {
    "clean": ({}, ()),
    "delay": ({"tau_s": 2e-5}, ("channel_delay",)),
    "gain": ({"gain": 1.02}, ("sensor_gain",)),
    "clamp": ({"k_theta_N_per_rad": 1.6e4}, ("clamp_compliance",)),
    "mass": ({"mass_kg": 3e-4}, ("added_mass",)),
    "alpha": ({"alpha": 0.3}, ("frequency_dependent_loss",)),
    "delay+clamp": (
        {"tau_s": 2e-5, "k_theta_N_per_rad": 1.6e4},
        ("channel_delay", "clamp_compliance"),
    ),
    # an orthotropic strip, D11 / D22 = 10, declared isotropic
    "anisotropy": ({"D11": 17.97, "D12": 0.54, "D22": 1.797, "D66": 1.2}, ("anisotropy",)),
}
MATERIAL = ("D", "nu", "D11", "D12", "D22", "D66")

# -- the CFRP plate ----------------------------------------------------------------------------
PLATE_STEPS = 120
PLATE_F_MAX_HZ = 800.0
PLATE_THICKNESS_M = 0.002
#: Engineering constants of the plate in the data: a CFRP laminate stiff along the length
#: (x, away from the clamp), E1 / E2 = 5, shear-soft.
PLATE_ENGINEERING = {"E1_Pa": 60e9, "E2_Pa": 12e9, "nu12": 0.30, "G12_Pa": 4.5e9}
PLATE_BETA = 0.005


def orthotropic_moduli(E1_Pa, E2_Pa, nu12, G12_Pa, thickness_m) -> dict:
    """``D11, D12, D22, D66`` (N m) of a homogeneous orthotropic plate (the inverse of
    :mod:`vibid.identify.assess.engineering`'s conversion)."""
    nu21 = nu12 * E2_Pa / E1_Pa
    q = thickness_m**3 / (12.0 * (1.0 - nu12 * nu21))
    return {
        "D11": E1_Pa * q,
        "D12": nu12 * E2_Pa * q,
        "D22": E2_Pa * q,
        "D66": G12_Pa * thickness_m**3 / 12.0,
    }


PLATE_TRUTH = orthotropic_moduli(**PLATE_ENGINEERING, thickness_m=PLATE_THICKNESS_M) | {
    "beta": PLATE_BETA
}


def plate_setup():
    """The declared setup of the plate: ``example_setup()`` with the specimen, the sensor's
    place and the stepped sine replaced. The 1 g sensor sits 10 mm from the free edge and
    30 mm off the centre line (it sees the torsion modes); the declared model is isotropic
    with the strip's box (D in [1, 100] N m covers D11, D22 and, for the loop's anisotropy
    candidate, D66 in [D_lo / 10, D_hi / 2])."""
    from vibid.setup_model import example_setup

    s = example_setup()
    specimen = dataclasses.replace(
        s.specimen,
        name="CFRP plate 150x100x2",
        length_m=0.150,
        width_m=0.100,
        thickness_m=PLATE_THICKNESS_M,
        density_kg_m3=1550.0,
    )
    response = dataclasses.replace(s.sensors.response, x_m=0.140, y_m=0.080)
    freqs = tuple(np.linspace(PLATE_F_MAX_HZ / PLATE_STEPS, PLATE_F_MAX_HZ, PLATE_STEPS))
    return dataclasses.replace(
        s,
        specimen=specimen,
        sensors=dataclasses.replace(s.sensors, response=response),
        excitation=dataclasses.replace(s.excitation, frequencies_hz=freqs),
        identification=dataclasses.replace(
            s.identification, bounds={"D": (1.0, 100.0), "nu": (0.0, 0.5), "beta": (1e-4, 0.1)}
        ),
    )


def strip_setup(steps: int):
    """The strip cases' setup: ``example_setup()`` with ``steps`` steps up to 1500 Hz."""
    from vibid.setup_model import example_setup

    s = example_setup()
    freqs = tuple(np.linspace(1500.0 / steps, 1500.0, steps))
    return dataclasses.replace(
        s, excitation=dataclasses.replace(s.excitation, frequencies_hz=freqs)
    )


# -- the real strips: AFCs measured on the seed paper's stand ----------------------------------
TITANIUM_DIR = os.environ.get("VIBID_TITANIUM_DIR") or os.path.normpath(
    os.path.join(_HERE, "..", "..", "shared", "data", "real-titanium")
)
#: the steel strip of the same stand (examples/real-steel/README.md)
STEEL_DIR = os.path.normpath(os.path.join(_HERE, "..", "examples", "real-steel"))
#: a real AFC's case name -> the folder of its afc.csv and setup.json
REAL_DIRS = {"titanium": TITANIUM_DIR, "steel": STEEL_DIR}


# -- the paper's Table 2 -------------------------------------------------------------------------
def table2_rows() -> list[tuple[float, int]]:
    """``(noise, f_max_hz)`` of every row of the paper's Table 2 (``paper_table.PAPER``), in
    paper_table.py's order: by f_max, then noise."""
    from paper_table import PAPER

    return sorted(PAPER, key=lambda k: (k[1], k[0]))


def table2_name(noise: float, f_max: float) -> str:
    return f"table2-{noise:g}-{f_max:g}"


# -- the beam cases: sessions from the exact beam of tests/beam_reference.py -----------------
_TESTS = os.path.join(os.path.dirname(_HERE), "tests")
STAND = {"f_hz_1": 660.0, "q_1": 30.0, "theta_rad_per_m_1": 0.3}
#: case -> (effects in the data, what the loop should add, the declared box of nu); every
#: default candidate in play (issue #25's cases: a model vibid did not write)
BEAM_CASES = {
    "beam-clean": ({}, (), None),
    "beam-stand": (STAND, ("stand_resonance",), None),
    # the clamp softens every mode, which a beam's nu mimics: the declared box of nu is the
    # lab's knowledge of its material (near 0, as the beam's)
    "beam-stand+clamp": (
        STAND | {"k_theta_N_per_rad": 1.6e4},
        ("stand_resonance", "clamp_compliance"),
        (-0.05, 0.05),
    ),
    "beam-delay": ({"tau_s": 2e-5}, ("channel_delay",), None),
    "beam-gain": ({"gain": 1.02}, ("sensor_gain",), None),
    "beam-mass": ({"mass_kg": 3e-4}, ("added_mass",), None),
    "beam-alpha": ({"alpha": 0.3}, ("frequency_dependent_loss",), None),
    # outside the library: 2 % of the base channel in the response channel; the loop
    # should say unexplained_residual with D, nu, beta in place (no expected effect)
    "beam-crosstalk": ({"crosstalk": 0.02}, None, None),
}
#: case -> the response sensor's offset (m) across the width of the independent polynomial
#: Ritz plate of tests/ritz_plate.py (the same strip, nu = 0; the setup declares the sensor
#: on the centre line, nu's default box): the offset shows the torsion, which the declared
#: model hides; the loop should add ``sensor_position``
RITZ_CASES = {"ritz-sensor": 0.003}


def beam_data(name: str):
    """``(setup, afc)`` of a beam case (tests/beam_sessions.py: 60 steps, 0.3 % noise)."""
    from types import SimpleNamespace

    if _TESTS not in sys.path:
        sys.path.insert(0, _TESTS)
    import beam_sessions as bs

    if name in RITZ_CASES:
        import ritz_plate as rs
        from loop_data import noisy

        t = bs.TRUTH
        H, sd = noisy(rs.afc(bs.F, t["D"], t["nu"], t["beta"], ys=0.010 + RITZ_CASES[name]), 1)
        return bs.setup(), SimpleNamespace(frequency_hz=bs.F, H=H, std=sd, used=None)
    effects, _, nu_box = BEAM_CASES[name]
    setup = bs.setup()
    if nu_box is not None:
        setup = dataclasses.replace(
            setup,
            identification=dataclasses.replace(
                setup.identification, bounds=dict(setup.identification.bounds) | {"nu": nu_box}
            ),
        )
    H, sd = bs.data(effects, seed=1)
    return setup, SimpleNamespace(frequency_hz=bs.F, H=H, std=sd, used=None)


# -- the catalogue -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """One benchmark case.

    kind: ``"strip"``, ``"beam"``, ``"plate"``, ``"real"`` (a measured AFC: titanium,
        steel) or ``"table2"``.
    effects_in_data: the undeclared effects' parameters in the data (strip cases).
    expected: what the loop should add; None: no expectation (ok = the loop finished).
    truth: every parameter the data were made with (material and effects), or None.
    seed: the seed of the identification (None: the command line's ``--seed``).
    row: ``(noise, f_max_hz)`` of a Table 2 row.
    """

    name: str
    kind: str
    expected: tuple[str, ...] | None
    truth: dict | None
    effects_in_data: dict = field(default_factory=dict)
    seed: int | None = None
    row: tuple[float, float] | None = None

    @property
    def truth_material(self) -> dict:
        """The truth of the material parameters and beta (what errors are reported for)."""
        return {k: v for k, v in (self.truth or {}).items() if k in MATERIAL or k == "beta"}


def _strip_case(name: str) -> Case:
    effects, expected = CASES[name]
    truth = (
        {k: v for k, v in TRUTH.items() if k not in ("D", "nu")}
        if "D11" in effects
        else dict(TRUTH)
    ) | effects
    return Case(name, "strip", tuple(expected), truth, dict(effects))


def get_case(name: str) -> Case:
    """The case of a name (``table2-0.01-600`` for one Table 2 row)."""
    if name in CASES:
        return _strip_case(name)
    if name in BEAM_CASES:
        effects, expected, _ = BEAM_CASES[name]
        return Case(
            name,
            "beam",
            None if expected is None else tuple(expected),
            {"D": 17.97, "nu": 0.0, "beta": 0.003} | effects,
            dict(effects),
        )
    if name in RITZ_CASES:  # the offset's sign is not the data's to tell: no truth for it
        return Case(name, "beam", ("sensor_position",), {"D": 17.97, "nu": 0.0, "beta": 0.003})
    if name == "plate":
        return Case("plate", "plate", ("anisotropy",), dict(PLATE_TRUTH))
    if name in REAL_DIRS:
        from vibid.pipeline import SEED

        return Case(name, "real", None, None, seed=SEED)  # as `vibid identify`
    if name.startswith("table2-"):
        from paper_table import TRUE

        for noise, fmax in table2_rows():
            if name == table2_name(noise, fmax):
                # paper_table.py's default seed (0) for the identification and its noise
                return Case(name, "table2", (), dict(TRUE), seed=0, row=(noise, float(fmax)))
    raise KeyError(
        f"unknown case {name!r}; expected one of {', '.join(all_names())} "
        "(or a group: all, strip, table2)"
    )


def all_names() -> list[str]:
    return (
        list(CASES)
        + list(BEAM_CASES)
        + list(RITZ_CASES)
        + ["plate", *REAL_DIRS]
        + [table2_name(*r) for r in table2_rows()]
    )


#: Names that stand for several cases on the command line.
GROUPS = {
    "strip": lambda: list(CASES),
    "beam": lambda: [*BEAM_CASES, *RITZ_CASES],
    "table2": lambda: [table2_name(*r) for r in table2_rows()],
    "all": all_names,
}


def expand(spec: str) -> list[str]:
    """Case names of a comma-separated ``--cases`` value (groups expanded, order kept,
    duplicates dropped); unknown names raise KeyError."""
    out = []
    for part in (p.strip() for p in spec.split(",")):
        if not part:
            continue
        names = GROUPS[part]() if part in GROUPS else [part]
        for n in names:
            get_case(n)
            if n not in out:
                out.append(n)
    return out


# -- data: made once per case (before the timed stages), then read by the signal stage ------
def prepare(case: Case, workdir: str, steps: int, seed: int, say=print) -> dict:
    """Make the case's data under ``workdir`` (not timed: the stand's part) and return its
    source, a JSON-able dict that :func:`signal_stage` reads."""
    if case.kind in ("strip", "plate"):
        from vibid.hardware_mocks.simulated_session import simulate_session

        setup = strip_setup(steps) if case.kind == "strip" else plate_setup()
        if case.kind == "plate":
            say(plate_description(setup))
        path = os.path.join(workdir, f"{case.name}.h5")
        simulate_session(path, setup, case.truth, seed=seed)
        return {"session": path}
    if case.kind == "beam":
        return {"beam": case.name}
    if case.kind == "real":
        return {
            "afc": os.path.join(REAL_DIRS[case.name], "afc.csv"),
            "setup": os.path.join(REAL_DIRS[case.name], "setup.json"),
        }
    return {"noise": case.row[0], "f_max_hz": case.row[1]}


def plate_description(setup=None, n: int = 8) -> str:
    """The plate's truth and its natural frequencies (full model, with the sensor)."""
    from vibid.identify import natural_frequencies

    setup = setup or plate_setup()
    f, _ = natural_frequencies(setup, PLATE_TRUTH, n=n)
    below = int(np.sum(f < PLATE_F_MAX_HZ))
    e = PLATE_ENGINEERING
    return (
        f"plate: {setup.specimen.name}, rho {setup.specimen.density_kg_m3:g} kg/m3, "
        f"sensor at ({setup.sensors.response.x_m * 1e3:g}, "
        f"{setup.sensors.response.y_m * 1e3:g}) mm; truth E1 {e['E1_Pa'] / 1e9:g} GPa, "
        f"E2 {e['E2_Pa'] / 1e9:g} GPa, nu12 {e['nu12']:g}, G12 {e['G12_Pa'] / 1e9:g} GPa -> "
        + ", ".join(f"{k} {v:.4g}" for k, v in PLATE_TRUTH.items())
        + f" (D11/D22 {PLATE_TRUTH['D11'] / PLATE_TRUTH['D22']:.2f}); first {n} natural "
        f"frequencies "
        + " ".join(f"{x:.1f}" for x in f)
        + f" Hz: {below} below {PLATE_F_MAX_HZ:g} Hz"
    )


#: Forward models of the Table 2 rows, by f_max, shared by a run's noise levels as in
#: paper_table.py (in one process only).
_TABLE2_MODELS: dict = {}


def table2_data(case: Case):
    """``(setup, afc, forward_model)`` of a Table 2 row, made as paper_table.py makes it:
    its setup and 201 frequencies from 0, the full model's AFC at the truth, its noise."""
    from types import SimpleNamespace

    from paper_table import TRUE, make_model, noisy
    from paper_table import strip_setup as table_setup

    level, fmax = case.row
    setup = table_setup(fmax)
    f = np.linspace(0, fmax, 201)
    if fmax not in _TABLE2_MODELS:
        fm = make_model(setup, f, toy=False)
        H = np.asarray(fm.afc_full(np.array([TRUE[k] for k in ("D", "nu", "beta")])))
        _TABLE2_MODELS[fmax] = (fm, H)
    fm, H = _TABLE2_MODELS[fmax]
    seed = case.seed
    Hn, sd = noisy(H, level, seed=seed + int(fmax) + int(1000 * level))  # paper_table's seeds
    std = None if level == 0 else np.full(f.size, sd)
    return setup, SimpleNamespace(frequency_hz=f, H=Hn, std=std, used=None), fm


def signal_stage(case: Case, source: dict):
    """``(setup, afc)``: what ``vibid identify`` reads before it identifies: a session's
    signal stage, or an imported AFC CSV with its setup (``vibid.cli.identify``'s own
    code path)."""
    from argparse import Namespace

    from vibid.cli.identify import _source

    if "beam" in source:
        return beam_data(source["beam"])
    if "session" in source:
        data = _source(Namespace(session=source["session"], afc=None, setup=None))
    else:
        data = _source(Namespace(session=None, afc=source["afc"], setup=source["setup"]))
    return data.setup, data.afc
