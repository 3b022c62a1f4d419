"""Property-based tests of every parser of user input: trees in bracket notation,
tableau entries, expressions, spec and tableau documents, the option readers and the JSON output.

Whatever the text, a parser returns a value or raises InputError (never another exception), and
where a value can be written back (trees, tableau entries, expressions, tableau files) reading what
it writes gives the same value. Examples are derandomized: every run checks the same inputs.
"""

from __future__ import annotations

import json
import math
import tempfile
from fractions import Fraction
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rkhp.base import bounds, documents
from rkhp.base.errors import InputError
from rkhp.base.expressions import CONSTANTS, FUNCTIONS, parse_expression
from rkhp.tableaux.files import load_file, save_tableau
from rkhp.tableaux.tableau import Tableau, entry_text, parse_entry
from rkhp.trees.rooted import Tree, format_tree, parse_tree, trees_up_to

FAST = settings(max_examples=300, deadline=None, derandomize=True)
SLOW = settings(max_examples=40, deadline=None, derandomize=True)


def refused_or(parse, *args, **kwargs):
    """parse(*args) or None when it raises InputError (any other exception fails the test)."""
    try:
        return parse(*args, **kwargs)
    except InputError as exc:
        assert str(exc) and "\n" not in str(exc)
        return None


# ----------------------------------------------------------------------------- trees


def tree_texts(max_leaves: int = 12):
    """Bracket texts of random trees, children in random order, with random spaces."""
    node = st.recursive(st.just("b"), lambda kids: st.lists(kids, min_size=1, max_size=4).map(
        lambda ks: "b[" + ",".join(ks) + "]"), max_leaves=max_leaves)
    return node


@FAST
@given(st.text(alphabet="b[], {}\\forestx", max_size=60))
def test_parse_tree_never_crashes_on_bracket_soup(text):
    t = refused_or(parse_tree, text)
    assert t is None or isinstance(t, Tree)


@FAST
@given(st.text(max_size=40))
def test_parse_tree_never_crashes_on_any_text(text):
    refused_or(parse_tree, text)


@FAST
@given(tree_texts())
def test_parse_tree_round_trip(text):
    t = parse_tree(text)
    assert parse_tree(format_tree(t)) == t
    assert parse_tree(" " + format_tree(t).replace(",", " , ") + " ") == t
    assert parse_tree("\\forest{" + format_tree(t) + "}") == t
    assert t.order == text.count("b")


def test_parse_tree_round_trip_every_tree_to_order_8():
    for t in trees_up_to(8):
        u = parse_tree(str(t))
        assert u == t and (u.sigma, u.gamma) == (t.sigma, t.gamma)


@pytest.mark.parametrize("depth", [252, 253, 254, 1000, 100_000])
def test_parse_tree_depth_limit(depth):
    text = "b[" * depth + "b" + "]" * depth
    t = refused_or(parse_tree, text)
    assert (t is not None) == (depth <= 253)
    if t is not None:
        assert t.order == depth + 1 and parse_tree(str(t)) == t


# ----------------------------------------------------------------------------- tableau entries


@FAST
@given(st.text(max_size=60))
def test_parse_entry_never_crashes_on_any_text(text):
    refused_or(parse_entry, text)


@FAST
@given(st.text(alphabet="0123456789+-*/^().eE sqrt", max_size=40))
def test_parse_entry_never_crashes_on_number_soup(text):
    refused_or(parse_entry, text)


@FAST
@given(st.one_of(st.booleans(), st.none(), st.lists(st.integers()), st.dictionaries(st.text(), st.integers()),
                 st.floats(allow_nan=True, allow_infinity=True).filter(lambda x: not math.isfinite(x))))
def test_parse_entry_refuses_what_is_not_a_number(value):
    assert refused_or(parse_entry, value) is None


@FAST
@given(st.fractions(max_denominator=10**30))
def test_parse_entry_round_trip_fractions(q):
    x = parse_entry(q)
    assert parse_entry(entry_text(x)) == q
    assert parse_entry(f"{q.numerator}/{q.denominator}") == q


@FAST
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_parse_entry_round_trip_floats(v):
    x = parse_entry(v)
    y = parse_entry(entry_text(x))
    assert float(y) == v and entry_text(y) == entry_text(x)


@FAST
@given(st.integers(min_value=1, max_value=50), st.integers(min_value=-10, max_value=10),
       st.integers(min_value=1, max_value=10))
def test_parse_entry_round_trip_radicals(d, p, q):
    """(p + sqrt(d)) / q: exact, and read back from its own text."""
    x = parse_entry(f"({p} + sqrt({d}))/{q}")
    assert parse_entry(entry_text(x)) == x
    assert abs(float(x) - (p + math.sqrt(d)) / q) < 1e-12 * (1 + abs(p) + math.sqrt(d))


