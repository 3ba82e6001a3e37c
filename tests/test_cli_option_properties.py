"""Property-based tests of the command line's readers (issue 62, "never silently wrong").

Every reader of a number the user types (``NAME=VALUE`` lists, targets ``D=0.1%``, priors
``D=17±30%``, a band ``LOW:HIGH``, a stand-time cap) and the setup JSON's numbers: a valid
value, however spelled (exponent forms, a sign, padding, another script's digits), reads
as the number its clean spelling gives; anything else (nan, inf, 1e999, zero or negative
where the rule wants positive, garbage, a name given twice) raises
:class:`~vibid.errors.VibidError` in one line, never another exception and never a
different number. The oracle of "valid" is written here from the rule, not from the
reader: ``float`` of the clean spelling, and the catalogue's rule in words.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, event, example, given, settings
from hypothesis import strategies as st

from vibid.cli import main
from vibid.cli.options import check_values, parse_number, parse_values
from vibid.cli.plan import parse_band
from vibid.errors import VibidError
from vibid.parameters import catalogue, specimen_scale
from vibid.planner.prior import (
    NormalPrior,
    Target,
    check_stand_time_cap,
    parse_prior,
    parse_targets,
)
from vibid.setup_model import SetupError, example_setup, parse_setup

PROPERTIES = settings(
    deadline=None,
    derandomize=True,
    database=None,
    max_examples=120,
    suppress_health_check=[HealthCheck.too_slow],
)
CLI = settings(PROPERTIES, max_examples=20)
NAMES = ("D", "nu", "beta")
STRIP = str(Path(__file__).parent.parent / "examples" / "strip_setup.json")

# -- numbers and their spellings ------------------------------------------------------------
finite = st.floats(allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=5e-324, allow_infinity=False)
#: digits of other scripts that Python reads as the same number (category Nd)
_SCRIPTS = (0xFF10, 0x0660, 0x0966)


def _digits(text: str, zero: int) -> str:
    return "".join(chr(zero + int(c)) if c.isascii() and c.isdigit() else c for c in text)


@st.composite
def spelled(draw, x: float, *, padded: bool = True) -> str:
    """``x`` written in one of the ways a person (or a script) writes it: ``repr``, 17
    significant digits, exponent forms, an explicit ``+``, leading zeros, another
    script's digits, surrounding spaces."""
    forms = [repr(x), f"{x:.17g}", f"{x:.17e}", f"{x:.17E}"]
    if x >= 0 and not math.copysign(1, x) < 0:
        forms += ["+" + repr(x), "00" + repr(x)]
    if x == int(x) and abs(x) < 1e300:
        forms.append(str(int(x)))
    text = draw(st.sampled_from(forms))
    if draw(st.booleans()):
        text = _digits(text, draw(st.sampled_from(_SCRIPTS)))
    if padded and draw(st.booleans()):
        text = f" {text}  "
    return text


NOT_NUMBERS = [
    "nan",
    "NaN",
    "-nan",
    "inf",
    "-inf",
    "Infinity",
    "1e999",
    "-1e999",
    "1e400",
    "",
    " ",
    "1,5",
    "0x10",
    "1e",
    "e5",
    ".",
    "--1",
    "1..2",
    "½",
    "²",
    "5 5",
    "٫5",
    "1%",
    "\u00a0",
    "one",
    "D",
    "5\n6",
    "\x00",
]
#: text that is mostly not a number, sometimes one
anything = st.one_of(
    st.sampled_from(NOT_NUMBERS), st.text(max_size=12), finite.flatmap(lambda x: spelled(x))
)


def clean(text: str) -> float | None:
    """What a clean spelling of ``text`` is: the finite number Python reads, or None."""
    try:
        x = float(text)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def one_line(exc: BaseException) -> str:
    text = str(exc)
    assert text and "\n" not in text and "\r" not in text, repr(text)
    return text


# -- parse_number, parse_values ---------------------------------------------------------------
@PROPERTIES
@given(finite.flatmap(lambda x: st.tuples(st.just(x), spelled(x))))
def test_a_number_however_spelled_reads_as_its_clean_spelling(pair):
    x, text = pair
    assert parse_number(text, "--x") == x == parse_number(repr(x), "--x")


