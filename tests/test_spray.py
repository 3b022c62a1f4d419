"""The exact Poisson-spray realisation of the general family (issue 10, part E).

Values from outside the code: the closed forms of docs/theory.md §4 (so(3)*: the rigid body's
c(|p|^2) realisation; se(3)*: phi(K(p)) x) which the spray realisation reduces to for linear pi,
the error constant of collocation averages derived with mpmath (docs/theory.md §9.3), the
birealisation axioms, and Casimirs of the Nambu system.
"""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp

from rkhp.integrators import integrate
from rkhp.systems import get_system
from rkhp.systems.check import check_birealisation
from rkhp.systems.problems import as_general
from rkhp.taylor.collocation import average_error_constant, collocation
from rkhp.taylor.composites import SPRAY_AFFINE_RATIO
from rkhp.taylor.interpreter import run_tape, tape_work
from rkhp.taylor.jets import jet_space
from rkhp.taylor.ops import ADD, CONST, DIV, EXP, MUL, MULC, POWI, SPRAY, SPRAY_MAX_NODES, SUB
from rkhp.taylor.tape import degree_in


@pytest.fixture(scope="module")
def rigid_body_general(rigid_body_spec):
    return get_system(rigid_body_spec)


def _mp_tables(q):
    """Gauss collocation tables on [0, 1] and the average weights, in mpmath (independent of
    rkhp.taylor.collocation): nodes from the shifted Legendre polynomial, integrals of the
    Lagrange basis through its monomial coefficients."""
    nodes = sorted(mpmath.findroot(lambda s: mpmath.legendre(q, 2 * s - 1), mpmath.mpf(g))
                   for g in (np.polynomial.legendre.leggauss(q)[0] + 1) / 2)
    inverse = mpmath.matrix([[c**k for k in range(q)] for c in nodes]) ** -1
    A = [[sum(inverse[k, j] * c ** (k + 1) / (k + 1) for k in range(q)) for j in range(q)]
         for c in nodes]
    w = [sum(inverse[k, j] / ((k + 1) * (k + 2)) for k in range(q)) for j in range(q)]
    return A, w


def test_average_error_constant():
    """For y' = lambda y, alpha = lambda / (e^lambda - 1) x; with Q Gauss nodes the average
    constraint gives alpha with the error (-1)^Q E_Q lambda^(2Q), E_Q = (Q!)^2 / ((2Q)!^2 (2Q+1))
    (mpmath at 60 digits); the float64 tables agree with mpmath's."""
    with mpmath.workdps(60):
        lam = mpmath.mpf("1e-3")
        for q in range(1, 7):
            A, w = _mp_tables(q)
            t = collocation(q)
            assert np.allclose(t.A, np.array([[float(v) for v in row] for row in A]), atol=1e-15)
            assert np.allclose(t.w, [float(v) for v in w], atol=1e-15)
            M = mpmath.matrix([[(1 if i == j else 0) - lam * (A[i][j] - w[j]) for j in range(q)]
                               for i in range(q)])
            Y = M**-1 * mpmath.matrix([1] * q)
            alpha = 1 - lam * sum(w[j] * Y[j] for j in range(q))
            error = (alpha - lam / (mpmath.e**lam - 1)) / lam ** (2 * q)
            assert float(error) == pytest.approx((-1) ** q * average_error_constant(q), rel=1e-2)


def _spray_flags(system):
    """The float parameter of each spray row of a system's alpha tape (1.0: X affine in y)."""
    tape = system.alpha_tape
    return [float(tape.fpar[r]) for r in range(tape.ops.shape[0]) if tape.ops[r, 0] == SPRAY]


@pytest.mark.parametrize("name, affine", [("heavy-top", True), ("toda:6", True),
                                          ("charged-particle", False),
                                          ("point-vortices", False), ("nambu", False)])
def test_the_field_is_marked_affine_exactly_for_linear_pi(name, affine):
    """pi linear in y (Lie–Poisson: heavy top; Flaschka's Toda lattice) makes X(y, p) affine in
    y; the charged particle (1/B), point vortices (1/(1 + 2|y|^2)) and the quartic Casimir's
    Nambu bracket (cubic) do not (problems' sources, rkhp.systems.problems)."""
    assert _spray_flags(as_general(name)) == [1.0 if affine else 0.0]


def test_the_rigid_body_spec_is_affine(rigid_body_general):
    assert _spray_flags(rigid_body_general) == [1.0]


