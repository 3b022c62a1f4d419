"""The one driver of the RKHP integrators and its table of substep providers
(rkhp.integrators.driver, rkhp.integrators.substeps; docs/engine.md "One driver, many substeps").

Values from outside the code: the final states and statuses of 216 runs (12 built-in systems, two
realisations, nine methods: tableaux explicit and implicit, RKHP Euler, compositions) computed by
the integrators as they were before they ran on one driver (tests/data/driver_reference.json),
and the midpoint rule's own equation for a step on a constant pi.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rkhp.integrators.driver import run, run_ensemble
from rkhp.integrators.methods import resolve_method, resolve_system
from rkhp.integrators.substeps import CLOSED, SPRAY, TOWER, choose, explain
from rkhp.systems import get_system
from rkhp.tableaux.compositions import load_composition
from rkhp.tableaux.files import load_tableau

REFERENCE = json.loads((Path(__file__).parent / "data" / "driver_reference.json").read_text())["runs"]
#: one system of each family and each kind of run in the normal suite; all 216 in the slow one
QUICK = [key for key in REFERENCE
         if key.split("/")[0] in ("rigid-body", "lotka-volterra", "pendulum", "charged-particle")
         and (key.split("/")[1] == "symmetric" or key.split("/")[2] in ("euler", "tj4"))]


def _check(key: str) -> None:
    """The run of `key` as the reference has it: its final state to 5e-13 (relative), or, for a
    run that failed, a failure of the same cause. The driver ran the 216 bit for bit as before;
    the direct forms have since changed at round-off (Rodrigues' formulas on so(3)*, Newton's
    method, more collocation nodes, sweeps in the first substeps), which moves a run at the edge
    of convergence by a step. The bound is round-off's after 20 steps: on point-vortices, Euler's
    run by the tower and by the spray's direct form differ by 1.3e-13."""
    name, realisation, method = key.split("/")
    trajectory = resolve_method(method).integrate(resolve_system(name, realisation), 0.1, 20)
    expected = REFERENCE[key]
    if expected["status"] != "ok":
        assert trajectory.status.split(": ", 1)[1] == expected["status"].split(": ", 1)[1]
        return
    assert trajectory.status == "ok"
    final = np.array(expected["final"])
    assert np.abs(trajectory.states[-1] - final).max() <= 5e-13 * max(1.0, np.abs(final).max())


@pytest.mark.parametrize("key", QUICK)
def test_the_driver_runs_as_the_integrators_did(key):
    _check(key)


@pytest.mark.slow
@pytest.mark.parametrize("key", [k for k in REFERENCE if k not in QUICK])
def test_the_driver_runs_as_the_integrators_did_everywhere(key):
    _check(key)


@pytest.mark.parametrize("name, realisation, method, provider", [
    ("rigid-body", "symmetric", "euler", CLOSED), ("lotka-volterra", "symmetric", "kahan-li8", CLOSED),
    ("pendulum", "symmetric", "tj4", CLOSED), ("nambu", "symmetric", "suzuki4", SPRAY),
    ("charged-particle", "symmetric", "euler", SPRAY), ("rigid-body", "shifted", "euler", TOWER),
    ("nambu", "quartic", "tj4", TOWER), ("rigid-body", "symmetric", "rk4", TOWER),
    ("charged-particle", "symmetric", "gauss2", TOWER),
])
def test_the_table_sends_euler_to_a_direct_form_on_the_symmetric_realisation(name, realisation, method, provider):
    system, m = get_system(name, realisation), resolve_method(method)
    assert choose(system, m.tableau).provider is provider
    told = explain(system, m)
    assert told.provider == provider.name and told.row[-1] == "tower"
    assert m.integrate(system, 0.1, 2).extra["substep"] == provider.name


def test_a_peer_is_not_run_by_the_driver():
    assert explain(get_system("pendulum"), resolve_method("classical:rk4")).provider is None


def test_every_provider_gives_the_same_step_to_round_off():
    """The direct forms and the tower compute the same RKHP Euler substeps (each solved to
    round-off), so a composition run by either agrees to round-off."""
    euler, gammas = load_tableau("euler"), load_composition("tj4").gamma_float
    for name in ("rigid-body", "lotka-volterra", "charged-particle"):
        system = get_system(name)
        direct = run(system, euler, 0.1, 10, gammas=gammas)
        tower = run(system, euler, 0.1, 10, gammas=gammas, provider=TOWER)
        assert direct.extra["substep"] != "tower"
        assert np.abs(direct.states - tower.states).max() < 1e-13


def test_a_consistent_composition_advances_by_n_h_exactly():
    trajectory = resolve_method("kahan-li8").integrate(get_system("rigid-body"), 0.1, 100)
    assert trajectory.times[-1] == 100 * 0.1
    np.testing.assert_array_equal(trajectory.times, 0.1 * np.arange(101))


def test_on_a_constant_pi_euler_is_the_implicit_midpoint_rule_on_every_provider():
    system = get_system("pendulum")
    J = np.array([[0.0, 1.0], [-1.0, 0.0]])
    for provider in (CLOSED, TOWER):
        trajectory = run(system, load_tableau("euler"), 0.2, 10, provider=provider)
        for y0, y1 in zip(trajectory.states[:-1], trajectory.states[1:], strict=True):
            residual = y1 - y0 - 0.2 * J @ system.grad_hamiltonian(0.5 * (y0 + y1))
            assert np.abs(residual).max() < 1e-14


def test_an_ensemble_is_one_run_at_a_time():
    system = get_system("rigid-body")
    starts = system.x0 * np.array([[1.0], [0.9], [1.1]])
    for method in ("paper-three-stage", "euler"):
        tableau = load_tableau(method)
        finals = run_ensemble(system, tableau, 0.1, 30, starts, threads=2)
        for x0, final in zip(starts, finals, strict=True):
            np.testing.assert_array_equal(final, run(system, tableau, 0.1, 30, x0).final_state)


@pytest.mark.parametrize("name, x0", [("charged-particle", (0.5, 0.1)), ("rigid-body", None),
                                      ("lotka-volterra", None), ("nambu", None)])
def test_a_symmetric_composition_retraces_itself_to_round_off(name, x0):
    """RKHP Euler on a symmetric birealisation is symmetric (docs/theory.md §12), and so is a
    symmetric composition of it: 100 steps of kahan-li8 forward, then 100 back, return to the
    start to round-off when every substep is solved to round-off."""
    system, method = resolve_system(name, x0=x0), resolve_method("kahan-li8")
    forward = method.integrate(system, 0.1, 100)
    back = method.integrate(system, -0.1, 100, x0=forward.final_state)
    assert np.abs(forward.final_state - system.x0).max() > 0.1
    assert np.abs(back.final_state - system.x0).max() < 1e-13


def test_a_time_on_the_grid_is_the_grid_state():
    """--t-eval at a grid time returns the grid state (docs/results.md), also where the grid time
    n h differs from the time asked by round-off (3 x 0.1 = 0.30000000000000004)."""
    from rkhp.integrators.output_times import states_at

    system, method = get_system("rigid-body"), resolve_method("kahan-li8")
    trajectory = method.integrate(system, 0.1, 100)
    timed = states_at(trajectory, method, [0.3, 0.35, 1.0, 10.0])
    np.testing.assert_array_equal(timed.substeps, [0.0, 0.35 - trajectory.times[3], 0.0, 0.0])
    np.testing.assert_array_equal(timed.states[[0, 2, 3]], trajectory.states[[3, 10, 100]])
