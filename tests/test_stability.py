"""`rkhp stability` and rkhp.tableaux.stability against the theory (docs/theory.md §13) and against
rkhp's own integrator on linear systems (docs/stability.md)."""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest
import sympy

from rkhp.base.errors import InputError, NumericalFailure
from rkhp.integrators import integrate_rkhp
from rkhp.systems.families import family_system
from rkhp.tableaux.files import builtin_names, load_tableau
from rkhp.tableaux.stability import (
    Z,
    analyse,
    composition_phase,
    m_polynomial,
    rotation_angle,
    shifted_trace,
    step_matrix_shifted,
)
from rkhp.tableaux.tableau import Tableau

GAUSS1 = Tableau.from_arrays([["1/2"]], [1], name="gauss1")
#: b has a negative weight: P = z sum b_i G_i becomes indefinite, the shifted step hyperbolic
NEGATIVE_WEIGHT = Tableau.from_arrays([[0, 0], [1, 0]], ["3/2", "-1/2"], name="negative-weight")
#: implicit (diagonally) with the same weights: its shifted step turns hyperbolic before its stages fold
NEGATIVE_WEIGHT_IMPLICIT = Tableau.from_arrays([["1/4", 0], [1, "1/4"]], ["3/2", "-1/2"],
                                               name="negative-weight-implicit")
EXPLICIT = [n for n in builtin_names() if load_tableau(n).is_explicit]


def oscillator(realisation="symmetric", omega=1.0):
    """H = omega |x|^2/2, pi = [[0, 1], [-1, 0]]: xdot = omega (x2, -x1), a clockwise rotation."""
    return family_system("constant", np.array(((0.0, 1.0), (-1.0, 0.0))),
                         lambda x: (0.5 * omega) * (x[0] * x[0] + x[1] * x[1]), name="oscillator",
                         x0=(1.0, 0.0), t_final=1.0, realisation=realisation)


def clockwise_angle(x) -> float:
    return math.atan2(-x[1], x[0])


def predicted_theta(tableau, z) -> float:
    """2 arctan(m(z)/2) from the exact polynomial m(z) where there is one (evaluated in mpmath),
    else from the stage recursion in float64."""
    m = m_polynomial(tableau)
    if m is None:
        return rotation_angle(tableau, z)
    with mpmath.workdps(40):
        value = sympy.N(m.as_expr().subs(Z, sympy.Rational(str(z))), 40)
        return float(2 * mpmath.atan(mpmath.mpf(str(value)) / 2))


# ----------------------------------------------------------------------------- acceptance values


def test_paper_three_stage():
    r = analyse(load_tableau("paper-three-stage"))
    assert r.m == "z + z^3/12 + z^5/128 + 3*z^7/16384"  # docs/theory.md §13
    assert r.phase.phase_order == 4
    # theta - z = (m - 2 tan(z/2)) cos^2(z/2) + ...: 1/128 - 1/120 = -1/1920
    assert r.phase.phase_constant.exact == "-1/1920"
    assert r.existence_limit is None and r.stability_interval is None


def test_euler_is_the_cayley_transform():
    r = analyse(load_tableau("euler"), order=11)
    assert r.m == "z" and r.phase.phase_order == 2
    exact = sympy.series(2 * sympy.atan(Z / 2) - Z, Z, 0, 12).removeO()
    for k, c in r.phase.coefficients:
        assert sympy.Rational(c.exact) == exact.coeff(Z, k)


@pytest.mark.parametrize("tableau,barrier", [(load_tableau("paper-implicit"), "sqrt(3)"), (GAUSS1, "2")])
def test_one_stage_barrier_is_the_discriminant(tableau, barrier):
    # m = z a (1 + m^2/4) has a real root iff 1 - z^2 a^2 >= 0: z* = 1/a
    r = analyse(tableau)
    assert r.existence_limit.exact == barrier
    a = float(tableau.A_float[0][0])
    assert r.existence_limit.value == pytest.approx(1 / a, rel=1e-15)


