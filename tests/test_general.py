"""The general family (rkhp.systems.general) and the truncated spray realisations.

Values from outside the code: the so(3)* closed form c(r) = (1 - (r/2) cot(r/2)) / r^2 (its Taylor
coefficients by mpmath), phi(z) = z / (1 - e^-z) = sum B_k^+ z^k / k! (Bernoulli numbers by
mpmath) for linear pi, the B-series coefficients of docs/theory.md §9 with elementary differentials
computed by sympy, and measured convergence orders.
"""

from __future__ import annotations

import json
import re

import mpmath
import numpy as np
import pytest
import sympy
from click.testing import CliRunner
from rkhp_cli.main import rkhp

from rkhp.base.errors import InputError
from rkhp.systems import get_system
from rkhp.systems.families import so3_matrix
from rkhp.systems.spray import (
    MAX_TRUNCATION,
    spray_series,
    truncated_order,
    truncated_realisation,
)
from rkhp.taylor import tape as tp
from rkhp.taylor.collocation import collocation
from rkhp.taylor.interpreter import evaluate


def _tape_values(n, program, x, p):
    return evaluate(tp.record_tape(n, program), np.concatenate([x, p]))


def _cross(a, b):
    return np.cross(a, b)


def test_quadrature_tables():
    """Gauss–Legendre on [0, 1]: b integrates s^k exactly (k < 2Q), A is the collocation matrix
    (A 1 = c), w integrates (1 - s) s^k for k < Q."""
    for q in (1, 2, 3, 5, 8):
        t = collocation(q)
        for k in range(2 * q):
            assert t.b @ t.nodes**k == pytest.approx(1 / (k + 1), rel=1e-14)
        for k in range(q):
            assert t.w @ t.nodes**k == pytest.approx(1 / ((k + 1) * (k + 2)), rel=1e-13)
            assert np.allclose(t.A @ t.nodes**k, t.nodes ** (k + 1) / (k + 1), rtol=1e-13)
        assert np.allclose(t.nodes + t.nodes[::-1], 1.0, atol=1e-15)
        # the symmetry that makes the spray realisation symmetric (docs/theory.md §9.3)
        assert np.allclose(t.A[::-1, ::-1], t.b[None, :] - t.A, atol=1e-15)
        assert np.allclose(t.w[::-1], t.b - t.w, atol=1e-15)


def test_truncated_so3_is_the_series_of_the_closed_form():
    """alpha_K = x + (p x x)/2 + c_K(|p|^2) p x (p x x), c_K the Taylor polynomial of
    c(r) = (1 - (r/2) cot(r/2)) / r^2 (docs/theory.md §4) of the degrees allowed by K."""
    # (r/2) cot(r/2) = sum_k (-1)^k B_2k r^2k / (2k)!, so c(u) = sum_k>=1 (-1)^(k+1) B_2k u^(k-1) / (2k)!
    coef = [float((-1) ** (k + 1) * mpmath.bernoulli(2 * k) / mpmath.factorial(2 * k))
            for k in range(1, 8)]
    assert coef[0] == pytest.approx(1 / 12) and coef[1] == pytest.approx(1 / 720)
    assert coef[2] == pytest.approx(1 / 30240)
    rng = np.random.default_rng(0)
    for K in range(1, 9):
        alpha, beta = truncated_realisation(so3_matrix, K)
        for _ in range(3):
            x, p = rng.normal(size=3), 0.4 * rng.normal(size=3)
            px, u = _cross(p, x), p @ p
            c = sum(coef[j] * u**j for j in range(7) if 2 + 2 * j <= K)
            expected = x + px / 2 + c * _cross(p, px)
            assert np.allclose(_tape_values(3, alpha, x, p), expected, rtol=0, atol=4e-16)
            assert np.allclose(_tape_values(3, beta, x, p), x - px / 2 + c * _cross(p, px),
                               rtol=0, atol=4e-16)


