"""The RKHP Euler step in direct form on the closed-form families, and its compositions
(rkhp.integrators.closed_euler; docs/compositions.md "The cost of a substep").

Values from outside the code: the engine's RKHP Euler step (alpha solved by Newton on Taylor jets
of H o alpha, the tower's substeps `rkhp.integrators.tower_substep`, run by the same driver),
the implicit midpoint rule's own equation (RKHP Euler on a constant pi, docs/theory.md §5), the
symmetry of RKHP Euler with a symmetric birealisation (docs/theory.md §12: Phi_-h o Phi_h = id),
mpmath's matrix exponential (the closed forms of the Lie-Poisson point on Toda's algebra),
the Casimirs of each family, and the orders 4 and 6 of tj4 and kahan-li6 against a DOP853
reference (`rkhp.studies.converge`).
"""

from __future__ import annotations

import warnings

import mpmath as mp
import numpy as np
import pytest

from rkhp.base.errors import InputError
from rkhp.integrators.closed_euler import (
    DEFECT_REACH,
    ClosedSubstep,
    _predict_z,
    _remember_z,
    chord_memory,
    closed_form,
    closed_work,
    resume,
)
from rkhp.integrators.direct_form import HISTORY
from rkhp.integrators.driver import integrate_closed_euler, run
from rkhp.integrators.failure import Failure
from rkhp.integrators.lie_poisson_point import (
    PHI_SERIES,
    PHI_TERMS,
    POINT_ENTRIES,
    _phi_functions,
    _phi_terms,
    diagonal_point,
    diagonal_point_at,
    generated_diagonal_point,
    se3_point,
)
from rkhp.integrators.methods import integrate, resolve_method
from rkhp.integrators.rkhp_method import integrate_rkhp as engine_integrate
from rkhp.integrators.substeps import CLOSED, TOWER, choose
from rkhp.studies.converge import converge
from rkhp.systems import get_system
from rkhp.systems.families import LieAlgebra, family_system
from rkhp.tableaux.compositions import load_composition, one_step
from rkhp.taylor import generated
from rkhp.taylor.kernel_cache import KernelCacheWarning
from rkhp.taylor.tape import functions as f

#: a constant pi of rank 2 on R^3 (Casimir k . x, k = (1, 2, 4)) with a non-quadratic H
CONSTANT_PI = np.array([[0.0, 1.0, -0.5], [-1.0, 0.0, 0.25], [0.5, -0.25, 0.0]])


def constant_system():
    return family_system("constant", CONSTANT_PI,
                         lambda x: 0.5 * (x[0] * x[0] + x[1] * x[1]) - f.cos(x[2]) + 0.1 * x[0] * x[1] * x[2],
                         name="constant-3", x0=(0.3, -0.2, 0.5), t_final=1.0)


SYSTEMS = {"rigid-body": 0.1, "toda:12": 0.05, "lotka-volterra": 0.1, "volterra-lattice:7": 0.05, "heavy-top": 0.1,
           "constant-3": 0.1}


def system_named(name):
    return constant_system() if name == "constant-3" else get_system(name)


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_euler_is_the_engine_euler(name):
    """40 steps; measured (largest difference / largest |y|): rigid-body 1.8e-14, toda:12
    4.5e-15, lotka-volterra 5.4e-15, volterra-lattice:7 1.3e-14, constant-3 2.3e-15, heavy-top 8.1e-16."""
    system, h = system_named(name), SYSTEMS[name]
    direct = integrate_closed_euler(system, (1.0,), h, 40)
    engine = engine_integrate(system, "euler", h, 40)
    assert direct.ok and engine.ok
    assert np.abs(direct.states - engine.states).max() < 5e-14 * np.abs(engine.states).max()
    assert np.abs(direct.states[-1] - system.x0).max() > 1e-3  # the run moved
    np.testing.assert_allclose(direct.times, engine.times, rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ["rigid-body", "toda:12", "lotka-volterra"])
