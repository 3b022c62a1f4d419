"""The one JSON encoder (rkhp.base.json_form) and the key lists of docs/json.md.

Every result type's keys, as the encoder writes them, are the keys docs/json.md lists for it: the
page's brace lists (``{"system", "method", "plan": {"method", ...}}``) are read here, each result
type found by the text before its list and the path of keys inside it. A class of rkhp that
declares ``json_keys`` and is missing from :data:`DOCUMENTED` fails the test: a new result type is
documented with its keys.
"""

from __future__ import annotations

import ast
import json
from fractions import Fraction
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

import rkhp
from rkhp.base.json_form import json_form, keys_of
from rkhp.ivp.poincare import Section
from rkhp.ivp.solve import Candidate, Plan, SolveResult
from rkhp.ivp.tolerance import Pilot, ToleranceStep
from rkhp.search.certificates import Certificate, CertificateCheck
from rkhp.search.driver import NextOrderEvidence, Optimisation, ProofSummary, SearchResult
from rkhp.search.optimise import KnownMethod
from rkhp.search.prove import ModularBasis, Proof
from rkhp.studies.bench import AbsentPeer, BenchCurve, BenchPoint, BenchStudy, Cheapest
from rkhp.studies.converge import ConvergenceRow, ConvergenceStudy, MethodConvergence
from rkhp.studies.longtime import Growth
from rkhp.studies.stress import (
    LongRun,
    LongRunResult,
    ModifiedWindows,
    NearSingularRun,
    RoundOffResult,
    SingularResult,
    StressStudy,
    SweepResult,
    SweepRow,
)
from rkhp.systems.check import BirealisationCheck
from rkhp.tableaux.compositions import CompositionOrder, CompositionVerification
from rkhp.tableaux.verification import ClaimedOrders, OrderBound, StageDifference, Verification
from rkhp.trees.relations import ConditionRow, OrderRelations, RelationData, RelationRow
from rkhp.trees.rooted import parse_tree

DOCS = Path(__file__).resolve().parent.parent / "docs"
JSON_PAGE = (DOCS / "json.md").read_text()

VERIFY = "- `rkhp verify`:"
SEARCH = "## `rkhp search`"
SOLVE = "`rkhp.json_form(rkhp.solve(...))`:"
CONVERGE = "- `rkhp converge`:"
BENCH = "- `rkhp bench`:"
STRESS = "- `rkhp stress`:"
RELATIONS = "The format of `--format json`"
COMPOSITION = "- `rkhp verify COMPOSITION`:"

#: result type -> (the text before its brace list on docs/json.md, the keys leading into the list,
#: keys the page lists that the type does not write, added around it)
DOCUMENTED = {
    Verification: (VERIFY, (), ()),
    ClaimedOrders: (VERIFY, ("claimed",), ()),
    StageDifference: (VERIFY, ("c_mismatch",), ()),
    OrderBound: ("Every order (`order`, `degenerate_order`, `symmetric_order` and the values of `orders`)", (), ()),
    CompositionVerification: (COMPOSITION, (), ()),
    CompositionOrder: (COMPOSITION, ("own",), ()),
    SearchResult: (SEARCH, (), ()),
    ProofSummary: (SEARCH, ("proof",), ()),
    NextOrderEvidence: (SEARCH, ("evidence_next_order",), ()),
    Optimisation: (SEARCH, ("optimization",), ()),
    KnownMethod: (SEARCH, ("optimization", "known"), ()),
    # the search writes the order a proof was about before the proof's own keys
    Proof: (SEARCH, ("proof_detail",), ("order",)),
    ModularBasis: (SEARCH, ("proof_detail", "modular"), ()),
    CertificateCheck: (SEARCH, ("proof_detail", "certificate"), ()),
    Certificate: ("which `--certificate FILE` writes as", (), ()),
    BirealisationCheck: ("`rkhp check`:", (), ()),
    Pilot: ("With `--tol`,", ("pilot",), ()),
    Candidate: ("With `--tol`,", ("candidates",), ()),
    Section: ("`rkhp poincare`:", (), ()),
    SolveResult: (SOLVE, (), ()),
    Plan: (SOLVE, ("plan",), ()),
    ToleranceStep: (SOLVE, ("plan", "choice"), ()),
    ConvergenceStudy: (CONVERGE, (), ()),
    MethodConvergence: (CONVERGE, ("methods",), ()),
    ConvergenceRow: (CONVERGE, ("methods", "rows"), ()),
    BenchStudy: (BENCH, (), ()),
    BenchCurve: (BENCH, ("curves",), ()),
    BenchPoint: (BENCH, ("curves", "points"), ()),
    Cheapest: (BENCH, ("cheapest",), ()),
    AbsentPeer: (BENCH, ("absent_peers",), ()),
    StressStudy: (STRESS, (), ()),
    SweepResult: (STRESS, ("sweep", "methods"), ()),
    SweepRow: (STRESS, ("sweep", "methods", "rows"), ()),
    LongRunResult: (STRESS, ("long_run",), ()),
    LongRun: ("with RUN =", (), ()),
    ModifiedWindows: ("with RUN =", ("modified_energy",), ()),
    SingularResult: (STRESS, ("near_singular",), ()),
    NearSingularRun: (STRESS, ("near_singular", "runs"), ()),
    RoundOffResult: (STRESS, ("round_off",), ()),
    Growth: ("## `rkhp long-time`", ("runs",), ()),
    # `rkhp relations` adds where the relations came from
    RelationData: (RELATIONS, (), ("source",)),
    OrderRelations: (RELATIONS, ("orders",), ()),
    RelationRow: (RELATIONS, ("orders", "relations"), ()),
    ConditionRow: (RELATIONS, ("orders", "conditions"), ()),
}

