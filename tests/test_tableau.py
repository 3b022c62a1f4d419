"""Tableau values and files: exact entries, kinds, row sums, round trips, bad input."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from rkhp.base.errors import InputError
from rkhp.tableaux.files import builtin_names, load_file, load_tableau, save_tableau
from rkhp.tableaux.tableau import GivenDecimal, Tableau, parse_entry

PUBLISHED = Path(__file__).resolve().parent / "data" / "published"

# The built-in tableaux that must ship: the paper's, the classical explicit and implicit ones and
# Feagin's; Curtis's and Ono's last.
REQUIRED = ["euler", "paper-two-stage", "paper-three-stage", "paper-implicit", "midpoint", "heun",
            "ralston", "kutta3", "ssprk3", "rk4", "rk38", "butcher5", "dopri5", "dop853",
            "gauss2", "gauss3", "radau-iia3", "lobatto-iiia3", "lobatto-iiic3", "feagin10",
            "feagin12", "feagin14", "curtis10", "ono12"]


@pytest.mark.parametrize("text, value", [
    ("11/27", Fraction(11, 27)), ("0.25", Fraction(1, 4)), (".5859375e-2", Fraction(3, 512)),
    (3, Fraction(3)), (0.1, Fraction(1, 10)), ("-0.8", Fraction(-4, 5)),
])
def test_exact_rationals_and_short_decimals(text, value):
    x = parse_entry(text)
    assert isinstance(x, Fraction) and x == value


@pytest.mark.parametrize("text, value", [
    ("sqrt(3)/4", sympy.sqrt(3) / 4), ("-1/sqrt(3)", -sympy.sqrt(3) / 3),
    ("(6 - sqrt(6))/10", sympy.Rational(3, 5) - sympy.sqrt(6) / 10), ("2^(1/2)", sympy.sqrt(2)),
])
def test_radicals_stay_exact(text, value):
    assert sympy.simplify(parse_entry(text) - value) == 0


def test_long_decimals_keep_their_digits():
    text = "0.111111111111111111111111111111111111111111111111111111111111"
    x = parse_entry(text)
    assert isinstance(x, GivenDecimal) and x.digits == 60 and x.text == text
    assert x.as_fraction() == Fraction(text)
    assert isinstance(parse_entry(2 ** 0.5), GivenDecimal)  # 17 significant digits


@pytest.mark.parametrize("bad, message", [
    ("abc", "unknown symbol"), ("__import__('os')", "call of __import__"), ("nan", "non-finite"),
    (float("inf"), "non-finite"), ("1/0", "division by zero"), ("sqrt(-1)", "not a real"),
    (True, "expected a number"), ("(1", "cannot read"), ([1], "expected a number"),
])
def test_bad_entries(bad, message):
    with pytest.raises(InputError, match=message) as info:
        parse_entry(bad, "f.toml: A[1][1]")
    assert str(info.value).startswith("f.toml: A[1][1]")


@pytest.mark.parametrize("name, kind", [
    ("rk4", "explicit"), ("paper-implicit", "diagonally implicit"), ("gauss2", "implicit"),
    ("lobatto-iiia3", "implicit"), ("dop853", "explicit"),
])
def test_kinds(name, kind):
    assert load_tableau(name).kind == kind


def test_row_sums_and_float_views():
    t = load_tableau("paper-three-stage")
    assert t.c[0] == 0 and sympy.simplify(t.c[1] + sympy.sqrt(3) / 4) == 0 and t.c[2] == Fraction(3, 4)
    assert t.A_float.shape == (3, 3) and abs(t.c_float[1] + 3 ** 0.5 / 4) < 1e-16
    assert not t.A_float.flags.writeable
    assert t.is_exact and not t.is_rational and t.digits is None
    assert load_tableau("feagin14").digits == 60


def test_given_c_differing_from_row_sums_is_reported():
    t = Tableau.from_arrays([[0, 0], ["1/2", 0]], [0, 1], c=[0, "0.6"])
    assert t.c == (Fraction(0), Fraction(1, 2))
    assert t.c_mismatch() == [(1, pytest.approx(0.1))]
    assert load_tableau("gauss3").c_mismatch() == []
    long = "-0.11111111111111111111111111111111111"  # inexact, negative row sum
    t = Tableau.from_arrays([[0, 0], [long, "1/2"]], [0, 1], c=[0, "0.38888888888888888888888888888888889"])
    assert t.c_mismatch() == []


def test_every_listed_builtin_exists_with_a_reference():
    names = builtin_names()
    assert set(REQUIRED) <= set(names)
    for name in names:
        t = load_tableau(name)
        assert t.reference and t.name == name


@pytest.mark.parametrize("name", ["euler", "paper-two-stage", "paper-three-stage", "paper-implicit"])
def test_the_papers_methods_cite_its_section_5_2(name):
    # the paper's methods are in Section 5 ("Numerical methods"), subsection 2 ("Runge-Kutta
    # approach to Hamiltonian Poisson integrators"); 5.1 is the Taylor approach, there is no 5.3
    reference = load_tableau(name).reference
    assert "Section 5.2" in reference and "Section 5.3" not in reference


def test_aliases_and_case():
    assert load_tableau("RK4") is load_tableau("classical")
    assert load_tableau("rk1412").name == "feagin14"


@pytest.mark.parametrize("name", REQUIRED)
@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_files_round_trip(tmp_path, name, suffix):
    t = load_tableau(name)
    path = tmp_path / f"copy{suffix}"
    save_tableau(t, path)
    u = load_file(path)
    assert u == t
    path2 = tmp_path / f"again{suffix}"
    save_tableau(u, path2)
    assert path2.read_text() == path.read_text()


def _feagin_format(t: Tableau) -> str:
    """Write a tableau in Feagin's 60-digit text format (sections c, b, A; 0-based)."""
    lines = ["   THE COEFFICIENTS OF A TEST METHOD", "", "  k          c[k]"]
    lines += [f"{k}\t{float(x)!r}" for k, x in enumerate(t.c)]
    lines += ["", "  k          b[k]"]
    lines += [f"{k}\t{getattr(x, 'text', str(float(x)))}" for k, x in enumerate(t.b)]
    lines += ["", " k     j      A[k,j]"]
    lines += [f"{k} {j} {getattr(x, 'text', repr(float(x)))}" for k, row in enumerate(t.A)
              for j, x in enumerate(row) if x != 0]
    lines += ["", " The estimate of the local truncation error is ..."]
    return "\n".join(lines) + "\n"