@PROPERTIES
@given(anything)
@example("1e999")
@example("nan")
@example("-inf")
def test_anything_else_is_a_one_line_error_never_another_value(text):
    want = clean(text)
    try:
        got = parse_number(text, "--x")
    except VibidError as exc:
        assert want is None, (text, exc)
        assert one_line(exc).startswith("--x must be a")
        return
    assert want is not None and got == want and math.isfinite(got)


names = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,6}", fullmatch=True)


@PROPERTIES
@given(
    st.dictionaries(names, finite, min_size=1, max_size=5).flatmap(
        lambda d: st.tuples(st.just(d), st.tuples(*[spelled(x) for x in d.values()]))
    )
)
def test_name_value_lists_read_every_value_as_given(case):
    values, texts = case
    items = [f"{n}={t}" for n, t in zip(values, texts)]
    assert parse_values(items, "--params") == values


@PROPERTIES
@given(st.dictionaries(names, finite, min_size=1, max_size=4), st.data())
def test_a_name_given_twice_is_refused_never_the_last_silently(values, data):
    items = [f"{n}={x!r}" for n, x in values.items()]
    again = data.draw(st.sampled_from(sorted(values)))
    items.insert(data.draw(st.integers(0, len(items))), f"{again}={data.draw(finite)!r}")
    with pytest.raises(VibidError) as info:
        parse_values(items, "--params")
    assert one_line(info.value) == f"--params: {again} is given twice"


NAME_GRAMMAR = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # ASCII letters, digits, underscores


@PROPERTIES
@given(
    st.lists(
        st.one_of(
            st.text(max_size=10),
            st.tuples(names, anything).map("=".join),
            st.tuples(names, finite.map(repr)).map("=".join),
        ),
        min_size=1,
        max_size=3,
    )
)
def test_any_name_value_list_reads_whole_or_is_a_one_line_error(items):
    parts = [i.partition("=") for i in items]
    valid = all(
        s and NAME_GRAMMAR.fullmatch(n) and clean(v) is not None for n, s, v in parts
    ) and len({n for n, _, _ in parts}) == len(parts)
    event("valid" if valid else "refused")
    try:
        got = parse_values(items, "--params")
    except VibidError as exc:
        assert not valid, (items, exc)
        assert one_line(exc).startswith("--params: ")
        return
    assert valid and got == {n: clean(v) for n, _, v in parts}


# -- the catalogue's rule of a value ------------------------------------------------------------
def allowed(q, x) -> bool:
    """The catalogue's rules in words: finite (or the term's null), and positive, not
    negative or inside the open interval as the parameter's rule says."""
    if x == q.null:
        return True
    if not math.isfinite(x):
        return False
    if q.rule == "positive":
        return x > 0
    if q.rule == "non-negative":
        return x >= 0
    if isinstance(q.rule, tuple):
        return q.rule[1] < x < q.rule[2]
    return True


@PROPERTIES
@given(
    st.sampled_from(sorted(catalogue())),
    st.one_of(
        st.floats(),
        st.sampled_from([0.0, -0.0, -1.0, 0.5, 1e-300, -1e-300, math.inf, -math.inf, math.nan]),
    ),
)
def test_a_value_is_refused_exactly_when_its_parameters_rule_says_so(name, x):
    q = catalogue()[name]
    problem = q.value_problem(x)
    assert (problem is None) == allowed(q, x), (name, x, problem)
    if problem is not None:
        assert "\n" not in problem and problem.startswith(name)


@PROPERTIES
@given(st.floats(min_value=0.0, max_value=1.0))
def test_an_added_mass_may_not_outweigh_the_specimen(mass_kg):
    scale = specimen_scale(example_setup())  # steel 100 x 20 x 1 mm: 15.84 g
    problem = catalogue()["mass_kg"].value_problem(mass_kg, scale)
    assert (problem is None) == (mass_kg <= 7920.0 * 0.1 * 0.02 * 0.001)
    if problem is not None:
        with pytest.raises(VibidError, match="^--effect added_mass: mass_kg .* outweighs"):
            check_values({"mass_kg": mass_kg}, "--effect added_mass", scale)


