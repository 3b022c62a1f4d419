"""Modified and modifying Hamiltonians (docs/modified.md, docs/theory.md §11).

Expected values come from outside the code: the exact flow (H~ = H), the principal error terms of
first-order backward error analysis, the implicit midpoint rule's modified Hamiltonian on the
harmonic oscillator ((2/h) arctan(h/2) H, the rotation angle of the Cayley transform) and its
modifying Hamiltonian ((2/h) tan(h/2) H), the count of free trees (OEIS A000055).
"""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest
import sympy

from rkhp.base.errors import InputError
from rkhp.base.modular import FieldEmbeddings, reconstruct_coordinates
from rkhp.series.modified import (
    NotATreeSeries,
    canonical_basis,
    canonical_coefficients,
    method_character,
    modified_hamiltonian,
    modifying_hamiltonian,
)
from rkhp.tableaux.files import load_tableau
from rkhp.trees.algebra import exact_flow_character
from rkhp.trees.rooted import LEAF, count_trees, parse_tree, trees_of_order, trees_up_to

T = parse_tree


def _euler(order):
    return method_character(load_tableau("euler"), order)


# ----------------------------------------------------------------------------- number fields


def test_field_embeddings_round_trip_through_several_primes():
    x = sympy.Rational(28569, 14186) - 5 * sympy.sqrt(3) / 77
    field = sympy.QQ.algebraic_field(sympy.sqrt(3))
    emb = FieldEmbeddings(field)
    primes = []
    for p, roots in emb.primes():
        assert len(roots) == 2 and all((r * r - 3) % p == 0 for r in roots)
        primes.append((p, roots))
        if len(primes) == 2:
            break
    coords = [emb.coordinates_mod(emb.images(x, p, roots), p, roots) for p, roots in primes]
    back = emb.element(reconstruct_coordinates(coords, [p for p, _ in primes]))
    assert sympy.simplify(back - x) == 0


def test_field_embeddings_of_two_radicals():
    field = sympy.QQ.algebraic_field(sympy.sqrt(2), sympy.sqrt(3))
    emb = FieldEmbeddings(field)
    x = sympy.sqrt(2) / 3 + sympy.sqrt(6)
    p, roots = next(emb.primes())
    assert len(roots) == 4
    q = emb.coordinates_mod(emb.images(x, p, roots), p, roots)
    p2, roots2 = next(r for r in emb.primes() if r[0] != p)
    q2 = emb.coordinates_mod(emb.images(x, p2, roots2), p2, roots2)
    assert sympy.simplify(emb.element(reconstruct_coordinates([q, q2], [p, p2])) - x) == 0


# ----------------------------------------------------------------------------- acceptance: exact flow, principal error


@pytest.mark.parametrize("cls", ["general", "degenerate", "symmetric"])
@pytest.mark.parametrize("solve", [modified_hamiltonian, modifying_hamiltonian])
def test_the_exact_flow_is_its_own_modified_hamiltonian(cls, solve):
    series = solve(exact_flow_character(5), 5, cls)
    assert series.terms() == [(LEAF, 1)]


def test_principal_error_terms_of_the_paper_three_stage_method():
    """Degenerate order 4 (paper §5.2): no correction below h^4, and the h^4 term is
    sum over T_0 of order 5 of (a(t) - e(t))/sigma(t) F(t) (first-order backward error analysis)."""
    a = method_character(load_tableau("paper-three-stage"), 6)
    series = modified_hamiltonian(a, 6, "degenerate")
    assert all(t.order in (1, 5, 6) for t, _ in series.terms())
    principal = {t: (a[t] - t.e) / t.sigma for t in trees_of_order(5, True)}
    for t in trees_of_order(5, True):
        assert sympy.simplify(series.coefficient(t) - principal[t]) == 0, t
    # symmetric class: the same term written in the canonical basis
    sym = modified_hamiltonian(a, 5, "symmetric")
    expected = canonical_coefficients(principal, 5, "symmetric")
    for t in canonical_basis(5, "symmetric"):
        assert sympy.simplify(sym.coefficient(t) - expected.get(t, 0)) == 0, t


def test_principal_error_terms_of_rk4_over_t():
    """General order 4 (Kutta): the first correction is h^4 sum over T of order 5 of (a - e)/sigma."""
    a = method_character(load_tableau("rk4"), 5)
    series = modified_hamiltonian(a, 5, "general")
    assert [t.order for t, _ in series.terms()][0] == 1
    assert all(t.order in (1, 5) for t, _ in series.terms())
    for t in trees_of_order(5):
        assert series.coefficient(t) == (a[t] - t.e) / t.sigma