def test_sixty_digit_text_format(tmp_path):
    t = load_tableau("feagin10")
    path = tmp_path / "rk108.txt"
    path.write_text(_feagin_format(t))
    u = load_tableau(str(path))
    assert u.A == t.A and u.b == t.b and u.c_given is not None


@pytest.mark.parametrize("fname, name", [("rk108.txt", "feagin10"), ("rk1210.txt", "feagin12"),
                                         ("rk1412.txt", "feagin14"), ("rk108curtis.txt", "curtis10"),
                                         ("rk129hiroshi.txt", "ono12")])
def test_builtins_hold_the_published_digits(fname, name):
    published = load_file(PUBLISHED / fname)
    builtin = load_tableau(name)
    assert published.A == builtin.A and published.b == builtin.b
    mismatch = published.c_mismatch()
    if fname == "rk1412.txt":  # tests/data/published/README.md: c[13] differs from its row sum by 1.6e-10
        assert [i for i, _ in mismatch] == [13] and abs(mismatch[0][1]) == pytest.approx(1.55e-10, rel=0.01)
    else:
        assert mismatch == []


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name, text, message", [
    ("square.toml", 'A = [["0", "0"], ["1"]]\nb = ["1", "0"]\n', "A is not square"),
    ("length.toml", 'A = [["0", "0"], ["1", "0"]]\nb = ["1"]\n', "b has 1 entries, A has 2 rows"),
    ("nonnum.toml", 'A = [["x"]]\nb = ["1"]\n', r"A\[1\]\[1\]: cannot read .x.: unknown symbol"),
    ("inf.toml", 'A = [[inf]]\nb = ["1"]\n', "non-finite"),
    ("syntax.toml", 'A = [[0]\nb = [1]\n', "TOML syntax error"),
    ("syntax.json", '{"A": [[0]], "b": [1],}', "JSON syntax error"),
    ("nan.json", '{"A": [[NaN]], "b": [1]}', "non-finite"),
    ("key.toml", 'A = [[0]]\nb = [1]\norders = 3\n', "unknown key 'orders'"),
    ("missing.toml", 'A = [[0]]\n', "missing key 'b'"),
    ("claim.toml", 'A = [[0]]\nb = [1]\norder = 0\n', "positive integer"),
])
def test_bad_files_name_the_file_and_the_problem(tmp_path, name, text, message):
    path = _write(tmp_path, name, text)
    with pytest.raises(InputError, match=message) as info:
        load_tableau(str(path))
    assert str(path) in str(info.value)


