"""Exit status (docs/exit-status.md): 0 success, 1 a failed check, 2 bad input."""

from __future__ import annotations

import json


def test_bare_rkhp_prints_the_help_on_stdout(run_cli):
    rc, out, err = run_cli()
    assert rc == 0 and err == ""
    assert out.startswith("Usage: rkhp") and "\n  show " in out and len(out.splitlines()) > 10


def test_overstated_claim_exits_1(run_cli, tmp_path):
    # RK4 claimed as order 5: Kutta's method has order 4 (Hairer, Norsett & Wanner I, II.1)
    path = tmp_path / "over.toml"
    path.write_text('order = 5\nA = [["0","0","0","0"],["1/2","0","0","0"],["0","1/2","0","0"],'
                    '["0","0","1","0"]]\nb = ["1/6","1/3","1/3","1/6"]\n')
    rc, out, err = run_cli("verify", str(path))
    assert rc == 1 and "overstated" in out
    assert err.count("\n") == 1 and "overstated" in err and "Traceback" not in err
    rc, out, err = run_cli("verify", str(path), "--format", "json")
    assert rc == 1 and json.loads(out)["claims"]["general"] == "overstated"
    # an understated claim is true (the order is at least the claim): exit 0
    path.write_text(path.read_text().replace("order = 5", "order = 3"))
    rc, out, err = run_cli("verify", str(path))
    assert rc == 0 and "understated" in out


def test_no_tableau_found_exits_1(run_cli):
    # two explicit stages cannot reach general order 3 (Butcher: order p needs p stages for p <= 4)
    rc, out, err = run_cli("search", "--stages", "2", "--order", "3", "--restarts", "2",
                           "--format", "json")
    assert rc == 1 and json.loads(out)["found"] is False
    assert err.count("\n") == 1 and "no tableau found" in err


def test_bad_input_exits_2(run_cli):
    for args in (("verify", "no-such-tableau"), ("show",), ("search", "--stages", "x")):
        rc, out, err = run_cli(*args)
        assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err


def test_numpys_floating_point_warnings_are_not_printed():
    """The pendulum from q = 1e308: a product in the run's bookkeeping overflows (numpy warns,
    two lines) though the run itself completes, and reports its energy error; stderr stays
    empty. In a process of its own: a test process's warnings are pytest's."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "rkhp", "integrate", "pendulum", "--method", "rk4", "--steps", "10",
                           "--x0", "1e308,0", "--format", "json"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and proc.stderr == ""
    assert json.loads(proc.stdout)["energy_error"] > 0
