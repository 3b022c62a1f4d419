"""Symmetric birealisations as a third class (docs/theory.md §8): the quartic realisation, the
symmetric check, minimal stage counts, saved tableaux, and convergence on the integrators.

Values from outside the code: the birealisation axioms and the definition of the quartic
realisation (docs/theory.md §8: alpha'' = alpha(x + grad K(p), p), K(p) = sum_k (u_k . p)^4 / 24, here
differentiated independently by finite differences); the target orders of the searches; orders
observed with the integrators against the exact (rigid body) or DOP853 (Lotka–Volterra,
pendulum) reference solution. (The relations, the order-4/5 conditions of docs/theory.md §8 and the
paper's methods' symmetric orders are tested in tests/test_relations.py; the 3-stage proof for
symmetric order 5 and a 5-stage order-6 search in tests/test_search.py.)
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rkhp.base.json_form import json_form
from rkhp.integrators.methods import resolve_methods
from rkhp.search.driver import SearchOptions, search
from rkhp.studies.converge import converge
from rkhp.systems import builtin_systems, get_system
from rkhp.systems.check import check_birealisation
from rkhp.tableaux.files import load_tableau
from rkhp.tableaux.verification import verify

# ----------------------------------------------------------------------------- quartic realisation


@pytest.mark.parametrize("name", builtin_systems())
@pytest.mark.parametrize("realisation,degenerate,symmetric", [("symmetric", True, True),
                                                              ("shifted", False, False),
                                                              ("quartic", True, False)])
def test_check_reports_degenerate_and_symmetric_separately(name, realisation, degenerate,
                                                           symmetric):
    system = get_system(name, realisation)
    result = check_birealisation(system, samples=30, seed=5)
    assert result.ok  # the axioms of a birealisation hold in every realisation
    assert (result.degenerate, result.symmetric) == (degenerate, symmetric)
    assert (system.degenerate, system.symmetric) == (degenerate, symmetric)
    assert json_form(result)["symmetric"] is symmetric
    if not symmetric:
        assert result.symmetry > 1e-3


def _grad_k(p: np.ndarray) -> np.ndarray:
    """grad K by central differences of K(p) = (sum_k p_k^4 + (sum_k p_k)^4) / 24 (README)."""

    def K(q):
        return (np.sum(q**4) + np.sum(q) ** 4) / 24.0

    h = 1e-5
    return np.array([(K(p + h * e) - K(p - h * e)) / (2 * h) for e in np.eye(len(p))])


@pytest.mark.parametrize("name", builtin_systems())
def test_quartic_is_the_documented_composition(name):
    base, quartic = get_system(name, "symmetric"), get_system(name, "quartic")
    rng = np.random.default_rng(2)
    for _ in range(5):
        x = base.x0 * rng.uniform(0.8, 1.2, base.dim)
        p = rng.uniform(-0.5, 0.5, base.dim)
        shifted = x + _grad_k(p)
        assert np.allclose(quartic.alpha(x, p), base.alpha(shifted, p), rtol=0, atol=1e-8)
        assert np.allclose(quartic.beta(x, p), base.beta(shifted, p), rtol=0, atol=1e-8)
        # odd shift: beta''(x, p) != alpha''(x, -p) although beta(x, p) = alpha(x, -p)
        assert np.allclose(base.beta(x, p), base.alpha(x, -p), rtol=0, atol=1e-14)
        assert not np.allclose(quartic.beta(x, p), quartic.alpha(x, -p), rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", builtin_systems())
def test_cli_check_quartic(run_cli, name):
    rc, out, err = run_cli("check", name, "--realisation", "quartic", "--samples", "20",
                           "--format", "json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["ok"] is True and doc["degenerate"] is True and doc["symmetric"] is False
    assert doc["realisation"] == "quartic"


# ----------------------------------------------------------------------------- minimal stages


def test_symmetric_order_4_needs_3_stages():
    two = search(2, 4, "symmetric", options=SearchOptions(restarts=5, prove=True))
    assert two.found is None and two.proof.proved
    three = search(3, 4, "symmetric", options=SearchOptions(restarts=20, seed=0))
    orders = three.found.verification.orders
    assert orders["symmetric"] >= 4 and orders["degenerate"] < 4  # fewer stages than T_0 needs


def test_symmetric_order_5_with_4_stages():
    # 3 stages are proved impossible in tests/test_search.py (slow)
    four = search(4, 5, "symmetric", options=SearchOptions(restarts=20, seed=0))
    assert four.found is not None and four.found.verification.orders["symmetric"] >= 5


def test_cli_prove_two_stages_for_symmetric_order_4(run_cli):
    rc, out, err = run_cli("search", "--stages", "2", "--order", "4", "--symmetric",
                           "--restarts", "3", "--prove")
    assert rc == 1 and "proved impossible" in err  # no tableau found (docs/exit-status.md)
    assert "proved impossible" in out and "Groebner basis [1]" in out


# ----------------------------------------------------------------------------- saved tableaux


@pytest.mark.parametrize("name,stages,order", [("search-symmetric-o4-s3", 3, 4),
                                               ("search-symmetric-o5-s4", 4, 5),
                                               ("search-symmetric-o7-s6", 6, 7)])
def test_saved_symmetric_tables(name, stages, order):
    tab = load_tableau(name)
    ver = verify(tab)
    assert tab.is_explicit and tab.stages == stages
    assert ver.orders["symmetric"] == order and ver.orders["degenerate"] < order
    assert ver.precision == "exact" or tab.digits >= 60
    assert ver.claim_ok


def test_paper_three_stage_has_symmetric_order_4_in_verify():
    assert verify("paper-three-stage").orders["symmetric"] == 4


# ----------------------------------------------------------------------------- convergence


def _orders(system, realisation, methods, steps, t_final=None):
    study = converge(get_system(system, realisation), resolve_methods(methods), steps, t_final)
    return {m.method: m for m in study.methods}, study


O6 = "search-symmetric-o6-s5"


def test_symmetric_order_6_observed_and_dropping_on_quartic_rigid_body():
    sym, study = _orders("rigid-body", "symmetric", [O6], [20, 40, 80, 160])
    assert study.symmetric and json_form(study)["symmetric"] is True
    assert sym[O6].expected_order == 6 and sym[O6].verdict == "confirmed"
    assert sym[O6].observed_order == pytest.approx(6, abs=0.2)
    quartic, study = _orders("rigid-body", "quartic", [O6, "paper-three-stage"],
                             [160, 320, 640, 1280])
    assert study.degenerate and not study.symmetric
    assert quartic[O6].expected_order == 3  # its degenerate order
    assert quartic[O6].observed_order == pytest.approx(3, abs=0.2)
    assert quartic["paper-three-stage"].observed_order == pytest.approx(4, abs=0.2)
    assert all(m.verdict == "confirmed" for m in quartic.values())


@pytest.mark.slow
@pytest.mark.parametrize("system,sym_steps,quartic_steps", [
    ("lotka-volterra", [40, 80, 160, 320], [160, 320, 640, 1280, 2560, 5120]),
    ("pendulum", [20, 40, 80, 160], [160, 320, 640, 1280])])
def test_symmetric_order_6_observed_and_dropping_on_quartic(system, sym_steps, quartic_steps):
    sym, _ = _orders(system, "symmetric", [O6, "paper-three-stage"], sym_steps)
    assert sym[O6].observed_order == pytest.approx(6, abs=0.2)
    quartic, _ = _orders(system, "quartic", [O6, "paper-three-stage"], quartic_steps)
    assert quartic[O6].observed_order == pytest.approx(3, abs=0.2)
    assert quartic["paper-three-stage"].observed_order == pytest.approx(4, abs=0.2)
    assert all(m.verdict == "confirmed" for m in [sym[O6], *quartic.values()])


def test_cli_converge_quartic(run_cli):
    rc, out, err = run_cli("converge", "pendulum", "--realisation", "quartic", "--method",
                           f"{O6},paper-three-stage", "--steps", "160", "--refinements", "3",
                           "--format", "json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["realisation"] == "quartic" and doc["degenerate"] is True
    assert doc["symmetric"] is False
    assert [m["expected_order"] for m in doc["methods"]] == [3, 4]


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("args", [
    ["conditions", "--order", "9", "--symmetric"],
    ["relations", "--order", "9"],
    ["search", "--stages", "3", "--order", "4", "--symmetric", "--degenerate"],
    ["check", "rigid-body", "--realisation", "cubic"],
    ["converge", "rigid-body", "--realisation", "quadratic"],
    ["integrate", "pendulum", "--method", "rk4", "--steps", "10", "--realisation", "x"],
])
def test_bad_input_is_one_line_exit_2(run_cli, args):
    rc, _, err = run_cli(*args)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