def _phi_truncated(Kmat, x, K):
    """sum_{k <= K} B_k^+ / k! K^k x (Bernoulli numbers by mpmath)."""
    out, v = np.zeros_like(x), x.copy()
    for k in range(K + 1):
        b = float(mpmath.bernoulli(k) / mpmath.factorial(k)) * (-1 if k == 1 else 1)
        out += b * v
        v = Kmat @ v
    return out


def test_truncated_linear_reproduces_phi_of_K():
    """Linear pi (the heavy top's se(3)*): alpha_K = phi_K(K(p)) x, K(p) x = -pi(x) p."""
    system = get_system("heavy-top")
    rng = np.random.default_rng(1)
    for K in (1, 2, 3, 6):
        trunc = get_system("heavy-top", f"truncated:{K}")
        for _ in range(3):
            x, p = rng.normal(size=6), 0.3 * rng.normal(size=6)
            Kmat = -np.column_stack([system.poisson(e) @ p for e in np.eye(6)])
            assert np.allclose(trunc.alpha(x, p), _phi_truncated(Kmat, x, K), atol=1e-15)
            assert np.allclose(trunc.beta(x, p), _phi_truncated(-Kmat, x, K), atol=1e-15)


def test_truncated_constant_pi_is_exact_to_round_off():
    pendulum = get_system("pendulum")
    rng = np.random.default_rng(2)
    for K in (1, 2, 5):
        trunc = get_system("pendulum", f"truncated:{K}")
        x, p = rng.normal(size=2), rng.normal(size=2)
        assert np.allclose(trunc.alpha(x, p), pendulum.alpha(x, p), rtol=0, atol=4e-16)
        assert np.allclose(trunc.beta(x, p), pendulum.beta(x, p), rtol=0, atol=4e-16)


# the B-series of alpha in the vector field X_p at x (docs/theory.md §9): (tree, c/sigma)
ALPHA_TREES = {1: [("b", -0.5)], 2: [("b[b]", 1 / 12)],
               3: [("b[b[b]]", 0.0), ("b[b,b]", -1 / 48)],
               4: [("b[b[b[b]]]", -1 / 720), ("b[b[b,b]]", 1 / 480), ("b[b,b[b]]", 1 / 360),
                   ("b[b,b,b]", 1 / 480)]}


def _elementary_differentials(X, y, x):
    """F(t)[X](x) of the trees of ALPHA_TREES: the derivatives of X (expressions in y) by sympy,
    contracted with the (numeric) elementary differentials of the subtrees at x."""
    point = dict(zip(y, x, strict=True))

    def d(*dirs):
        out = []
        for comp in X:
            e = comp
            for direction in dirs:
                e = sum(sympy.diff(e, yj) * float(direction[j]) for j, yj in enumerate(y))
            out.append(float(e.subs(point)))
        return np.array(out)

    F = {"b": d()}
    F["b[b]"] = d(F["b"])
    F["b[b[b]]"] = d(F["b[b]"])
    F["b[b,b]"] = d(F["b"], F["b"])
    F["b[b[b[b]]]"] = d(F["b[b[b]]"])
    F["b[b[b,b]]"] = d(F["b[b,b]"])
    F["b[b,b[b]]"] = d(F["b"], F["b[b]"])
    F["b[b,b,b]"] = d(F["b"], F["b"], F["b"])
    return F


def _nambu():
    """pi v = grad C x v, C = x1^2/2 + x2^4/4 + x1 x3 + x3^3/3 (non-linear Nambu structure)."""
    y = sympy.symbols("y1:4", real=True)
    C = y[0] ** 2 / 2 + y[1] ** 4 / 4 + y[0] * y[2] + y[2] ** 3 / 3
    g = [sympy.diff(C, v) for v in y]
    pi = [[sum(sympy.LeviCivita(i, j, k) * g[j] for j in range(3)) for k in range(3)]
          for i in range(3)]

    def program(Y):
        gY = [Y[0] + Y[2], Y[1] ** 3, Y[0] + Y[2] * Y[2]]
        return [[0.0, -gY[2], gY[1]], [gY[2], 0.0, -gY[0]], [-gY[1], gY[0], 0.0]]

    return y, pi, program, np.array([0.3, -0.7, 0.5]), np.array([0.2, 0.1, -0.3])


