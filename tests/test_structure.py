"""Checks of Poisson matrices given as expressions (rkhp.systems.structure).

The structures come from outside the code: so(3)* (Lie–Poisson of the rigid body), the Nambu
bracket pi v = grad C x v (Poisson for every C; Nambu 1973), 1/B(x) J in 2-d (every antisymmetric
2 x 2 matrix is Poisson), log-canonical pi_ij = lambda_ij x_i x_j (Poisson for every antisymmetric
lambda), and the classical criterion in 3-d: pi_ij = eps_ijk w_k is Poisson iff w . curl w = 0.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy

from rkhp.base.errors import InputError
from rkhp.base.expressions import parse_expression, variable_names
from rkhp.systems.structure import (
    TOLERANCE,
    check_antisymmetric_expressions,
    check_matrix_finite_at,
    check_structure,
    decide_zero,
    lie_poisson_matrix,
    log_canonical_matrix,
)

X = sympy.symbols("x1:4", real=True)


def matrix(rows):
    n = len(rows)
    return [[parse_expression(e, variable_names(n)) for e in row] for row in rows]


def expr(text, n=3):
    return parse_expression(text, variable_names(n))


def from_w(w):
    """pi_ij = eps_ijk w_k, i.e. pi v = v x w (pi_12 = w3, pi_23 = w1, pi_31 = w2)."""
    return [[sum(sympy.LeviCivita(i, j, k) * w[k] for k in range(3)) for j in range(3)]
            for i in range(3)]


def nambu(C):
    """pi v = grad C x v, i.e. pi_ik = eps_ijk d_j C."""
    g = [sympy.diff(C, v) for v in X]
    return [[sum(sympy.LeviCivita(i, j, k) * g[j] for j in range(3)) for k in range(3)]
            for i in range(3)]


SO3 = [["0", "-x3", "x2"], ["x3", "0", "-x1"], ["-x2", "x1", "0"]]


def test_so3_and_its_casimir():
    check = check_structure(matrix(SO3), casimirs=[expr("(x1^2 + x2^2 + x3^2)/2")])
    assert check.method == "symbolic" and check.casimir_identities == 3


def test_not_a_casimir_is_refused():
    with pytest.raises(InputError, match=r"casimir 1 \(x1\) is not a Casimir.*\{C, x2\} = -x3"):
        check_structure(matrix(SO3), casimirs=[expr("x1")])


@pytest.mark.parametrize("C", ["x1^2/2 + x2^4/4 + x3^6/6 + x1*x2*x3",
                               "cos(x1) + x2^4/4 + exp(x3) + x1*x2*x3"])
def test_nambu_structure_is_poisson_with_casimir_C(C):
    c = expr(C)
    check = check_structure(nambu(c), casimirs=[c], x0=[0.5, 0.5, 0.5])
    assert check.jacobi_triples == 1 and check.method == "symbolic"
    # a function of C is a Casimir too; an unrelated function is not
    check_structure(nambu(c), casimirs=[sympy.exp(c)], x0=[0.5, 0.5, 0.5])
    with pytest.raises(InputError, match="is not a Casimir"):
        check_structure(nambu(c), casimirs=[expr("x1^2 + x2^2 + x3^2")], x0=[0.5, 0.5, 0.5])


def test_numeric_only_when_no_symbolic_budget():
    c = expr("cos(x1) + x2^4/4 + exp(x3) + x1*x2*x3")
    check = check_structure(nambu(c), casimirs=[c], x0=[0.5, 0.5, 0.5], symbolic_seconds=None)
    assert check.method == "numeric" and check.jacobi_symbolic == 0
    assert check.residual <= 1e-14 and check.points == 12


def test_two_dimensional_one_over_B():
    B = "(1 + 2*x1^2 + 2*x2^2)"
    check = check_structure(matrix([["0", f"1/{B}"], [f"-1/{B}", "0"]]))
    assert check.jacobi_triples == 0


@pytest.mark.parametrize("w, poisson", [
    # w = grad f: curl w = 0
    (("x1", "0", "x3"), True),
    # w = g grad f: w . curl w = g grad f . (grad g x grad f) = 0
    (("x2*x3*exp(x1)", "x1*x3*exp(x1)", "x1*x2*exp(x1)"), True),
    # w . curl w = (x2, 0, 1) . (0, 0, -1) = -1
    (("x2", "0", "1"), False),
    # linear, not a Lie algebra: {x1,x2} = x1: w = (x1, x2, x1), w . curl w = -x2
    (("x1", "x2", "x1"), False),
    # w . curl w = (sin x2, 0, 1) . (0, 0, -cos x2) = -cos x2
    (("sin(x2)", "0", "1"), False),
])
def test_three_dimensional_criterion(w, poisson):
    ws = [expr(v) for v in w]
    curl = [sympy.diff(ws[2], X[1]) - sympy.diff(ws[1], X[2]),
            sympy.diff(ws[0], X[2]) - sympy.diff(ws[2], X[0]),
            sympy.diff(ws[1], X[0]) - sympy.diff(ws[0], X[1])]
    assert (sympy.simplify(sum(a * b for a, b in zip(ws, curl))) == 0) == poisson
    if poisson:
        check_structure(from_w(ws))
    else:
        with pytest.raises(InputError, match=r"fails the Jacobi identity at \(i, j, k\) = "
                                             r"\(1, 2, 3\)"):
            check_structure(from_w(ws))


def test_failing_triple_and_residual_of_a_hand_checked_example():
    """pi = [[0,1,0],[-1,0,x2],[0,-x2,0]]: {x1,{x2,x3}} = {x1, x2} = 1, the other two terms
    vanish, so J_123 = 1 everywhere."""
    bad = matrix([["0", "1", "0"], ["-1", "0", "x2"], ["0", "-x2", "0"]])
    for seconds in (10.0, None):
        with pytest.raises(InputError) as info:
            check_structure(bad, symbolic_seconds=seconds)
        message = str(info.value)
        assert "(i, j, k) = (1, 2, 3)" in message and "cyclic = 1 at x" in message
        assert "\n" not in message


def test_the_briefs_example_is_poisson():
    """pi = [[0, x3, 0], [-x3, 0, x1], [0, -x1, 0]] has w = (x1, 0, x3) = grad (|x|^2 - x2^2)/2:
    curl w = 0, so it IS Poisson (every Jacobi term vanishes on its own)."""
    check_structure(matrix([["0", "x3", "0"], ["-x3", "0", "x1"], ["0", "-x1", "0"]]))


def test_log_canonical_any_lambda_and_linear_structures():
    rng = np.random.default_rng(1)
    L = rng.integers(-3, 4, size=(5, 5)).astype(float)
    L = L - L.T
    check = check_structure(log_canonical_matrix(L), x0=np.ones(5))
    assert check.jacobi_triples > 0 and check.method == "symbolic"
    so3 = np.zeros((3, 3, 3))
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        so3[i, j, k], so3[j, i, k] = -1.0, 1.0
    check_structure(lie_poisson_matrix(so3))
    broken = so3.copy()
    broken[0, 1, 2], broken[1, 0, 2] = 0.0, 0.0
    broken[0, 1, 0], broken[1, 0, 0] = 1.0, -1.0  # {x1, x2} = x1 instead of -x3
    with pytest.raises(InputError, match="Jacobi"):
        check_structure(lie_poisson_matrix(broken))


@pytest.mark.parametrize("rows, message", [
    ([["0", "x2"], ["x2", "0"]], r"\(1, 2\) and \(2, 1\) do not sum to 0"),
    ([["x1", "1"], ["-1", "0"]], r"diagonal entry \(1, 1\)"),
    ([["0", "x1*(x2 + 1)"], ["-x1*x2 - x1 + 1e-30", "0"]], "do not sum to 0"),
])
def test_not_antisymmetric(rows, message):
    with pytest.raises(InputError, match=message):
        check_antisymmetric_expressions(matrix(rows))


def test_antisymmetric_up_to_rewriting():
    check_antisymmetric_expressions(matrix([["0", "x1*(x2 + 1)"], ["-x1*x2 - x1", "0"]]))
    check_antisymmetric_expressions(matrix([["0", "sin(x1)^2"], ["cos(x1)^2 - 1", "0"]]))


def test_singular_at_x0():
    pi = matrix([["0", "1/(x1 - 1/2)"], ["-1/(x1 - 1/2)", "0"]])
    with pytest.raises(InputError, match=r"singular at x0 = \(0.5, 1\): entry \(1, 2\)"):
        check_matrix_finite_at(pi, [0.5, 1.0])
    assert check_matrix_finite_at(pi, [1.5, 1.0])[0, 1] == 1.0


def test_decide_zero():
    x1, x2, _ = X
    assert decide_zero(sympy.sin(x1) ** 2 + sympy.cos(x1) ** 2 - 1) is True
    assert decide_zero((x1 + x2) ** 3 - x1**3 - 3 * x1**2 * x2 - 3 * x1 * x2**2 - x2**3) is True
    assert decide_zero(x1 / (1 + x2) - x1 / (1 + x2) + x2 * 1e-20) is False
    # too large to expand within the bound: undecided, left to the numeric check
    assert decide_zero((x1 + x2 + 1) ** 200 * (x1 - x2) ** 50 - 1) is None
    assert TOLERANCE <= 1e-8


@pytest.mark.parametrize("c", ["1", "1e200"])
def test_jacobi_failure_found_whatever_the_size_of_pi(c):
    """c [[0, 1, 0], [-1, 0, e^x2], [0, -e^x2, 0]]: J_123 = c^2 e^x2, all of its terms; at
    c = 1e200 the products of the numeric check would overflow (inf - inf) unless scaled."""
    bad = matrix([["0", c, "0"], [f"-{c}", "0", f"{c}*exp(x2)"], ["0", f"-{c}*exp(x2)", "0"]])
    for seconds in (10.0, None):
        with pytest.raises(InputError, match=r"\(i, j, k\) = \(1, 2, 3\)") as info:
            check_structure(bad, symbolic_seconds=seconds)
        assert "\n" not in str(info.value)
    assert "cyclic = inf" not in str(info.value) and "nan" not in str(info.value)


@pytest.mark.parametrize("c", [1.0, 1e200])
def test_casimir_failure_found_whatever_the_size_of_pi_and_grad_c(c):
    """so(3)* times c: c |x|^2 is a Casimir, c e^x1 is not (grad C . pi of size c^2)."""
    so3 = np.zeros((3, 3, 3))
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        so3[i, j, k], so3[j, i, k] = -c, c
    pi = lie_poisson_matrix(so3)
    check_structure(pi, casimirs=[expr(f"{c:g}*(x1^2 + x2^2 + x3^2)")], x0=[0.5, 0.0, 0.9])
    with pytest.raises(InputError, match=r"casimir 1 .* is not a Casimir") as info:
        check_structure(pi, casimirs=[expr(f"{c:g}*exp(x1)")], x0=[0.5, 0.0, 0.9], symbolic_seconds=None)
    assert "\n" not in str(info.value)
