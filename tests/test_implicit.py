"""Implicit tableaux in the RKHP engine (docs/implicit.md, docs/theory.md §10).

Values from outside the code: the classical orders of the Gauss methods (2s with s stages: Butcher
1964; Hairer, Norsett & Wanner I, Table II.7.x), the paper's one-stage implicit method of
degenerate order 3 (Remark 5.5), the implicit midpoint rule on the harmonic oscillator (a closed
form: a rotation by 2 arctan(h/2) per step), and the order the exact verification of a searched
tableau records in its file.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp

from rkhp.integrators import integrate_rkhp
from rkhp.integrators.failure import Failure
from rkhp.integrators.methods import resolve_method
from rkhp.studies.converge import converge
from rkhp.systems import get_system
from rkhp.tableaux.files import save_tableau
from rkhp.tableaux.tableau import Tableau

IMPLICIT_BUILTINS = ("paper-implicit", "gauss2", "gauss3", "radau-iia3", "lobatto-iiia3",
                     "lobatto-iiic3")
FOUND = "search-degenerate-o4-s2-implicit"

OSCILLATOR = """family = "constant"
poisson = [[0, 1], [-1, 0]]
hamiltonian = "(x1^2 + x2^2)/2"
x0 = [1, 0.5]
"""


def midpoint_rotation(x0, step, n):
    """n steps of the implicit midpoint rule x' = x + step J (x + x')/2, J = [[0, 1], [-1, 0]]
    (the Cayley transform of step J), from x0."""
    J = np.array([[0.0, 1.0], [-1.0, 0.0]])
    M = np.linalg.solve(np.eye(2) - step / 2 * J, np.eye(2) + step / 2 * J)
    out = [np.asarray(x0, dtype=float)]
    for _ in range(n):
        out.append(M @ out[-1])
    return np.array(out)


def test_gauss1_on_the_harmonic_oscillator_is_the_midpoint_rule_of_a_longer_step(tmp_path):
    """One-stage Gauss (A = [1/2], b = [1]) as an RKHP tableau on H = |x|^2/2, pi = J, alpha =
    x - J p/2: Z(x) = c x solves Z = (h/2) grad H(x - J Z/2) when c = (h/2)(1 + c^2/4), and then
    psi = 2c x, so the step is the implicit midpoint rule with step 2c = (8/h)(1 - sqrt(1 - h^2/4))
    (= h + h^3/16 + ...; docs/implicit.md). Stage polynomials of degree 1 represent Z exactly,
    so the engine must agree to round-off. RKHP Euler is the midpoint rule with step h
    (tests/test_integrators.py)."""
    path = tmp_path / "oscillator.toml"
    path.write_text(OSCILLATOR)
    system = get_system(str(path))
    gauss1 = Tableau.from_arrays([[0.5]], [1.0], name="gauss1")
    for h in (0.1, 0.5):
        n = 40
        tr = integrate_rkhp(system, gauss1, h, n).raise_if_failed()
        step = 8.0 / h * (1.0 - math.sqrt(1.0 - h * h / 4.0))
        # round-off only: about one unit in the last place per step
        assert np.abs(tr.states - midpoint_rotation(system.x0, step, n)).max() < n * 1e-15
        # ... and not the midpoint rule of step h: they differ by O(h^3) per step
        assert np.abs(tr.states - midpoint_rotation(system.x0, h, n)).max() > n * h**3 / 100


@pytest.mark.parametrize(("realisation", "method", "order"), [
    ("symmetric", "paper-implicit", 3),  # paper, Remark 5.5: degenerate order 3
    ("symmetric", "gauss2", 4),          # Gauss, s = 2: order 4 in every class
    ("shifted", "gauss2", 4),
    ("shifted", "gauss3", 6),            # Gauss, s = 3: order 6
    ("shifted", "paper-implicit", 1),    # not degenerate: the paper's method drops to order 1
])
def test_orders_on_the_rigid_body(realisation, method, order):
    """`rkhp converge rigid-body --method paper-implicit,gauss2` (and on --realisation shifted
    gauss2, gauss3, paper-implicit), default steps: the published orders are observed."""
    study = converge(get_system("rigid-body", realisation), [method])
    (m,) = study.methods
    assert m.expected_order == order
    assert m.verdict == "confirmed", (m.observed_order, m.fit)
    assert len(m.fit.fit_rows) >= 3
    assert max(r.casimir_error for r in m.rows if r.casimir_error is not None) < 1e-13


@pytest.mark.parametrize("system", ["rigid-body", "lotka-volterra"])
def test_the_searched_implicit_method_has_order_4(system):
    """tables/search-degenerate-o4-s2-implicit.toml (found by `rkhp search --stages 2 --implicit
    --degenerate`, its degenerate order 4 verified exactly and recorded in the file) confirms
    order 4 on both degenerate built-ins."""
    method = resolve_method(FOUND)
    assert method.tableau.kind != "explicit" and method.tableau.claims["degenerate"] == 4
    study = converge(system, [FOUND])
    (m,) = study.methods
    assert m.expected_order == 4 and m.verdict == "confirmed", (m.observed_order, m.fit)


@pytest.mark.parametrize("method", [*IMPLICIT_BUILTINS, FOUND])
def test_every_implicit_builtin_integrates(method):
    """rkhp.integrate accepts every implicit built-in: 50 steps of h = 0.2 on the rigid body keep
    the Casimir and are accurate to the method's order (against the exact solution)."""
    import rkhp

    tr = rkhp.integrate("rigid-body", method, 0.2, 50).raise_if_failed()
    system = get_system("rigid-body")
    assert tr.cause == Failure.OK and tr.stage_sweeps.min() >= 1
    assert np.abs(system.casimir_values(tr.final_state) - system.casimir_values(system.x0)).max() < 1e-14
    assert np.abs(tr.final_state - system.exact_solution(10.0)).max() < 1e-2