def test_series_of_an_implicit_method_matches_its_root():
    """The series of the branch through m(0) = 0 agrees with the root of the quadratic."""
    r = analyse(GAUSS1, order=15)
    z = sympy.Rational(1, 3)
    m = (1 - sympy.sqrt(1 - z**2 / 4)) / (z / 8)  # root of (z/8) m^2 - m + z/2 = 0 through 0
    theta = float(2 * sympy.atan(m / 2))
    series = float(z) + sum(c.value * float(z) ** k for k, c in r.phase.coefficients)
    assert series == pytest.approx(theta, abs=1e-10)


def test_min_phase_table_beats_the_paper():
    """The shipped --optimize phase result: degenerate order 4 (verified at its 60 digits), phase
    order 8, so its phase error is below the paper's -z^5/1920 for every z up to 1."""
    from rkhp.tableaux.verification import verify

    tableau = load_tableau("search-degenerate-o4-s3-min-phase")
    assert verify(tableau).orders["degenerate"] == 4
    r = analyse(tableau)
    assert r.phase.phase_order == 8 and abs(r.phase.phase_constant.value) < 1 / 1920
    paper = load_tableau("paper-three-stage")
    for z in (0.1, 0.5, 1.0):
        assert abs(predicted_theta(tableau, z) - z) < abs(predicted_theta(paper, z) - z)


# ----------------------------------------------------------------------------- against the integrator


@pytest.fixture(scope="module")
def symmetric_oscillator():
    return oscillator()


@pytest.mark.parametrize("name", EXPLICIT)
def test_one_step_rotation_equals_the_integrator(name, symmetric_oscillator):
    tableau = load_tableau(name)
    for z in (0.3, 1.0, 2.5):
        run = integrate_rkhp(symmetric_oscillator, tableau, z, 1)
        assert run.status == "ok"
        x = run.final_state
        assert math.hypot(*x) == pytest.approx(1.0, abs=1e-13)  # amplitude is exact
        difference = math.remainder(clockwise_angle(x) - predicted_theta(tableau, z), 2 * math.pi)
        assert abs(difference) <= 1e-13, (name, z, difference)


@pytest.mark.parametrize("name", ["gauss2", "radau-iia3", "paper-implicit"])
def test_implicit_rotation_equals_the_integrator(name, symmetric_oscillator):
    tableau = load_tableau(name)
    for z in (0.3, 1.0):
        x = integrate_rkhp(symmetric_oscillator, tableau, z, 1).final_state
        assert clockwise_angle(x) == pytest.approx(rotation_angle(tableau, z), abs=1e-12)


def test_two_frequencies_angle_per_mode():
    """pi = [[0, I], [-I, 0]] on R^4, H = (w1 (x1^2 + x3^2) + w2 (x2^2 + x4^2))/2: the modes (x1, x3)
    and (x2, x4) rotate by theta(h w1) and theta(h w2) per step."""
    w1, w2, h, steps = 1.0, 7.3, 0.3, 5
    pi = np.zeros((4, 4))
    pi[0, 2] = pi[1, 3] = 1.0
    pi[2, 0] = pi[3, 1] = -1.0

    def hamiltonian(x):
        return (0.5 * w1) * (x[0] * x[0] + x[2] * x[2]) + (0.5 * w2) * (x[1] * x[1] + x[3] * x[3])

    system = family_system("constant", pi, hamiltonian,
                           name="two-frequencies", x0=(1.0, 1.0, 0.0, 0.0), t_final=h * steps)
    tableau = load_tableau("paper-three-stage")
    x = integrate_rkhp(system, tableau, h, steps).final_state
    for (i, j), w in (((0, 2), w1), ((1, 3), w2)):
        expected = math.remainder(steps * predicted_theta(tableau, h * w), 2 * math.pi)
        assert math.atan2(-x[j], x[i]) == pytest.approx(expected, abs=1e-12)
        assert math.hypot(x[i], x[j]) == pytest.approx(1.0, abs=1e-13)


def _run_oscillator(run_cli, tmp_path, method, h, steps=1, realisation="symmetric"):
    spec = tmp_path / "oscillator.toml"
    spec.write_text('family = "constant"\npoisson = [[0, 1], [-1, 0]]\nhamiltonian = "(x1^2 + x2^2)/2"\n'
                    "x0 = [1, 0]\n", encoding="utf-8")
    return run_cli("integrate", str(spec), "--method", method, "--h", repr(h), "--t-final", repr(h * steps),
                   "--realisation", realisation, "--format", "json")