def test_a_composition_is_the_engine_composition(name):
    system, h = system_named(name), SYSTEMS[name]
    tj4 = load_composition("tj4")
    direct = integrate_closed_euler(system, tj4.gamma_float, h, 20)
    engine = run(system, resolve_method("euler").tableau, h, 20, gammas=tj4.gamma_float, provider=TOWER)
    assert direct.ok and engine.ok
    assert np.abs(direct.states - engine.states).max() < 5e-14 * np.abs(engine.states).max()


def test_on_a_constant_pi_euler_is_the_implicit_midpoint_rule():
    system = constant_system()
    run = integrate_closed_euler(system, (1.0,), 0.1, 30)
    for y0, y1 in zip(run.states[:-1], run.states[1:], strict=True):
        residual = y1 - y0 - 0.1 * CONSTANT_PI @ system.grad_hamiltonian(0.5 * (y0 + y1))
        assert np.abs(residual).max() < 1e-15


@pytest.mark.parametrize("name", ["rigid-body", "toda:12", "lotka-volterra", "volterra-lattice:7"])
def test_backward_steps_return_to_the_start(name):
    system, h = system_named(name), SYSTEMS[name]
    for gammas in ((1.0,), load_composition("tj4").gamma_float):
        forward = integrate_closed_euler(system, gammas, h, 100)
        back = integrate_closed_euler(system, gammas[::-1], -h, 100, x0=forward.final_state)
        assert forward.ok and back.ok
        assert np.abs(forward.final_state - system.x0).max() > 1e-2
        assert np.abs(back.final_state - system.x0).max() < 1e-13 * max(1.0, np.abs(system.x0).max())


@pytest.mark.parametrize("name", ["volterra-lattice:7", "toda:12", "constant-3"])
def test_casimirs_are_kept_to_round_off(name):
    system, h = system_named(name), SYSTEMS[name]
    assert system.casimirs
    run = integrate_closed_euler(system, load_composition("kahan-li6").gamma_float, h, 200)
    c = np.array([system.casimir_values(x) for x in run.states])
    assert run.ok and np.abs(c - c[0]).max() < 1e-13 * max(1.0, np.abs(c[0]).max())


def _structure(system):
    """C_ijk of a Lie-Poisson system from its pi (pi(x)_ij = sum_k C_ijk x_k)."""
    n = system.dim
    return np.stack([np.asarray(system.poisson(np.eye(n)[k]), dtype=float) for k in range(n)], axis=2)


def _exponentials(K, y0):
    """e^-K y0 - y0 and phi_1(-K) y0 (phi_1(A) = sum_m A^m / (m + 1)!, the upper right block of
    exp([[A, I], [0, 0]])) by mpmath's expm at 30 digits."""
    n = K.shape[0]
    block = mp.zeros(2 * n, 2 * n)
    for i in range(n):
        block[i, n + i] = 1
        for k in range(n):
            block[i, k] = -K[i, k]
    with mp.workdps(30):
        E = mp.expm(block)
        exponential = [sum(E[i, k] * y0[k] for k in range(n)) - y0[i] for i in range(n)]
        psi = [sum(E[i, n + k] * y0[k] for k in range(n)) for i in range(n)]
    return np.array(exponential, dtype=float), np.array(psi, dtype=float)


