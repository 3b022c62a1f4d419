"""rkhp.solve, integrate --tol, events, dense output, Poincaré sections and declared invariants
(docs/solve.md), against values from outside the code: closed-form periods (elliptic integrals,
mpmath), the rigid body's exact solution, DOP853 and mpmath reference solutions."""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest
import sympy
from click.testing import CliRunner
from rkhp_cli.main import rkhp as cli

import rkhp
from rkhp.base.errors import InputError
from rkhp.integrators.methods import resolve_system
from rkhp.ivp import tolerance
from rkhp.studies.reference import reference, symbolic_field
from rkhp.systems import builtin_systems

SPEC = """
name = "my-body"
family = "lie-poisson"
structure_constants = [[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
x0 = [0.4536, 0.0, 0.8912]
t_final = 10.0
casimirs = ["x1^2 + x2^2 + x3^2"]
invariants = ["x1^2/2 + x2^2 + 3*x3^2/2"]
"""

GENERAL_SPEC = """
name = "nambu-spec"
family = "general"
poisson = [["0", "-x3", "x2"], ["x3", "0", "-(x1 + x1^3)"], ["-x2", "x1 + x1^3", "0"]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
casimirs = ["(x1^2 + x2^2 + x3^2)/2 + x1^4/4"]
x0 = [0.45359612142557731, 0.0, 0.89120736006143542]
t_final = 5.0
"""


def _invoke(*args):
    result = CliRunner().invoke(cli, list(args))
    return result.exit_code, result.stdout, result.stderr