@pytest.fixture
def gauss1_file(tmp_path):
    path = tmp_path / "gauss1.toml"
    path.write_text('name = "gauss1"\nA = [["1/2"]]\nb = ["1"]\n', encoding="utf-8")
    return str(path)


def test_barrier_existence_of_the_branch():
    """Below z* the branch through 0 has a real point (Newton continuation), above it has none; for
    one stage, the quadratic's discriminant decides independently."""
    for tableau in (GAUSS1, load_tableau("paper-implicit"), load_tableau("gauss2")):
        z_star = analyse(tableau).existence_limit.value
        assert rotation_angle(tableau, 0.999 * z_star) is not None
        assert rotation_angle(tableau, 1.001 * z_star) is None
    for z, real in ((1.99, True), (2.01, False)):
        roots = np.roots([z / 8, -1.0, z / 2])
        assert bool(np.all(np.abs(roots.imag) < 1e-12)) is real


@pytest.mark.parametrize("method,z_star", [("paper-implicit", math.sqrt(3)), ("gauss1", 2.0)])
def test_barrier_integrator_above_fails(run_cli, tmp_path, gauss1_file, method, z_star):
    method = gauss1_file if method == "gauss1" else method
    status, out, _ = _run_oscillator(run_cli, tmp_path, method, 1.02 * z_star)
    assert status == 1 and json.loads(out)["status"].startswith("failed")
    status, out, _ = _run_oscillator(run_cli, tmp_path, method, 0.5 * z_star)
    assert status == 0, out


@pytest.mark.parametrize("method,z_star", [("paper-implicit", math.sqrt(3)), ("gauss1", 2.0)])
def test_barrier_integrator_just_below_integrates(run_cli, tmp_path, gauss1_file, method, z_star):
    method = gauss1_file if method == "gauss1" else method
    status, out, _ = _run_oscillator(run_cli, tmp_path, method, 0.98 * z_star)
    assert status == 0, out


def test_wrap_limit_where_theta_turns():
    """m = z - z^3/8: m' = 0 at z = 2 sqrt(6)/3; the integrator's rotation grows below and falls above."""
    r = analyse(NEGATIVE_WEIGHT)
    assert r.m == "z - z^3/8"
    assert r.wrap_limit.exact == "2*sqrt(6)/3"
    z0 = r.wrap_limit.value
    system = oscillator()
    angle = [clockwise_angle(integrate_rkhp(system, NEGATIVE_WEIGHT, z, 1).final_state)
             for z in (z0 - 0.1, z0, z0 + 0.1)]
    assert angle[0] < angle[1] and angle[2] < angle[1]
    # without an exact m(z) (35 stages): found numerically, and the integrator turns there too
    feagin = load_tableau("feagin14")
    z1 = analyse(feagin).wrap_limit.value
    assert 2.12 < z1 < 2.15
    angle = [clockwise_angle(integrate_rkhp(system, feagin, z, 1).final_state) for z in (z1 - 0.02, z1, z1 + 0.02)]
    assert angle[0] < angle[1] and angle[2] < angle[1]


def _slope_60_digits(tableau, z):
    """m'(z) of an explicit tableau at 60 digits: the stage recursion m_i = z sum_j a_ij (1 + m_j^2/4)
    on the tableau's decimals, differentiated by mpmath.diff (an evaluation independent of rkhp's)."""
    with mpmath.workdps(60):
        A = [[mpmath.mpf(str(x)) for x in row] for row in tableau.A]
        b = [mpmath.mpf(str(x)) for x in tableau.b]

        def m(x):
            ms = []
            for row in A:
                ms.append(x * mpmath.fsum(a * (1 + mj**2 / 4) for a, mj in zip(row, ms)))
            return x * mpmath.fsum(bi * (1 + mi**2 / 4) for bi, mi in zip(b, ms))

        return mpmath.diff(m, mpmath.mpf(z))


