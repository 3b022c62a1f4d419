"""Results a researcher keeps (docs/results.md): trajectory files, states at chosen times,
provenance."""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp as cli

import rkhp
from rkhp.base.provenance import KEYS, read_provenance_line
from rkhp.systems import get_system

RUN = ["integrate", "rigid-body", "--method", "paper-three-stage", "--steps", "100"]


def _invoke(*args):
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.stdout, result.stderr


def _read_csv(path):
    lines = path.read_text().splitlines()
    record = read_provenance_line(lines[0])
    rows = list(csv.reader(lines[1:]))
    return record, rows[0], rows[1:]


def test_csv_trajectory_has_every_step_and_the_json_final_state_bit_for_bit(tmp_path):
    out = tmp_path / "t.csv"
    code, stdout, _ = _invoke(*RUN, "--output", str(out), "--format", "json")
    assert code == 0
    doc = json.loads(stdout)
    record, header, rows = _read_csv(out)
    assert header == ["t", "x1", "x2", "x3", "energy", "casimir1", "newton_iterations", "stage_sweeps"]
    assert len(rows) == 101 and doc["output"] == {"file": str(out), "rows": 101}
    last = [float(v) for v in rows[-1][1:4]]
    assert [v.hex() for v in last] == [v.hex() for v in doc["x_final"]]
    assert float(rows[-1][0]) == pytest.approx(10.0, abs=1e-12)
    # energy and Casimir columns are H and |x|^2/2 of the states (rigid body, docs/theory.md §6)
    x = np.array([[float(v) for v in r[1:4]] for r in rows])
    casimir = np.array([float(r[5]) for r in rows])
    assert np.allclose(casimir, 0.5 * (x ** 2).sum(axis=1), rtol=0, atol=1e-15)
    energy = np.array([float(r[4]) for r in rows])
    assert np.allclose(energy, x[:, 0] ** 2 / 4 + x[:, 1] ** 2 / 2 + 3 * x[:, 2] ** 2 / 4, rtol=0, atol=1e-15)
    newton = [int(r[6]) for r in rows]
    assert newton[0] == 0 and all(k >= 1 for k in newton[1:])  # the first row has no step
    assert list(record) == list(KEYS) and record["command"].startswith("rkhp integrate rigid-body")
    assert record["numpy"] == np.__version__


def test_npz_trajectory_and_every(tmp_path):
    code, stdout, _ = _invoke(*RUN, "--output", str(tmp_path / "t.npz"), "--format", "json")
    assert code == 0
    doc = json.loads(stdout)
    data = np.load(tmp_path / "t.npz")  # no pickle needed
    assert data.files[:4] == ["t", "x1", "x2", "x3"] and len(data["t"]) == 101
    assert [data[f"x{i}"][-1].hex() for i in (1, 2, 3)] == [v.hex() for v in doc["x_final"]]
    assert json.loads(str(data["provenance"]))["rkhp_version"] == rkhp.__version__
    code, _, _ = _invoke(*RUN, "--output", str(tmp_path / "e.csv"), "--every", "10")
    assert code == 0
    _, _, rows = _read_csv(tmp_path / "e.csv")
    assert len(rows) == 11 and [round(float(r[0]), 9) for r in rows] == [float(k) for k in range(11)]


def test_python_trajectory_gives_the_same_columns_and_files(tmp_path):
    run = rkhp.integrate("rigid-body", "paper-three-stage", 0.1, 100)
    columns = run.columns(every=7)
    assert len(columns["t"]) == 16  # rows 0, 7, ..., 98 and the last, 100
    run.write(tmp_path / "p.csv", every=7)
    _, header, rows = _read_csv(tmp_path / "p.csv")
    assert header == list(columns)
    for k, name in enumerate(header):
        assert [float(r[k]) for r in rows] == columns[name].tolist()
    assert np.array_equal(columns["x2"], run.states[[*range(0, 100, 7), 100], 1])


