"""The parameter catalogue (vibid.parameters): import-light, the one declaration of every
parameter that the terms use, and the instance-suffix rule."""

import dataclasses
import math
import subprocess
import sys

import pytest

from vibid import parameters
from vibid.parameters import (
    EFFECT_PARAMETERS_BY_EFFECT,
    MULTI_INSTANCE,
    Parameter,
    catalogue,
    effect_parameters,
    instance_name,
    known_effect_parameter,
    known_parameter,
    split_instance,
)


def test_setup_layer_imports_no_numerical_core():
    code = (
        "import sys, vibid.setup_model, vibid.parameters\n"
        "bad = sorted(m for m in sys.modules if m.startswith('vibid.identify') or "
        "m.split('.')[0] in ('jax', 'jaxlib', 'numpy', 'scipy'))\n"
        "print(' '.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_parameter_is_one_class():
    from vibid.identify.model.terms import Parameter as TermsParameter

    assert TermsParameter is Parameter


def test_every_effect_term_takes_its_parameters_from_the_catalogue():
    from vibid.identify.effects import EFFECT_PARAMETERS, EFFECTS, effects_for

    assert EFFECT_PARAMETERS == parameters.EFFECT_PARAMETERS
    for name, term in EFFECTS.items():
        assert name in EFFECT_PARAMETERS_BY_EFFECT, f"{name} is not in the catalogue"
        declared = getattr(term, "all_parameters", term.parameters)
        expected = EFFECT_PARAMETERS_BY_EFFECT[name]
        if name in MULTI_INSTANCE:  # the term's names carry its instance's suffix
            assert declared == tuple(
                dataclasses.replace(q, name=instance_name(q.name, term.instance)) for q in expected
            )
        else:
            assert declared == expected
            assert all(a is b for a, b in zip(declared, expected))
        for q in declared:
            assert known_parameter(q.name) == q
            assert known_effect_parameter(q.name) == q
        if declared:
            assert effects_for([declared[0].name]) == (term,)


def test_transverse_shear_has_g13_on_an_orthotropic_plate_only():
    from vibid.identify.effects import EFFECTS
    from vibid.identify.effects.transverse_shear import G13, TransverseShear

    assert G13 is parameters.G13
    assert EFFECTS["transverse_shear"].all_parameters == (parameters.G13,)
    assert TransverseShear(orthotropic=False).parameters == ()
    assert effect_parameters("transverse_shear", "isotropic") == ()
    assert TransverseShear(orthotropic=True).parameters == (parameters.G13,)
    assert effect_parameters("transverse_shear", "orthotropic") == (parameters.G13,)


def test_effect_modules_keep_their_names():
    from vibid.identify.effects import (
        added_mass,
        channel_delay,
        clamp_compliance,
        frequency_dependent_loss,
        sensor_gain,
        sensor_position,
    )

    assert clamp_compliance.K_THETA is parameters.K_THETA
    assert added_mass.MASS is parameters.MASS
    assert channel_delay.TAU is parameters.TAU
    assert sensor_gain.GAIN is parameters.GAIN
    assert frequency_dependent_loss.ALPHA is parameters.ALPHA
    assert sensor_position.DY is parameters.DY


def test_every_material_takes_its_parameters_from_the_catalogue():
    from vibid.identify.model import materials
    from vibid.identify.model.materials import Material
    from vibid.setup_model import MODEL_PARAMETERS

    assert materials.STIFFNESS is parameters.STIFFNESS
    assert materials.PER_MODULUS_LOSS is parameters.PER_MODULUS_LOSS
    assert materials.MODELS == parameters.MODELS == ("isotropic", "orthotropic", "monoclinic")
    assert materials.NU is parameters.NU
    for model in parameters.MODELS:
        assert MODEL_PARAMETERS[model] == Material(model).names
        for pml in (False, True):
            m = Material(model, pml)
            assert m.parameters == parameters.material_parameters(model, pml)
            for q in m.parameters:
                assert known_parameter(q.name) is q
                assert known_effect_parameter(q.name) is None
    assert Material("isotropic").names == ("D", "nu", "beta")
    assert Material("monoclinic", True).names == (
        "D11",
        "D12",
        "D22",
        "D66",
        "D16",
        "D26",
        "beta11",
        "beta12",
        "beta22",
        "beta66",
        "beta16",
        "beta26",
    )
    assert known_parameter("D12").kind == ("linear",) and known_parameter("D12").rule is None
    assert known_parameter("D").rule == "positive"


def test_catalogue_holds_every_parameter_once():
    cat = catalogue()
    assert set(parameters.MATERIAL_PARAMETERS) <= set(cat)
    assert set(parameters.EFFECT_PARAMETERS) <= set(cat)
    assert len(cat) == len(parameters.MATERIAL_PARAMETERS) + len(parameters.EFFECT_PARAMETERS)
    assert all(cat[n].name == n for n in cat)
    assert "f_hz" in cat and "f_hz_1" not in cat
    cat.clear()  # a copy: the catalogue stays whole
    assert known_parameter("D") is parameters.D


def test_instances():
    q2 = known_parameter("f_hz_2")
    assert q2.name == "f_hz_2" and q2.unit == "Hz"
    assert dataclasses.replace(q2, name="f_hz") == parameters.F_HZ
    assert known_parameter("q_1").unit == "1"
    assert known_parameter("theta_rad_per_m_3").unit == "rad/m"
    assert known_parameter("f_hz").unit == "Hz"
    assert split_instance("q_1") == ("q", 1)
    assert split_instance("f_hz_12") == ("f_hz", 12)
    assert split_instance("theta_rad_per_m_2") == ("theta_rad_per_m", 2)
    assert split_instance("q") == ("q", None)
    # only the parameters of an effect with instances carry a suffix
    assert split_instance("beta11") == ("beta11", None)
    assert split_instance("tau_s_2") == ("tau_s_2", None)
    assert split_instance("q_0") == ("q_0", None)
    assert known_parameter("tau_s_2") is None
    assert instance_name("f_hz", 2) == "f_hz_2"
    assert split_instance(instance_name("theta_rad_per_m", 7)) == ("theta_rad_per_m", 7)
    with pytest.raises(ValueError):
        instance_name("tau_s", 1)
    with pytest.raises(ValueError):
        instance_name("f_hz", 0)
    assert MULTI_INSTANCE == ("stand_resonance",)


def test_unknown_names():
    assert known_parameter("E") is None
    assert known_parameter("") is None
    assert known_parameter("f_hz_") is None
    assert known_effect_parameter("D") is None
    assert parameters.describe("E") == ""


def test_new_effects_parameters_and_their_boxes():
    expected = {
        "stand_resonance": ("f_hz", "q", "theta_rad_per_m"),
        "clamp_loss": ("beta_clamp",),
        "free_length": ("dL_m",),
        "sensor_inertia": ("height_m",),
    }
    for effect, names in expected.items():
        params = EFFECT_PARAMETERS_BY_EFFECT[effect]
        assert tuple(q.name for q in params) == names
        for q in params:
            assert q.bounds is not None and q.bounds_problem(*q.bounds) is None, q.name
    assert parameters.F_HZ.bounds == (5.0, 5000.0) and parameters.F_HZ.rule == "positive"
    assert parameters.Q.bounds == (2.0, 500.0) and parameters.Q.null is None
    assert parameters.THETA.null == 0.0 and parameters.THETA.unit == "rad/m"
    assert parameters.BETA_CLAMP.null is None and parameters.BETA_CLAMP.rule == "non-negative"
    assert parameters.DL.bounds == (-5e-3, 5e-3) and parameters.DL.null == 0.0
    assert parameters.HEIGHT.bounds == (0.0, 0.02) and parameters.HEIGHT.rule == "non-negative"
    # every effect parameter with a default box accepts it
    for q in parameters.EFFECT_PARAMETERS.values():
        assert q.bounds_problem(*q.bounds) is None, q.name


def test_every_parameter_has_a_description_and_the_report_reads_the_catalogue():
    from vibid.report import quantities, values

    for name in catalogue():
        assert parameters.describe(name), name
    assert parameters.describe("f_hz_2").endswith("(2)")
    (d,) = quantities({"parameters": {"D": {"value": 17.97, "std": 0.01}}, "effects": []})
    assert d.meaning == "bending stiffness" and d.unit == "N m"
    assert values.unit_of("f_hz_2") == "Hz"
    assert values.unit_of("k_theta_N_per_rad") == "N/rad"
    assert values.unit_of("G13_Pa") == "Pa"
    assert values.unit_of("E") == "1"


def test_setup_bounds_may_name_an_instance():
    from vibid.setup_model import SetupError, example_setup, parse_setup

    doc = example_setup().to_dict()
    doc["identification"]["bounds"]["f_hz_1"] = [20.0, 80.0]
    doc["identification"]["bounds"]["q_2"] = [5.0, 50.0]
    assert parse_setup(doc).identification.bounds["f_hz_1"] == (20.0, 80.0)
    doc["identification"]["bounds"]["q_2"] = [-1.0, 50.0]
    with pytest.raises(SetupError, match="q_2 is a quality factor and must be positive"):
        parse_setup(doc)
    doc["identification"]["bounds"]["q_2"] = [5.0, 50.0]
    doc["identification"]["bounds"]["tau_s_1"] = [-1e-4, 1e-4]
    with pytest.raises(SetupError, match="tau_s_1 is not a parameter"):
        parse_setup(doc)


def test_a_single_value_respects_its_parameters_rule_and_the_specimens_scale():
    """value_problem (issue 62): a prior box's rule for one value, the interval open at both
    ends (an isotropic nu in (-1, 0.5)); the term's null is a value (the rigid clamp's inf);
    the physical limits need the declared specimen's sizes."""
    from vibid.parameters import specimen_scale
    from vibid.setup_model import example_setup

    nu, k, mass, dl, dy = (
        known_parameter(n) for n in ("nu", "k_theta_N_per_rad", "mass_kg", "dL_m", "sensor_dy_m")
    )
    assert nu.value_problem(0.3) is None and nu.value_problem(-0.999) is None
    assert "must lie in (-1, 0.5)" in nu.value_problem(0.5)
    assert "must lie in (-1, 0.5)" in nu.value_problem(-1.0)
    assert nu.bounds_problem(0.0, 0.5) is None  # a box may end at 0.5, a value may not
    assert k.value_problem(math.inf) is None and "must be positive" in k.value_problem(0.0)
    assert "finite" in mass.value_problem(math.nan)
    scale = specimen_scale(example_setup())  # 15.84 g of steel, 100 x 20 mm, sensor at y = 15 mm
    assert scale["specimen_mass_kg"] == pytest.approx(0.01584)
    assert mass.value_problem(1e6) is None  # no scale: no limit
    assert "outweighs the specimen" in mass.value_problem(0.02, scale)
    assert mass.value_problem(0.015, scale) is None
    assert (
        "leaves no free length" in dl.value_problem(-0.1, scale)
        and dl.value_problem(-0.09, scale) is None
    )
    assert (
        "off the plate" in dy.value_problem(0.0051, scale)
        and dy.value_problem(-0.015, scale) is None
    )
    assert (
        known_parameter("q_2")
        .value_problem(-5.0)
        .startswith("q_2 (a quality factor) must be positive")
    )