def test_one_compilation_serves_every_explicit_and_every_implicit_tableau():
    from rkhp.integrators.driver import drive

    system = get_system("pendulum")
    for method in ("paper-three-stage", "gauss2"):
        integrate_rkhp(system, method, 0.1, 5).raise_if_failed()
    compiled = len(drive.signatures)
    for method in ("rk4", "paper-implicit", "lobatto-iiia3"):
        integrate_rkhp(system, method, 0.1, 5).raise_if_failed()
    assert len(drive.signatures) == compiled


def test_a_step_too_large_for_the_stages_is_one_line_exit_1(run_cli):
    tr = integrate_rkhp(get_system("rigid-body"), "gauss2", 5.0, 2)
    assert tr.cause == Failure.STAGES_NO_CONVERGENCE and tr.failed_step == 0
    rc, out, err = run_cli("integrate", "rigid-body", "--method", "gauss2", "--h", "5")
    assert rc == 1 and err.count("\n") == 1 and "Traceback" not in err
    assert "failed at step 0 (t = 0 -> 5)" in err and "implicit stages did not converge" in err
    rc, out, err = run_cli("integrate", "rigid-body", "--method", "gauss2", "--h", "5",
                           "--format", "json")
    assert rc == 1 and json.loads(out)["status"].startswith("failed at step 0")


