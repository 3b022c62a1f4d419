"""Studies: order fits (synthetic tables), references, converge / bench / stress, plots, CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from rkhp_cli.main import rkhp

from rkhp.base.errors import InputError
from rkhp.base.json_form import json_form
from rkhp.studies.fit import fit_order, local_order, verdict
from rkhp.systems import get_system

H = [0.5 / 2**k for k in range(8)]


# ----------------------------------------------------------------------------------------------
# fits on synthetic tables with known slopes, pre-asymptotic points and floors


def test_fit_exact_power_law():
    fit = fit_order(H, [3.0 * h**3 for h in H])
    assert fit.slope == pytest.approx(3.0, abs=1e-12)
    assert fit.fit_rows == tuple(range(8)) and fit.excluded == ()
    assert fit.local_orders[0] is None
    assert all(p == pytest.approx(3.0) for p in fit.local_orders[1:])


def test_fit_leaves_out_pre_asymptotic_rows():
    # e = h^4 + 40 h^6: the h^6 term dominates the coarse rows
    errors = [h**4 + 40 * h**6 for h in H]
    fit = fit_order(H, errors)
    assert fit.slope == pytest.approx(4.0, abs=0.05)
    assert dict(fit.excluded).get(0) == "pre-asymptotic"
    assert all(why == "pre-asymptotic" for _, why in fit.excluded)
    assert fit.fit_rows[-1] == len(H) - 1


def test_fit_leaves_out_round_off_floor():
    rng = np.random.default_rng(0)
    errors = [max(1e-3 * h**4, 1e-10 * (1 + rng.random())) for h in H]
    fit = fit_order(H, errors)
    assert fit.slope == pytest.approx(4.0, abs=1e-9)
    floor = [i for i, why in fit.excluded if why == "round-off floor"]
    assert floor and min(floor) > max(fit.fit_rows)
    assert floor[-1] == len(H) - 1
    assert all(1e-3 * H[i] ** 4 < 1e-10 for i in floor)  # only rows where h^4 is below the floor


def test_fit_below_reference_accuracy_and_failures():
    errors = [None, *[h**2 for h in H[1:-2]], 1e-20, 1e-21]
    fit = fit_order(H, errors, floor=1e-15)
    reasons = dict(fit.excluded)
    assert reasons[0] == "failed"
    assert reasons[6] == reasons[7] == "below reference accuracy"
    assert fit.slope == pytest.approx(2.0, abs=1e-12)
    assert fit.fit_rows == (1, 2, 3, 4, 5)


def test_fit_without_asymptotic_range_is_inconclusive():
    errors = [1e-3, 2e-3, 5e-4, 3e-3, 1e-4]
    fit = fit_order(H[:5], errors)
    assert fit.slope is None and fit.fit_rows == ()
    assert verdict(fit.slope, 2) == "inconclusive"


def test_fit_needs_three_decreasing_step_sizes():
    with pytest.raises(InputError, match="at least 3"):
        fit_order([0.1, 0.05], [1e-2, 1e-3])
    with pytest.raises(InputError, match="decreasing"):
        fit_order([0.1, 0.2, 0.05], [1e-2, 1e-3, 1e-4])


def test_local_order_and_verdicts():
    assert local_order(0.2, 16e-4, 0.1, 1e-4) == pytest.approx(4.0)
    assert verdict(3.9, 4) == "confirmed"
    assert verdict(4.6, 4) == "higher than expected"
    assert verdict(1.1, 2) == "lower than expected"


# ----------------------------------------------------------------------------------------------
# references


def test_exact_reference_agrees_with_dop853():
    from rkhp.studies.reference import dop853_reference, reference

    rigid = get_system("rigid-body")
    exact = reference(rigid, 10.0)
    assert exact.kind == "exact" and exact.error_estimate < 1e-13
    numeric = dop853_reference(rigid, 10.0)
    assert numeric.error_estimate < 1e-12
    assert np.linalg.norm(exact.state - numeric.state) <= numeric.error_estimate + exact.error_estimate


def test_dop853_reference_of_lotka_volterra_keeps_its_casimir():
    from rkhp.studies.reference import reference

    lv = get_system("lotka-volterra")
    ref = reference(lv, 3.0)
    assert ref.kind == "dop853" and 0 < ref.error_estimate < 1e-12
    (casimir,) = lv.casimirs
    assert abs(casimir(ref.state) - casimir(lv.x0)) < 1e-12
    assert ref.floor == pytest.approx(10 * ref.error_estimate)


def test_dop853_error_estimate_is_honest_against_mpmath():
    """Lotka–Volterra (docs/theory.md §6) solved independently by mpmath's Taylor integrator at 25 digits:
    the DOP853 reference is within its own error estimate."""
    import mpmath

    from rkhp.studies.reference import reference

    lam = [[0, 1, 2], [-1, 0, 1], [-2, -1, 0]]
    with mpmath.workdps(25):
        solution = mpmath.odefun(lambda t, x: [x[i] * sum(lam[i][j] * (x[j] - 1) for j in range(3))
                                               for i in range(3)], 0, [mpmath.mpf("0.5"), 1, 2])
        exact = np.array([float(v) for v in solution(3)])
    ref = reference(get_system("lotka-volterra"), 3.0)
    assert np.linalg.norm(ref.state - exact) <= ref.error_estimate


# ----------------------------------------------------------------------------------------------
# convergence studies with the RKHP integrators (orders: paper Table 1 / Theorem 5.1, docs/theory.md §6)


def _study(system, realisation, methods, steps, t_final=None):
    from rkhp.integrators.methods import resolve_methods
    from rkhp.studies.converge import converge

    return converge(get_system(system, realisation=realisation), resolve_methods(methods), steps, t_final)


SYMMETRIC = {"euler": 2, "paper-two-stage": 3, "paper-three-stage": 4, "rk4": 4}


@pytest.mark.parametrize(("system", "t_final"), [("rigid-body", None), ("lotka-volterra", 3.0)])
def test_symmetric_orders(system, t_final):
    study = _study(system, "symmetric", list(SYMMETRIC), [40, 80, 160, 320, 640, 1280, 2560], t_final)
    assert study.degenerate
    for m in study.methods:
        assert m.expected_order == SYMMETRIC[m.method]
        assert m.observed_order == pytest.approx(SYMMETRIC[m.method], abs=0.15), m.method
        assert m.verdict == "confirmed"
        assert len(m.fit.fit_rows) >= 3
        assert max(r.casimir_error for r in m.rows) < 1e-12  # RKHP keeps the Casimir


@pytest.mark.parametrize(("system", "t_final"), [("rigid-body", None), ("lotka-volterra", 3.0)])
def test_shifted_realisation_drops_euler_not_rk4(system, t_final):
    study = _study(system, "shifted", ["euler", "rk4"], [80, 160, 320, 640, 1280, 2560], t_final)
    assert not study.degenerate
    euler, rk4 = study.methods
    assert (euler.expected_order, rk4.expected_order) == (1, 4)
    assert euler.observed_order == pytest.approx(1, abs=0.15)
    assert rk4.observed_order == pytest.approx(4, abs=0.15)
    assert euler.verdict == rk4.verdict == "confirmed"


def test_errors_below_reference_accuracy_are_not_measurements():
    study = _study("nambu", "symmetric", ["rk4"], [100, 1000, 10000, 20000])  # reference: DOP853
    (m,) = study.methods
    floor = study.reference.floor
    for i, r in enumerate(m.rows):
        assert r.error is None or r.error > floor
        if r.error is None:
            assert dict(m.fit.excluded)[i] == "below reference accuracy"
            assert r.measured_error <= floor
    assert m.rows[-1].error is None


def test_classical_peers_as_methods():
    study = _study("rigid-body", "symmetric", ["classical:rk4", "implicit-midpoint"], [40, 80, 160, 320])
    rk4, midpoint = study.methods
    assert (rk4.kind, midpoint.kind) == ("classical", "implicit-midpoint")
    assert (rk4.expected_order, midpoint.expected_order) == (4, 2)
    assert rk4.verdict == midpoint.verdict == "confirmed"
    assert rk4.rows[-1].casimir_error > 1e-12  # classical RK drifts off the Casimir


# ----------------------------------------------------------------------------------------------
# CLI: converge JSON, plots, bad input


def _run(args):
    result = CliRunner().invoke(rkhp, args)
    return result


CONVERGE_KEYS = {"system", "realisation", "degenerate", "symmetric", "x0", "t_final", "reference", "methods",
                 "interrupted", "provenance"}
METHOD_KEYS = {"method", "expected_order", "observed_order", "verdict", "fit_rows", "rows",
               "realisation_bound", "steps_chosen"}
ROW_KEYS = {"h", "steps", "error", "local_order", "casimir_error_max", "energy_error_max", "newton_mean", "newton_max",
            "seconds", "invariant_error_max"}


def test_converge_json_keys_and_plots(tmp_path):
    magic = {"png": b"\x89PNG\r\n\x1a\n", "pdf": b"%PDF-", "svg": b"<?xml"}
    for ext, head in magic.items():
        path = tmp_path / f"conv-{ext}.{ext}"  # each plot has its own data file (.csv)
        result = _run(["converge", "rigid-body", "--method", "euler,rk4", "--steps", "20,40,80",
                       "--plot", str(path), "--format", "json"])
        assert result.exit_code == 0, result.output
        assert path.read_bytes().startswith(head)
        if ext == "svg":
            assert b"<svg" in path.read_bytes()[:2000]
    data = json.loads(result.output)
    assert set(data) == CONVERGE_KEYS
    assert set(data["reference"]) == {"kind", "error_estimate", "choice"}
    assert [m["method"] for m in data["methods"]] == ["euler", "rk4"]
    for m in data["methods"]:
        assert set(m) == METHOD_KEYS
        assert all(set(r) == ROW_KEYS for r in m["rows"])


def test_converge_table_ends_with_verdicts():
    result = _run(["converge", "rigid-body", "--method", "paper-three-stage", "--steps", "20", "--refinements", "3"])
    assert result.exit_code == 0, result.output
    tail = result.output.strip().splitlines()[-3:]
    assert any("paper-three-stage: observed order" in line for line in tail)
    assert "confirmed" in result.output.split("verdicts")[-1]


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["converge", "no-such-system"], "no-such-system"),
        (["converge", "rigid-body", "--method", "no-such-method"], "no-such-method"),
        (["converge", "rigid-body", "--steps", "10,20"], "at least 3"),
        (["converge", "rigid-body", "--steps", "10", "--refinements", "1"], "at least 3"),
        (["converge", "rigid-body", "--t-final", "0"], "final time"),
        (["converge", "rigid-body", "--t-final", "-2"], "final time"),
        (["converge", "rigid-body", "--plot", "/no/such/folder/x.png"], "does not exist"),
        (["converge", "rigid-body", "--plot", "x.gif"], "extension"),
        (["converge", "rigid-body", "--steps", "a,b"], "integers"),
        (["bench", "rigid-body", "--peers", "nope"], "nope"),
        (["bench", "rigid-body", "--peers", "midpoint"], "implicit-midpoint (the implicit midpoint rule)"),
        (["bench", "rigid-body", "--peers", "dop853"], "scipy:dop853"),
        (["bench", "rigid-body", "--peers", "paper-two-stage"], "give it with --method"),
        (["converge", "rigid-body", "--method", "scipy:dop853"], "runs by tolerance"),
        (["converge", "rigid-body", "--method", "thp9"], "from 1 to 8"),
        (["converge", "rigid-body", "--x0", "1,2"], "has dimension 3"),
        (["stress", "rigid-body", "--x0", "a,b,c"], "comma-separated numbers"),
        (["bench", "rigid-body", "--plot", "x.jpg"], "extension"),
        (["stress", "no-such-system"], "no-such-system"),
        (["stress", "rigid-body", "--t-final", "nan"], "final time"),
    ],
)
def test_bad_input_is_one_line_exit_2(args, fragment):
    result = _run(args)
    assert result.exit_code == 2, result.output
    err = result.stderr if hasattr(result, "stderr") else result.output
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and fragment in lines[0], err
    assert "Traceback" not in result.output


def test_unwritable_plot_path(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        import os

        if os.access(folder, os.W_OK):  # running as root: permissions are not enforced
            pytest.skip("permissions are not enforced for this user")
        result = _run(["converge", "rigid-body", "--plot", str(folder / "x.png")])
        assert result.exit_code == 2 and "not writable" in result.stderr
    finally:
        folder.chmod(0o700)


# ----------------------------------------------------------------------------------------------
# bench


def _bench_json(args):
    result = _run(["bench", "rigid-body", *args, "--format", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)  # stderr may hold the cost note (docs/methods.md)


def test_bench_error_falls_as_cost_rises(tmp_path):
    plot = tmp_path / "wp.png"
    data = _bench_json(["--method", "paper-three-stage", "--peers", "scipy:dop853,classical:rk4",
                        "--steps", "10,20,40,80,160",
                        "--tolerances", "1e-4,1e-6,1e-8", "--repeats", "1", "--plot", str(plot)])
    assert plot.read_bytes().startswith(b"\x89PNG")
    assert set(data) == {"system", "realisation", "x0", "t_final", "reference", "repeats", "ensemble", "curves",
                         "cheapest", "interrupted", "absent_peers", "left_out", "provenance"}
    kinds = {c["method"]: c["kind"] for c in data["curves"]}
    assert kinds == {"paper-three-stage": "rkhp", "classical:rk4": "classical", "scipy:dop853": "scipy"}
    for c in data["curves"]:
        points = c["points"]
        cost = [p["steps"] if p["steps"] is not None else p["evaluations"] for p in points]
        errors = [p["error"] for p in points]
        assert cost == sorted(cost) and len(set(cost)) == len(cost)
        assert all(e is not None for e in errors)
        assert all(b < a for a, b in zip(errors, errors[1:], strict=False)), c["method"]
        # the times are measured, not asserted: a run of 10 steps preempted on a loaded machine can
        # take longer than one of 160 (timings belong in benchmarks/)
        assert all(p["seconds"] > 0 and math.isfinite(p["seconds"]) for p in points)
    targets = [c["target"] for c in data["cheapest"]]
    assert targets == [1e-4, 1e-6, 1e-8, 1e-10, 1e-12]
    for c in data["cheapest"]:
        if c["method"] is not None:
            assert c["error"] is None or c["error"] <= c["target"]


def test_bench_interleaves_the_curves_in_rounds():
    """In one process every curve is warmed up, then each round times every point once, each round
    starting one point further on (rkhp.studies.bench): the calls of two curves alternate."""
    from types import SimpleNamespace

    from rkhp.studies import bench as B
    from rkhp.studies.reference import reference

    system = get_system("rigid-body")
    ref = reference(system, 1.0)
    calls = []

    def method(name):
        def integrate(sys_, h, n, keep_all=True):
            calls.append((name, n))
            return SimpleNamespace(final_state=ref.state + 1e-3 / n, ok=True, status="ok", compile_seconds=0.0)

        return SimpleNamespace(name=name, kind="rkhp", integrate=integrate)

    curves, interrupted = B._interleaved_curves([method("a"), method("b")], system, ref, (10, 20), (), 1.0, 2)
    assert not interrupted
    assert calls == [("a", 10), ("b", 10),  # warm-up
                     ("a", 10), ("a", 20), ("b", 10), ("b", 20),  # round 1
                     ("a", 20), ("b", 10), ("b", 20), ("a", 10)]  # round 2, one point further on
    assert [c.method for c in curves] == ["a", "b"]
    assert [p.error for p in curves[0].points] == pytest.approx([np.sqrt(3) * 1e-4, np.sqrt(3) * 5e-5])


def test_bench_ensemble_mode():
    data = _bench_json(["--method", "paper-three-stage", "--peers", "scipy:dop853", "--steps", "20,40,80",
                        "--tolerances", "1e-6,1e-9", "--repeats", "1", "--ensemble", "6"])
    assert data["ensemble"] == 6
    rkhp_curve, scipy_curve = data["curves"]
    assert rkhp_curve["trajectories"] == 6 and scipy_curve["trajectories"] == 6
    errors = [p["error"] for p in rkhp_curve["points"]]
    assert errors[0] > errors[1] > errors[2]


# ----------------------------------------------------------------------------------------------
# stress


def test_stress_finds_the_newton_failure_range_of_the_rigid_body():
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.stress import sweep

    rigid = get_system("rigid-body")
    result = sweep(resolve_method("paper-three-stage"), rigid, 10.0, coarsest=20)
    bad = result.first_failure
    assert bad is not None and "Newton" in bad.status
    assert result.largest_ok_h is not None and result.largest_ok_h < bad.h
    assert all(r.ok for r in result.rows if r.h <= result.largest_ok_h)
    assert "fails from h" in result.verdict()


def test_stress_cli_parts_end_with_verdicts(tmp_path):
    plot = tmp_path / "drift.pdf"
    result = _run(["stress", "lotka-volterra", "--method", "paper-three-stage", "--long-steps", "3000",
                   "--sweep-coarsest", "10", "--round-off-steps", "30,100,300,1000", "--plot", str(plot),
                   "--format", "json"])
    assert result.exit_code == 0, result.output
    assert plot.read_bytes().startswith(b"%PDF-")
    data = json.loads(result.output)
    assert set(data) == {"system", "realisation", "x0", "t_final", "sweep", "long_run", "near_singular", "round_off",
                         "interrupted", "provenance"}
    for part in ("sweep", "long_run", "near_singular", "round_off"):
        assert data[part]["verdict"]
    runs = data["long_run"]["runs"]
    assert runs[0]["casimir_max"] < 1e-12  # RKHP keeps the Casimir
    assert data["long_run"]["peer"]["casimir_max"] > 100 * runs[0]["casimir_max"]  # classical RK4 does not
    singular = data["near_singular"]
    assert singular["applicable"]
    assert {r["first_species"] for r in singular["runs"]} == {1e-3, 1e-6}
    assert all(r["kept"] and r["min_component"] > 0 for r in singular["runs"])


def test_stress_table_has_four_verdict_lines():
    result = _run(["stress", "rigid-body", "--method", "euler", "--long-steps", "1000", "--sweep-coarsest", "10",
                   "--round-off-steps", "30,100,300"])
    assert result.exit_code == 0, result.output
    for part in "abcd":
        assert f"verdict ({part}):" in result.output
    assert "not applicable" in result.output  # (c) is for log-canonical systems


@pytest.mark.slow
def test_full_stress_rigid_body():
    """The full study: 10^5-step long run, sweep from T/200, round-off down to T/10^5."""
    result = _run(["stress", "rigid-body", "--format", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert all(r["casimir_max"] < 1e-12 for r in data["long_run"]["runs"])
    assert data["long_run"]["steps"] == 100_000
    assert all(m["first_failure_h"] is not None for m in data["sweep"]["methods"])


@pytest.mark.slow
def test_full_default_converge_and_bench():
    result = _run(["converge", "rigid-body", "--format", "json"])
    assert result.exit_code == 0
    assert all(m["verdict"] == "confirmed" for m in json.loads(result.stdout)["methods"])
    data = _bench_json([])
    assert any(c["method"] is not None for c in data["cheapest"])


def test_round_off_floor_of_the_energy_error():
    """Part (d): the energy error of the 3-stage method stops falling at round-off level."""
    from rkhp.integrators.methods import resolve_method
    from rkhp.studies.stress import round_off

    rigid = get_system("rigid-body")
    result = round_off([resolve_method("paper-three-stage")], rigid, 10.0, steps=(100, 316, 1000, 3162, 10000, 31623))
    (study,), (energy,) = result.studies, result.energy_fits
    assert energy.slope == pytest.approx(4, abs=0.15)
    data = json_form(result)["methods"][0]
    assert data["energy_floor_h"] is not None
    floor_row = next(r for r in study.rows if r.h == data["energy_floor_h"])
    assert floor_row.energy_error < 1e-13  # round-off level for |H| ~ 0.65 after ~10^4 steps
    assert "round-off floor" in result.verdict()


def test_converge_on_spec_file_system_with_tableau_file(tmp_path):
    """A system from a spec file (no exact solution: DOP853 reference) and a method from a file."""
    from rkhp.tableaux.files import load_tableau, save_tableau

    spec = tmp_path / "lv.json"
    spec.write_text('{"family": "log-canonical", "lambda": [[0,1,2],[-1,0,1],[-2,-1,0]], '
                    '"hamiltonian": "x1 + x2 + x3 - log(x1) - log(x2) - log(x3)", "x0": [0.5, 1, 2]}')
    method = tmp_path / "three.toml"
    save_tableau(load_tableau("paper-three-stage"), method)
    result = _run(["converge", str(spec), "--method", f"{method},classical:{method}", "--t-final", "3",
                   "--steps", "40", "--refinements", "4", "--format", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["reference"]["kind"] == "dop853" and data["t_final"] == 3.0
    rkhp_m, classical_m = data["methods"]
    assert (rkhp_m["expected_order"], classical_m["expected_order"]) == (4, 1)  # degenerate vs general order
    assert rkhp_m["verdict"] == classical_m["verdict"] == "confirmed"


def test_the_mpmath_reference_keeps_the_invariants_and_agrees_with_dop853():
    """The 26-digit reference of nambu (H and the Casimir C = (x1^2 + x2^2)/2 + x3^4/4 are first
    integrals) and of the charged particle (H = cos x1 + sin x2): the invariants at x(T) equal
    those at x0 to a few ulps, and DOP853 agrees within its own error estimate."""
    from rkhp.studies.reference import dop853_reference, reference

    nambu, particle = get_system("nambu"), get_system("charged-particle")
    ref = reference(nambu, 2.0, kind="mpmath")
    assert ref.kind == "mpmath" and ref.error_estimate < 1e-15
    def casimir(x):
        return (x[0] ** 2 + x[1] ** 2) / 2 + x[2] ** 4 / 4

    def energy(x):
        return x[0] ** 2 / 4 + x[1] ** 2 / 2 + 3 * x[2] ** 2 / 4

    assert abs(casimir(ref.state) - casimir(nambu.x0)) < 1e-15 and abs(energy(ref.state) - energy(nambu.x0)) < 1e-15
    check = dop853_reference(nambu, 2.0)
    assert np.linalg.norm(ref.state - check.state) < check.error_estimate
    ref = reference(particle, 2.0, kind="mpmath")
    y, y0 = ref.state, particle.x0
    assert abs(np.cos(y[0]) + np.sin(y[1]) - (np.cos(y0[0]) + np.sin(y0[1]))) < 1e-15


#: the Nambu system of docs/general-poisson.md as a spec file: pi v = grad C x v,
#: C = |x|^2/2 + x1^4/4, H = x1^2/4 + x2^2/2 + 3 x3^2/4
MY_NAMBU = """name = "my-nambu"
family = "general"
poisson = [["0",  "-x3", "x2"], ["x3", "0", "-(x1 + x1^3)"], ["-x2", "x1 + x1^3", "0"]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
casimirs = ["(x1^2 + x2^2 + x3^2)/2 + x1^4/4"]
x0 = [0.45359612142557731, 0.0, 0.89120736006143542]
"""


def _mpmath_solve(field, x0, t_final, digits=25):
    """x(t_final) of xdot = field(x) by mpmath's Taylor solver, a vector field written by hand."""
    import mpmath

    with mpmath.workdps(digits):
        solution = mpmath.odefun(lambda t, x: field(x), 0, [mpmath.mpf(float(v)) for v in x0])
        return np.array([float(v) for v in solution(t_final)])


def test_the_mpmath_reference_of_a_spec_file_and_of_lotka_volterra(tmp_path):
    """--reference mpmath on a spec file (its expressions) and on lotka-volterra (a built-in system):
    within its error estimate of an independent mpmath solve of the vector field written by hand
    (Nambu: xdot = grad C x grad H; Lotka-Volterra: xdot_i = x_i sum_j lambda_ij (x_j - 1))."""
    from rkhp.studies.reference import reference

    path = tmp_path / "my-nambu.toml"
    path.write_text(MY_NAMBU)
    nambu = get_system(str(path))

    def nambu_field(x):
        c = (x[0] + x[0] ** 3, x[1], x[2])
        g = (x[0] / 2, x[1], 3 * x[2] / 2)
        return [c[1] * g[2] - c[2] * g[1], c[2] * g[0] - c[0] * g[2], c[0] * g[1] - c[1] * g[0]]

    lam = [[0, 1, 2], [-1, 0, 1], [-2, -1, 0]]

    def lv_field(x):
        return [x[i] * sum(lam[i][j] * (x[j] - 1) for j in range(3)) for i in range(3)]

    for system, field in ((nambu, nambu_field), (get_system("lotka-volterra"), lv_field)):
        ref = reference(system, 2.0, kind="mpmath")
        assert ref.kind == "mpmath" and ref.error_estimate < 1e-15
        assert np.linalg.norm(ref.state - _mpmath_solve(field, system.x0, 2)) <= ref.error_estimate


def test_an_mpmath_reference_needs_expressions():
    """A system built from Python programs alone has no expressions to give mpmath: one clear InputError."""
    from rkhp.studies.reference import reference
    from rkhp.systems.families import family_system

    system = family_system("constant", np.array(((0.0, 1.0), (-1.0, 0.0))),
                           lambda x: 0.5 * (x[0] * x[0] + x[1] * x[1]), name="oscillator", x0=(1.0, 0.0),
                           t_final=1.0)
    with pytest.raises(InputError, match="built from programs alone"):
        reference(system, 1.0, kind="mpmath")


def test_the_reference_option_refuses_what_it_cannot_give(run_cli):
    cases = [("converge", "nambu", "--reference", "exact"),
             ("converge", "charged-particle", "--reference", "mpmath", "--t-final", "1e6"),
             ("converge", "nambu", "--reference", "quad")]
    for args in cases:
        code, _, err = run_cli(*args, "--method", "euler")
        assert code == 2 and len(err.strip().splitlines()) == 1, (args, err)


# ----------------------------------------------------------------------------------------------
# the steps chosen by pilot runs (docs/studies.md "How the steps are chosen")


def test_chosen_steps_keep_every_row_above_the_floor_and_confirm_a_sixth_order():
    """search-symmetric-o6-s5 (symmetric order 6, docs/symmetric.md) on the rigid body: the doublings
    20..1280 leave its three finest rows out of the fit (round-off); the chosen steps keep all seven
    measurable and confirm order 6. The rk4 of the same study keeps the doublings."""
    from rkhp.studies.converge import converge

    given = converge("rigid-body", ["search-symmetric-o6-s5"], steps=[20])
    assert len(given.methods[0].fit.fit_rows) == 4
    study = converge("rigid-body", ["search-symmetric-o6-s5", "rk4"])
    six, four = study.methods
    assert len(six.rows) == 7 and all(r.error is not None for r in six.rows)
    assert six.expected_order == 6 and six.verdict == "confirmed" and abs(six.observed_order - 6) < 0.2
    assert len(six.fit.fit_rows) >= 5
    assert "chosen by pilot runs" in six.steps_chosen
    assert [r.steps for r in four.rows] == [20, 40, 80, 160, 320, 640, 1280] and four.verdict == "confirmed"
    assert study.reference.kind == "exact" and study.reference_choice is None


#: the built-in nambu system (rkhp.systems.problems.nambu: C = (x1^2 + x2^2)/2 + x3^4/4, the rigid
#: body's H) as a spec file
NAMBU_SPEC = """name = "nambu-spec"
family = "general"
poisson = [["0", "-x3^3", "x2"], ["x3^3", "0", "-x1"], ["-x2", "x1", "0"]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
casimirs = ["(x1^2 + x2^2)/2 + x3^4/4"]
x0 = [0.45359612142557731, 0.0, 0.89120736006143542]
"""


def test_a_tenth_order_composition_on_a_spec_file_gets_mpmath_and_measurable_rows(tmp_path):
    """sofroniou-spaletta10 (order 10, Sofroniou & Spaletta 2005) on a Nambu spec file, T = 10: with
    the doublings 20..1280 every row but the first is below DOP853's accuracy; chosen, the study takes the mpmath
    reference, every successful row is measurable, and the local order of the finest rows nears 10."""
    from rkhp.studies.converge import converge

    path = tmp_path / "nambu-spec.toml"
    path.write_text(NAMBU_SPEC)
    given = converge(str(path), ["sofroniou-spaletta10"], steps=[20])
    assert given.reference.kind == "dop853" and all(r.error is None for r in given.methods[0].rows[1:])
    study = converge(str(path), ["sofroniou-spaletta10"])
    assert study.reference.kind == "mpmath" and "DOP853's floor" in study.reference_choice
    rows = [r for r in study.methods[0].rows if r.status == "ok"]
    assert len(rows) >= 5 and all(r.error is not None for r in rows)
    assert abs(rows[-1].local_order - 10) < 1
    doc = json_form(study)
    assert doc["reference"]["choice"] == study.reference_choice
    assert doc["methods"][0]["steps_chosen"] == study.methods[0].steps_chosen


def test_the_convergence_plot_draws_slopes_over_the_data_and_readable_h_labels(tmp_path, monkeypatch):
    """A narrow range of h (0.22 to 0.33, where matplotlib labels 2.2, 2.4, ..., 3.4 x 10^-1 and two
    overlap): no two drawn tick labels of the saved figure overlap, and the dashed slope line is
    drawn above the data line."""
    from rkhp.studies import plots
    from rkhp.studies.converge import converge

    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, *args: figures.append(fig))
    study = converge("rigid-body", ["rk4"], steps=[30, 34, 38, 42, 46])
    plots.plot_convergence(study, tmp_path / "c.png")
    (fig,) = figures
    (ax,) = fig.axes
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for axis in (ax.xaxis, ax.yaxis):
        lo, hi = axis.get_view_interval()
        boxes = [t.get_window_extent(renderer) for tick, t in
                 ((tick, tick.label1) for tick in axis.get_major_ticks() + axis.get_minor_ticks())
                 if t.get_visible() and t.get_text() and min(lo, hi) <= tick.get_loc() <= max(lo, hi)]
        assert boxes
        assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    data, slope = (line for line in ax.get_lines()[:2])
    assert data.get_linestyle() == "-" and slope.get_linestyle() == "--"
    assert slope.get_zorder() > data.get_zorder()