def test_degree_in_polynomial_and_non_polynomial_rows():
    """degree_in on hand-written rows (code, out, a, b, k) over inputs 0, 1 and a parameter 2:
    products add degrees, sums take the larger, a division by a constant keeps it, powers
    multiply it, functions of an input and divisions by one are not polynomial."""
    rows = [(MUL, 3, 0, 2, 0),      # y0 p: 1
            (MUL, 4, 0, 1, 0),      # y0 y1: 2
            (ADD, 5, 3, 4, 0),      # 2
            (CONST, 6, -1, -1, 0),  # 0
            (DIV, 7, 3, 6, 0),      # y0 p / c: 1
            (POWI, 8, 0, -1, 3),    # y0^3: 3
            (EXP, 9, 2, -1, 0),     # exp(p): 0
            (EXP, 10, 0, -1, 0),    # exp(y0): not polynomial
            (DIV, 11, 2, 0, 0),     # p / y0: not polynomial
            (SUB, 12, 7, 9, 0),     # 1
            (MULC, 13, 8, -1, 0)]   # 3
    assert degree_in(rows, (0, 1), (3, 12)) == 1.0
    assert degree_in(rows, (0, 1), (6, 9)) == 0.0
    assert degree_in(rows, (0, 1), (5,)) == 2.0
    assert degree_in(rows, (0, 1), (13, 3)) == 3.0
    assert degree_in(rows, (0, 1), (10,)) == math.inf
    assert degree_in(rows, (0, 1), (11,)) == math.inf


def _average_error_series(q, terms):
    """r_k, k = 0..terms: for X affine in y, x - alpha_Q - (x - alpha) = sum_k r_k J^(k-1) X(x)
    with r(z) = z / (e^z - 1) - 1 + z w^T (I - z (A - w))^-1 1 (mpmath tables), so
    r_k = B_k / k! + w^T (A - w)^(k-1) 1 for k >= 1."""
    A, w = _mp_tables(q)
    AW = mpmath.matrix([[A[i][j] - w[j] for j in range(q)] for i in range(q)])
    v = mpmath.matrix([1] * q)
    r = [mpmath.mpf(0)]
    for k in range(1, terms + 1):
        r.append(mpmath.bernoulli(k) / mpmath.factorial(k) + sum(w[j] * v[j] for j in range(q)))
        v = AW * v
    return r


def test_affine_error_bound_of_the_average():
    """The a-priori choice of Q for X affine in y (docs/theory.md §9.3): the truncation error's
    series starts at z^(2Q) with |r_2Q| = E_Q, and |r_k| <= E_Q SPRAY_AFFINE_RATIO^(k - 2Q)
    (mpmath at 100 digits, 60 terms past 2Q, every Q the kernel may use; the ratio tends to
    rho(A - w) <= 1 / (2 pi) beyond)."""
    with mpmath.workdps(100):
        for q in range(1, SPRAY_MAX_NODES + 1):
            r = _average_error_series(q, 2 * q + 60)
            E = average_error_constant(q)
            assert max(abs(r[k]) for k in range(2 * q)) < mpmath.mpf(10) ** -80
            assert float(abs(r[2 * q])) == pytest.approx(E, rel=1e-12)
            for k in range(2 * q + 1, 2 * q + 61):
                assert abs(r[k]) <= E * SPRAY_AFFINE_RATIO ** (k - 2 * q)


def _jets(tape, point, seeds, degree):
    """The output jets of a tape at `point`, in all of its inputs (input i = point[i] +
    seeds[i] t_i), to `degree`."""
    space = jet_space(len(point), degree)
    work = tape_work((tape,), space.size)
    work.W[: len(point), 0] = point
    if degree > 0:
        for i in range(len(point)):
            work.W[i, 1 + i] = seeds[i]
    run_tape(tape, np.int64(degree), space, work)
    return work.W[tape.outputs, : space.size].copy()


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_affine_spray_is_the_closed_form_on_jets(rigid_body_general, degree):
    """so(3)*: the spray realisation's Taylor coefficients in (x, p) equal the closed form's
    (docs/theory.md §4) to a few units of round-off, at |p| from 1e-9 to 0.75 (the a-priori Q at
    the values where |d_y X|_F <= 1, the checked Q elsewhere and on jets), p's directions
    scaled like p itself, as in an RKHP step (docs/theory.md §9.3, "Choice of Q": on jets Q is
    chosen at the values)."""
    builtin = get_system("rigid-body")
    rng = np.random.default_rng(3)
    for r in (1e-9, 1e-4, 0.05, 0.3, 0.75):
        for _ in range(3):
            x, d = rng.normal(size=3), rng.normal(size=3)
            point = np.concatenate([x, r * d / np.linalg.norm(d)])
            seeds = [1.0] * 3 + [r] * 3
            for tape, closed in ((rigid_body_general.alpha_tape, builtin.alpha_tape),
                                 (rigid_body_general.beta_tape, builtin.beta_tape)):
                a, b = _jets(tape, point, seeds, degree), _jets(closed, point, seeds, degree)
                scale = max(1.0, np.abs(b).max())
                assert np.abs(a - b).max() <= 8 * 2.0**-52 * scale