def test_commands_accept_implicit_and_taylor_methods(tmp_path):
    """integrate, converge, bench and stress take implicit tableaux (built-in and file) and thpN."""
    runner = CliRunner()
    table = tmp_path / "found.toml"
    save_tableau(resolve_method(FOUND).tableau, table)
    methods = f"gauss2,{table},thp4"
    res = runner.invoke(rkhp, ["integrate", "rigid-body", "--method", str(table), "--steps", "50",
                               "--format", "json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["exact_error"] < 1e-4
    res = runner.invoke(rkhp, ["converge", "rigid-body", "--method", methods, "--steps", "40,80,160",
                               "--format", "json"])
    assert res.exit_code == 0, res.output
    assert [m["verdict"] for m in json.loads(res.output)["methods"]] == ["confirmed"] * 3
    res = runner.invoke(rkhp, ["bench", "rigid-body", "--method", methods, "--peers", "",
                               "--steps", "20,40", "--repeats", "1", "--format", "json"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(rkhp, ["stress", "rigid-body", "--method", "gauss2,paper-implicit",
                               "--long-steps", "500", "--sweep-coarsest", "10",
                               "--round-off-steps", "30,100,300", "--format", "json"])
    assert res.exit_code == 0, res.output
    runs = json.loads(res.output)["long_run"]["runs"]
    assert all(r["casimir_max"] < 1e-13 for r in runs)


def test_an_implicit_run_is_announced_as_a_poisson_map_up_to_its_truncation(monkeypatch, capsys):
    """On a terminal, `rkhp integrate` with an implicit tableau says that its step is a Poisson map
    up to O(h^(D + 1)), D the stage degree N + 1 (gauss2: order 4, D = 5; docs/implicit.md), and
    says nothing for an explicit one or in JSON mode."""
    import sys

    from rkhp_cli.systems_cmd import _implicit_notice

    from rkhp.integrators.methods import resolve_method

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    _implicit_notice(resolve_method("gauss2"), True)
    assert "degree 5, so a step is a Poisson map up to O(h^6)" in capsys.readouterr().err
    _implicit_notice(resolve_method("rk4"), True)
    _implicit_notice(resolve_method("gauss2"), False)
    assert capsys.readouterr().err == ""


#: four point vortices in the deformed plane (benchmarks/data/vortices-8.toml: 8 variables, pi with
#: the non-affine blocks 2/(1 + 2|q_k|^2)), over T = 0.2, with its momentum map declared: H and pi
#: are invariant under rotations of all q_k, generated by J = sum_k |q_k|^2 + |q_k|^4 (dJ/d|q|^2 =
#: 1 + 2|q|^2 cancels the block's factor), so J is a first integral of the flow
VORTICES_MOMENTUM = 'invariants = ["' + " + ".join(
    f"x{2 * k + 1}^2 + x{2 * k + 2}^2 + (x{2 * k + 1}^2 + x{2 * k + 2}^2)^2" for k in range(4)) + '"]\n'


def _momentum(x) -> float:
    r2 = np.asarray(x[0::2]) ** 2 + np.asarray(x[1::2]) ** 2
    return float(np.sum(r2 + r2**2))


def test_an_implicit_step_moves_a_momentum_map_at_its_truncation_order_and_says_by_how_much(run_cli, tmp_path):
    """gauss2's stages are polynomials of degree 5 (docs/implicit.md): the momentum map of the
    vortices moves, and the run reports by how much (the largest drift of the declared invariant,
    at least its change at the end, computed here from the final state), falling at least like
    the announced O(h^6) a step (h^5 over a fixed time) when h is halved; an explicit composition
    keeps it to round-off."""
    from pathlib import Path

    source = Path(__file__).resolve().parent.parent / "benchmarks" / "data" / "vortices-8.toml"
    lines = [line for line in source.read_text().splitlines() if not line.startswith("t_final")]
    spec = tmp_path / "vortices.toml"
    spec.write_text("\n".join(lines) + "\nt_final = 0.2\n" + VORTICES_MOMENTUM)
    x0 = [0.5, 0.1, 0.5, -0.1, -0.5, 0.3, -0.5, -0.3]
    drifts = {}
    for method, steps in (("gauss2", 20), ("gauss2", 40), ("kahan-li8", 20)):
        code, out, err = run_cli("integrate", str(spec), "--method", method, "--steps", str(steps), "--format", "json")
        assert code == 0, err
        doc = json.loads(out)
        (reported,) = doc["invariant_errors_max"]
        assert reported >= abs(_momentum(doc["x_final"]) - _momentum(x0)) - 1e-15
        drifts[method, steps] = reported
    assert drifts["gauss2", 20] > 1e-12  # not a Poisson map to round-off
    assert drifts["gauss2", 20] / drifts["gauss2", 40] >= 2**5
    assert drifts["kahan-li8", 20] < 1e-14