def test_euler_on_degenerate_realisations_starts_with_the_midpoint_rule_term():
    """RKHP Euler: H~ = H - h^2/6 F(b[b,b]) + O(h^3) (docs/theory.md §11: -h^2/24 H''(f, f))."""
    series = modified_hamiltonian(_euler(3), 3, "degenerate")
    assert series.terms() == [(LEAF, 1), (T("b[b,b]"), Fraction(-1, 6))]


def test_the_modifying_hamiltonian_starts_with_the_opposite_correction():
    modifying = modifying_hamiltonian(_euler(3), 3, "symmetric")
    assert modifying.terms() == [(LEAF, 1), (T("b[b,b]"), Fraction(1, 6))]


def test_degenerate_and_symmetric_results_agree_modulo_the_relations():
    """Two different generic families (shifted constant pi vs constant pi): the degenerate series,
    reduced with the symmetric relations, is the symmetric series."""
    a = method_character(load_tableau("paper-three-stage"), 6)
    deg = modified_hamiltonian(a, 6, "degenerate")
    sym = modified_hamiltonian(a, 6, "symmetric")
    for n in range(1, 7):
        reduced = canonical_coefficients({t: deg.coefficient(t) for t in trees_of_order(n, True)}, n, "symmetric")
        for t in canonical_basis(n, "symmetric"):
            assert sympy.simplify(reduced.get(t, 0) - sym.coefficient(t)) == 0, (n, t)


# ----------------------------------------------------------------------------- harmonic oscillator


@pytest.mark.parametrize("cls", ["degenerate", "symmetric"])
def test_implicit_midpoint_on_the_harmonic_oscillator_is_the_arctan_series(cls, oscillator):
    """The implicit midpoint rule rotates by 2 arctan(h/2): H~ = (2/h) arctan(h/2) H
    = (1 - h^2/12 + h^4/80 - ...) H, to the order computed (6: the tree series stops there)."""
    got = oscillator(modified_hamiltonian(_euler(6), 6, cls).coefficients, 6)
    assert got == [1, 0, Fraction(-1, 12), 0, Fraction(1, 80), 0]


def test_modifying_hamiltonian_of_the_midpoint_rule_is_the_tan_series(oscillator):
    """A midpoint step of K = c H rotates by 2 arctan(c h / 2): the exact rotation by h needs
    c = (2/h) tan(h/2) = 1 + h^2/12 + h^4/120 + ..."""
    got = oscillator(modifying_hamiltonian(_euler(6), 6, "symmetric").coefficients, 6)
    assert got == [1, 0, Fraction(1, 12), 0, Fraction(1, 120), 0]


# ----------------------------------------------------------------------------- where no tree series exists


def test_euler_on_general_realisations_has_no_tree_series_at_order_3():
    with pytest.raises(NotATreeSeries) as info:
        modified_hamiltonian(_euler(3), 3, "general")
    assert info.value.order == 3


def test_euler_on_symmetric_realisations_has_no_tree_series_at_order_7():
    """At order 7 the F(t) of T_0 span 17 - 7 = 10 dimensions on constant pi, the elementary
    Hamiltonians of the free trees of order 7 (OEIS A000055: 11, none vanishing at odd order) 11:
    the implicit midpoint rule's h^6 term needs the missing one."""
    from rkhp.trees.relations import shipped_order

    assert count_trees(7, True) - len(shipped_order(7).relations) == 10
    with pytest.raises(NotATreeSeries) as info:
        modified_hamiltonian(_euler(7), 7, "symmetric")
    assert info.value.order == 7


# ----------------------------------------------------------------------------- input


def test_bad_input_is_refused():
    with pytest.raises(InputError):
        modified_hamiltonian(_euler(3), 9, "symmetric")
    with pytest.raises(InputError):
        modified_hamiltonian({LEAF: 1}, 3, "symmetric")
    with pytest.raises(InputError):
        modified_hamiltonian(_euler(3), 3, "nonsense")
    zero = {t: Fraction(0) for t in trees_up_to(3)}
    with pytest.raises(InputError):
        modifying_hamiltonian(zero, 3, "general")
    with pytest.raises(InputError):
        method_character(load_tableau("dop853"), 3)
    with pytest.raises(InputError):
        modified_hamiltonian(_euler(3), 3, "symmetric", seed=-1)