def _arctangent():
    """pi = a(y) J in the plane, a = 2 + atan(y1 y2): atan is known to the series only by its
    derivative (`Series.apply`, the chain rule)."""
    y = sympy.symbols("y1:3", real=True)
    a = 2 + sympy.atan(y[0] * y[1])

    def program(Y):
        aY = 2.0 + tp.functions.atan(Y[0] * Y[1])
        return [[0.0, aY], [-aY, 0.0]]

    return y, [[0, a], [-a, 0]], program, np.array([0.6, -0.9]), np.array([0.3, 0.2])


@pytest.mark.parametrize("structure", [_nambu, _arctangent], ids=["nambu", "atan"])
def test_series_terms_are_the_b_series_of_docs_theory(structure):
    """a_m (degree m in p) = sum over trees with m vertices of c(t)/sigma(t) F(t)[X_p](x)."""
    y, pi, program, x, p = structure()
    n = len(y)
    X = [sum(pi[i][k] * p[k] for k in range(n)) for i in range(n)]
    F = _elementary_differentials(X, y, x)

    def terms(xv, pv):
        series = spray_series(program, xv, pv, 4)
        return [v for m in range(4) for v in series.start[m] + series.end[m]]

    values = _tape_values(n, terms, x, p).reshape(4, 2, n)
    for m in range(1, 5):
        expected = sum(coef * F[t] for t, coef in ALPHA_TREES[m])
        a_m, end_m = values[m - 1]
        assert np.allclose(a_m, expected, rtol=1e-12, atol=1e-15), m
        # beta = Phi_1(alpha) = alpha(x, -p): the end value's term of degree m is (-1)^m a_m
        assert np.allclose(end_m, (-1) ** m * a_m, rtol=1e-12, atol=1e-16), m


def test_truncated_order_rule():
    """docs/theory.md §9: min(m1, m2 - 1), m1 the first non-vanishing degree beyond K and m2
    the first odd one (linear pi: odd degrees >= 3 vanish; constant pi: all degrees >= 2)."""
    assert [truncated_order(K, None) for K in range(1, 7)] == [2, 2, 4, 4, 6, 6]
    assert [truncated_order(K, 2) for K in range(1, 7)] == [2, 2, 4, 4, 6, 6]
    assert [truncated_order(K, 1) for K in range(1, 7)] == [2, 4, 4, 6, 6, 8]
    assert truncated_order(3, 0) is None


@pytest.mark.parametrize("name", ["truncated:0", "truncated:x", f"truncated:{MAX_TRUNCATION + 1}",
                                  "truncated:-1"])
def test_bad_truncation(name):
    with pytest.raises(InputError, match="K in truncated:K"):
        get_system("rigid-body", name)


def test_general_spec_rigid_body_matches_builtin(rigid_body_spec):
    """The rigid body written as a general spec has the same truncated realisation."""
    path = rigid_body_spec
    rng = np.random.default_rng(3)
    for K in (1, 4):
        spec, builtin = get_system(path, f"truncated:{K}"), get_system("rigid-body", f"truncated:{K}")
        assert spec.family == "general" and spec.poisson_degree == 1
        assert spec.realisation_order == builtin.realisation_order
        for _ in range(3):
            x, p = rng.normal(size=3), 0.4 * rng.normal(size=3)
            assert np.allclose(spec.alpha(x, p), builtin.alpha(x, p), rtol=1e-14, atol=1e-15)
            assert np.allclose(spec.poisson(x), builtin.poisson(x))


