"""The setup model: JSON round trip and checks of meaning."""

import json

import pytest

from vibid.setup_model import MODEL_PARAMETERS, SetupError, example_setup, parse_setup


def test_json_round_trip():
    s = example_setup()
    assert parse_setup(s.to_json()) == s
    assert json.loads(s.to_json())["identification"]["bounds"]["D"] == [1.0, 100.0]


def test_every_problem_is_listed_at_once():
    doc = example_setup().to_dict()
    doc["specimen"]["thickness_m"] = 0
    doc["daq"]["sample_rate_hz"] = 2000.0  # 1500 Hz steps are then above Nyquist
    doc["identification"]["bounds"]["beta"] = [-0.1, 0.1]
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    problems = err.value.problems
    assert "setup.specimen.thickness_m: must be a positive number, got 0.0" in problems
    assert (
        "setup.identification.bounds.beta: the loss factor cannot be negative, low is -0.1"
        in problems
    )
    assert sum("Nyquist" in p for p in problems) == sum(
        f >= 1000.0 for f in example_setup().excitation.frequencies_hz
    )


@pytest.mark.parametrize("model", list(MODEL_PARAMETERS))
def test_each_model_needs_exactly_its_parameters(model):
    doc = example_setup().to_dict()
    doc["identification"] = {
        "model": model,
        "bounds": {n: [0.1, 0.4] for n in MODEL_PARAMETERS[model]},
    }
    assert parse_setup(doc).identification.parameter_names == MODEL_PARAMETERS[model]
    doc["identification"]["bounds"].popitem()
    with pytest.raises(SetupError, match="needs bounds for"):
        parse_setup(doc)


def test_mistyped_fields_are_named():
    doc = example_setup().to_dict()
    doc["sensors"]["response"]["x_m"] = None
    doc["excitation"]["frequencies_hz"] = "5..1500"
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    assert err.value.problems == [
        "setup.sensors.response.x_m: expected a number, got null",
        "setup.excitation.frequencies_hz: expected a list of numbers",
    ]


def test_bounds_may_name_effect_parameters_as_priors():
    """session-format.md: bounds may name an effect's parameters (a prior for the loop),
    which does not declare the effect; unknown names and impossible boxes stay errors."""
    doc = example_setup().to_dict()
    doc["identification"]["bounds"]["k_theta_N_per_rad"] = [1e3, 1e7]
    doc["identification"]["bounds"]["tau_s"] = [-1e-4, 1e-4]
    setup = parse_setup(doc)
    assert setup.identification.bounds["k_theta_N_per_rad"] == (1e3, 1e7)
    assert setup.identification.parameter_names == ("D", "nu", "beta")
    doc["identification"]["bounds"]["k_theta_N_per_rad"] = [-1.0, 1e7]
    with pytest.raises(SetupError, match="k_theta_N_per_rad is a stiffness and must be positive"):
        parse_setup(doc)
    doc["identification"]["bounds"]["k_theta_N_per_rad"] = [1e3, 1e7]
    doc["identification"]["bounds"]["E"] = [1.0, 2.0]
    with pytest.raises(SetupError, match="E is not a parameter of model 'isotropic'"):
        parse_setup(doc)


def test_specimen_material_is_optional_free_text():
    """issue #26: ``specimen.material`` names the material's class; absent, it is None and
    not written back."""
    s = example_setup()
    assert s.specimen.material is None
    assert "material" not in json.loads(s.to_json())["specimen"]
    doc = s.to_dict()
    doc["specimen"]["material"] = "Ti-6Al-4V"
    with_material = parse_setup(doc)
    assert with_material.specimen.material == "Ti-6Al-4V"
    assert parse_setup(with_material.to_json()) == with_material
    doc["specimen"]["material"] = 4
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    assert err.value.problems == ["setup.specimen.material: expected a string, got a number"]