def test_wrap_limit_of_dop853_is_the_first_sign_change_of_m_prime():
    """dop853: m'(z) first vanishes at z = 6.00395425216271026... (60-digit recursion), where
    pi - theta = 1.1e-13, invisible to a float64 scan of theta."""
    r = analyse(load_tableau("dop853"))
    assert r.wrap_limit.exact is None
    assert r.wrap_limit.value == pytest.approx(6.00395425216271026, rel=1e-15)


@pytest.mark.parametrize("name", ["curtis10", "ono12", "search-general-o6-s7", "search-symmetric-o8-s7"])
def test_wrap_limit_numeric_against_a_60_digit_slope(name):
    """Without an exact m(z): m' > 0 (60 digits) on a grid below the reported wrap limit and changes
    sign within 1e-13 of it (ono12: there m = 4e61077, beyond float64's range)."""
    tableau = load_tableau(name)
    z0 = analyse(tableau).wrap_limit.value
    assert all(_slope_60_digits(tableau, z0 * k / 16) > 0 for k in range(1, 16))
    assert _slope_60_digits(tableau, z0 * (1 - 1e-13)) > 0 > _slope_60_digits(tableau, z0 * (1 + 1e-13))


# ----------------------------------------------------------------------------- shifted realisation


def test_shifted_trace_equals_the_integrator_step_matrix():
    system = oscillator("shifted")
    for name in ("euler", "paper-three-stage", "rk4"):
        tableau = load_tableau(name)
        trace = shifted_trace(tableau)
        for z in (0.3, 1.0, 2.5):
            columns = [integrate_rkhp(system, tableau, z, 1, x0=e).final_state for e in ((1.0, 0.0), (0.0, 1.0))]
            R = np.array(columns).T
            assert np.trace(R) == pytest.approx(float(trace.subs(Z, sympy.Rational(str(z)))), abs=1e-13)
            assert np.allclose(R, step_matrix_shifted(tableau, z), atol=1e-13)
            assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)


def test_shifted_interval_by_integration():
    """Just inside the interval the run stays bounded (elliptic), just outside it grows."""
    r = analyse(NEGATIVE_WEIGHT, realisation="shifted")
    z0 = r.stability_interval.value
    assert z0 == pytest.approx(0.887236173133650, rel=1e-14)
    system = oscillator("shifted")
    inside = integrate_rkhp(system, NEGATIVE_WEIGHT, 0.97 * z0, 2000)
    outside = integrate_rkhp(system, NEGATIVE_WEIGHT, 1.03 * z0, 2000)
    assert inside.ok and np.linalg.norm(inside.final_state) < 10
    # the growth is a divergence: the run ends when the energy error passes 1e8 (docs/exit-status.md)
    assert outside.cause.name == "DIVERGED" and np.linalg.norm(outside.final_state) > 1e3


def test_shifted_positive_weights_are_elliptic_for_every_z():
    """Positive weights and rkhp's positive definite Q: R is similar to a rotation (docs/stability.md);
    at z = 20 the run stays bounded."""
    r = analyse(load_tableau("rk4"), realisation="shifted")
    assert r.stability_interval.exact == "oo"
    x = integrate_rkhp(oscillator("shifted"), load_tableau("rk4"), 20.0, 500).final_state
    assert np.linalg.norm(x) < 10


def _step_matrix_of_the_integrator(system, tableau, z):
    return np.array([integrate_rkhp(system, tableau, z, 1, x0=e).final_state for e in ((1.0, 0.0), (0.0, 1.0))]).T


@pytest.mark.parametrize("tableau", [GAUSS1, load_tableau("paper-implicit"), load_tableau("gauss2"),
                                     NEGATIVE_WEIGHT_IMPLICIT], ids=lambda t: t.name)