def test_general_spec_runs_and_keeps_its_casimir(rigid_body_spec):
    path = rigid_body_spec
    res = CliRunner().invoke(rkhp, ["integrate", str(path), "--method", "paper-three-stage",
                                    "--steps", "20", "--realisation", "truncated:4",
                                    "--format", "json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["casimir_error"] < 1e-14 and doc["status"] == "ok"


BAD_SPECS = {
    "jacobi": ('poisson = [["0", "1", "0"], ["-1", "0", "x2"], ["0", "-x2", "0"]]',
               r"fails the Jacobi identity at \(i, j, k\) = \(1, 2, 3\): .* = 1 at x"),
    "antisymmetric": ('poisson = [["0", "x3", "0"], ["x3", "0", "x1"], ["0", "-x1", "0"]]',
                      r"not antisymmetric: entries \(1, 2\) and \(2, 1\)"),
    "symbol": ('poisson = [["0", "y", "0"], ["-y", "0", "x1"], ["0", "-x1", "0"]]',
               "unknown symbol 'y'"),
    "singular": ('poisson = [["0", "1/(x1 - 1)", "0"], ["-1/(x1 - 1)", "0", "0"], '
                 '["0", "0", "0"]]', r"singular at x0 = \(1, 1, 1\): entry \(1, 2\)"),
    "casimir": ('poisson = [["0", "-x3", "x2"], ["x3", "0", "-x1"], ["-x2", "x1", "0"]]\n'
                'casimirs = ["x1 + x2"]', r"casimir 1 \(x1 \+ x2\) is not a Casimir"),
    "shape": ('poisson = [["0", "1"], ["-1", "0"]]', "x0 has 3 entries but poisson is 2 x 2"),
}


@pytest.mark.parametrize("kind", list(BAD_SPECS))
def test_general_spec_refusals(tmp_path, kind):
    """One line on stderr, exit status 2."""
    poisson, message = BAD_SPECS[kind]
    path = tmp_path / "bad.toml"
    path.write_text(f'family = "general"\n{poisson}\nhamiltonian = "x1^2"\nx0 = [1, 1, 1]\n')
    res = CliRunner().invoke(
        rkhp, ["integrate", str(path), "--method", "euler", "--steps", "2",
               "--realisation", "truncated:2"])
    assert res.exit_code == 2
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and re.search(message, lines[0]), res.stderr


def _orders(system, method, realisation, steps):
    from rkhp.integrators.methods import resolve_methods
    from rkhp.studies.converge import converge

    study = converge(get_system(system, realisation), resolve_methods([method]), steps=steps,
                     t_final=None)
    (m,) = study.methods
    return m.observed_order, m.expected_order, m.verdict


def test_truncated_two_discriminates_linear_from_quadratic_pi():
    """truncated:2 with the paper's three-stage method (symmetric order 4): order 4 on the rigid
    body (linear pi: A_3 = 0) but order 2 on Lotka–Volterra (quadratic pi)."""
    steps = (80, 160, 320, 640)
    observed, expected, verdict = _orders("rigid-body", "paper-three-stage", "truncated:2", steps)
    assert expected == 4 and verdict == "confirmed" and abs(observed - 4) < 0.1
    observed, expected, verdict = _orders("lotka-volterra", "paper-three-stage", "truncated:2",
                                          steps)
    assert expected == 2 and verdict == "confirmed" and abs(observed - 2) < 0.1


@pytest.mark.parametrize("K", range(1, 7))
def test_converge_rigid_body_truncated(K):
    """`rkhp converge rigid-body --realisation truncated:K`: every default method confirmed."""
    res = CliRunner().invoke(rkhp, ["converge", "rigid-body", "--realisation", f"truncated:{K}",
                                    "--format", "json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    bound = truncated_order(K, 1)
    for m in doc["methods"]:
        assert m["verdict"] == "confirmed", m
        assert m["expected_order"] == min(bound, {"euler": 2, "paper-two-stage": 3}.get(m["method"], 4))


@pytest.mark.slow
@pytest.mark.parametrize("K, expected", [(3, 4), (4, 4), (5, 6), (6, 6)])
def test_converge_truncated_order_six_method_on_quadratic_pi(K, expected):
    """A method of symmetric order 6 sees the bound of truncated:K on Lotka–Volterra."""
    observed, exp, verdict = _orders("lotka-volterra", "search-symmetric-o6-s5", f"truncated:{K}",
                                     None)
    assert exp == expected and verdict == "confirmed"