def test_cli_json_keys_and_values(run_cli):
    code, out, err = run_cli("modified", "--method", "euler", "--order", "5", "--symmetric", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert list(doc)[:4] == ["method", "class", "order", "terms"]
    assert doc["method"] == "euler" and doc["class"] == "symmetric" and doc["order"] == 5
    terms = {d["tree"]: d["coefficient"] for d in doc["terms"]}
    assert terms["b"] == "1" and terms["b[b,b]"] == "-1/6"
    assert all(set(d) == {"tree", "order", "coefficient"} for d in doc["terms"])


@pytest.mark.parametrize("cls", [(), ("--degenerate",), ("--symmetric",)])
def test_cli_exact_flow_gives_h_itself(run_cli, cls):
    # the exact flow's character e(t) = 1/gamma(t) (paper eq. (e)): H~ = H, every higher term zero
    code, out, err = run_cli("modified", "--method", "exact", "--order", "6", *cls, "--format", "json")
    assert code == 0, err
    assert json.loads(out)["terms"] == [{"tree": "b", "order": 1, "coefficient": "1"}]


def test_cli_errors_are_one_line(run_cli):
    code, out, err = run_cli("modified", "--method", "euler", "--order", "4")
    assert code == 1 and out == "" and len(err.strip().splitlines()) == 1 and "order 3" in err
    code, out, err = run_cli("modified", "--method", "euler", "--order", "0")
    assert code == 2 and len(err.strip().splitlines()) == 1
    code, out, err = run_cli("modified", "--method", "euler", "--order", "3", "--symmetric", "--degenerate")
    assert code == 2 and len(err.strip().splitlines()) == 1


# ----------------------------------------------------------------------------- evaluation on systems


def test_midpoint_modified_hamiltonian_on_the_pendulum():
    """H~ = H - h^2/24 H''(f, f), f = pi grad H (Hairer-Lubich-Wanner, ch. IX), for RKHP Euler on the
    pendulum H = p^2/2 - cos q: H''(f, f) = cos(q) p^2 + sin(q)^2."""
    from rkhp.integrators.modified_energy import ModifiedEnergy
    from rkhp.systems import get_system

    pendulum = get_system("pendulum")
    h = 0.3
    H3 = ModifiedEnergy(pendulum, modified_hamiltonian(_euler(3), 3, "symmetric"), h)
    for q, p in np.random.default_rng(1).uniform(-2, 2, size=(5, 2)):
        expected = p * p / 2 - np.cos(q) - h * h / 24 * (np.cos(q) * p * p + np.sin(q) ** 2)
        assert H3([q, p]) == pytest.approx(expected, abs=1e-14)


def test_integrate_reports_the_modified_energy_error(run_cli):
    code, out, err = run_cli("integrate", "pendulum", "--method", "euler", "--h", "0.1", "--t-final", "20",
                             "--modified", "6", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["modified_order"] == 6 and doc["modified_class"] == "symmetric"
    # the implicit midpoint rule conserves H~_6 to O(h^6) while H oscillates at O(h^2)
    assert doc["modified_energy_error"] < 1e-3 * doc["energy_error_max"]
    code, out, err = run_cli("integrate", "pendulum", "--method", "euler", "--h", "0.1", "--t-final", "1",
                             "--modified", "7")
    assert code == 1 and "order 7" in err and len(err.strip().splitlines()) == 1


def test_stress_long_run_has_the_modified_energy():
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.stress import long_run
    from rkhp.systems import get_system

    result = long_run([resolve_method("paper-three-stage")], get_system("lotka-volterra"), 0.1, 3000)
    run = result.runs[0]
    assert run.modified.order == 6 and run.modified.condition_class == "symmetric" and run.modified.stride == 2
    assert run.modified.max < max(run.energy_windows) / 5
    assert result.peer.modified is None


@pytest.mark.slow
def test_rigid_body_modified_energy_of_the_paper_method(run_cli):
    """paper-three-stage on the rigid body, h = 0.2, 10^4 steps: the error of H~_N falls as
    N goes 4, 6, 8, and at N = 8 it is at least 100 times below the energy error of H."""
    errors = {}
    for N in (4, 6, 8):
        code, out, err = run_cli("integrate", "rigid-body", "--method", "paper-three-stage", "--h", "0.2",
                                 "--t-final", "2000", "--modified", str(N), "--format", "json")
        assert code == 0, err
        doc = json.loads(out)
        assert doc["steps"] == 10_000
        errors[N] = doc["modified_energy_error"]
        energy = doc["energy_error_max"]
    assert errors[4] > errors[6] > errors[8]
    assert errors[8] * 100 <= energy


def test_the_taylor_integrator_misses_exactly_the_next_order():
    """THP of order N (paper Thm 5.1) has the character e up to N and 0 above: its first correction
    is -sum over the trees of order N + 1 of e(t)/sigma(t) F(t)."""
    from rkhp.integrators.methods import resolve_method

    series = modified_hamiltonian(method_character(resolve_method("thp4-t0"), 5), 5, "degenerate")
    assert series.terms() == [(LEAF, 1)] + [(t, -t.e / t.sigma) for t in trees_of_order(5, True)]