@pytest.mark.parametrize("name", ["toda", "toda:12", "heavy-top"])
def test_the_closed_points_are_the_matrix_exponential(name):
    """The closed forms of e^-K y0 - y0 and psi(K) y0 = phi_1(-K) y0 on Toda's diagonal algebra
    (K(p) = [[D, 0], [E, 0]]) and on se(3)* (the heavy top, K = [[hat q, hat r], [0, hat q]])
    against mpmath's expm, at random z with |K|_F from 1e-6 to near the guard of phi (measured:
    1.4e-16 relative at |K|_F = 5 on toda:12, where scipy's expm is 3e-14 off)."""
    system = get_system(name)
    n, C = system.dim, _structure(system)
    form = closed_form(system)
    point = se3_point if name == "heavy-top" else diagonal_point
    assert (form.rotation != 0.0) == (name == "heavy-top") and (form.diagonal.size == n) == (name != "heavy-top")
    work = closed_work(form, n)
    rng = np.random.default_rng(7)
    for size in (1e-6, 0.1, 1.0, 5.0):
        y0 = rng.normal(size=n)
        z = rng.normal(size=n)
        z *= size / np.linalg.norm(np.einsum("ijk,j->ik", C, z))
        K = np.einsum("ijk,j->ik", -C, z)
        work.z[:] = z
        assert (point(y0, form, work, n) if point is diagonal_point else point(y0, form, work)) == Failure.OK
        exponential, psi = _exponentials(K, y0)
        scale = max(np.abs(y0).max(), np.abs(exponential).max())
        np.testing.assert_allclose(work.dy, exponential, rtol=0, atol=1e-15 * scale)
        np.testing.assert_allclose(work.xbar, psi, rtol=0, atol=1e-15 * scale)


def _algebra(name):
    """Two small diagonal algebras beside Toda's, each with a non-quadratic H: the Heisenberg
    algebra ([e1, e2] = e3: K = [[0, E]], no diagonal entry) and the ax + b algebra
    ([e1, e2] = e2: K_22 = p_1)."""
    n = 3 if name == "heisenberg" else 2
    C = np.zeros((n, n, n))
    top = 2 if name == "heisenberg" else 1
    C[0, 1, top], C[1, 0, top] = 1.0, -1.0
    x0 = (0.3, -0.2, 0.5) if n == 3 else (0.3, 0.8)
    return family_system("lie-poisson", LieAlgebra(C),
                         lambda x: 0.5 * x[0] * x[0] + f.sin(x[1]) + 0.1 * x[0] * x[1] * x[n - 1],
                         name=name, x0=x0, t_final=1.0)


@pytest.mark.parametrize("name", ["toda", "toda:12", "heisenberg", "ax+b"])
def test_the_generated_point_is_the_interpreted_one_bit_for_bit(name):
    """The point written out per algebra (`diagonal_point_source`) against `diagonal_point`: the
    same values to the last bit at |K|_F from 1e-9 (phi_2's series of a few terms) through 1 and 3
    (entries past PHI_SERIES: expm1) to past phi's guard, where both fail."""
    system = _algebra(name) if name in ("heisenberg", "ax+b") else get_system(name)
    n, C = system.dim, _structure(system)
    form = closed_form(system)
    assert form.point_at != 0
    interpreted, generated = closed_work(form, n), closed_work(form, n)
    rng = np.random.default_rng(11)
    for size in (1e-9, 1e-3, 0.3, 1.0, 3.0, 6.0):
        y0, z = rng.normal(size=n), rng.normal(size=n)
        z *= size / np.linalg.norm(np.einsum("ijk,j->ik", C, z))
        interpreted.z[:] = generated.z[:] = z
        cause = diagonal_point(y0, form, interpreted, n)
        assert generated_diagonal_point(y0, form, generated, n) == cause
        assert cause == (Failure.OK if size < 5.0 else Failure.NEWTON_NON_FINITE)
        if cause == Failure.OK:
            assert np.array_equal(generated.dy, interpreted.dy) and np.array_equal(generated.xbar, interpreted.xbar)


def test_no_point_is_generated_past_its_size():
    """An algebra with more than POINT_ENTRIES entries of K keeps the interpreted point (address
    0) without writing a module."""
    entries = POINT_ENTRIES + 1
    pairs = np.array([[k, k] for k in range(entries)], dtype=np.int64)
    starts, cols = np.arange(entries + 1, dtype=np.int64), np.zeros(entries, dtype=np.int64)
    assert diagonal_point_at(pairs, starts, cols, np.ones(entries), np.arange(entries), entries) == 0