# -- targets and priors ---------------------------------------------------------------------------
sep = st.sampled_from(["±", "+-", "+/-", " ± ", " +- "])


@st.composite
def target(draw, value=positive):
    name, x, pct = draw(st.sampled_from(NAMES)), draw(value), draw(st.booleans())
    eq = draw(st.sampled_from(["=", " = "]))
    return f"{name}{eq}{draw(spelled(x, padded=False))}{'%' if pct else ''}", Target(
        name, x / 100 if pct else x, pct
    )


@PROPERTIES
@given(st.lists(target(), min_size=1, max_size=3, unique_by=lambda t: t[1].name))
def test_targets_read_as_their_clean_spelling(pairs):
    texts = [t for t, _ in pairs]
    assert parse_targets(texts, NAMES) == tuple(want for _, want in pairs)


@PROPERTIES
@given(
    st.one_of(
        target(st.floats(max_value=0.0, allow_infinity=False)),
        st.tuples(
            st.sampled_from(NAMES),
            st.sampled_from(["1e999", "nan", "inf", "-1e999", "", "x", "1e-999"]),
            st.sampled_from(["", "%"]),
        ).map(lambda t: (f"{t[0]}={t[1]}{t[2]}", None)),
    )
)
def test_a_target_that_is_not_a_positive_finite_number_is_a_one_line_error(case):
    text, _ = case
    with pytest.raises(VibidError) as info:
        parse_targets([text], NAMES)
    assert one_line(info.value).startswith("--target")


@PROPERTIES
@given(st.lists(anything, min_size=1, max_size=3))
def test_any_target_reads_whole_or_is_a_one_line_error(texts):
    try:
        got = parse_targets(texts, NAMES)
    except VibidError as exc:
        assert one_line(exc).startswith("--target")
        return
    assert all(math.isfinite(t.value) and t.value > 0 and t.name in NAMES for t in got)


@st.composite
def prior(draw):
    name, mean, std, pct = (
        draw(st.sampled_from(NAMES)),
        draw(finite),
        draw(positive),
        draw(st.booleans()),
    )
    text = (
        f"{name}={draw(spelled(mean, padded=False))}{draw(sep)}"
        f"{draw(spelled(std, padded=False))}{'%' if pct else ''}"
    )
    s = std / 100 * abs(mean) if pct else std
    return text, (NormalPrior(name, mean, s) if s > 0 and math.isfinite(s) else None)


@PROPERTIES
@given(st.lists(prior(), min_size=1, max_size=3, unique_by=lambda p: p[0].split("=")[0]))
def test_priors_read_as_their_clean_spelling_or_say_why_not(pairs):
    texts = [t for t, _ in pairs]
    if all(want is not None for _, want in pairs):
        assert parse_prior(texts, NAMES) == {w.name: w for _, w in pairs}
        return
    with pytest.raises(VibidError) as info:  # a relative std of zero or beyond the floats
        parse_prior(texts, NAMES)
    assert "standard deviation must be a positive finite number" in one_line(info.value)


@PROPERTIES
@given(
    st.sampled_from(NAMES), st.sampled_from(["1e999", "nan", "inf", "-1e999"]), st.booleans(), sep
)
def test_a_prior_of_no_finite_number_is_a_one_line_error(name, bad, where, s):
    text = f"{name}={bad}{s}5" if where else f"{name}=5{s}{bad}"
    with pytest.raises(VibidError) as info:
        parse_prior([text], NAMES)
    assert one_line(info.value).startswith("--prior")


@PROPERTIES
@given(
    st.sampled_from(NAMES),
    st.lists(st.sampled_from(["17±3", "17+-30%", "0.3+/-0.05"]), min_size=2, max_size=3),
)
def test_a_prior_or_target_given_twice_is_refused(name, specs):
    with pytest.raises(VibidError, match=f"^--prior: {name} is given twice$"):
        parse_prior([f"{name}={s}" for s in specs], NAMES)
    with pytest.raises(VibidError, match=f"^--target: {name} is given twice$"):
        parse_targets([f"{name}=1%", f"{name}=2%"], NAMES)