def test_shifted_implicit_step_matrix_equals_the_integrator(tableau):
    """Implicit stages with the shifted realisation: the predicted step matrix (the branch of the
    matrix stage equations through 0) is the integrator's, det R = 1, tr R depends on
    delta = det(P^-1 + Q) alone as 2 (4 delta - 1)/(4 delta + 1), and the series of theta(z) - z
    matches arccos(tr R/2) of the integrator's step at small z."""
    system = oscillator("shifted")
    r = analyse(tableau, order=9, realisation="shifted")
    for z in (0.05, 0.3):
        R = _step_matrix_of_the_integrator(system, tableau, z)
        assert np.allclose(R, step_matrix_shifted(tableau, z), rtol=0, atol=1e-13)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)
        # P from R alone: R (I + D P) = I + D' P, so P = (R D - D')^-1 (I - R)
        Q, half_J = np.array([[0.5, 0.25], [0.25, 0.5]]), np.array([[0.0, 0.5], [-0.5, 0.0]])
        P = np.linalg.solve(R @ (Q - half_J) - (Q + half_J), np.eye(2) - R)
        delta = np.linalg.det(np.linalg.inv(P) + Q)
        assert np.trace(R) == pytest.approx(2 * (4 * delta - 1) / (4 * delta + 1), abs=1e-12)
    z = 0.05
    series = z + sum(c.value * z**k for k, c in r.phase.coefficients)
    theta = math.acos(np.trace(_step_matrix_of_the_integrator(system, tableau, z)) / 2)
    assert theta == pytest.approx(series, abs=1e-11)


def test_one_stage_shifted_fold_by_elimination():
    """One stage: M = c G(M), c = z a. Eliminating M from the stage equations and det J = 0 leaves
    a polynomial in c with the root 1/3, where the branch through 0 folds: z* = 1/(3a)."""
    c, u, v, w = sympy.symbols("c u v w")
    Q = sympy.Matrix([[sympy.Rational(1, 2), sympy.Rational(1, 4)], [sympy.Rational(1, 4), sympy.Rational(1, 2)]])
    D = Q - sympy.Matrix([[0, 1], [-1, 0]]) / 2
    M = sympy.Matrix([[u, v], [v, w]])
    N = sympy.eye(2) + D * M
    F = M - c * N.T * N
    equations = [sympy.expand(F[0, 0]), sympy.expand(F[0, 1]), sympy.expand(F[1, 1])]
    jacobian = sympy.Matrix(equations).jacobian([u, v, w]).det()
    basis = sympy.groebner([*equations, sympy.expand(jacobian)], u, v, w, c, order="lex")
    eliminant = [g for g in basis.exprs if g.free_symbols <= {c}][-1]
    assert eliminant.subs(c, sympy.Rational(1, 3)) == 0
    for tableau, exact in ((GAUSS1, "2/3"), (load_tableau("paper-implicit"), "sqrt(3)/3")):
        r = analyse(tableau, realisation="shifted")
        assert r.existence_limit.exact == exact and r.stability_interval.exact == exact
        assert r.existence_limit.value == pytest.approx(1 / (3 * tableau.A_float[0][0]), rel=1e-15)


def test_shifted_implicit_interval_by_integration():
    """Positive weights: P is a positive combination of Gram matrices, the step is elliptic wherever
    the stages exist, and the interval ends at their fold: 200 steps stay bounded just inside, and
    just outside the stage iteration fails. A negative weight: the step turns hyperbolic before the
    fold; 2000 steps stay bounded just inside and diverge just outside."""
    system = oscillator("shifted")
    for tableau in (GAUSS1, load_tableau("gauss2")):
        z0 = analyse(tableau, realisation="shifted").stability_interval.value
        inside = integrate_rkhp(system, tableau, 0.98 * z0, 200)
        assert inside.ok and np.linalg.norm(inside.final_state) < 10
        outside = integrate_rkhp(system, tableau, 1.02 * z0, 200)
        assert not outside.ok and "did not converge" in outside.status
    r = analyse(NEGATIVE_WEIGHT_IMPLICIT, realisation="shifted")
    z0, fold = r.stability_interval.value, r.existence_limit.value
    assert z0 < 0.97 * fold
    assert abs(np.trace(_step_matrix_of_the_integrator(system, NEGATIVE_WEIGHT_IMPLICIT, z0))) \
        == pytest.approx(2.0, abs=1e-12)
    inside = integrate_rkhp(system, NEGATIVE_WEIGHT_IMPLICIT, 0.97 * z0, 2000)
    outside = integrate_rkhp(system, NEGATIVE_WEIGHT_IMPLICIT, 1.03 * z0, 2000)
    assert inside.ok and np.linalg.norm(inside.final_state) < 10
    assert outside.cause.name == "DIVERGED" and np.linalg.norm(outside.final_state) > 1e3