def test_unknown_names_suggest_close_ones():
    with pytest.raises(InputError, match=r"did you mean feagin12, feagin14\?"):
        load_tableau("feagn14")
    with pytest.raises(InputError, match="no such file"):
        load_tableau("nowhere/rk.toml")


#: names that no file can have: a component longer than a file system allows (255 bytes), and a
#: path longer than the system's limit on paths
NO_FILE_NAMES = ["x" * 300, "x" * 300 + ".toml", "/".join(["x" * 200] * 30) + ".toml"]


@pytest.mark.parametrize("name", NO_FILE_NAMES, ids=["name", "file", "path"])
def test_a_name_no_file_can_have_is_bad_input(name):
    with pytest.raises(InputError) as info:
        load_tableau(name)
    assert "\n" not in str(info.value)


def test_an_empty_name_is_refused_as_empty():
    with pytest.raises(InputError, match="empty tableau name"):
        load_tableau("")


def test_unreadable_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_tableau(str(tmp_path))  # a directory


def test_json_schema_matches_toml(tmp_path):
    doc = {"name": "mine", "A": [[0, 0], ["2/3", 0]], "b": ["1/4", 0.75], "order": 2}
    path = _write(tmp_path, "mine.json", json.dumps(doc))
    t = load_tableau(str(path))
    assert t.name == "mine" and t.claimed_order == 2 and t.b == (Fraction(1, 4), Fraction(3, 4))


_entries = st.one_of(
    st.fractions(max_denominator=10 ** 6).map(str),
    st.decimals(allow_nan=False, allow_infinity=False, places=40,
                min_value=-10, max_value=10).map(str),
    st.tuples(st.integers(-9, 9), st.sampled_from([2, 3, 5, 6, 15]), st.integers(1, 50))
      .map(lambda t: f"{t[0]}*sqrt({t[1]})/{t[2]}"),
)


@settings(max_examples=15, deadline=None)
@given(st.integers(1, 3).flatmap(lambda s: st.tuples(
    st.lists(st.lists(_entries, min_size=s, max_size=s), min_size=s, max_size=s),
    st.lists(_entries, min_size=s, max_size=s))), st.sampled_from([".toml", ".json"]))
def test_random_tableaux_round_trip(tmp_path_factory, data, suffix):
    A, b = data
    t = Tableau.from_arrays(A, b, name="random")
    path = tmp_path_factory.mktemp("rt") / f"t{suffix}"
    save_tableau(t, path)
    assert load_file(path) == t


def test_expression_entries_are_read_once_and_refusals_never_kept():
    """An expression entry read again (the compositions repeat theirs) is the same exact number;
    a refused text is refused again, naming the new place."""
    from rkhp.tableaux.tableau import parse_entry

    first = parse_entry("1/(2 - 2^(1/3))", "a")
    again = parse_entry(" 1/(2 - 2^(1/3)) ", "b")
    assert sympy.simplify(first - 1 / (2 - sympy.cbrt(2))) == 0 and again == first
    for where in ("first place", "second place"):
        with pytest.raises(InputError, match=f"^{where}: not a real algebraic number"):
            parse_entry("log(2)", where)