def test_rigid_body_spray_is_the_closed_form(rigid_body_general):
    """so(3)*: the spray realisation is the closed form of docs/theory.md §4 (to round-off, for
    |p| up to 2), and it is symmetric."""
    builtin = get_system("rigid-body")
    rng = np.random.default_rng(0)
    for r in (1e-9, 1e-3, 0.1, 0.5, 1.0, 2.0):
        for _ in range(3):
            x, d = rng.normal(size=3), rng.normal(size=3)
            p = r * d / np.linalg.norm(d)
            a, b = rigid_body_general.alpha(x, p), rigid_body_general.beta(x, p)
            assert np.allclose(a, builtin.alpha(x, p), rtol=0, atol=2e-15)
            assert np.allclose(b, builtin.beta(x, p), rtol=0, atol=2e-15)
            assert np.allclose(b, rigid_body_general.alpha(x, -p), rtol=0, atol=5e-16)


def test_rigid_body_trajectory_matches_the_builtin(rigid_body_general):
    """Acceptance: 100 steps of paper-three-stage at h = 0.1 agree to <= 1e-12."""
    a = integrate(get_system("rigid-body"), "paper-three-stage", 0.1, 100)
    b = integrate(rigid_body_general, "paper-three-stage", 0.1, 100)
    assert a.ok and b.ok
    assert np.abs(a.states - b.states).max() <= 1e-12


def test_heavy_top_spray_is_phi_of_K():
    """se(3)*: the general family's spray realisation equals the Lie–Poisson family's
    phi(K(p)) x, and their trajectories agree."""
    closed, spray = get_system("heavy-top"), as_general("heavy-top")
    assert spray.family == "general" and closed.family == "lie-poisson"
    rng = np.random.default_rng(1)
    for _ in range(5):
        x, p = rng.normal(size=6), 0.4 * rng.normal(size=6) / math.sqrt(6)
        assert np.allclose(spray.alpha(x, p), closed.alpha(x, p), rtol=0, atol=5e-15)
        assert np.allclose(spray.beta(x, p), closed.beta(x, p), rtol=0, atol=5e-15)
    a = integrate(closed, "paper-three-stage", 0.1, 50)
    b = integrate(spray, "paper-three-stage", 0.1, 50)
    assert np.abs(a.states - b.states).max() <= 1e-12


def test_truncated_series_converge_to_the_spray():
    """truncated:K -> the exact realisation as K grows, by about |p|^(K+1) (nambu)."""
    exact = get_system("nambu")
    x, d = np.array(exact.x0), np.array([0.3, -0.5, 0.2])
    gaps = []
    for K in (2, 4, 6, 8):
        trunc = get_system("nambu", f"truncated:{K}")
        gaps.append(np.abs(trunc.alpha(x, 0.1 * d) - exact.alpha(x, 0.1 * d)).max())
    assert gaps[-1] < 1e-12
    assert all(b < 0.1 * a for a, b in zip(gaps, gaps[1:]))


def test_failure_is_nan_never_a_wrong_value():
    """Where the collocation cannot reach round-off (|p| far too large), alpha is NaN and the
    integration reports a numerical failure (exit 1)."""
    s = get_system("nambu")
    assert np.all(np.isnan(s.alpha(s.x0, [1.2, 2.0, -3.2])))
    traj = integrate(s, "paper-three-stage", 4.0, 3)
    assert not traj.ok and "non-finite" in traj.status
    res = CliRunner().invoke(rkhp, ["integrate", "nambu", "--method", "paper-three-stage",
                                    "--h", "4", "--t-final", "12"])
    assert res.exit_code == 1 and res.output.count("\n") >= 1


@pytest.mark.parametrize("name", ["charged-particle", "point-vortices", "nambu"])
def test_check_on_general_builtins(name):
    """Acceptance: each axiom to <= 1e-12 (relative) at |p| <= 0.5; symmetric."""
    result = check_birealisation(get_system(name), samples=30, seed=2)
    assert result.ok and result.symmetric and result.degenerate
    assert max(result.deviations.values()) <= 1e-12


def test_check_json_on_a_general_spec(rigid_body_spec):
    res = CliRunner().invoke(rkhp, ["check", str(rigid_body_spec), "--samples", "10", "--format", "json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["ok"] and doc["symmetric"] and doc["realisation"] == "symmetric"


@pytest.mark.slow
def test_nambu_casimir_over_1e5_steps():
    """Acceptance: the Casimir of nambu stays within 1e-12 over 10^5 steps (h = 0.1)."""
    s = get_system("nambu")
    traj = integrate(s, "paper-three-stage", 0.1, 100_000)
    assert traj.ok
    C = np.array([s.casimir_values(x)[0] for x in traj.states])
    assert np.abs(C - C[0]).max() <= 1e-12


@pytest.mark.parametrize("name", ["charged-particle", "nambu"])
def test_converge_confirms_the_expected_orders(name):
    """Acceptance: `rkhp converge` confirms euler, paper-two-stage, paper-three-stage, rk4."""
    res = CliRunner().invoke(rkhp, ["converge", name, "--format", "json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert {m["method"]: m["verdict"] for m in doc["methods"]} == {
        "euler": "confirmed", "paper-two-stage": "confirmed", "paper-three-stage": "confirmed",
        "rk4": "confirmed"}