# ----------------------------------------------------------------------------- expressions

NAMES = ("x1", "x2", "x3")


def expressions():
    """Texts in the grammar of rkhp.base.expressions (random, possibly not finite: 1/0)."""
    atom = st.one_of(st.sampled_from(NAMES + tuple(CONSTANTS)), st.integers(0, 10**6).map(str),
                     st.decimals(min_value=0, max_value=1000, allow_nan=False, places=3).map(str))

    def combine(sub):
        return st.one_of(
            st.tuples(sub, st.sampled_from(["+", "-", "*", "/"]), sub).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
            st.tuples(sub, st.integers(-4, 4)).map(lambda t: f"({t[0]})^{t[1]}"),
            st.tuples(st.sampled_from(tuple(FUNCTIONS)), sub).map(lambda t: f"{t[0]}({t[1]})"),
            sub.map(lambda e: f"-{e}"))

    return st.recursive(atom, combine, max_leaves=10)


@FAST
@given(st.text(max_size=60))
def test_parse_expression_never_crashes_on_any_text(text):
    refused_or(parse_expression, text, NAMES)


@FAST
@given(st.text(alphabet="x123+-*/^()._ eEpi,[]{}:'\"lambdaforin__import__ ", max_size=60))
def test_parse_expression_never_crashes_on_python_soup(text):
    refused_or(parse_expression, text, NAMES)


@FAST
@given(expressions())
def test_parse_expression_round_trip(text):
    """An expression of the grammar reads, and sympy's text of it reads back as the same expression."""
    e = refused_or(parse_expression, text, NAMES)
    if e is not None:
        back = parse_expression(str(e), NAMES)
        assert back == e or _same_values(back, e)


def _same_values(a, b) -> bool:
    """Equal values at a few points where both are finite (sympy may distribute 1000*(x1 + x2))."""
    import sympy

    symbols = [sympy.Symbol(n, real=True) for n in NAMES]
    fa, fb = (sympy.lambdify(symbols, e, "mpmath") for e in (a, b))
    import mpmath

    for point in ((0.3, 0.7, 1.9), (1.1, -0.4, 0.6), (2.5, 1.5, -3.0)):
        with mpmath.workdps(40):
            try:
                va, vb = complex(fa(*point)), complex(fb(*point))
            except (ZeroDivisionError, ValueError, OverflowError):
                continue
        if abs(va - vb) > 1e-25 * max(1.0, abs(va)):
            return False
    return True


@SLOW
@given(st.integers(2, 6), st.integers(0, 3))
def test_parse_expression_bounds_before_work(levels, extra):
    """Towers of powers and long literals are refused at once (no huge number is ever built)."""
    tower = "^".join(["10"] * levels)
    value = refused_or(parse_expression, tower)
    assert (value is not None) == (levels == 2)
    assert refused_or(parse_expression, "1e-" + "9" * (extra + 9) + " + x1", NAMES) is None


# ----------------------------------------------------------------------------- documents

JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False, allow_infinity=False),
              st.text(max_size=20)),
    lambda sub: st.one_of(st.lists(sub, max_size=4), st.dictionaries(st.text(max_size=8), sub, max_size=4)),
    max_leaves=20)


def depth(value) -> int:
    if isinstance(value, list | dict):
        items = value.values() if isinstance(value, dict) else value
        return 1 + max((depth(v) for v in items), default=0)
    return 0


@FAST
@given(JSON_VALUES)
def test_nesting_depth_of_json(value):
    text = json.dumps(value)
    assert documents.nesting_depth(text, toml=False) == depth(value)


@FAST
@given(st.text(max_size=80))
def test_parse_document_never_crashes(text):
    for kind in ("json", "toml"):
        data = refused_or(documents.parse_document, text, "doc", kind)
        assert data is None or isinstance(data, dict)


@FAST
@given(st.text(alphabet='{}[]":,0123456789.eE-+ \nabtrufalsnNIy=#\'', max_size=80))
def test_parse_document_never_crashes_on_syntax_soup(text):
    for kind in ("json", "toml"):
        refused_or(documents.parse_document, text, "doc", kind)


@FAST
@given(JSON_VALUES)
def test_parse_document_of_json_data(value):
    data = refused_or(documents.parse_document, json.dumps(value), "doc", "json")
    if isinstance(value, dict) and depth(value) <= bounds.MAX_NESTING and not _has_big_int(value):
        assert data == value
    else:
        assert data is None


def _has_big_int(value) -> bool:
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return len(str(abs(value))) > 30
    if isinstance(value, list | dict):
        return any(_has_big_int(v) for v in (value.values() if isinstance(value, dict) else value))
    return False


SPEC = {"family": "constant", "poisson": [[0, 1], [-1, 0]], "hamiltonian": "x2^2/2 - cos(x1)", "x0": [1.5, 0.0]}