# ----------------------------------------------------------------------------- compositions


def test_triple_jump_of_euler_has_phase_order_4():
    g = 1 / (2 - sympy.root(2, 3))
    ph = composition_phase(load_tableau("euler"), [g, 1 - 2 * g, g])
    assert ph.phase_order == 4
    # theta = sum 2 arctan(gamma_i z/2): the z^5 coefficient is (1/80) sum gamma_i^5
    expected = sympy.Rational(1, 80) * (2 * g**5 + (1 - 2 * g) ** 5)
    assert ph.phase_constant.value == pytest.approx(float(expected), rel=1e-14)
    # against three Euler substeps of the integrator (a step -h on H is a step h on -H)
    h = 0.4
    x = (1.0, 0.0)
    for gamma in (g, 1 - 2 * g, g):
        system = oscillator(omega=float(np.sign(float(gamma))))
        x = integrate_rkhp(system, "euler", abs(float(gamma)) * h, 1, x0=x).final_state
    long = composition_phase(load_tableau("euler"), [g, 1 - 2 * g, g], order=31)
    series = h + sum(c.value * h**k for k, c in long.coefficients)
    assert clockwise_angle(x) == pytest.approx(series, abs=1e-13)


# ----------------------------------------------------------------------------- the command


def test_cli_json(run_cli):
    status, out, _ = run_cli("stability", "paper-three-stage,euler,paper-implicit", "--format", "json")
    assert status == 0
    doc = json.loads(out)
    keys = {"m", "theta_series", "phase_order", "phase_constant", "wrap_limit", "existence_limit",
            "stability_interval"}
    for r in doc["methods"]:
        assert keys <= set(r)
    p3, euler, implicit = doc["methods"]
    assert p3["m"] == "z + z^3/12 + z^5/128 + 3*z^7/16384"
    assert (p3["phase_order"], p3["phase_constant"]["exact"]) == (4, "-1/1920")
    assert euler["phase_order"] == 2
    assert implicit["existence_limit"]["exact"] == "sqrt(3)"
    assert implicit["existence_limit"]["float"] == pytest.approx(math.sqrt(3), rel=1e-15)


def test_cli_plot_and_bad_input(run_cli, tmp_path):
    path = tmp_path / "phase.png"
    status, _, _ = run_cli("stability", "euler,rk4", "--plot", str(path))
    assert status == 0 and path.stat().st_size > 1000
    status, _, err = run_cli("stability", "no-such-method")
    assert status == 2 and err.count("\n") == 1
    status, _, err = run_cli("stability", "classical:rk4")
    assert status == 2 and "RKHP method" in err


def _repeated_midpoint(stages: int) -> Tableau:
    """The implicit midpoint rule written as `stages` identical uncoupled stages: A = I/2, b_i = 1/s."""
    A = [["1/2" if i == j else 0 for j in range(stages)] for i in range(stages)]
    return Tableau.from_arrays(A, [f"1/{stages}"] * stages, name=f"midpoint-x{stages}")


@pytest.mark.parametrize("realisation, stages", [("symmetric", 9), ("shifted", 5)])
def test_implicit_stages_beyond_the_bound_are_refused_before_work(realisation, stages):
    with pytest.raises(InputError, match=f"of {stages} stages.*at most") as info:
        analyse(_repeated_midpoint(stages), realisation=realisation)
    assert "\n" not in str(info.value)
    with pytest.raises(InputError, match="at most"):
        rotation_angle(_repeated_midpoint(stages), 1.0, realisation)


def test_a_fold_of_several_stages_at_once_is_one_clear_failure():
    """Two stages folding together at z = 2 make the refinement's Jacobian singular there."""
    with pytest.raises(NumericalFailure, match="near z = 1.99.*several stages fold at once") as info:
        analyse(_repeated_midpoint(2))
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------------------- long-time behaviour


def _growth(system, steps, method, tolerance=1e-8):
    from rkhp.studies.longtime import energy_growth

    return energy_growth(system, method, 0.1, steps, tolerance)