def test_a_planned_setup_lists_settle_and_record_times_per_step():
    """issue #28: ``excitation.settle_s`` may be a list (one per frequency) and
    ``excitation.record_s`` a number or such a list (session-format.md)."""
    doc = example_setup().to_dict()
    doc["excitation"]["frequencies_hz"] = [10.0, 20.0, 30.0]
    doc["excitation"]["settle_s"] = [0.1, 2.5, 0.0]
    doc["excitation"]["record_s"] = [0.5, 1.0, 0.25]
    planned = parse_setup(doc)
    assert [planned.excitation.settle_at(i) for i in range(3)] == [0.1, 2.5, 0.0]
    assert planned.excitation.record_at(1) == 1.0
    assert json.loads(planned.to_json())["excitation"]["settle_s"] == [0.1, 2.5, 0.0]
    assert parse_setup(planned.to_json()) == planned
    assert "record_s" not in json.loads(example_setup().to_json())["excitation"]
    assert example_setup().excitation.record_at(0) is None
    doc["excitation"]["settle_s"] = [0.1, -1.0]
    doc["excitation"]["record_s"] = [0.5, 0.0, 1.0]
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    assert err.value.problems == [
        "setup.excitation.settle_s: lists 2 values for 3 frequencies (one per step)",
        "setup.excitation.record_s[1]: must be positive, got 0.0",
    ]


@pytest.mark.parametrize("raw, digits", [("1" * 400, 400), ("-" + "9" * 5000, 5000)])
def test_an_integer_beyond_the_floats_names_its_field_in_one_line(raw, digits):
    """issue 62: a JSON integer too large for a float (OverflowError) or of more digits than
    Python's int-string limit (json's ValueError) is a SetupError naming the field."""
    text = example_setup().to_json().replace('"length_m": 0.1,', f'"length_m": {raw},')
    with pytest.raises(SetupError) as err:
        parse_setup(text)
    assert err.value.problems == [
        (
            f"setup.specimen.length_m: must be a finite number, got an integer of {digits} digits "
            "(beyond the floating-point range)"
        )
    ]


def test_integers_beyond_the_floats_in_lists_and_bounds_name_their_place():
    doc = example_setup().to_dict()
    doc["excitation"]["frequencies_hz"][1] = 10**400
    doc["excitation"]["settle_s"] = [0.5] * 199 + [-(10**5000)]
    doc["identification"]["bounds"]["D"] = [1, 10**5000]
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    assert [p.split(":")[0] for p in err.value.problems] == [
        "setup.excitation.frequencies_hz[1]",
        "setup.excitation.settle_s[199]",
        "setup.identification.bounds.D[1]",
    ]
    assert "401 digits" in err.value.problems[0] and "5001 digits" in err.value.problems[2]
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", ["D\nnu", "D\r", "x\u2028y", "\x00"])
def test_an_odd_bounds_name_is_quoted_on_one_line(name):
    doc = example_setup().to_dict()
    doc["identification"]["bounds"][name] = [1.0, 2.0]
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    text = str(err.value)
    assert text.splitlines() == [text]
    assert f"setup.identification.bounds: {name!r} is not a parameter" in text
    doc["identification"]["bounds"][name] = "1..2"
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    assert err.value.problems == [
        f"setup.identification.bounds[{name!r}]: expected [low, high], " + 'got "1..2"'
    ]


def test_a_bad_bounds_pair_is_shown_short_on_one_line():
    doc = example_setup().to_dict()
    doc["identification"]["bounds"]["D"] = [1.0] * 1000
    doc["identification"]["bounds"]["nu"] = {"a\nb": 10**5000}
    with pytest.raises(SetupError) as err:
        parse_setup(doc)
    d, nu = err.value.problems
    assert d.startswith("setup.identification.bounds.D: expected [low, high], got [1.0, 1.0")
    assert d.endswith("...") and len(d) < 150
    assert nu == "setup.identification.bounds.nu: expected [low, high], got an object"


def test_json_nested_too_deeply_is_a_setup_error():
    with pytest.raises(SetupError, match=r"^setup: not valid JSON \(nested too deeply\)$"):
        parse_setup("[" * 100_000)