def test_t_eval_has_the_method_order_and_stays_on_the_leaf():
    """Seven times off the grid: the error against the exact solution falls as h^4 for the
    fourth-order method (an interpolation between grid points would give h^2), and the Casimir
    keeps its value to round-off (a step of size t - t_n is a Poisson map)."""
    system = get_system("rigid-body")
    times = [0.37, 1.234, 2.61, 3.33, 5.1, 7.77, 9.2]
    errors = []
    for n in (20, 40, 80, 160):
        run = rkhp.integrate(system, "paper-three-stage", 10.0 / n, n)
        timed = rkhp.states_at(run, "paper-three-stage", times)
        assert np.all(timed.substeps > 0) and np.all(timed.substeps < 10.0 / n)
        errors.append(max(np.abs(system.exact_solution(t) - x).max() for t, x in zip(times, timed.states,
                                                                                      strict=True)))
        casimir = np.abs(0.5 * (timed.states ** 2).sum(axis=1) - 0.5 * (system.x0 ** 2).sum()).max()
        assert casimir < 5e-15
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:], strict=False)]
    assert all(3.8 < p < 4.3 for p in orders), orders


def test_t_eval_on_a_non_quadratic_casimir(tmp_path):
    """The README's Nambu system (Casimir |x|^2/2 + x1^4/4): at chosen times off the grid the
    Casimir holds to round-off with the paper's method."""
    spec = tmp_path / "nambu.toml"
    spec.write_text(NAMBU)
    code, stdout, _ = _invoke("integrate", str(spec), "--method", "paper-three-stage", "--steps", "40",
                              "--t-eval", "0.33,1.7,4.05,9.99", "--format", "json")
    assert code == 0
    timed = json.loads(stdout)["t_eval"]
    x = np.array(timed["states"])
    start = np.array([0.45359612142557731, 0.0, 0.89120736006143542])

    def casimir(v):
        return (v ** 2).sum(axis=-1) / 2 + v[..., 0] ** 4 / 4

    assert np.abs(casimir(x) - casimir(start)).max() < 5e-15
    assert timed["casimir_error"] < 5e-15 and timed["times"] == [0.33, 1.7, 4.05, 9.99]


def test_t_eval_count_and_file(tmp_path):
    code, stdout, _ = _invoke(*RUN, "--t-eval-count", "7", "--output", str(tmp_path / "c.csv"),
                              "--format", "json")
    assert code == 0
    doc = json.loads(stdout)
    assert doc["t_eval"]["times"] == np.linspace(0, 10, 7).tolist()
    _, _, rows = _read_csv(tmp_path / "c.csv")
    assert len(rows) == 7 and [float(r[0]) for r in rows] == doc["t_eval"]["times"]
    assert [float(v) for v in rows[-1][1:4]] == doc["t_eval"]["states"][-1]