def test_a_folder_that_cannot_hold_the_point_leaves_it_interpreted(tmp_path, monkeypatch):
    """Where the generated module cannot be written, the diagonal algebra's point is interpreted
    (`diagonal_point`, address 0), and the run is the same as by the generated point."""
    system = _algebra("ax+b")
    method = resolve_method("kahan-li6")
    compiled = method.integrate(system, 0.1, 20).raise_if_failed().final_state
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(generated, "generated_folder", lambda: blocker / "generated")
    monkeypatch.setattr("rkhp.taylor.kernel_cache._SAID", set())
    monkeypatch.setattr(generated, "_LOADED", {})
    with pytest.warns(KernelCacheWarning, match="interpreted instead"):
        interpreted = closed_form(_algebra("ax+b"))
    assert interpreted.point_at == 0 and interpreted.derivatives_at == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KernelCacheWarning)
        by_structure = method.integrate(_algebra("ax+b"), 0.1, 20).raise_if_failed().final_state
    np.testing.assert_allclose(by_structure, compiled, rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("name", ["heisenberg", "ax+b"])
def test_on_other_diagonal_algebras_euler_is_the_engine_euler(name):
    """40 steps of h = 0.1 (measured: 3e-16 and 9e-16 relative)."""
    system = _algebra(name)
    assert closed_form(system).diagonal.size == system.dim
    direct = integrate_closed_euler(system, (1.0,), 0.1, 40)
    engine = engine_integrate(system, "euler", 0.1, 40)
    assert direct.ok and engine.ok
    assert np.abs(direct.states - engine.states).max() < 5e-14 * np.abs(engine.states).max()
    assert np.abs(direct.states[-1] - system.x0).max() > 1e-2


@pytest.mark.parametrize("name", ["rigid-body", "heavy-top"])
def test_the_rotation_algebras_are_not_diagonal(name):
    assert closed_form(get_system(name)).diagonal.size == 0


def test_the_orders_of_tj4_and_kahan_li6_on_toda():
    study = converge("toda:12", ("tj4", "kahan-li6"))
    verdicts = {m.method: (m.expected_order, m.verdict) for m in study.methods}
    assert verdicts == {"tj4": (4, "confirmed"), "kahan-li6": (6, "confirmed")}


@pytest.mark.parametrize("name", ["rigid-body", "toda:12", "lotka-volterra", "pendulum"])
def test_euler_and_its_compositions_are_routed_here(name):
    system = get_system(name)
    for method in ("euler", "suzuki4"):
        m = resolve_method(method)
        assert choose(system, m.tableau).provider is CLOSED
        run = m.integrate(system, 0.1, 5)
        gammas = (1.0,) if method == "euler" else m.composition.gamma_float
        assert run.method == method
        np.testing.assert_array_equal(run.states, integrate_closed_euler(system, gammas, 0.1, 5).states)
    assert choose(system, resolve_method("rk4").tableau).provider is TOWER


@pytest.mark.parametrize("realisation", ["shifted", "truncated:3"])
def test_other_realisations_run_in_the_engine(realisation):
    system = get_system("rigid-body", realisation)
    assert choose(system, resolve_method("euler").tableau).provider is TOWER
    with pytest.raises(InputError):
        closed_form(system)
    assert integrate(system, "euler", 0.1, 3).ok


def test_a_step_beyond_the_guard_of_phi_fails_with_a_cause():
    run = integrate_closed_euler(get_system("rigid-body"), (1.0,), 40.0, 5)
    assert not run.ok and run.cause == Failure.NEWTON_NON_FINITE
    assert run.failed_step == 0 and len(run.states) == 1
    assert run.status.startswith("failed at step 0")


def test_a_solve_that_does_not_converge_fails_with_a_cause():
    """The first step's substep has no previous solutions: it converges by fixed-point sweeps;
    the second iterates with the chord matrix, one iteration allowed."""
    run = integrate_closed_euler(get_system("toda:12"), (1.0,), 0.05, 5, max_iter=1)
    assert run.cause == Failure.NEWTON_NO_CONVERGENCE and run.failed_step == 1
    assert run.stage_sweeps[0] >= 1 and run.newton_iterations[0] == 0


def test_substeps_without_previous_solutions_converge_by_sweeps():
    """One step of bcm8-s13 (Blanes, Casas & Ros' processed composition: a processor of 20
    substeps run once from y0, a kernel of 13, the inverse processor once at the end) on toda:12
    at h = 0.1: no substep has previous solutions; the sweeps z := G(x(z)) converge, with no
    chord iteration and no matrix built, on the states of the same substeps solved by the
    engine's Taylor tower (Newton on the jets, an independent solver)."""
    system, euler = get_system("toda:12"), resolve_method("euler").tableau
    comp = load_composition("bcm8-s13")
    gammas, m = np.array(one_step(comp, float)), len(comp.processor)
    direct = run(system, euler, 0.1, 1, gammas=gammas, processor=m, keep_all=False)
    engine = run(system, euler, 0.1, 1, gammas=gammas, processor=m, provider=TOWER, keep_all=False)
    assert choose(system, euler).provider is CLOSED and direct.ok and engine.ok
    assert direct.newton_iterations.sum() == 0 and sum(direct.extra["refreshes"]) == 0
    assert direct.stage_sweeps.sum() >= len(gammas)
    assert np.abs(direct.final_state - engine.final_state).max() < 1e-14 * np.abs(engine.final_state).max()


def test_a_substep_starts_from_its_extrapolation_corrected_by_the_substep_before():
    """Two substeps whose solutions are their steps times one function of the step index,
    z_i(k) = hs_i f(k), f quartic: the cubic extrapolation over the last four steps errs by f's
    fourth difference (24 a for a k^4) times hs; with substep 0's error per unit of step added,
    substep 1 starts on its solution. A substep extrapolating from fewer solutions than the one
    before (quadratic: off by the third difference, 108 a from k = 3) takes no correction, nor
    the first after `resume` (the next substep does not follow the last in time)."""
    system = get_system("rigid-body")
    n, form = system.dim, closed_form(system)
    work, memory = closed_work(form, n), chord_memory(2, n)
    a, b = np.array([0.3, -0.7, 1.1]), np.array([0.5, 0.2, -0.4])

    def f(k):
        return a * k**4 + b * k

    hs, y0 = (0.3, -0.2), np.array(system.x0)
    assert HISTORY == 4
    for i in (0, 1):
        memory.z_hist[i] = [hs[i] * f(5 - r) for r in range(HISTORY)]
        memory.count[i] = HISTORY
    _predict_z(0, y0, hs[0], form, work, memory, n)
    np.testing.assert_allclose(work.z, hs[0] * (f(6) - 24 * a), rtol=1e-13)
    work.z[:] = hs[0] * f(6)
    _remember_z(0, hs[0], memory, work, n)
    _predict_z(1, y0, hs[1], form, work, memory, n)
    np.testing.assert_allclose(work.z, hs[1] * f(6), rtol=1e-13)
    memory.count[1] = 3
    _predict_z(1, y0, hs[1], form, work, memory, n)
    np.testing.assert_allclose(work.z, hs[1] * (f(6) - 108 * a), rtol=1e-13)
    memory.count[1] = HISTORY
    resume(ClosedSubstep(form, work, memory, work.y), y0)
    _predict_z(1, y0, hs[1], form, work, memory, n)
    np.testing.assert_allclose(work.z, hs[1] * (f(6) - 24 * a), rtol=1e-13)


def test_a_substep_starts_from_the_line_through_the_two_defects_before():
    """Three substeps of steps hs_i whose solutions are hs_i g(tau) at their midpoint times tau
    (the clock from 0) and at the same times 1, 2, 3, 4 earlier (the steps before), g quintic:
    the cubic extrapolation errs by E(tau) per unit of step, a line in tau (g's fourth
    difference). The first starts off by E(tau_0); the second, corrected by the first's defect
    alone, by E(tau_1) - E(tau_0); the third, on the line through both defects, on its solution,
    unless it lies farther than DEFECT_REACH times the two's distance in time: then it takes the
    last defect alone, off by E(tau_2) - E(tau_1); so too where the two lie at one time (a step
    and its inverse), the third at that time too: it starts on its solution."""
    system = get_system("rigid-body")
    n, form = system.dim, closed_form(system)
    a, b = np.array([0.3, -0.7, 1.1]), np.array([0.5, 0.2, -0.4])
    y0 = np.array(system.x0)

    def g(t):
        return a * t**5 + b * t

    def E(t):
        return sum(w * g(t - 1 - r) for w, r in zip((4, -6, 4, -1), range(4), strict=True)) - g(t)

    def start_errors(hs):
        work, memory = closed_work(form, n), chord_memory(len(hs), n)
        times = np.cumsum((0.0,) + hs[:-1]) + 0.5 * np.array(hs)
        errors = []
        for i, tau in enumerate(times):
            memory.z_hist[i] = [hs[i] * g(tau - 1 - r) for r in range(HISTORY)]
            memory.count[i] = HISTORY
            _predict_z(i, y0, hs[i], form, work, memory, n)
            errors.append((work.z - hs[i] * g(tau)) / hs[i])
            work.z[:] = hs[i] * g(tau)
            _remember_z(i, hs[i], memory, work, n)
        return errors, times

    assert HISTORY == 4
    errors, tau = start_errors((0.3, -0.2, 0.25))
    np.testing.assert_allclose(tau, (0.15, 0.2, 0.225))
    np.testing.assert_allclose(errors[0], E(tau[0]), rtol=1e-12)
    np.testing.assert_allclose(errors[1], E(tau[1]) - E(tau[0]), rtol=1e-9)
    assert np.abs(E(tau[1]) - E(tau[0])).max() > 1.0 and np.abs(errors[2]).max() < 1e-11
    errors, tau = start_errors((0.3, -0.2, 1.0))
    assert tau[2] - tau[1] > DEFECT_REACH * (tau[1] - tau[0])
    np.testing.assert_allclose(errors[2], E(tau[2]) - E(tau[1]), rtol=1e-9)
    errors, tau = start_errors((0.3, -0.3, 0.3))  # a step and its inverse: the two at one time
    assert tau[0] == tau[1] == tau[2] and np.abs(errors[2]).max() < 1e-11


def test_a_failed_run_is_one_line_and_exit_1(run_cli):
    code, out, err = run_cli("integrate", "rigid-body", "--method", "tj4", "--h", "40", "--t-final", "120")
    assert code == 1
    assert len(err.strip().splitlines()) == 1 and "Newton" in err


def test_phi_series_takes_the_terms_its_argument_needs():
    """phi_1(w) = (e^w - 1) / w and phi_2(w) = (e^w - 1 - w) / w^2 summed with the terms
    `_phi_terms` gives for |w| (PHI_REACH: the next term below 2^-56 of the first) against mpmath
    at 50 digits: within 4 units of round-off for |w| from 1e-9 to just below PHI_SERIES, both
    signs, while the count grows from 2 to PHI_TERMS."""
    counts = set()
    with mp.workdps(50):
        for size in np.geomspace(1e-9, 0.999 * PHI_SERIES, 60):
            terms = _phi_terms(size)
            counts.add(terms)
            for w in (size, -size):
                p1, p2 = _phi_functions(w, terms)
                x = mp.mpf(w)
                exact1 = mp.expm1(x) / x
                exact2 = (mp.expm1(x) - x) / x**2
                assert abs(p1 - exact1) <= 4 * 2.0**-53 * abs(exact1), (w, terms)
                assert abs(p2 - exact2) <= 4 * 2.0**-53 * abs(exact2), (w, terms)
    assert min(counts) == 2 and max(counts) == PHI_TERMS