# -- a band, a cap --------------------------------------------------------------------------------
@PROPERTIES
@given(
    finite.flatmap(lambda lo: st.tuples(st.just(lo), spelled(lo))),
    finite.flatmap(lambda hi: st.tuples(st.just(hi), spelled(hi))),
)
def test_a_band_reads_as_its_clean_spelling(lo, hi):
    assert parse_band(f"{lo[1]}:{hi[1]}") == (lo[0], hi[0])


@PROPERTIES
@given(anything, anything)
def test_any_band_reads_whole_or_is_a_one_line_error(lo, hi):
    text = f"{lo}:{hi}"
    low, _, high = text.partition(":")
    event("valid" if clean(low) is not None and clean(high) is not None else "refused")
    try:
        got = parse_band(text)
    except VibidError as exc:
        assert clean(low) is None or clean(high) is None, (text, exc)
        assert one_line(exc).startswith("--band ")
        return
    assert got == (clean(low), clean(high))


@PROPERTIES
@given(st.one_of(st.floats(), st.integers(-10, 10)))
def test_a_stand_time_cap_is_a_positive_finite_number_of_seconds(seconds):
    if math.isfinite(seconds) and seconds > 0:
        check_stand_time_cap(seconds)
        return
    with pytest.raises(VibidError) as info:
        check_stand_time_cap(seconds)
    assert one_line(info.value).endswith("must be a positive number of seconds")


# -- the setup JSON's numbers ---------------------------------------------------------------------
#: Numeric fields of the setup document, by their path in it.
FIELDS = [
    ("specimen", "length_m"),
    ("specimen", "thickness_m"),
    ("specimen", "density_kg_m3"),
    ("sensors", "base", "sensitivity_mV_per_g"),
    ("sensors", "response", "mass_kg"),
    ("sensors", "response", "x_m"),
    ("daq", "sample_rate_hz"),
    ("excitation", "settle_s"),
    ("identification", "bounds", "D", 0),
    ("identification", "bounds", "nu", 1),
]
TOKEN = "__VALUE__"


def setup_text(path, raw: str) -> str:
    """The example setup as JSON text with the field at ``path`` written as ``raw``."""
    doc = example_setup().to_dict()
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = TOKEN
    return json.dumps(doc).replace(json.dumps(TOKEN), raw)


def read(text: str):
    """``("ok", setup)`` or ``("error", message)``: what the reader makes of ``text``."""
    try:
        return "ok", parse_setup(text)
    except SetupError as exc:
        return "error", one_line(exc)


def field_of(setup, path):
    node = setup.to_dict()
    for key in path:
        node = node[key]
    return node


@st.composite
def json_spelled(draw, x: float) -> str:
    """``x`` as JSON writes a number: ``json.dumps``, exponent forms, an integer."""
    forms = [json.dumps(x), f"{x:.17e}", f"{x:.17E}", f"{x:.17g}"]
    if x == int(x) and abs(x) < 1e300:
        forms.append(str(int(x)))
    return draw(st.sampled_from([f for f in forms if "inf" not in f and "nan" not in f]))


@PROPERTIES
@given(
    st.sampled_from(FIELDS),
    st.floats(min_value=-1e6, max_value=1e6).flatmap(
        lambda x: st.tuples(st.just(x), json_spelled(x))
    ),
)
def test_a_setup_number_reads_as_its_clean_spelling_or_is_refused_the_same(path, pair):
    x, raw = pair
    got, clean_one = read(setup_text(path, raw)), read(setup_text(path, json.dumps(x)))
    assert got[0] == clean_one[0]
    if got[0] == "ok":
        assert field_of(got[1], path) == x == field_of(clean_one[1], path)
    else:
        assert got[1] == clean_one[1]