@pytest.mark.parametrize("extra, message", [
    (["--t-eval", "11"], "outside the run"),
    (["--t-eval", "2,1"], "increasing"),
    (["--t-eval", "1", "--t-eval-count", "3"], "at most one"),
    (["--every", "3"], "--every"),
    (["--output", "t.txt"], "extension"),
])
def test_bad_output_options_are_input_errors(extra, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, stderr = _invoke(*RUN, *extra)
    assert code == 2 and message in stderr and len(stderr.strip().splitlines()) == 1


NAMBU = """name = "my-nambu"
family = "general"
poisson = [["0",  "-x3",          "x2"],
           ["x3", "0",            "-(x1 + x1^3)"],
           ["-x2", "x1 + x1^3",   "0"]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
casimirs = ["(x1^2 + x2^2 + x3^2)/2 + x1^4/4"]
x0 = [0.45359612142557731, 0.0, 0.89120736006143542]
t_final = 10.0
"""


# ------------------------------------------------------------------------------------ tables

STUDIES = {
    "converge": ["converge", "rigid-body", "--method", "paper-two-stage,rk4", "--steps", "20", "--refinements", "2"],
    "bench": ["bench", "rigid-body", "--method", "euler", "--peers", "scipy:rk45", "--steps", "10,20",
              "--tolerances", "1e-4", "--repeats", "1"],
    "stress": ["stress", "lotka-volterra", "--method", "paper-two-stage", "--t-final", "2", "--long-steps", "200",
               "--sweep-coarsest", "8", "--round-off-steps", "8,16,32"],
    "verify": ["verify", "paper-three-stage"],
}


def _csv_rows(text):
    lines = text.splitlines()
    record = read_provenance_line(lines[0])
    assert not any(line.startswith("#") for line in lines[1:])
    return record, list(csv.DictReader(lines[1:]))


def _number(text):
    return None if text == "" else float(text)


def test_converge_csv_round_trips_and_matches_the_json():
    code, text, _ = _invoke(*STUDIES["converge"], "--format", "csv")
    assert code == 0
    record, rows = _csv_rows(text)
    assert record["command"] == "rkhp " + " ".join(STUDIES["converge"]) + " --format csv"
    code, stdout, _ = _invoke(*STUDIES["converge"], "--format", "json")
    doc = json.loads(stdout)
    expected = [(m["method"], r) for m in doc["methods"] for r in m["rows"]]
    assert len(rows) == len(expected) == 6
    for row, (method, r) in zip(rows, expected, strict=True):
        assert row["method"] == method and int(row["steps"]) == r["steps"]
        for key in ("h", "error", "local_order", "casimir_error_max", "energy_error_max"):
            assert _number(row[key]) == r[key]  # bit for bit: floats by repr
    rk4 = next(m for m in doc["methods"] if m["method"] == "rk4")
    assert {float(r["observed_order"]) for r in rows if r["method"] == "rk4"} == {rk4["observed_order"]}


def test_bench_stress_and_verify_csv_round_trip():
    code, text, _ = _invoke(*STUDIES["bench"], "--format", "csv")
    assert code == 0
    record, rows = _csv_rows(text)
    assert record["seed"] == 0 and [r["method"] for r in rows] == ["euler", "euler", "scipy:rk45"]
    assert rows[2]["tolerance"] == "0.0001" and rows[2]["steps"] == "" and int(rows[2]["evaluations"]) > 0
    code, text, _ = _invoke(*STUDIES["stress"], "--format", "csv")
    assert code == 0
    _, rows = _csv_rows(text)
    assert {r["part"] for r in rows} == {"a", "b", "c", "d"}
    casimir = [float(r["value"]) for r in rows if r["part"] == "b" and r["quantity"] == "casimir_max"
               and r["method"] == "paper-two-stage"]
    assert len(casimir) == 1 and casimir[0] < 1e-13  # an RKHP method keeps the Casimir x1 x2 ... (theory §6)
    code, text, _ = _invoke(*STUDIES["verify"], "--format", "csv")
    assert code == 0
    _, rows = _csv_rows(text)
    orders = {r["class"]: int(r["order"]) for r in rows}
    assert orders == {"general": 1, "degenerate": 4, "symmetric": 4}  # paper §5.2


def _unescape(cell: str) -> str:
    return (cell.replace("\\_", "_").replace("\\textless{}", "<").replace("\\textbar{}", "|")
            .replace("\\~{}", "~").strip())


def _latex_rows(text):
    """(header, cells) of every data row of every tabular, unescaped."""
    out, header, inside = [], None, False
    lines = text.splitlines()
    for k, line in enumerate(lines):
        if line == "\\toprule":
            header = [_unescape(c) for c in lines[k + 1].removesuffix(" \\\\").split(" & ")]
        elif line == "\\midrule":
            inside = True
        elif line == "\\bottomrule":
            inside = False
        elif inside:
            out.append((header, [_unescape(c) for c in line.removesuffix(" \\\\").split(" & ")]))
    return out


#: a number as the tables print it: 0.5, 20, 1.24e-04, x0.94, 4.4/7 (two numbers)
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e[-+]\d+)?")


def _in_order(tokens, line) -> bool:
    """Whether ``tokens`` occur in ``line`` (a list of tokens) in this order."""
    rest = iter(line)
    return all(any(t == u for u in rest) for t in tokens)


