"""The RKHP Euler step of the spray realisation in direct form, and its compositions
(rkhp.integrators.spray_euler; docs/general-poisson.md "The Euler step in direct form").

Values from outside the code: the engine's RKHP Euler step (alpha solved by Newton, the spray
kernel's collocation), the implicit midpoint rule (RKHP Euler on a constant pi, docs/theory.md §5),
the symmetry of RKHP Euler with a symmetric birealisation (docs/theory.md §12: Phi_-h o Phi_h = id),
the Casimir of the Nambu system, and the order 4 of the triple jump (Yoshida 1990; Hairer–Lubich–
Wanner II.4) against a DOP853 reference (rkhp.studies.reference).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rkhp.base.errors import InputError
from rkhp.integrators import integrate_midpoint, integrate_rkhp
from rkhp.integrators.driver import integrate_spray_euler, run
from rkhp.integrators.failure import Failure
from rkhp.integrators.spray_euler import (
    HISTORY,
    _out_of_reach,
    _remember,
    _start_stages,
    euler_work,
    spray_tapes,
    substep_memory,
)
from rkhp.integrators.substeps import SPRAY, TOWER, choose
from rkhp.studies.reference import reference
from rkhp.systems import get_system
from rkhp.systems.problems import ProblemData, build
from rkhp.tableaux.compositions import load_composition, one_step
from rkhp.tableaux.files import load_tableau
from rkhp.taylor.interpreter import evaluate
from rkhp.taylor.ops import CRB, FUNCTION, OPS
from rkhp.taylor.scalar import SCALAR_CODES, gradients, shared, values
from rkhp.taylor.tape import functions as f
from rkhp.taylor.tape import record_tape

TRIPLE_JUMP = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module", params=["charged-particle", "nambu"])
def system(request):
    return get_system(request.param)


def test_euler_is_the_engine_euler(system):
    """Measured: 1.4e-14 (charged particle), 4.1e-15 (nambu) after 50 steps of h = 0.1."""
    direct = integrate_spray_euler(system, (1.0,), 0.1, 50)
    engine = integrate_rkhp(system, "euler", 0.1, 50)
    assert direct.ok and engine.ok
    assert np.abs(direct.states - engine.states).max() < 3e-14
    np.testing.assert_allclose(direct.times, engine.times, rtol=0, atol=1e-15)


def test_backward_steps_return_to_the_start(system):
    forward = integrate_spray_euler(system, (1.0,), 0.1, 100)
    back = integrate_spray_euler(system, (1.0,), -0.1, 100, x0=forward.final_state)
    assert back.ok and back.times[-1] == pytest.approx(-10.0)
    assert np.abs(forward.final_state - system.x0).max() > 0.1
    assert np.abs(back.final_state - system.x0).max() < 1e-13


def test_composed_backward_steps_return_to_the_start():
    system = get_system("charged-particle")
    g = (TRIPLE_JUMP, 1.0 - 2.0 * TRIPLE_JUMP, TRIPLE_JUMP)
    forward = integrate_spray_euler(system, g, 0.1, 100)
    back = integrate_spray_euler(system, g[::-1], -0.1, 100, x0=forward.final_state)
    assert np.abs(back.final_state - system.x0).max() < 1e-13


@pytest.mark.parametrize("gammas", [(1.0,), (TRIPLE_JUMP, 1.0 - 2.0 * TRIPLE_JUMP, TRIPLE_JUMP)])
def test_nambu_casimir_is_kept(gammas):
    """Measured over 2000 steps of h = 0.1: 1.9e-15 (Euler; the engine's Euler 1.3e-14) and
    2.1e-16 (triple jump), relative."""
    system = get_system("nambu")
    run = integrate_spray_euler(system, gammas, 0.1, 2000, keep_all=False)
    c0, c1 = (system.casimir_values(x)[0] for x in run.states)
    assert abs(c1 - c0) < 2e-14 * abs(c0)


def test_triple_jump_has_order_four():
    system = get_system("charged-particle")
    T = 10.0
    ref = reference(system, T)
    g = (TRIPLE_JUMP, 1.0 - 2.0 * TRIPLE_JUMP, TRIPLE_JUMP)
    errors = [np.linalg.norm(integrate_spray_euler(system, g, T / n, n, keep_all=False).final_state
                             - ref.state) for n in (40, 80)]
    assert errors[1] > 100 * ref.floor
    assert math.log2(errors[0] / errors[1]) == pytest.approx(4.0, abs=0.15)


def test_euler_has_order_two():
    system = get_system("charged-particle")
    ref = reference(system, 10.0)
    errors = [np.linalg.norm(integrate_spray_euler(system, (1.0,), 10.0 / n, n,
                                                   keep_all=False).final_state - ref.state)
              for n in (100, 200)]
    assert math.log2(errors[0] / errors[1]) == pytest.approx(2.0, abs=0.05)


def pendulum_general():
    return build(ProblemData("pendulum-general", (("0", "1"), ("-1", "0")), "x2^2/2 - cos(x1)",
                             (), (), (1.5, 0.0), 10.0, "pendulum, constant pi in the general family"))


def test_constant_pi_is_the_implicit_midpoint_rule():
    system = pendulum_general()
    direct = integrate_spray_euler(system, (1.0,), 0.2, 50)
    midpoint = integrate_midpoint(system, 0.2, 50)
    assert np.abs(direct.states - midpoint.states).max() < 1e-13


def test_keep_all_false_keeps_the_start_and_the_end(system):
    full = integrate_spray_euler(system, (0.5, 0.5), 0.1, 20)
    short = integrate_spray_euler(system, (0.5, 0.5), 0.1, 20, keep_all=False)
    np.testing.assert_array_equal(short.states, full.states[[0, -1]])
    assert short.times.tolist() == pytest.approx([0.0, 2.0])
    solves = full.newton_iterations + full.stage_sweeps
    assert len(solves) == 20 and solves.min() >= 1
    np.testing.assert_array_equal(short.newton_iterations, full.newton_iterations)
    np.testing.assert_array_equal(short.stage_sweeps, full.stage_sweeps)


@pytest.mark.parametrize("name, realisation", [("rigid-body", "symmetric"),
                                               ("charged-particle", "truncated:4"),
                                               ("charged-particle", "shifted")])
def test_other_realisations_are_refused(name, realisation):
    with pytest.raises(InputError, match="Poisson-spray realisation"):
        integrate_spray_euler(get_system(name, realisation), (1.0,), 0.1, 1)


@pytest.mark.parametrize("gammas, h, n", [((), 0.1, 1), ((1.0, math.nan), 0.1, 1),
                                          ((1.0,), math.inf, 1), ((1.0,), 0.1, -1),
                                          ((1.0,), 0.1, 1.5), ("a", 0.1, 1)])
def test_bad_arguments_are_refused(gammas, h, n):
    with pytest.raises(InputError):
        integrate_spray_euler(get_system("charged-particle"), gammas, h, n)


def test_a_step_too_large_fails_with_a_cause():
    run = integrate_spray_euler(get_system("nambu"), (1.0,), 40.0, 5)
    assert not run.ok and run.cause != Failure.OK
    assert run.failed_step is not None and len(run.states) == run.failed_step + 1
    assert run.status.startswith(f"failed at step {run.failed_step}")


def test_substeps_near_the_largest_that_converge_take_newtons_method():
    """tj8 (the triple jump of triple jumps, Yoshida 1990: 27 substeps of up to 2.83 h) on the
    charged particle at h = 1/3: substeps of |h| up to 0.94, where a chord matrix built at y0
    contracts by 0.1 to 0.25 and 20 chord iterations do not reach the tolerance; with Newton's
    method the run ends, on the states of the same substeps solved by the engine's Taylor tower
    (Newton on the jets, an independent solver). Measured: 2.2e-11 over the 30 steps."""
    system = get_system("charged-particle")
    gammas = load_composition("tj8").gamma_float
    direct = integrate_spray_euler(system, tuple(gammas), 1.0 / 3.0, 30)
    tower = run(system, load_tableau("euler"), 1.0 / 3.0, 30, gammas=gammas, provider=TOWER)
    assert direct.ok and tower.ok
    assert np.abs(direct.states - tower.states).max() < 1e-9


def test_substeps_without_previous_solutions_converge_by_sweeps():
    """One step of bcm6-s11 (Blanes, Casas & Ros' processed composition: a processor of 12
    substeps run once from y0, a kernel of 11, the inverse processor once at the end) on nambu at
    h = 10/54: no substep has previous solutions, each starts from p = h grad H(y0), off by
    O(h^2); its first sweep carries that error into the stages (measured: the second change is
    0.6 to 0.8 times the first), and then the sweeps contract by 0.01 to 0.05: they converge with
    no chord iteration and no matrix built, on the states of the same substeps solved by the
    engine's Taylor tower (Newton on the jets, an independent solver)."""
    system, euler = get_system("nambu"), load_tableau("euler")
    comp = load_composition("bcm6-s11")
    gammas, m = np.array(one_step(comp, float)), len(comp.processor)
    direct = run(system, euler, 10 / 54, 1, gammas=gammas, processor=m, keep_all=False)
    tower = run(system, euler, 10 / 54, 1, gammas=gammas, processor=m, provider=TOWER, keep_all=False)
    assert choose(system, euler).provider is SPRAY and direct.ok and tower.ok
    assert direct.newton_iterations.sum() == 0 and sum(direct.extra["refreshes"]) == 0
    assert direct.stage_sweeps.sum() >= len(gammas)
    assert np.abs(direct.final_state - tower.final_state).max() < 1e-13


def test_large_steps_converge_with_few_jacobians():
    """Euler at h = 0.8 on nambu (ten nodes), 250 steps: the sweeps contract slowly but go on
    while a chord iteration would not gain twice their decades (the kept matrix contracts by
    0.1 to 0.2), and past half its iterations a substep takes the exact Jacobian only where the
    kept matrix would not meet the stop test in the iterations left: the run builds a few dozen
    matrices at most (taking the Jacobian at each late iteration, and leaving the sweeps at a
    contraction of 1/4, built 442), on the states of the same steps solved by the Taylor tower
    (Newton on the jets, an independent solver), and retraces itself (RKHP Euler with the
    symmetric realisation is symmetric, docs/theory.md §12) to round-off over the run."""
    system, euler = get_system("nambu"), load_tableau("euler")
    direct = run(system, euler, 0.8, 250)
    tower = run(system, euler, 0.8, 250, provider=TOWER)
    back = run(system, euler, -0.8, 250, direct.states[-1], keep_all=False)
    assert direct.ok and tower.ok and back.ok
    assert sum(direct.extra["refreshes"]) <= 40
    assert np.abs(direct.states - tower.states).max() < 1e-13
    assert np.abs(back.final_state - system.x0).max() < 1e-13


def test_late_iterations_take_the_jacobian_only_out_of_reach():
    """`_out_of_reach` at iteration 10 of 20 (two spare), tolerance 2^-60: corrections of 1e-12
    contracting by 0.1 meet the stop test in the 7 iterations left (0.1^7 1e-12 0.1 / 0.9 is
    1.1e-20), by 0.5 they do not (0.5^7 1e-12 = 7.8e-15); a contraction not yet measured
    (since < 2) or not below 1 takes the Jacobian."""
    tol = 2.0**-60
    assert not _out_of_reach(10, 3, 1e-12, 0.1, 20, tol)
    assert _out_of_reach(10, 3, 1e-12, 0.5, 20, tol)
    assert _out_of_reach(10, 1, 1e-12, 0.1, 20, tol)
    assert _out_of_reach(10, 3, 1e-12, 1.5, 20, tol)
    assert _out_of_reach(17, 3, 1e-12, 0.1, 20, tol)


@pytest.mark.parametrize("name", ["charged-particle", "benchmarks/data/vortices-8.toml"])
def test_a_tolerance_below_round_off_iterates_to_stagnation(name):
    """kahan-li8 at h = 0.1 with the chord iterations' tolerance 2^-90, far below round-off: the
    corrections end wandering at round-off, and the iterations stop there (docs/general-poisson.md
    "The Euler step in direct form") on the states of the default tolerance, to round-off over
    the run; no new matrix is taken for a correction at round-off, which kept them from it."""
    system = get_system(str(ROOT / name) if name.endswith(".toml") else name)
    gammas = load_composition("kahan-li8").gamma_float
    default = run(system, load_tableau("euler"), 0.1, 100, gammas=gammas)
    tight = run(system, load_tableau("euler"), 0.1, 100, gammas=gammas, tol=2.0**-90)
    assert default.ok and tight.ok
    assert np.abs(tight.states - default.states).max() < 1e-12


# ----------------------------------------------------------------------------------------------
# rkhp.taylor.scalar


def test_every_function_of_mathematical_text_is_evaluated_on_scalars():
    assert {op.code for op in OPS if op.kind == FUNCTION and op.code != CRB} <= SCALAR_CODES


def all_functions(x, p):
    u = x[0] * x[1] + 1.5
    return [f.exp(x[0]) * f.log(u) - f.sin(x[1]) / f.cos(x[0]) + f.sqrt(u) ** 3,
            u ** -2 + u ** 2.5 + f.atan(x[1] - x[0]) * 3.0 - (x[0] - 1.0) * p[0],
            u ** 0 + (-x[1]) * 2.0]


@pytest.mark.parametrize("tape", ["functions", "field", "hamiltonian"])
def test_scalar_values_and_gradients_are_the_interpreters(tape):
    if tape == "functions":
        t, inputs = record_tape(2, all_functions), np.array([0.3, -0.7, 0.2, 0.9])
    else:
        t = getattr(spray_tapes(get_system("nambu")), tape)
        inputs = np.array([0.4, -0.3, 0.8, 0.05, -0.02, 0.07])
    value, jac = evaluate(t, inputs, degree=1, n_vars=len(inputs))
    W = np.zeros((t.n_slots, len(inputs) + 1))
    W[: len(inputs), 0] = inputs
    values(t, W)
    np.testing.assert_allclose(W[t.outputs, 0], value, rtol=1e-15, atol=1e-15)
    W[: len(inputs), 1:] = np.eye(len(inputs))
    gradients(t, W, len(inputs))
    np.testing.assert_allclose(W[t.outputs, 0], value, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(W[t.outputs, 1:], jac, rtol=1e-14, atol=1e-14)


def test_shared_rows_are_computed_once():
    def twice(x, p):
        b = 1.0 + x[0] * x[0]
        c = 1.0 + x[0] * x[0]
        return [p[0] / b, p[1] / c, x[1] * x[0] + x[0] * x[1]]

    t = record_tape(2, twice)
    s = shared(t)
    inputs = np.array([0.3, 2.0, 0.5, -1.0])
    assert len(s.ops) == len(t.ops) - 3  # the second 1 + x0^2 (2 rows) and x0 x1 (1 row)
    W = np.zeros((t.n_slots, 1))
    W[:4, 0] = inputs
    values(s, W)
    np.testing.assert_array_equal(W[s.outputs, 0], evaluate(t, inputs))


def test_the_start_extrapolates_the_last_solutions_across_the_ring():
    """Stage increments Z(k) = f(k), f cubic in the step index k, remembered for k = 0..10 (more
    than HISTORY, so the ring of solutions wraps): the start of step 11 is f(11), exactly for an
    extrapolation of degree 3 or more; after 7 pushes only (cubic from 7 values: the order is
    chosen among them) it is f(7) too, and with 3 it is off by f's third difference (6 a)."""
    system = get_system("charged-particle")
    n, q = system.dim, 3
    work, memory = euler_work(spray_tapes(system), n), substep_memory(1, n)
    rng = np.random.default_rng(7)
    a, b, c = (rng.standard_normal((q, n)) for _ in range(3))

    def f(k):
        return a * k**3 + b * k**2 + c

    y0 = np.zeros(n)
    memory.z_nodes[0] = q
    for count, pushes, expected in ((HISTORY, 11, f(11)), (7, 7, f(7)), (3, 3, f(3) - 6 * a)):
        memory.counts[0] = 0
        for k in range(pushes):
            work.Z[:q] = f(k)
            work.xbar[:] = f(k)[0]
            _remember(0, q, memory, y0, work, n)
        assert memory.counts[0, 1] == count
        memory.order[0] = HISTORY
        work.Z[:] = np.nan
        _start_stages(0, q, memory, work, n)
        np.testing.assert_allclose(work.Z[:q], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