@SLOW
@given(st.dictionaries(st.sampled_from(["name", "family", "poisson", "lambda", "structure_constants",
                                        "hamiltonian", "x0", "t_final", "casimirs", "other"]),
                       JSON_VALUES, max_size=4))
def test_load_spec_never_crashes(changes):
    """A valid spec with random keys replaced: a system or InputError."""
    from rkhp.systems.spec import load_spec

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.json"
        path.write_text(json.dumps({**SPEC, **changes}), encoding="utf-8")
        system = refused_or(load_spec, path)
    assert system is None or system.dim == len(system.x0)


@SLOW
@given(st.text(max_size=200))
def test_load_spec_of_any_toml_text(text):
    from rkhp.systems.spec import load_spec

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.toml"
        path.write_text(text, encoding="utf-8")
        refused_or(load_spec, path)


@SLOW
@given(st.integers(1, 5).flatmap(lambda s: st.tuples(
    st.lists(st.lists(st.fractions(max_denominator=1000), min_size=s, max_size=s), min_size=s, max_size=s),
    st.lists(st.fractions(max_denominator=1000), min_size=s, max_size=s))), st.sampled_from([".toml", ".json"]))
def test_tableau_file_round_trip(Ab, suffix):
    A, b = Ab
    tab = Tableau.from_arrays(A, b, name="random")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / ("t" + suffix)
        save_tableau(tab, path)
        back = load_file(path)
    assert back.A == tab.A and back.b == tab.b and back.name == "random"


@SLOW
@given(st.dictionaries(st.sampled_from(["A", "b", "c", "name", "order", "aliases", "other"]), JSON_VALUES,
                       max_size=4), st.sampled_from([".toml", ".json"]))
def test_load_tableau_file_never_crashes(changes, suffix):
    import tomli_w

    doc = {"A": [["0", "0"], ["1", "0"]], "b": ["1/2", "1/2"], **changes}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / ("t" + suffix)
        try:
            text = json.dumps(doc) if suffix == ".json" else tomli_w.dumps(doc)
        except (TypeError, ValueError):  # TOML cannot write null: the JSON file covers it
            return
        path.write_text(text, encoding="utf-8")
        refused_or(load_file, path)


# ----------------------------------------------------------------------------- options and JSON output


@FAST
@given(st.text(max_size=40))
def test_option_readers_never_crash(text):
    for read in (bounds.parse_int, bounds.parse_float):
        refused_or(read, text, "--x")
    refused_or(bounds.parse_list, text, "--x", lambda t: bounds.parse_float(t, "--x"))


@FAST
@given(st.floats(), st.floats())
def test_step_plan_never_crashes(t_final, h):
    plan = refused_or(bounds.step_plan, t_final, None, h)
    if plan is not None:
        n, step = plan
        assert n >= 1 and abs(n * step - t_final) <= 1e-8 * abs(t_final)


@FAST
@given(st.one_of(st.floats(), st.integers(), st.fractions(), st.text(max_size=5), st.none(), st.booleans()),
       st.one_of(st.integers(), st.floats(), st.text(max_size=5), st.booleans()))
def test_check_step_never_crashes(h, n_steps):
    """The one step check of every integrator: h finite and non-zero (negative: backwards),
    0 <= n_steps <= MAX_STEPS, or InputError."""
    checked = refused_or(bounds.check_step, h, n_steps)
    if checked is not None:
        assert isinstance(h, int | float | Fraction) and not isinstance(h, bool)
        assert isinstance(n_steps, int) and not isinstance(n_steps, bool)
        assert checked == (float(h), n_steps) and checked[0] != 0 and 0 <= n_steps <= bounds.MAX_STEPS


@FAST
@given(st.recursive(st.one_of(st.floats(), st.integers(), st.text(max_size=5), st.none()),
                    lambda sub: st.one_of(st.lists(sub, max_size=4), st.dictionaries(st.text(max_size=5), sub,
                                                                                       max_size=4)),
                    max_leaves=20))
def test_json_output_is_valid_json(value):
    from rkhp_cli.options import NON_FINITE, json_text

    def strict(name):
        raise AssertionError(f"bare {name} in the output")

    back = json.loads(json_text(value), parse_constant=strict)

    def same(a, b):
        if isinstance(a, float) and not math.isfinite(a):
            return b in NON_FINITE.values() and (math.isnan(float(b)) if math.isnan(a) else float(b) == a)
        if isinstance(a, list | tuple):
            return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
        if isinstance(a, dict):
            return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
        return a == b

    assert same(value, back)


def test_fraction_entries_are_exact():
    assert parse_entry("0.1") == Fraction(1, 10)
    assert parse_entry("1e-20") == Fraction(1, 10**20)
