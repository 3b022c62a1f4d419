"""The RKHP engine, the Taylor (THP) integrator and `rkhp integrate`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp

from rkhp.base.errors import InputError, NumericalFailure
from rkhp.integrators import integrate_ensemble, integrate_rkhp
from rkhp.integrators.failure import Failure
from rkhp.systems import get_system
from rkhp.tableaux.tableau import Tableau

T_ORDERS = 2.0
STEPS = (20, 40, 80, 160)
THP_REFERENCE = json.loads((Path(__file__).parent / "data" / "thp_reference.json").read_text())


def observed_order(system, method, steps=STEPS, t_final=T_ORDERS) -> float:
    """Least-squares slope of log(error) against log(h) (docs/theory.md §6), error vs the exact solution."""
    hs, errors = [], []
    for n in steps:
        h = t_final / n
        tr = integrate_rkhp(system, method, h, n).raise_if_failed()
        hs.append(h)
        errors.append(np.abs(tr.final_state - system.exact_solution(t_final)).max())
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


@pytest.mark.parametrize("realisation,method,order", [
    ("symmetric", "euler", 2), ("symmetric", "paper-two-stage", 3),
    ("symmetric", "paper-three-stage", 4), ("symmetric", "rk4", 4),
    ("shifted", "rk4", 4), ("shifted", "euler", 1),
])
def test_observed_orders_rigid_body(realisation, method, order):
    """Paper §5: degenerate orders on the symmetric realisation, classical ones on the shifted."""
    slope = observed_order(get_system("rigid-body", realisation), method)
    assert abs(slope - order) <= 0.15, slope


def test_tableau_is_data():
    """A tableau built from arrays gives the same run as the built-in with the same entries."""
    system = get_system("rigid-body")
    a = 0.5 * np.sqrt(3.0)
    own = Tableau.from_arrays([[0, 0, 0], [-a / 2, 0, 0], [0, 0.75, 0]],
                              [11 / 27, 0, 16 / 27], name="mine")
    ref = integrate_rkhp(system, "paper-three-stage", 0.1, 30)
    mine = integrate_rkhp(system, own, 0.1, 30)
    assert np.abs(mine.states - ref.states).max() < 1e-15


def _implicit_midpoint(system, h, n):
    """x1 = x0 + h pi grad H((x0 + x1)/2), solved by fixed point to round-off."""
    x = system.x0.copy()
    out = [x]
    for _ in range(n):
        y = x.copy()
        for _ in range(200):
            y_new = x + h * system.vector_field(0.5 * (x + y))
            if np.abs(y_new - y).max() <= 1e-17:
                break
            y = y_new
        x = y_new
        out.append(x)
    return np.array(out)


def test_euler_on_constant_pi_is_implicit_midpoint():
    """docs/theory.md §5: RKHP Euler on a constant pi is the implicit midpoint rule."""
    for realisation in ("symmetric",):
        system = get_system("pendulum", realisation)
        tr = integrate_rkhp(system, "euler", 0.1, 50).raise_if_failed()
        assert np.abs(tr.states - _implicit_midpoint(system, 0.1, 50)).max() < 1e-13


@pytest.mark.parametrize("name", ["rigid-body", "lotka-volterra"])
def test_casimirs_kept_over_10k_steps(name):
    system = get_system(name)
    tr = integrate_rkhp(system, "paper-three-stage", 1e-3, 10_000).raise_if_failed()
    values = np.array([system.casimir_values(x) for x in tr.states[::50]])
    assert np.abs(values - values[0]).max() <= 1e-13


def test_too_large_h_is_a_newton_failure():
    system = get_system("lotka-volterra")
    tr = integrate_rkhp(system, "rk4", 1.0, 10)
    assert not tr.ok and "Newton did not converge" in tr.status
    assert tr.cause == Failure.NEWTON_NO_CONVERGENCE
    assert tr.failed_step == 0 and len(tr.states) == 1 and "t = 0" in tr.status
    with pytest.raises(NumericalFailure):
        tr.raise_if_failed()
    # failure after some good steps keeps exactly those
    tr = integrate_rkhp(get_system("pendulum"), "rk4", 3.0, 5)
    assert not tr.ok and "Newton" in tr.status
    assert len(tr.states) == tr.failed_step + 1 and np.all(np.isfinite(tr.states))


def test_bad_input():
    system = get_system("rigid-body")
    for h in (0.0, -0.0, float("nan"), float("inf"), -float("inf")):  # negative h runs backwards
        with pytest.raises(InputError):
            integrate_rkhp(system, "euler", h, 10)
    with pytest.raises(InputError):
        integrate_rkhp(system, "no-such-method", 0.1, 10)
    with pytest.raises(InputError, match="components"):
        integrate_rkhp(system, "euler", 0.1, 10, x0=[1.0, 2.0])
    with pytest.raises(InputError, match="domain"):
        integrate_rkhp(get_system("lotka-volterra"), "euler", 0.1, 10, x0=[1.0, -2.0, 1.0])


def test_ensemble_matches_single_runs():
    system = get_system("lotka-volterra")
    rng = np.random.default_rng(0)
    x0s = system.x0 * rng.uniform(0.8, 1.2, size=(16, 3))
    finals = integrate_ensemble(system, "paper-three-stage", 0.05, 40, x0s)
    for x0, xf in zip(x0s, finals, strict=True):
        single = integrate_rkhp(system, "paper-three-stage", 0.05, 40, x0=x0)
        assert np.abs(single.final_state - xf).max() < 1e-15


def test_spec_file_integrates_like_builtin(tmp_path):
    from test_systems import SPEC_RIGID_BODY

    path = tmp_path / "rb.toml"
    path.write_text(SPEC_RIGID_BODY)
    for realisation in ("symmetric", "shifted"):
        spec = integrate_rkhp(get_system(path, realisation), "paper-three-stage", 0.05, 100)
        ref = integrate_rkhp(get_system("rigid-body", realisation), "paper-three-stage", 0.05, 100)
        assert np.abs(spec.states - ref.states).max() < 1e-13


def test_cli_integrate_json_and_failures():
    runner = CliRunner()
    res = runner.invoke(rkhp, ["integrate", "rigid-body", "--method", "paper-three-stage",
                               "--steps", "100", "--format", "json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    keys = ["system", "method", "h", "steps", "t_final", "x_final", "casimir_error",
            "energy_error", "newton_mean", "newton_max", "status", "compile_seconds", "run_seconds"]
    assert list(doc)[: len(keys)] == keys
    assert doc["status"] == "ok" and doc["steps"] == 100 and doc["h"] == pytest.approx(0.1)
    assert doc["casimir_error"] < 1e-14
    # docs/theory.md §7: the paper's 3-stage method reaches 3e-8 at T = 10 in 100 steps
    assert 1e-8 < doc["exact_error"] < 5e-8
    res = runner.invoke(rkhp, ["integrate", "lotka-volterra", "--method", "rk4", "--h", "1"])
    assert res.exit_code == 1
    for args in (["--h", "-1", "--t-final", "10"], ["--h", "nan"], ["--steps", "0"], ["--x0", "1,2"],
                 ["--x0", "a,b,c"], []):
        res = runner.invoke(rkhp, ["integrate", "rigid-body", "--method", "rk4", *args])
        assert res.exit_code == 2, args
    res = runner.invoke(rkhp, ["integrate", "rigid-body", "--method", "nosuch", "--steps", "5"])
    assert res.exit_code == 2


def test_thp_two_over_t0_is_rkhp_euler():
    """Over T_0 the THP of order 2 keeps only the leaf: S = h H, i.e. RKHP Euler."""
    from rkhp.integrators import integrate_taylor

    system = get_system("rigid-body")
    thp = integrate_taylor(system, 2, True, 0.1, 20).raise_if_failed()
    euler = integrate_rkhp(system, "euler", 0.1, 20)
    assert np.abs(thp.states - euler.states).max() <= 1e-15


def test_thp_degenerate_trees_vanish_on_symmetric_realisation():
    """On a degenerate realisation F(t) = 0 for t outside T_0: THP over T equals THP over T_0."""
    from rkhp.integrators import integrate_taylor

    system = get_system("lotka-volterra")
    over_t = integrate_taylor(system, 4, False, 0.1, 10).raise_if_failed()
    over_t0 = integrate_taylor(system, 4, True, 0.1, 10).raise_if_failed()
    assert np.abs(over_t.states - over_t0.states).max() <= 1e-14


@pytest.mark.parametrize("order,degenerate,expected", [(2, False, 2), (3, False, 3),
                                                       (4, False, 4), (3, True, 1)])
def test_thp_orders_on_shifted_rigid_body(order, degenerate, expected):
    """Paper Thm 5.1: THP of order N over T has order N on a general birealisation; over T_0
    it drops to order 1 there (the shifted realisation is not degenerate)."""
    from rkhp.integrators import integrate_taylor

    system = get_system("rigid-body", "shifted")
    hs, errors = [], []
    for n in (20, 40, 80):
        tr = integrate_taylor(system, order, degenerate, T_ORDERS / n, n).raise_if_failed()
        hs.append(T_ORDERS / n)
        errors.append(np.abs(tr.final_state - system.exact_solution(T_ORDERS)).max())
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert abs(slope - expected) <= 0.15, slope


@pytest.mark.parametrize("key", list(THP_REFERENCE["runs"]))
def test_thp_runs_as_its_own_loop_did(key):
    """THP on the driver (provider thp) against THP's final states and Newton iterations as its
    own Python loop computed them (tests/data/thp_reference.json): final state to 1e-13
    (relative to max(1, |y|)), the same iterations."""
    from rkhp.integrators.methods import resolve_method, resolve_system

    name, realisation, method = key.split("/")
    tr = resolve_method(method).integrate(resolve_system(name, realisation), 0.1, 20)
    expected = THP_REFERENCE["runs"][key]
    final = np.array(expected["final"])
    assert tr.status == expected["status"] and tr.extra["substep"] == "thp"
    assert np.abs(tr.states[-1] - final).max() <= 1e-13 * max(1.0, np.abs(final).max())
    assert int(tr.newton_iterations.sum()) == expected["newton_iterations"]


@pytest.mark.parametrize("key", list(THP_REFERENCE["failures"]))
def test_thp_names_the_step_where_newton_fails(key):
    """A step h too large: the same failing step, cause and Newton iterations per step as THP's
    own loop had (tests/data/thp_reference.json), the states before the failing step kept."""
    from rkhp.integrators.methods import resolve_method, resolve_system

    name, method, h = key.split("/")
    tr = resolve_method(method).integrate(resolve_system(name), float(h), 20)
    expected = THP_REFERENCE["failures"][key]
    assert tr.status == expected["status"] and tr.failed_step == expected["failed_step"]
    assert tr.newton_iterations.tolist() == expected["newton_iterations"]
    assert len(tr.states) == expected["failed_step"] + 1
    with pytest.raises(NumericalFailure, match=f"failed at step {expected['failed_step']} "):
        tr.raise_if_failed()


def test_thp_ensemble_runs_each_start_as_one_run():
    from rkhp.integrators.methods import resolve_method

    system, m = get_system("rigid-body", "shifted"), resolve_method("thp3")
    x0s = np.array([system.x0, [0.3, 0.4, 0.8], [0.1, 0.9, 0.2]])
    finals = m.integrate_ensemble(system, 0.1, 10, x0s, threads=2)
    for x0, final in zip(x0s, finals, strict=True):
        assert np.array_equal(final, m.integrate(system, 0.1, 10, x0=x0).final_state)


def test_taylor_arithmetic_against_sympy():
    """Degree-4 jets of a Hamiltonian using every primitive, against sympy's derivatives."""
    import math

    import sympy

    from rkhp.base.expressions import FUNCTIONS
    from rkhp.systems.spec import parse_spec_expression, to_program
    from rkhp.taylor.interpreter import interpreter, tape_work
    from rkhp.taylor.jets import jet_space, monomials
    from rkhp.taylor.tape import record_tape

    text = ("exp(x1) * sin(x2) / (1 + x1^2) + sqrt(x2 + 2) * cos(x1 * x2) + log(x1 + 3) "
            "- x2^(-3) + (x1 + 2)^1.5 + tan(x1 / 3) + cosh(x2) * tanh(x1) + sinh(x1 - x2) "
            "+ atan(x1 * x2 - 1)")
    assert all(f"{name}(" in text for name in FUNCTIONS)
    expr, symbols = parse_spec_expression(text, 2, "test")
    tape = record_tape(2, lambda x, p: [to_program(expr, symbols)(x)])
    x0 = (0.3, 0.7)
    D = 4
    space = jet_space(2, D)
    work = tape_work((tape,), space.size)
    for k in range(2):
        work.W[k, 0] = x0[k]
        work.W[k, 1 + k] = 1.0
    interpreter(tape)(tape, D, space, work)
    jet = work.W[tape.outputs[0]]
    at = dict(zip(symbols, x0, strict=True))
    for index, (e1, e2) in enumerate(monomials(2, D)):
        exact = float(sympy.diff(expr, symbols[0], e1, symbols[1], e2).evalf(30, subs=at))
        exact /= math.factorial(e1) * math.factorial(e2)
        assert jet[index] == pytest.approx(exact, rel=1e-12, abs=1e-12), (e1, e2)
