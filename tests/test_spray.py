"""The exact Poisson-spray realisation of the general family (rkhp.systems.spray).

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

from rkhp.integrators import integrate_rkhp
from rkhp.systems import get_system
from rkhp.systems.check import check_birealisation
from rkhp.systems.problems import as_general
from rkhp.taylor.collocation import average_error_constant, collocation
from rkhp.taylor.composites import SPRAY_BERNOULLI_MAJORANT
from rkhp.taylor.interpreter import interpreter, tape_work
from rkhp.taylor.jets import jet_space
from rkhp.taylor.ops import ADD, CONST, DIV, EXP, MUL, MULC, POWI, SPRAY, SUB
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


def test_bernoulli_majorant():
    """The tail bound of the Bernoulli series for X affine in y (docs/theory.md §9.3):
    |B_k / k!| <= SPRAY_BERNOULLI_MAJORANT (2 pi)^-k for 2 <= k < 200 (mpmath's Bernoulli
    numbers; for even k, B_k / k! = (-1)^(k/2+1) 2 zeta(k) / (2 pi)^k)."""
    with mpmath.workdps(60):
        for k in range(2, 200):
            b = abs(mpmath.bernoulli(k) / mpmath.factorial(k))
            assert b <= SPRAY_BERNOULLI_MAJORANT * (2 * mpmath.pi) ** -k
            if k % 2 == 0:
                assert b == pytest.approx(2 * mpmath.zeta(k) / (2 * mpmath.pi) ** k, rel=1e-40)


def test_affine_spray_with_a_constant_part(tmp_path):
    """pi(y) = pi_so3(y + s), affine with a constant part: its flows are so(3)*'s translated by
    -s, so alpha(x, p) = alpha_so3(x + s, p) - s, the closed form (docs/theory.md §4) at the
    shifted point; likewise beta. |p| from 1e-9 to 1."""
    path = tmp_path / "shifted.toml"
    path.write_text('name = "shifted-rigid-body"\n'
                    'family = "general"\n'
                    'poisson = [["0", "-(x3 + 2)", "x2 - 1"], ["x3 + 2", "0", "-(x1 + 0.5)"],'
                    ' ["-(x2 - 1)", "x1 + 0.5", "0"]]\n'
                    'hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"\n'
                    'x0 = [0.4, 0.1, 0.9]\n')
    shifted, closed = get_system(path), get_system("rigid-body")
    assert _spray_flags(shifted) == [1.0]
    s = np.array([0.5, -1.0, 2.0])
    rng = np.random.default_rng(4)
    for r in (1e-9, 1e-3, 0.1, 0.5, 1.0):
        x, d = rng.normal(size=3), rng.normal(size=3)
        p = r * d / np.linalg.norm(d)
        assert np.allclose(shifted.alpha(x, p), closed.alpha(x + s, p) - s, rtol=0, atol=4e-15)
        assert np.allclose(shifted.beta(x, p), closed.beta(x + s, p) - s, rtol=0, atol=4e-15)


def _jets(tape, point, seeds, degree):
    """The output jets of a tape at `point`, in all of its inputs (input i = point[i] +
    seeds[i] t_i), to `degree`."""
    space = jet_space(len(point), degree)
    work = tape_work((tape,), space.size)
    work.W[: len(point), 0] = point
    if degree > 0:
        for i in range(len(point)):
            work.W[i, 1 + i] = seeds[i]
    interpreter(tape)(tape, degree, space, work)
    return work.W[tape.outputs, : space.size].copy()


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_affine_spray_is_the_closed_form_on_jets(rigid_body_general, degree):
    """so(3)*: the spray realisation's Taylor coefficients in (x, p) equal the closed form's
    (docs/theory.md §4) to a few units of round-off, at |p| from 1e-9 to 0.75 (the Bernoulli
    series), p's directions scaled like p itself, as in an RKHP step, and of unit size (the
    series' stopping rule follows the jets' own ratios)."""
    builtin = get_system("rigid-body")
    rng = np.random.default_rng(3)
    for r in (1e-9, 1e-4, 0.05, 0.3, 0.75):
        for _ in range(3):
            x, d = rng.normal(size=3), rng.normal(size=3)
            point = np.concatenate([x, r * d / np.linalg.norm(d)])
            for seeds in ([1.0] * 3 + [r] * 3, [1.0] * 6):
                for tape, closed in ((rigid_body_general.alpha_tape, builtin.alpha_tape),
                                     (rigid_body_general.beta_tape, builtin.beta_tape)):
                    a, b = _jets(tape, point, seeds, degree), _jets(closed, point, seeds, degree)
                    scale = max(1.0, np.abs(b).max())
                    assert np.abs(a - b).max() <= 8 * 2.0**-52 * scale


def test_rigid_body_spray_is_the_closed_form(rigid_body_general):
    """so(3)*: the spray realisation is the closed form of docs/theory.md §4 (to round-off, for
    |p| up to 2 by the Bernoulli series; at |p| = 3, |d_y X|_F = 3 sqrt(2) > pi, by the
    collocation, nearer the closed form's pole at 2 pi), and it is symmetric."""
    builtin = get_system("rigid-body")
    rng = np.random.default_rng(0)
    for r in (1e-9, 1e-3, 0.1, 0.5, 1.0, 2.0, 3.0):
        for _ in range(3):
            x, d = rng.normal(size=3), rng.normal(size=3)
            p = r * d / np.linalg.norm(d)
            a, b = rigid_body_general.alpha(x, p), rigid_body_general.beta(x, p)
            tol = 2e-15 if r <= 2.0 else 4e-15
            assert np.allclose(a, builtin.alpha(x, p), rtol=0, atol=tol)
            assert np.allclose(b, builtin.beta(x, p), rtol=0, atol=tol)
            assert np.allclose(b, rigid_body_general.alpha(x, -p), rtol=0,
                               atol=5e-16 if r <= 2.0 else tol)


def test_rigid_body_trajectory_matches_the_builtin(rigid_body_general):
    """Acceptance: 100 steps of paper-three-stage at h = 0.1 agree to <= 1e-12."""
    a = integrate_rkhp(get_system("rigid-body"), "paper-three-stage", 0.1, 100)
    b = integrate_rkhp(rigid_body_general, "paper-three-stage", 0.1, 100)
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
    a = integrate_rkhp(closed, "paper-three-stage", 0.1, 50)
    b = integrate_rkhp(spray, "paper-three-stage", 0.1, 50)
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
    traj = integrate_rkhp(s, "paper-three-stage", 4.0, 3)
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
    traj = integrate_rkhp(s, "paper-three-stage", 0.1, 100_000)
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
