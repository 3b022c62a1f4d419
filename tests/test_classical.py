"""Classical peers (rkhp.integrators.classical): orders, invariants, failures, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rkhp.base.errors import InputError
from rkhp.integrators.classical import (
    integrate_classical,
    integrate_midpoint,
)
from rkhp.integrators.energy import hamiltonian_values
from rkhp.integrators.failure import Failure
from rkhp.systems import get_system
from rkhp.tableaux.files import load_tableau


@pytest.fixture(scope="module")
def rigid():
    return get_system("rigid-body")


def _error(traj, system, t):
    return float(np.linalg.norm(traj.final_state - system.exact_solution(t)))


@pytest.mark.parametrize("name", ["rigid-body", "lotka-volterra", "pendulum"])
@pytest.mark.parametrize("realisation", ["symmetric", "shifted"])
def test_vector_field_from_tapes_is_pi_grad_h(name, realisation):
    """pi = D^T - D with D = d_p alpha(x, 0) (docs/theory.md §4) in both realisations."""
    system = get_system(name, realisation=realisation)
    f = system.vector_field
    rng = np.random.default_rng(1)
    for _ in range(5):
        x = np.asarray(system.x0) * (1 + 0.3 * rng.random(system.dim)) + 0.1
        expected = system.poisson(x) @ system.grad_hamiltonian(x)
        assert np.allclose(f(x), expected, rtol=1e-13, atol=1e-14)


def test_hamiltonian_values_match_the_system(rigid):
    states = np.array([rigid.x0, [0.1, 0.2, 0.3], [1.0, -2.0, 0.5]])
    expected = [rigid.hamiltonian(x) for x in states]
    assert np.allclose(hamiltonian_values(rigid, states), expected, rtol=1e-15)


@pytest.mark.parametrize(("name", "order"), [("euler", 1), ("heun", 2), ("kutta3", 3), ("rk4", 4)])
def test_classical_orders_on_rigid_body(rigid, name, order):
    """Halving h divides the global error by about 2^p (classical order p of the tableau)."""
    tableau = load_tableau(name)
    T = 2.0
    e1 = _error(integrate_classical(rigid, tableau, T / 200, 200), rigid, T)
    e2 = _error(integrate_classical(rigid, tableau, T / 400, 400), rigid, T)
    assert math.log2(e1 / e2) == pytest.approx(order, abs=0.1)


def test_rk4_step_by_hand(rigid):
    """One RK4 step equals the textbook formula on f = pi grad H."""
    f = rigid.vector_field
    x, h = np.asarray(rigid.x0), 0.3
    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    expected = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    got = integrate_classical(rigid, load_tableau("rk4"), h, 1).final_state
    assert np.allclose(got, expected, rtol=0, atol=1e-15)


def test_midpoint_order_and_quadratic_casimir(rigid):
    """Order 2; the implicit midpoint rule keeps the quadratic Casimir |x|^2 to round-off."""
    T = 2.0
    a = integrate_midpoint(rigid, T / 100, 100)
    b = integrate_midpoint(rigid, T / 200, 200)
    assert math.log2(_error(a, rigid, T) / _error(b, rigid, T)) == pytest.approx(2, abs=0.05)
    r2 = np.sum(b.states**2, axis=1)
    assert np.max(np.abs(r2 - r2[0])) < 1e-14
    assert b.newton_iterations.min() >= 1 and b.newton_iterations.max() <= 5
    # the midpoint equation holds at every step
    f = rigid.vector_field
    x0, x1 = b.states[10], b.states[11]
    assert np.allclose(x1, x0 + T / 200 * f((x0 + x1) / 2), rtol=0, atol=1e-15)


def test_midpoint_equals_rkhp_euler_on_constant_pi():
    """docs/theory.md §5: RKHP Euler on a constant Poisson structure is the implicit midpoint rule."""
    from rkhp.integrators import integrate_rkhp

    pendulum = get_system("pendulum")
    a = integrate_midpoint(pendulum, 0.1, 200)
    b = integrate_rkhp(pendulum, load_tableau("euler"), 0.1, 200)
    assert a.ok and b.ok
    assert np.max(np.abs(a.states - b.states)) < 1e-12


def test_midpoint_newton_failure_is_reported(rigid):
    traj = integrate_midpoint(rigid, 10.0, 5)
    assert not traj.ok
    assert "Newton" in traj.status and "step 0 " in traj.status  # steps numbered from 0
    assert traj.failed_step == 0 and traj.cause != Failure.OK
    assert traj.states.shape == (1, 3)  # only the states before the failure
    with pytest.raises(Exception, match="Newton"):
        traj.raise_if_failed()


def test_leaving_the_domain_is_reported():
    lv = get_system("lotka-volterra")
    traj = integrate_classical(lv, load_tableau("euler"), 1.0, 10)
    assert not traj.ok and "domain" in traj.status and traj.cause == Failure.LEFT_DOMAIN
    assert np.all(traj.states > 0)
    assert len(traj.states) == traj.failed_step + 1


def test_classical_loses_the_casimir_rkhp_keeps(rigid):
    """The point of the comparison: classical RK4 drifts off |x|^2 = const."""
    traj = integrate_classical(rigid, load_tableau("rk4"), 0.2, 500)
    r2 = np.sum(traj.states**2, axis=1)
    assert np.max(np.abs(r2 - r2[0])) > 1e-8


@pytest.mark.parametrize(("h", "n"), [(0.0, 10), (-0.0, 10), (math.nan, 10), (math.inf, 1), (0.1, -1), (0.1, 2.5),
                                    ("0.1", 10), (0.1, True)])
def test_bad_step_input(rigid, h, n):
    with pytest.raises(InputError):
        integrate_classical(rigid, load_tableau("rk4"), h, n)
    with pytest.raises(InputError):
        integrate_midpoint(rigid, h, n)


def test_zero_steps_is_the_start_alone(rigid):
    """The one rule of every integrator (rkhp.base.bounds.check_step): 0 <= n_steps."""
    for traj in (integrate_classical(rigid, load_tableau("rk4"), 0.1, 0), integrate_midpoint(rigid, 0.1, 0)):
        assert traj.ok and traj.states.tolist() == [list(rigid.x0)]


def test_bad_start_and_tableau(rigid):
    with pytest.raises(InputError, match="dimension"):
        integrate_classical(rigid, load_tableau("rk4"), 0.1, 10, x0=[1.0, 2.0])
    with pytest.raises(InputError, match="domain"):
        integrate_midpoint(get_system("lotka-volterra"), 0.1, 10, x0=[-1.0, 1.0, 1.0])
    with pytest.raises(InputError, match="explicit"):
        integrate_classical(rigid, load_tableau("gauss2"), 0.1, 10)


def test_kernel_self_check_turns_a_mismatch_into_an_error(rigid, monkeypatch):
    """A compiled kernel that disagrees with the system's own evaluation (as a stale numba cache
    would) raises instead of returning numbers."""
    from dataclasses import replace

    from rkhp.base.errors import NumericalFailure
    from rkhp.integrators import classical

    monkeypatch.setattr(classical, "_VERIFIED", set())
    wrong = replace(rigid, poisson=lambda x: 2 * rigid.poisson(x))  # pi differs from the alpha tape's
    with pytest.raises(NumericalFailure, match="stale numba cache"):
        integrate_classical(wrong, load_tableau("rk4"), 0.1, 10)
    assert integrate_classical(rigid, load_tableau("rk4"), 0.1, 10).ok
