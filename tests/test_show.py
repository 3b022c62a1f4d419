"""`rkhp show`, the tableau's text and LaTeX forms, and standalone LaTeX output.

Expected entries are RK4's Butcher array (Kutta 1901; Hairer, Norsett & Wanner I, Table II.1.2)
and the two-stage Gauss method's (c = 1/2 -+ sqrt(3)/6; HW II, Table IV.5.1); the conditions
document is the paper's Table 1 (8 trees of T_0 up to order 5).
"""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from rkhp.tableaux.files import load_tableau

RK4_ROWS = ["0   │", "1/2 │ 1/2", "1/2 │ 0    1/2", "1   │ 0    0    1"]


def test_print_a_tableau_shows_its_butcher_array():
    text = str(load_tableau("rk4"))
    lines = text.splitlines()
    assert lines[0] == "rk4 (4 stages, explicit)"
    assert lines[1:5] == RK4_ROWS
    assert lines[6] == "    │ 1/6  1/3  1/3  1/6"


def test_latex_of_a_tableau():
    tex = load_tableau("rk4").to_latex()
    assert tex.startswith("\\begin{array}{c|cccc}") and tex.endswith("\\end{array}")
    assert "\\frac{1}{2} & \\frac{1}{2} &  &  &  \\\\" in tex
    assert tex.splitlines()[-2] == " & \\frac{1}{6} & \\frac{1}{3} & \\frac{1}{3} & \\frac{1}{6}"
    assert load_tableau("rk4")._repr_latex_() == "$$" + tex + "$$"
    gauss = load_tableau("gauss2").to_latex()
    assert "\\frac{1}{2} - \\frac{\\sqrt{3}}{6}" in gauss  # c_1 = 1/2 - sqrt(3)/6


def test_show_table_and_json(run_cli):
    rc, out, err = run_cli("show", "rk4")
    assert rc == 0, err
    assert "source: tables/rk4.toml" in out and "Kutta (1901)" in out
    assert "claimed orders: general 4, degenerate -, symmetric -" in out
    assert all(row in out for row in RK4_ROWS)
    assert "0.166666666667" in out  # the decimals block
    rc, out, err = run_cli("show", "gauss2", "--format", "json")
    doc = json.loads(out)
    assert doc["c"] == ["1/2 - sqrt(3)/6", "sqrt(3)/6 + 1/2"] and doc["b"] == ["1/2", "1/2"]
    assert doc["decimals"]["c"][0] == pytest.approx(0.5 - 3**0.5 / 6, abs=1e-16)
    assert doc["claimed"] == {"order": 4, "degenerate_order": None, "symmetric_order": None}
    assert doc["kind"] == "implicit" and doc["source"] == "tables/gauss2.toml"


def test_show_a_file_and_bad_input(run_cli, tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('order = 2\nA = [["0", "0"], ["2/3", "0"]]\nb = ["1/4", "3/4"]\n')
    rc, out, _ = run_cli("show", str(path))
    assert rc == 0 and "2/3 │ 2/3" in out and "claimed orders: general 2" in out
    rc, out, err = run_cli("show", "rk5x")
    assert rc == 2 and out == "" and err.count("\n") == 1
    rc, out, err = run_cli("tables", "rk4")  # one tableau is shown by `rkhp show`
    assert rc == 2 and out == "" and err.count("\n") == 1 and "rkhp show rk4" in err


def _compile(tmp_path, tex: str) -> None:
    (tmp_path / "doc.tex").write_text(tex)
    proc = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "doc.tex"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:]
    assert (tmp_path / "doc.pdf").stat().st_size > 1000


def test_latex_documents_are_complete(run_cli):
    rc, out, _ = run_cli("conditions", "--order", "5", "--degenerate", "--format", "latex")
    assert rc == 0 and out.startswith("\\documentclass") and out.rstrip().endswith("\\end{document}")
    assert out.count("\\rkhptree{") == 8 and "\\forest" not in out  # the paper's Table 1
    rc, out, err = run_cli("trees", "--order", "5", "--count", "--format", "latex")
    assert rc == 0 and "Traceback" not in err and "5 & 9\\\\" in out  # 9 trees of order 5 (A000081)


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="pdflatex is not installed")
@pytest.mark.parametrize("args", [("show", "rk4"), ("show", "gauss2"),
                                  ("conditions", "--order", "5", "--degenerate"),
                                  ("trees", "--order", "5", "--count"), ("trees", "--order", "4"),
                                  ("conditions", "--order", "6", "--symmetric"),
                                  ("modified", "--method", "paper-three-stage", "--order", "5", "--symmetric")])
def test_latex_compiles_with_pdflatex(run_cli, tmp_path, args):
    rc, out, err = run_cli(*args, "--format", "latex")
    assert rc == 0, err
    _compile(tmp_path, out)