def test_long_time_short_version():
    """2 10^4 steps on the rigid body: the RKHP energy error stays bounded (exponent about 0), DOP853's
    drifts (about 1)."""
    from rkhp.systems import get_system

    system = get_system("rigid-body")
    assert abs(_growth(system, 20_000, "paper-three-stage").exponent) < 0.1
    assert _growth(system, 20_000, "scipy:dop853").exponent > 0.8


def test_long_time_compositions_and_the_integrable_lotka_volterra():
    """10^4 steps (t = 1000): compositions (triple jump tj4, Kahan–Li order 6) keep the energy
    error bounded on the rigid body and on the integrable 5-d Lotka–Volterra system, as the RKHP
    method does; DOP853 drifts on the latter (its H is not linear, docs/stability.md)."""
    from rkhp.systems import get_system

    rigid, lv5 = get_system("rigid-body"), get_system("lv5-integrable")
    for method in ("tj4", "kahan-li6"):
        assert abs(_growth(rigid, 10_000, method).exponent) < 0.1, method
    for method in ("paper-three-stage", "tj4", "kahan-li6"):
        assert abs(_growth(lv5, 10_000, method).exponent) < 0.1, method
    assert 0.8 < _growth(lv5, 10_000, "scipy:dop853").exponent < 1.2


def test_growth_fit_recovers_a_power():
    from rkhp.studies.longtime import fit_exponent

    t = np.geomspace(1, 1e5, 50)
    assert fit_exponent(t, 3e-9 * t**0.5, 1e5) == pytest.approx(0.5, abs=1e-12)
    assert fit_exponent(t, np.zeros(50), 1e5) is None


@pytest.mark.slow
@pytest.mark.parametrize("system_name,tolerance", [("rigid-body", 1e-8), ("lotka-volterra", 1e-6)])
def test_long_time_million_steps(system_name, tolerance):
    """10^6 steps (t = 10^5): RKHP methods bounded, DOP853 drifting (docs/stability.md)."""
    from rkhp.systems import get_system

    system = get_system(system_name)
    for method in ("paper-three-stage", "euler"):
        assert abs(_growth(system, 10**6, method).exponent) < 0.1
    assert _growth(system, 10**6, "scipy:dop853", tolerance).exponent > 0.7


def test_long_time_cli(run_cli, tmp_path):
    path = tmp_path / "long.png"
    status, out, _ = run_cli("long-time", "rigid-body", "--steps", "2000", "--method", "euler",
                             "--plot", str(path), "--format", "json")
    assert status == 0 and path.stat().st_size > 1000
    run = json.loads(out)["runs"][0]
    assert run["method"] == "euler" and run["status"] == "ok" and len(run["times"]) == len(run["energy_errors"])
    status, _, err = run_cli("long-time", "rigid-body", "--steps", "10")
    assert status == 2 and err.count("\n") == 1
    status, out, _ = run_cli("long-time", "rigid-body", "--steps", "200", "--method", "tj4,kahan-li6",
                             "--format", "json")
    assert status == 0 and [r["method"] for r in json.loads(out)["runs"]] == ["tj4", "kahan-li6"]
    status, _, err = run_cli("long-time", "rigid-body", "--method", "tj4,no-such-method")
    assert status == 2 and err.count("\n") == 1


def test_a_failed_long_run_is_shown_and_gives_status_1_in_one_line(run_cli):
    """rk4 at h = 50 on the pendulum: Newton fails at the first step; the run is in the document
    with its failure beside DOP853's, and the command ends as a numerical failure naming it
    (docs/exit-status.md)."""
    status, out, err = run_cli("long-time", "pendulum", "--method", "scipy:dop853,rk4", "--h", "50",
                               "--steps", "100", "--format", "json")
    runs = {r["method"]: r["status"] for r in json.loads(out)["runs"]}
    assert status == 1 and runs == {"scipy:dop853": "ok", "rk4": runs["rk4"]}
    assert runs["rk4"].startswith("failed at step 0") and err.count("\n") == 1
    assert err == f"rkhp: numerical failure: pendulum: rk4 (h = 50): {runs['rk4']}\n"