def _spec(tmp_path, text=SPEC, name="body.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _meets(system_name, method, tol, ref=None):
    """The solve's end state against the reference: (relative error, estimated error)."""
    system = resolve_system(system_name)
    result = rkhp.solve(system, (0.0, system.t_final), method, tol, t_eval=[system.t_final])
    assert result.success, result.message
    ref = ref or reference(system, system.t_final)
    assert ref.floor < tol, "the reference cannot tell whether the tolerance is met"
    final = result.y[:, -1]
    actual = float(np.linalg.norm(final - ref.state)) / max(1.0, float(np.linalg.norm(final)))
    return actual, result.estimated_error


# ----------------------------------------------------------------------------------------------
# the tolerance


@pytest.mark.parametrize("system,method,tol", [
    ("rigid-body", "paper-three-stage", 1e-4),
    ("rigid-body", "kahan-li8", 1e-12),
    ("lotka-volterra", "paper-three-stage", 1e-8),
    ("pendulum", "search-symmetric-o6-s5", 1e-10),
    ("toda", "kahan-li8", 1e-6),
])
def test_the_tolerance_is_met_against_the_reference(system, method, tol):
    actual, estimated = _meets(system, method, tol)
    assert actual <= tol
    # the estimate is of the right size (within a factor 4 of the measured error)
    assert actual / 4 <= estimated <= 4 * actual + 1e-15


def test_the_tolerance_is_met_on_spec_files(tmp_path):
    for text, name, tol in ((SPEC, "body.toml", 1e-9), (GENERAL_SPEC, "nambu.toml", 1e-7)):
        path = _spec(tmp_path, text, name)
        system = resolve_system(path)
        result = rkhp.solve(path, None, "paper-three-stage", 1e-9 if name == "body.toml" else tol)
        ref = reference(system, system.t_final)
        error = np.linalg.norm(result.y[:, -1] - ref.state) / max(1.0, np.linalg.norm(ref.state))
        assert result.success and error <= result.tolerance


@pytest.mark.slow
@pytest.mark.parametrize("system", builtin_systems())
@pytest.mark.parametrize("method", ["paper-three-stage", "kahan-li8"])
def test_the_tolerance_is_met_on_every_built_in_system(system, method):
    """1e-4..1e-12 against DOP853 or the closed form, or mpmath where DOP853's own error is too large."""
    poisson = resolve_system(system)
    ref = reference(poisson, poisson.t_final)
    for tol in (1e-4, 1e-6, 1e-8, 1e-10, 1e-12):
        if ref.floor >= tol:
            ref = reference(poisson, poisson.t_final, kind="mpmath")
        try:
            actual, _ = _meets(system, method, tol, ref)
        except InputError as exc:  # refused before the run: its steps' round-off bound passes tol
            assert "round-off" in str(exc) and tol <= 1e-10, (system, method, tol, str(exc))
            continue
        assert actual <= tol, (system, method, tol, actual)


def test_a_tolerance_within_the_round_off_of_its_steps_is_refused():
    """The paper's method on the heavy top needs about 10^4 steps for 1e-12: a run of that length
    ends 1.3e-12 from an independent reference (a tenth-order composition at two step sizes,
    agreeing to 6e-14), the truncation error estimated at 4.8e-13 and the rest round-off, so the
    promise cannot be kept and the solve says so before the run; at 1e-10 it is kept."""
    system = resolve_system("heavy-top")
    with pytest.raises(InputError, match="round-off"):
        rkhp.solve(system, (0.0, system.t_final), "paper-three-stage", 1e-12)
    ref = rkhp.integrate("heavy-top", "sofroniou-spaletta10", system.t_final / 2000, 2000).states[-1]
    result = rkhp.solve(system, (0.0, system.t_final), "paper-three-stage", 1e-10, t_eval=[system.t_final])
    assert np.linalg.norm(result.y[:, -1] - ref) / max(1.0, np.linalg.norm(ref)) <= 1e-10


def test_the_pilot_estimate_is_richardson_of_the_method_order():
    # Euler (order 2 on the symmetric realisation) on the rigid body: d_k / d_(k+1) -> 4
    system = resolve_system("rigid-body")
    method = rkhp.resolve_method("euler")
    pilot = tolerance.pilot_runs(system, method, tolerance.Span(0.0, 10.0), 2)
    assert abs(pilot.observed_order - 2) < 0.2
    assert pilot.estimate == pytest.approx(pilot.differences[-1] / 3, rel=0.1)


def test_a_tolerance_that_needs_too_many_steps_is_refused_before_the_run():
    with pytest.raises(InputError, match="needs about"):
        rkhp.solve("rigid-body", (0, 1000), "euler", 1e-13, t_eval=[1000])


def test_method_auto_chooses_the_cheapest_candidate_that_meets_the_tolerance():
    result = rkhp.solve("lv5-nonintegrable", None, "auto", 1e-10, t_eval=[10.0])
    chosen = [c for c in result.plan.candidates if c.method == result.method][0]
    assert chosen.choice.predicted_seconds == min(c.choice.predicted_seconds for c in result.plan.candidates
                                                  if c.choice is not None)
    ref = reference(resolve_system("lv5-nonintegrable"), 10.0)
    assert np.linalg.norm(result.y[:, -1] - ref.state) / np.linalg.norm(ref.state) <= 1e-10


# ----------------------------------------------------------------------------------------------
# dense output and t_eval


def test_dense_output_has_the_method_order_and_keeps_the_casimir():
    system = rkhp.get_system("rigid-body")
    result = rkhp.solve(system, (0, 10), "paper-three-stage", 1e-8, dense_output=True)
    times = np.linspace(0, 10, 41) + 0.0123
    times[-1] = 10.0
    states = result.sol(times)
    assert states.shape == (3, 41)
    assert np.abs(states.T - system.exact_solution(times)).max() < 1e-8
    casimir = 0.5 * np.sum(states**2, axis=0)
    assert np.abs(casimir - 0.5 * np.dot(system.x0, system.x0)).max() < 1e-14
    assert result.sol(3.3).shape == (3,)
    with pytest.raises(InputError):
        result.sol(10.5)


def test_t_eval_gives_the_states_at_those_times_only():
    system = rkhp.get_system("rigid-body")
    result = rkhp.solve(system, (0, 10), "kahan-li8", 1e-11, t_eval=[0.0, 2.5, 7.1, 10.0])
    assert result.t.tolist() == [0.0, 2.5, 7.1, 10.0]
    assert np.abs(result.y.T - system.exact_solution(result.t)).max() < 1e-11


def test_a_backward_solve_returns_to_the_start():
    system = rkhp.get_system("pendulum")
    forward = rkhp.solve(system, (0, 5), "paper-three-stage", 1e-10, t_eval=[5.0])
    back = rkhp.solve(system, (5, 0), "paper-three-stage", 1e-10, x0=forward.y[:, -1], t_eval=[0.0])
    assert np.abs(back.y[:, -1] - system.x0).max() < 1e-9


# ----------------------------------------------------------------------------------------------
# events and Poincaré sections


def _rigid_body_period():
    """The period of the rigid body's orbit from x0 = (A, 0, C): 4 K(m) / lambda (Jacobi's
    elliptic functions, rkhp.systems.builtins.rigid_body_exact's constants, recomputed here)."""
    inertia = (2.0, 1.0, 2.0 / 3.0)
    a1, a2, a3 = (mpmath.mpf(1) / mpmath.mpf(v) for v in inertia)
    A, C = mpmath.cos(mpmath.mpf("1.1")), mpmath.sin(mpmath.mpf("1.1"))
    lam = C * mpmath.sqrt((a3 - a2) * (a3 - a1))
    m = (a2 - a1) * A * A / ((a3 - a2) * C * C)
    return float(4 * mpmath.ellipk(m) / lam)


def test_the_rigid_body_section_is_a_fixed_point_at_every_period():
    """Every orbit of the rigid body is periodic, x = (A cn, B sn, C dn)(lambda t) with B < 0: x2 = 0
    upwards at tau = 2K mod 4K, always at the point (-A, 0, C), at t = (k + 1/2) T."""
    period = _rigid_body_period()
    section = rkhp.poincare_section("rigid-body", "x2", 5 * period, "kahan-li8", 1e-11)
    assert len(section.times) == 5
    assert np.abs(section.times - (np.arange(5) + 0.5) * period).max() < 1e-9
    A, _, C = rkhp.get_system("rigid-body").x0
    assert np.abs(section.points - [-A, 0.0, C]).max() < 1e-10


def test_the_pendulum_section_crosses_at_the_elliptic_period():
    """H = p^2/2 - cos q from (q0, 0): period 4 K(sin^2(q0/2)); p = 0 upwards at q = -q0, t = T/2 + k T."""
    period = float(4 * mpmath.ellipk(mpmath.sin(0.75) ** 2))
    code, out, _ = _invoke("poincare", "pendulum", "--section", "x2", "--t-final", "40", "--tol", "1e-10",
                           "--format", "json")
    assert code == 0
    doc = json.loads(out)
    assert doc["count"] == 5
    assert np.abs(np.array(doc["times"]) - (period / 2 + period * np.arange(5))).max() < 1e-9
    assert np.abs(np.array(doc["points"]) - [-1.5, 0.0]).max() < 1e-10


def test_event_times_agree_with_an_mpmath_solve():
    """The charged particle's first crossing of x1 = 1/2, against mpmath's Taylor-series solve at
    20 digits and its root by mpmath.findroot."""
    system = resolve_system("charged-particle")
    result = rkhp.solve(system, (0, 3), "kahan-li8", 1e-12, events=["x1 - 0.5"])
    (found,) = result.t_events[0]
    symbols, field = symbolic_field(system)
    f = sympy.lambdify(symbols, field, modules="mpmath")
    with mpmath.workdps(20):
        solution = mpmath.odefun(lambda t, y: f(*y), 0, [mpmath.mpf(1), mpmath.mpf(1)])
        root = mpmath.findroot(lambda t: solution(t)[0] - mpmath.mpf("0.5"), mpmath.mpf(found))
    assert abs(float(root) - found) < 1e-11
    assert abs(result.y_events[0][0][0] - 0.5) < 1e-15


def test_direction_and_terminal_events():
    period = _rigid_body_period()
    end = 2.75 * period
    up = rkhp.solve("rigid-body", (0, end), "kahan-li8", 1e-10, t_eval=[end],
                    events=[rkhp.event("x2", direction=1), rkhp.event("x2", direction=-1), "x2"])
    counts = [len(t) for t in up.t_events]
    assert counts == [3, 2, 5]  # x2 = B sn(lambda t), B < 0: up at (k + 1/2) T, down at k T
    assert np.abs(up.t_events[1] - [period, 2 * period]).max() < 1e-8
    stop = rkhp.solve("rigid-body", (0, end), "kahan-li8", 1e-10,
                      events=[rkhp.event("x2", direction=-1, terminal=2)])
    assert stop.status == 1 and stop.success
    assert stop.t[-1] == pytest.approx(2 * period, abs=1e-8) and stop.t[-1] == stop.t_events[0][-1]
    assert len(stop.t_events[0]) == 2


def test_a_python_event_function_as_scipy_takes_it():
    def g(t, y):
        return y[1]

    g.terminal = True
    g.direction = -1
    result = rkhp.solve("rigid-body", (0, 20), "paper-three-stage", 1e-8, events=g)
    assert result.status == 1
    assert result.t_events[0][0] == pytest.approx(_rigid_body_period(), abs=1e-7)


def test_hostile_event_text_is_refused_before_anything_runs():
    for text in ("__import__('os').system('true')", "x1.real", "x9", "x1 +* 2", "10^10^10"):
        with pytest.raises(InputError):
            rkhp.solve("rigid-body", (0, 1), "euler", steps=10, events=[text])
    code, out, err = _invoke("poincare", "rigid-body", "--section", "open('x')")
    assert code == 2 and err.startswith("rkhp: error: --section") and len(err.splitlines()) == 1


def test_a_pole_of_the_section_is_no_crossing():
    """x1 / (x1^2 - 1) changes sign at its zero x1 = 0 and at its poles x1 = +-1, all crossed by
    the pendulum's swing (|x1| <= 1.5): the crossings are those of x1 = 0 alone; 1/x1 has none."""
    zeros = rkhp.poincare_section("pendulum", "x1", steps=100, direction="both")
    section = rkhp.poincare_section("pendulum", "x1/(x1^2 - 1)", steps=100, direction="both")
    assert section.count == zeros.count == 3
    np.testing.assert_allclose(section.times, zeros.times, rtol=1e-12)
    assert np.abs(section.points[:, 0]).max() < 1e-15
    assert rkhp.poincare_section("pendulum", "1/x1", steps=100, direction="both").count == 0


def test_a_section_undefined_along_the_orbit_is_a_numerical_failure():
    """sqrt(x1) is NaN once the pendulum swings to x1 < 0: its crossings cannot be told."""
    with pytest.raises(rkhp.NumericalFailure, match=r"event sqrt\(x1\): not finite at t = "):
        rkhp.poincare_section("pendulum", "sqrt(x1)", steps=100, direction="both")
    code, out, err = _invoke("poincare", "pendulum", "--section", "sqrt(x1)", "--steps", "100")
    assert code == 1 and len(err.splitlines()) == 1 and "not finite at t = " in err


@pytest.mark.parametrize("text", ["x1 - 1e308*1e308", "x1 - 1e200*1e200*x2"])
def test_a_section_not_finite_at_the_start_is_refused_in_one_line(text):
    """A constant beyond the float range (read exactly, 10^616) gives no finite value anywhere:
    refused at x0, as a spec file's Hamiltonian is."""
    with pytest.raises(InputError, match="not finite at x0"):
        rkhp.solve("pendulum", (0, 1), "euler", steps=10, events=[text])
    code, out, err = _invoke("poincare", "pendulum", "--section", text, "--steps", "100")
    assert code == 2 and out == "" and len(err.splitlines()) == 1
    assert err.startswith("rkhp: error: --section: expression") and "not finite at x0" in err


# ----------------------------------------------------------------------------------------------
# the command line


def test_integrate_tol_says_its_steps_before_the_run_and_reports_its_estimate():
    code, out, _ = _invoke("integrate", "rigid-body", "--tol", "1e-8")
    assert code == 0
    first = out.splitlines()[0]
    assert first.startswith("tol 1e-08: kahan-li8 (order 8)") and "chose 16" in out
    code, out, _ = _invoke("integrate", "rigid-body", "--tol", "1e-8", "--format", "json")
    doc = json.loads(out)
    assert doc["steps"] == 16 and doc["tolerance"]["met"]
    assert doc["exact_error"] <= 1e-8 and doc["tolerance"]["estimated_error"] <= 1e-8


@pytest.mark.parametrize("args,message", [
    (("--tol", "1e-8", "--steps", "10"), "give one of --tol, --steps and --h"),
    (("--method", "auto", "--steps", "10"), "--method auto chooses by a tolerance"),
    (("--tol", "1e-20"), "--tol"),
    (("--tol", "1e-8", "--method", "scipy:dop853"), "runs by tolerance"),
])
def test_integrate_tol_bad_input(args, message):
    code, _, err = _invoke("integrate", "rigid-body", *args)
    assert code == 2 and message in err and len(err.splitlines()) == 1


def test_poincare_csv_and_plot(tmp_path):
    plot = tmp_path / "section.png"
    code, out, _ = _invoke("poincare", "lv5-nonintegrable", "--section", "x1 - 1", "--t-final", "60",
                           "--tol", "1e-6", "--axes", "x2,x4", "--plot", str(plot), "--format", "csv")
    assert code == 0 and plot.exists() and plot.with_suffix(".csv").exists()
    lines = out.splitlines()
    assert lines[0].startswith("# provenance: ") and lines[1] == "crossing,t,x1,x2,x3,x4,x5"
    rows = [list(map(float, line.split(","))) for line in lines[2:]]
    assert rows and all(abs(r[2] - 1.0) < 1e-12 for r in rows)


# ----------------------------------------------------------------------------------------------
# declared invariants


def test_declared_invariants_are_reported_like_the_energy(tmp_path):
    path = _spec(tmp_path)
    out_file = tmp_path / "run.csv"
    code, out, _ = _invoke("integrate", path, "--steps", "100", "--output", str(out_file), "--format", "json")
    assert code == 0
    doc = json.loads(out)
    # 2H is the invariant here: its largest drift is at least twice the energy error at the end
    assert 2 * doc["energy_error"] * (1 - 1e-9) <= doc["invariant_errors_max"][0] < 1e-6
    header = out_file.read_text().splitlines()[1].split(",")
    assert header == ["t", "x1", "x2", "x3", "energy", "casimir1", "invariant1", "newton_iterations",
                      "stage_sweeps"]
    code, out, _ = _invoke("converge", path, "--method", "paper-two-stage", "--steps", "20", "--refinements", "2",
                           "--format", "json")
    rows = json.loads(out)["methods"][0]["rows"]
    assert all(r["invariant_error_max"] is not None and r["invariant_error_max"] < 1e-2 for r in rows)
    code, out, _ = _invoke("long-time", path, "--steps", "200", "--method", "euler", "--format", "json")
    assert json.loads(out)["runs"][0]["invariant_errors_max"][0] < 1e-2


def test_an_invariant_that_is_not_conserved_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"invariants\[1\] x2 is not conserved"):
        rkhp.system(family="lie-poisson", structure_constants=[[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]],
                    hamiltonian="x1^2/4 + x2^2/2 + 3*x3^2/4", x0=[0.4536, 0.0, 0.8912], invariants=["x2"])
    code, _, err = _invoke("integrate", _spec(tmp_path, SPEC.replace('"x1^2/2 + x2^2 + 3*x3^2/2"', '"x1*x2 + x3"'),
                                              "bad.toml"), "--steps", "10")
    assert code == 2 and "is not conserved" in err


def test_the_kovalevskaya_style_integral_of_a_spec_file_is_kept_by_solve():
    """The heavy top's two Casimirs declared as invariants of the problem (M.Gamma and |Gamma|^2)
    are conserved to the tolerance's order by a solve, and the energy."""
    system = rkhp.system(family="lie-poisson", structure_constants=_heavy_top_constants(),
                         hamiltonian="x1^2/4 + x2^2/2 + 3*x3^2/4 + x6",
                         x0=[math.cos(1.1), 0.0, math.sin(1.1), 0.6, 0.0, 0.8],
                         invariants=["x1*x4 + x2*x5 + x3*x6"])
    result = rkhp.solve(system, (0, 10), "paper-three-stage", 1e-8, t_eval=[10.0])
    assert result.invariant_errors_max[0] < 1e-13  # a Casimir of the structure: kept to round-off
    assert result.energy_error_max < 1e-7


def _heavy_top_constants():
    rows = []
    for i, j, k, sign in ((1, 2, 3, -1), (2, 3, 1, -1), (3, 1, 2, -1)):
        rows += [[i, j, k, sign], [i, j + 3, k + 3, sign], [i + 3, j, k + 3, sign]]
    return rows