@pytest.mark.parametrize("name", list(STUDIES))
def test_latex_tables_are_booktabs_with_the_terminal_numbers(name):
    """Every row of the LaTeX tables is a line of the terminal's table, number for number (run
    times apart: they differ from run to run)."""
    code, text, _ = _invoke(*STUDIES[name], "--format", "latex")
    assert code == 0
    assert read_provenance_line(text.splitlines()[0])["command"].endswith("--format latex")
    assert text.count("\\begin{tabular}") == text.count("\\end{tabular}") == text.count("\\toprule") >= 1
    code, terminal, _ = _invoke(*STUDIES[name])
    assert code == 0
    shown = [NUMBER.findall(line) for line in terminal.splitlines()]
    rows = _latex_rows(text)
    assert rows
    missing = []
    for header, cells in rows:
        assert len(header) == len(cells)
        kept = [c for h, c in zip(header, cells, strict=True) if h not in ("s", "seconds", "CPU s", "wall s")]
        tokens = NUMBER.findall(" ".join(kept[1:]))  # the first column names the row
        if tokens and not any(_in_order(tokens, line) for line in shown):
            missing.append(tokens)
    # rows the terminal folds over several lines (long captions, narrow columns) may be missed
    assert len(missing) <= len(rows) // 4, missing


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="pdflatex is not installed")
@pytest.mark.parametrize("name", list(STUDIES))
def test_latex_tables_compile_with_pdflatex(name, tmp_path):
    code, text, _ = _invoke(*STUDIES[name], "--format", "latex")
    assert code == 0
    (tmp_path / "doc.tex").write_text("\\documentclass{article}\n\\usepackage{booktabs}\n\\begin{document}\n"
                                      + text + "\\end{document}\n")
    proc = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "doc.tex"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:]


def test_plot_data_is_written_beside_the_plot(tmp_path):
    plot = tmp_path / "c.png"
    code, _, _ = _invoke(*STUDIES["converge"], "--plot", str(plot), "--format", "json")
    assert code == 0 and plot.stat().st_size > 1000
    record, rows = _csv_rows((tmp_path / "c.csv").read_text())
    assert record["command"].startswith("rkhp converge")
    code, stdout, _ = _invoke(*STUDIES["converge"], "--format", "json")
    for m in json.loads(stdout)["methods"]:
        drawn = [(float(r["x"]), float(r["y"])) for r in rows if r["curve"] == m["method"]]
        assert drawn == [(r["h"], r["error"]) for r in m["rows"] if r["error"] is not None]


# ----------------------------------------------------------------------------- rkhp.system


def test_a_system_from_python_gives_the_spec_file_trajectory_bit_for_bit(tmp_path):
    import sympy

    spec = tmp_path / "my-nambu.toml"
    spec.write_text(NAMBU)
    x1, x2, x3 = sympy.symbols("x1 x2 x3", real=True)
    keys = dict(name="my-nambu", family="general", t_final=10.0,
                x0=[0.45359612142557731, 0.0, 0.89120736006143542])
    from_strings = rkhp.system(**keys, poisson=[["0", "-x3", "x2"], ["x3", "0", "-(x1 + x1^3)"],
                                                ["-x2", "x1 + x1^3", "0"]],
                               hamiltonian="x1^2/4 + x2^2/2 + 3*x3^2/4",
                               casimirs=["(x1^2 + x2^2 + x3^2)/2 + x1^4/4"])
    from_sympy = rkhp.system(**keys, poisson=sympy.Matrix([[0, -x3, x2], [x3, 0, -(x1 + x1 ** 3)],
                                                            [-x2, x1 + x1 ** 3, 0]]),
                             hamiltonian=x1 ** 2 / 4 + x2 ** 2 / 2 + 3 * x3 ** 2 / 4,
                             casimirs=[(x1 ** 2 + x2 ** 2 + x3 ** 2) / 2 + x1 ** 4 / 4])
    reference = rkhp.integrate(str(spec), "paper-three-stage", 0.25, 40).states
    for system in (from_strings, from_sympy):
        assert np.array_equal(rkhp.integrate(system, "paper-three-stage", 0.25, 40).states, reference)


