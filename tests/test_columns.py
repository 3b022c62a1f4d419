"""At 80 columns no table cuts a number or a name across lines.

The checker reads a command's JSON (or a saved file) and asks that every name and every number
it holds appear whole, as one token, in the table the same command prints with COLUMNS=80: a
string's words verbatim, an integer as written, a float in some rounding (the tables show 3 to 12
significant digits). A number folded mid-digit (``-0.103471`` / ``829727``) or a name cut with an
ellipsis (``lobatto-ii…``) leaves no such token.
"""

from __future__ import annotations

import json
import re

import pytest
from cli_run import rkhp

_SEPARATORS = re.compile(r"[\s│┃─━┏┓┗┛┡┩└┘┼╇┳┻┴┬├┤╈╋]+")


def _tokens(text: str) -> set[str]:
    out = set()
    for token in _SEPARATORS.split(text):
        token = token.strip(",;:")
        while token.startswith("(") and not token.endswith(")") or token.startswith("`"):
            token = token[1:]
        while token.endswith(")") and token.count(")") > token.count("(") or token.endswith("`"):
            token = token[:-1]
        if token:
            out.add(token)
    return out


def _roundings(value: float) -> set[str]:
    out = {repr(value)}
    for k in range(3, 16):  # the tables show 3 significant digits at least
        out |= {f"{value:.{k}g}", f"{value:.{k}e}", f"{value:.{k}f}"}
    return out


def _leaves(doc):
    if isinstance(doc, dict):
        for v in doc.values():
            yield from _leaves(v)
    elif isinstance(doc, list):
        for v in doc:
            yield from _leaves(v)
    elif doc is not None and not isinstance(doc, bool):
        yield doc


def missing(doc, text: str) -> list:
    """The leaves of ``doc`` that do not appear whole in ``text`` (see the module docstring)."""
    tokens = _tokens(text)
    out = []
    for leaf in _leaves(doc):
        if isinstance(leaf, str):
            words = [w for w in _tokens(leaf) if w != "-"]
            numeric = re.fullmatch(r"[-+]?\d*\.\d+(e[-+]?\d+)?", leaf.strip())
            if numeric and leaf.strip() not in tokens:  # a long decimal is shown rounded
                if not _roundings(float(leaf)) & tokens:
                    out.append(leaf)
            elif not numeric and not all(w in tokens for w in words):
                out.append(leaf)
        elif isinstance(leaf, int):
            if str(leaf) not in tokens and not any(t.startswith(f"{leaf}/") or t.endswith(f"/{leaf}")
                                                   or t in (f">={leaf}",) for t in tokens):
                out.append(leaf)
        elif not _roundings(float(leaf)) & tokens:
            out.append(leaf)
    return out


def _run(*args: str) -> str:
    proc = rkhp(*args, env={"COLUMNS": "80"})
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _check(table: str, doc) -> None:
    assert max(len(line.rstrip()) for line in table.splitlines()) <= 80
    assert "…" not in table
    assert missing(doc, table) == []


def test_the_checker_sees_a_cut_number_and_a_cut_name():
    doc = {"A": ["-0.103471829727"], "name": "lobatto-iiia3", "x": 0.4536}
    assert missing(doc, "│ -0.103471 │\n│ 829727 │ lobatto-iiia3 0.4536") == ["-0.103471829727"]
    assert missing(doc, "-0.103471829727 lobatto-ii… 0.454") == ["lobatto-iiia3"]
    assert missing(doc, "-0.103471829727 lobatto-iiia3 0.45\n36") == [0.4536]


def test_search_at_80_columns(tmp_path):
    # 6 stages, general order 5 (30-digit entries, shown to 12 digits)
    path = tmp_path / "found.json"
    table = _run("search", "--stages", "6", "--order", "5", "--seed", "0", "--save", str(path))
    saved = json.loads(path.read_text())
    _check(table, {"A": saved["A"], "b": saved["b"]})


@pytest.mark.parametrize("name", ["dop853", "paper-two-stage"])
def test_verify_at_80_columns(name):
    doc = json.loads(_run("verify", name, "--format", "json"))
    table = _run("verify", name)
    shown = {"name": doc["name"], "stages": doc["stages"], "checked": doc["class_checked_up_to"],
             "orders": doc["orders"], "principal_error": doc["principal_error"],
             "failing": {cls: f[:10] for cls, f in doc["failing"].items()}}
    _check(table, shown)


def test_tables_at_80_columns():
    rows = json.loads(_run("tables", "--format", "json"))["tables"]
    table = _run("tables")
    _check(table, [{"name": r["name"], "stages": r["stages"], "orders": r["orders"],
                    "claimed": r["claimed"]} for r in rows])


def test_systems_at_80_columns():
    rows = json.loads(_run("systems", "--format", "json"))["systems"]
    table = _run("systems")
    _check(table, [{k: r[k] for k in ("name", "family", "dim", "domain", "x0", "t_final", "casimirs")}
                   for r in rows])


@pytest.mark.parametrize("name", ["rk4", "dopri5", "gauss2", "feagin10", "search-symmetric-o7-s6"])
def test_show_at_80_columns(name):
    doc = json.loads(_run("show", name, "--format", "json"))
    table = _run("show", name)
    _check(table, {k: doc[k] for k in ("name", "aliases", "stages", "source", "reference", "claimed",
                                      "A", "b", "c", "decimals")})


@pytest.mark.parametrize("args", [("conditions", "--order", "6", "--symmetric"), ("relations", "--order", "6"),
                                  ("trees", "--order", "6")])
def test_trees_and_conditions_at_80_columns(args):
    table = _run(*args)
    doc = json.loads(_run(*args, "--format", "json"))
    if "orders" in doc:  # relations: their text, term by term
        _check(table, [r["text"] for o in doc["orders"] for r in (*o["relations"], *o["conditions"])])
        return
    rows = doc.get("conditions") or doc.get("trees")
    _check(table, [t for r in rows for t in (r.get("trees") or [r["tree"]])])
