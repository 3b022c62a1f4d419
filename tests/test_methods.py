"""One method grammar for every command and the Python API (docs/methods.md).

Expected values come from outside the code: the rigid body's closed-form solution (Jacobi
elliptic functions), the orders of the methods (RK4: 4; THP of order N: N, paper Thm 5.1; the
implicit midpoint rule: 2, and it keeps the quadratic Casimir |x|^2 exactly up to round-off).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp as cli

import rkhp
from rkhp.base.errors import InputError
from rkhp.integrators.methods import resolve_method
from rkhp.systems import get_system


def _error(trajectory) -> float:
    exact = get_system("rigid-body").exact_solution(trajectory.times[-1])
    return float(np.abs(trajectory.final_state - exact).max())


def test_rkhp_integrate_takes_names():
    by_name = rkhp.integrate("rigid-body", "rk4", 0.1, 100)
    by_object = rkhp.integrate(get_system("rigid-body"), rkhp.load_tableau("rk4"), 0.1, 100)
    assert by_name.ok and np.array_equal(by_name.states, by_object.states)
    # order 4: halving h divides the error at T = 10 by about 16
    half = rkhp.integrate("rigid-body", "rk4", 0.05, 200)
    assert 12 < _error(by_name) / _error(half) < 20


@pytest.mark.parametrize("spec, kind", [("rk4", "rkhp"), ("thp4", "taylor"), ("thp3-t0", "taylor"),
                                        ("classical:rk4", "classical"), ("implicit-midpoint", "implicit-midpoint"),
                                        ("scipy:dop853", "scipy"), ("gauss2", "rkhp")])
def test_every_form_resolves(spec, kind):
    method = resolve_method(spec)
    assert method.kind == kind and method.name == spec
    assert resolve_method(method) is method


def test_the_resolver_does_not_refuse_implicit_tableaux():
    # Gauss2 is implicit (HW II, Table IV.5.1): whether it integrates is the engine's business
    method = resolve_method("gauss2")
    assert method.tableau.kind == "implicit" and method.expected_order("general") == 4


@pytest.mark.parametrize("spec, steps, order", [("thp4", (10, 20), 4), ("classical:rk4", (40, 80), 4),
                                                ("implicit-midpoint", (40, 80), 2)])
def test_each_kind_integrates_with_its_order(spec, steps, order):
    coarse, fine = (rkhp.integrate("rigid-body", spec, 10 / n, n) for n in steps)
    assert coarse.ok and fine.ok
    assert abs(np.log2(_error(coarse) / _error(fine)) - order) < 0.35


def test_midpoint_keeps_the_quadratic_casimir():
    t = rkhp.integrate("rigid-body", "implicit-midpoint", 0.1, 100)
    norms = (t.states**2).sum(axis=1)
    assert np.abs(norms - norms[0]).max() < 1e-13


def test_bad_method_names():
    for spec, message in (("thp9", "from 1 to 8"), ("scipy:euler", "unknown scipy method"),
                          ("classical:nope", "unknown tableau"), ("", "empty")):
        with pytest.raises(InputError, match=message):
            resolve_method(spec)
    with pytest.raises(InputError, match="runs by tolerance"):
        rkhp.integrate("rigid-body", "scipy:dop853", 0.1, 10)


def _cli(*args):
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.output


@pytest.mark.parametrize("method", ["classical:rk4", "implicit-midpoint", "thp3", "paper-three-stage"])
def test_integrate_command_takes_every_form(method):
    rc, out = _cli("integrate", "rigid-body", "--method", method, "--steps", "40", "--format", "json")
    assert rc == 0, out
    doc = json.loads(out)
    assert doc["method"] == method and doc["status"] == "ok" and doc["exact_error"] < 2e-2


def test_integrate_without_a_method_runs_a_composition_of_order_8():
    # kahan-li8, Kahan & Li's composition of 17 RKHP Euler substeps, has order 8 on a symmetric
    # birealisation (Kahan & Li 1997; docs/compositions.md), which the rigid body's is: halving h
    # divides its error against the closed-form solution by about 2^8
    errors = []
    for steps in ("12", "24"):
        rc, out = _cli("integrate", "rigid-body", "--steps", steps, "--format", "json")
        assert rc == 0, out
        doc = json.loads(out)
        assert doc["method"] == "kahan-li8" and doc["status"] == "ok"
        errors.append(doc["exact_error"])
    assert 7.5 < np.log2(errors[0] / errors[1]) < 8.7


def test_thp_orders_per_class():
    # THP of order N over T has order N (paper Thm 5.1); over T_0 the tree b[b] is missing, so on
    # a general realisation order 1; in the symmetric class the even orders' conditions have
    # weights summing to 0, so that odd N gains one order there
    assert resolve_method("thp3").expected_order("general") == 3
    assert resolve_method("thp3-t0").expected_order("general") == 1
    assert resolve_method("thp4-t0").expected_order("degenerate") == 4
    assert resolve_method("thp3").expected_order("symmetric") == 4


@pytest.mark.parametrize("realisation, expected", [("symmetric", 4), ("shifted", 3)])
def test_converge_takes_thp_and_x0(realisation, expected):
    # away from the default start there is no closed form: the reference is DOP853
    rc, out = _cli("converge", "rigid-body", "--method", "thp3,classical:rk4", "--x0", "0.5,0.5,0.5",
                   "--realisation", realisation, "--steps", "40", "--refinements", "3", "--format", "json")
    assert rc == 0, out
    doc = json.loads(out)
    assert doc["x0"] == [0.5, 0.5, 0.5] and doc["reference"]["kind"] == "dop853"
    assert [(m["method"], m["expected_order"], m["verdict"]) for m in doc["methods"]] == [
        ("thp3", expected, "confirmed"), ("classical:rk4", 4, "confirmed")]


def test_bench_and_stress_take_x0():
    rc, out = _cli("bench", "rigid-body", "--method", "paper-two-stage", "--peers", "scipy:rk45",
                   "--x0", "0.6,0,0.8", "--steps", "10,20", "--tolerances", "1e-6", "--repeats", "1",
                   "--format", "json")
    assert rc == 0, out
    doc = json.loads(out)
    assert doc["x0"] == [0.6, 0.0, 0.8] and [c["method"] for c in doc["curves"]] == ["paper-two-stage",
                                                                                       "scipy:rk45"]
    rc, out = _cli("stress", "rigid-body", "--method", "paper-two-stage", "--x0", "0.6,0,0.8", "--t-final",
                   "2", "--long-steps", "200", "--sweep-coarsest", "8", "--round-off-steps", "8,16,32",
                   "--format", "json")
    assert rc == 0, out
    assert json.loads(out)["x0"] == [0.6, 0.0, 0.8]


def test_peers_and_methods_mean_the_same():
    # `midpoint` is the explicit midpoint tableau everywhere; the implicit midpoint rule is
    # `implicit-midpoint`, in --peers as in --method
    assert resolve_method("midpoint").kind == "rkhp"
    rc, out = _cli("bench", "rigid-body", "--peers", "midpoint")
    assert rc == 2 and "implicit-midpoint" in out