@pytest.mark.parametrize("keys", [
    dict(family="general", poisson=[["0", "x1"], ["x1", "0"]], hamiltonian="x1", x0=[1.0, 2.0]),
    dict(family="general", poisson=[["0", "-x3", "x2"], ["x3", "0", "-x1"], ["-x2", "x1", "0"]],
         hamiltonian="x1^2", casimirs=["x1"], x0=[1.0, 2.0, 3.0]),
    dict(family="general", poisson=[["0", "x1"], ["-x1", "0"]], hamiltonian="x1", x0=[1.0, True]),
    dict(family="lie-poisson", structure_constants=[[1, 2, 3, 1]], hamiltonian="__import__('os')", x0=[1, 0, 0]),
    dict(family="constant", poisson=[[0, 1], [-1, 0]], hamiltonian="x1", x0=[0.0, 1.0], colour="red"),
])
def test_a_system_from_python_is_refused_as_its_spec_file(keys, tmp_path):
    """The same checks and the same messages as the file reader (antisymmetry, a declared Casimir
    that is none, a boolean coordinate, an unsafe expression, an unknown key)."""
    import tomli_w

    with pytest.raises(rkhp.InputError) as from_python:
        rkhp.system(**keys)
    spec = tmp_path / "s.toml"
    spec.write_text(tomli_w.dumps(keys))
    with pytest.raises(rkhp.InputError) as from_file:
        get_system(str(spec))
    assert str(from_python.value).replace("rkhp.system", "@") == str(from_file.value).replace(str(spec), "@")


def test_t_eval_at_the_end_of_a_grid_that_misses_it_by_round_off():
    """49 steps of 1/49 end at 0.9999999999999999: T = 1 is still a time of the run, the grid
    state there (a time within round-off of a grid time is that grid time, docs/results.md)."""
    code, stdout, _ = _invoke("integrate", "rigid-body", "--method", "paper-three-stage", "--steps", "49",
                              "--t-final", "1", "--t-eval", "1", "--format", "json")
    assert code == 0
    doc = json.loads(stdout)
    assert doc["t_final"] < 1.0 and doc["t_eval"]["times"] == [1.0]
    assert doc["t_eval"]["substeps"][0] == 0.0
    assert doc["t_eval"]["states"][0] == doc["x_final"]


# ----------------------------------------------------------------------------- files and --force


def test_output_and_plot_data_need_force_to_replace_a_file(tmp_path):
    out = tmp_path / "t.csv"
    out.write_text("kept\n")
    code, _, err = _invoke(*RUN, "--output", str(out))
    assert code == 2 and "--force" in err and out.read_text() == "kept\n"
    code, _, _ = _invoke(*RUN, "--output", str(out), "--force")
    assert code == 0 and read_provenance_line(out.read_text().splitlines()[0])["command"].endswith("--force")
    data = tmp_path / "c.csv"  # the plot's data file exists, the plot does not
    data.write_text("kept\n")
    code, _, err = _invoke(*STUDIES["converge"], "--plot", str(tmp_path / "c.png"))
    assert code == 2 and "data file" in err and data.read_text() == "kept\n"
    assert not (tmp_path / "c.png").exists()
    code, _, _ = _invoke(*STUDIES["converge"], "--plot", str(tmp_path / "c.png"), "--force")
    assert code == 0 and data.read_text().startswith("# provenance: ")


def test_write_output_is_atomic_and_never_writes_through_a_link(tmp_path):
    from rkhp.base.errors import InputError
    from rkhp.base.provenance import write_output

    target = tmp_path / "target.txt"
    target.write_text("target\n")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    with pytest.raises(InputError, match="symbolic link"):
        write_output(link, "new\n")
    write_output(link, "new\n", force=True)
    assert not link.is_symlink() and link.read_text() == "new\n" and target.read_text() == "target\n"
    with pytest.raises(InputError, match="exists"):
        write_output(target, "other\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.csv", "target.txt"]  # no temporary left
