"""`rkhp trees` and `rkhp conditions` as a user runs them, including bad input."""

from __future__ import annotations

import json

import pytest


def test_conditions_json_keys_and_table_1(run_cli):
    rc, out, err = run_cli("conditions", "--order", "5", "--degenerate", "--format", "json")
    assert rc == 0, err
    doc = json.loads(out)
    assert list(doc) == ["order", "degenerate", "class", "counts", "conditions", "provenance"]
    assert doc["class"] == "degenerate"
    assert doc["counts"] == {"1": 1, "2": 0, "3": 1, "4": 2, "5": 4}
    first = doc["conditions"][1]
    assert first == {"tree": "b[b,b]", "order": 3, "sigma": 2, "gamma": 3, "rhs": "1/3",
                     "condition": "sum_i b_i c_i^2 = 1/3",
                     "latex": "\\sum_{i=1}^s b_i c_i^2 = \\frac{1}{3}"}


def test_conditions_table_and_latex(run_cli):
    rc, out, _ = run_cli("conditions", "--order", "5", "--degenerate")
    assert rc == 0 and "b[b,b[b,b]]" in out and "sum_{i,j} b_i c_i a_ij c_j^2 = 1/15" in out
    rc, out, _ = run_cli("conditions", "--order", "5", "--degenerate", "--format", "latex")
    assert rc == 0 and "\\begin{longtable}{C|C|C}" in out and out.count("\\rkhptree{") == 8
    rc, out, _ = run_cli("conditions", "--order", "4", "--exact-order", "--format", "markdown")
    assert rc == 0 and out.count("\n| 4 |") == 4


def test_trees_json_and_count(run_cli):
    rc, out, _ = run_cli("trees", "--order", "4", "--format", "json")
    doc = json.loads(out)
    assert doc["counts"] == {"1": 1, "2": 1, "3": 2, "4": 4}
    assert doc["trees"][3] == {"tree": "b[b,b]", "order": 3, "sigma": 2, "gamma": 3}
    rc, out, _ = run_cli("trees", "--order", "16", "--count", "--format", "json")
    doc = json.loads(out)
    assert "trees" not in doc and doc["counts"]["16"] == 235381
    rc, out, _ = run_cli("trees", "--order", "18", "--degenerate", "--count", "--exact-order", "--format", "json")
    assert rc == 0 and list(json.loads(out)["counts"]) == ["18"]


@pytest.mark.parametrize("args, needle", [
    (("conditions", "--order", "0"), "at least 1"),
    (("conditions", "--order", "-3"), "at least 1"),
    (("conditions", "--order", "2.5"), "not a valid integer"),
    (("trees", "--order", "99"), "maximum"),
    (("trees", "--order", "3", "--format", "yaml"), "--format"),
    (("conditions",), "--order"),
    (("nonsense",), "No such command"),
])
def test_bad_input_is_one_line_exit_2(run_cli, args, needle):
    rc, out, err = run_cli(*args)
    assert rc == 2
    assert err.count("\n") == 1 and needle in err and "Traceback" not in err


def test_python_m_rkhp_and_help(run_cli):
    rc, out, _ = run_cli("--help")
    assert rc == 0 and "conditions" in out and "trees" in out


def test_conditions_does_not_import_heavy_modules(run_cli):
    import subprocess
    import sys

    code = ("import atexit, sys; "
            "atexit.register(lambda: sys.stderr.write('HEAVY:' + ','.join("
            "m for m in ('jax', 'numba', 'sympy', 'scipy', 'matplotlib') if m in sys.modules))); "
            "sys.argv = ['rkhp', 'conditions', '--order', '5', '--degenerate']; "
            "from rkhp_cli.main import main; main()")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert "HEAVY:" in proc.stderr and proc.stderr.split("HEAVY:")[1].strip() == ""


def test_symmetric_and_degenerate_conflict(run_cli):
    rc, _, err = run_cli("conditions", "--order", "4", "--symmetric", "--degenerate")
    assert rc == 2 and err.count("\n") == 1 and "exclusive" in err