@PROPERTIES
@given(
    st.sampled_from(FIELDS),
    st.sampled_from(
        [
            "NaN",
            "Infinity",
            "-Infinity",
            "1e999",
            "-1e999",
            '"5"',
            "true",
            "null",
            "[]",
            "{}",
            "[1, 2]",
            '"nan"',
            "0",
            "-1",
            '""',
        ]
    ),
)
def test_a_setup_value_that_is_no_possible_number_is_a_one_line_error(path, raw):
    kind, what = read(setup_text(path, raw))
    if raw == "0" and path[-1] in ("mass_kg", "settle_s"):
        assert kind == "ok"  # zero: no sensor mass, no settling
        return
    assert kind == "error", (path, raw)
    assert what.startswith("setup"), what


@pytest.mark.parametrize("digits", [400, 5000])
def test_a_setup_integer_beyond_the_floats_is_a_one_line_error(digits):
    kind, what = read(setup_text(("specimen", "length_m"), "1" * digits))
    assert kind == "error" and what.startswith("setup.specimen.length_m")


def test_a_setup_bounds_name_with_a_line_break_is_a_one_line_error():
    doc = example_setup().to_dict()
    doc["identification"]["bounds"]["D\nnu"] = [1.0, 2.0]
    with pytest.raises(SetupError) as info:
        parse_setup(doc)
    one_line(info.value)


# -- the command line: rc and one line on stderr ------------------------------------------------
@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """``vibid simulate`` with the simulation replaced by recording the truth it is given."""
    import vibid.hardware_mocks.simulated_session
    import vibid.identify.effects  # noqa: F401 - imported before stderr is captured

    truths = []
    mp = pytest.MonkeyPatch()
    mp.setattr(
        vibid.hardware_mocks.simulated_session,
        "simulate_session",
        lambda out, setup, truth, **kw: truths.append(dict(truth)),
    )
    yield tmp_path_factory.mktemp("simulate"), truths
    mp.undo()


@CLI
@given(
    st.one_of(
        st.sampled_from(NOT_NUMBERS),
        finite.flatmap(lambda x: spelled(x)),
        st.text(
            alphabet=st.characters(blacklist_characters=",", blacklist_categories=("Cs",)),
            max_size=8,
        ),
    )
)
def test_simulate_takes_a_delay_as_its_number_or_refuses_it_in_one_line(simulated, text):
    folder, truths = simulated
    assume("," not in text)
    out = folder / "S.h5"
    argv = ["simulate", STRIP, "--out", str(out), f"--effect=channel_delay:tau_s={text}"]
    err = _stderr_of(argv)
    want = clean(text)
    event("refused" if want is None else "taken")
    if want is None:
        assert err.rc == 1 and err.lines == 1, err
        assert err.text.startswith("vibid simulate: error: --effect channel_delay: tau_s"), err
    else:
        assert err.rc == 0 and truths[-1]["tau_s"] == want, err


def _argparse_float(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


@CLI
@given(
    st.one_of(st.sampled_from(NOT_NUMBERS), st.floats(max_value=0.0).map(repr), st.text(max_size=6))
)
def test_plan_refuses_a_cap_that_is_no_positive_number_in_one_line(tmp_path_factory, text):
    import vibid.planner

    x = _argparse_float(text)
    assume(x is None or not (math.isfinite(x) and x > 0))
    out = tmp_path_factory.getbasetemp() / "p.json"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(vibid.planner, "plan_test", lambda *a, **k: pytest.fail("planning started"))
        err = _stderr_of(
            ["plan", STRIP, "--target", "D=1%", f"--max-stand-time={text}", "--out", str(out)]
        )
    if x is None:
        assert err.rc == 2, err  # argparse's usage error: not a number at all
        return
    assert err.rc == 1 and err.lines == 1, err
    assert err.text.startswith("vibid plan: error: --max-stand-time "), err


class _Run:
    def __init__(self, rc, text):
        self.rc, self.text = rc, text
        self.lines = text.count("\n")

    def __repr__(self):
        return f"rc {self.rc}: {self.text!r}"


def _stderr_of(argv) -> _Run:
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
    text = err.getvalue()
    assert "Traceback" not in text, text
    return _Run(rc, text)