#: types that declare their keys but are written by no command (the structure check is kept on a
#: system, `rkhp.systems.general`)
UNWRITTEN = {"StructureCheck"}


def brace_keys(text: str, start: int) -> tuple[dict, int]:
    """The keys of the brace list opening at ``text[start]``, each with the keys of the brace list
    that is its value (None for a plain value): ``{"a", "b": null | {"c"}, "d": [{"e"}]}`` gives
    ``{"a": None, "b": {"c": None}, "d": {"e": None}}``. Strings after ``:`` or inside ``[...]``
    are values, not keys; backticks and line breaks are the page's markup."""
    keys: dict = {}
    last, key_next, depth, i = None, True, 0, start + 1
    while True:
        c = text[i]
        if c == "}":
            return keys, i + 1
        if c == '"':
            end = text.index('"', i + 1)
            if key_next and depth == 0:
                last = text[i + 1:end]
                keys[last] = None
            key_next, i = False, end + 1
            continue
        if c == "{":
            inner, i = brace_keys(text, i)
            if last is not None and keys[last] is None:
                keys[last] = inner
            continue
        if c == "[":
            depth += 1
        elif c == "]":
            depth -= 1
        elif c == ",":
            key_next = depth == 0
        elif not (c.isspace() or c == "`"):
            key_next = False
        i += 1


def documented_keys(anchor: str, path: tuple[str, ...]) -> set[str]:
    """The keys docs/json.md lists in the first brace list after ``anchor``, at ``path``."""
    found = JSON_PAGE.index(anchor)
    keys, _ = brace_keys(JSON_PAGE, JSON_PAGE.index("{", found))
    for key in path:
        keys = keys[key]
    return set(keys)


@pytest.mark.parametrize("kind", DOCUMENTED, ids=lambda k: k.__name__)
def test_every_result_type_writes_the_keys_docs_json_lists(kind):
    anchor, path, around = DOCUMENTED[kind]
    written = {key for key, _ in keys_of(kind)} | set(around)
    assert written == documented_keys(anchor, path)


def test_brace_lists_are_read_as_the_page_writes_them():
    text = '`{"a", "b": null | {"c", "d": [{"e"}]}, "f": "x" | "y", "g": [RUN],\n"h"}`'
    assert brace_keys(text, 1)[0] == {"a": None, "b": {"c": None, "d": {"e": None}}, "f": None, "g": None,
                                      "h": None}


def test_every_type_that_declares_its_keys_is_documented():
    names = {kind.__name__ for kind in DOCUMENTED} | UNWRITTEN
    root = Path(rkhp.__file__).parent
    declared = set()
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and any(
                    isinstance(s, ast.Assign) and any(getattr(t, "id", None) == "json_keys" for t in s.targets)
                    for s in node.body):
                declared.add(node.name)
    assert declared and declared <= names, sorted(declared - names)


# ----------------------------------------------------------------------------- the encoder


class Point(NamedTuple):
    x: float
    label: str


def test_values_take_their_json_forms():
    assert json_form(Fraction(-2, 6)) == "-1/3"
    assert json_form(parse_tree("b[b,b[b]]")) == "b[b,b[b]]"
    assert json_form(np.array([[1.0, 2.5]])) == [[1.0, 2.5]]
    assert json_form(np.int64(3)) == 3 and type(json_form(np.int64(3))) is int
    assert json_form((1, [Fraction(1, 2)], {"k": (None, True)})) == [1, ["1/2"], {"k": [None, True]}]
    assert json_form(Point(0.5, "p")) == {"x": 0.5, "label": "p"}
    with pytest.raises(TypeError, match="no JSON form for a value of type object"):
        json_form(object())


def test_a_record_writes_its_declared_keys_in_order():
    row = SweepRow(0.5, 4, "ok", 3, 0.25, 0.125)
    assert list(json_form(row)) == ["h", "steps", "ok", "status", "cause", "newton_max", "relative_error",
                                    "relative_energy_error_max"]
    assert json_form(row)["ok"] is True and json_form(row)["relative_energy_error_max"] == 0.125
    # a method without arguments is called, a dotted name reads through the attributes
    sweep = SweepResult("euler", (row, SweepRow(1.0, 2, "Newton failed", 9, None, None)))
    assert json_form(sweep)["verdict"] == sweep.verdict() and json_form(sweep)["first_failure"] == "Newton failed"
    assert json_form(sweep)["rows"][0] == json_form(row)


def test_a_document_reads_back_from_its_json_text():
    data = RelationData(1, (OrderRelations(1, (parse_tree("b"),), (), (((parse_tree("b"),), (Fraction(1),)),)),))
    doc = json.loads(json.dumps(json_form(data)))
    assert doc["format"] == "rkhp-symmetric-relations" and doc["orders"][0]["conditions"] == [
        {"trees": ["b"], "weights": ["1"], "text": "r(b) = 0"}]
