"""No cost per call: systems built once, methods resolved once, prepared runs lent to one run at a
time (rkhp.systems.builtins.get_system, rkhp.integrators.methods.resolve_method,
rkhp.integrators.prepared, rkhp.integrators.driver), ensembles, and the methods chosen by cost
(docs/methods.md "The default method").

Values from outside the code: bit-for-bit equality with runs made on new objects (a system built
afresh, prepared data built afresh, one trajectory at a time); the number of monomials of degree
at most D in 2n variables, C(2n + D, D), against the jet space's own table.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import rkhp
from rkhp.integrators import driver
from rkhp.integrators.methods import BENCH_METHODS, resolve_method, resolve_system
from rkhp.integrators.prepared import Lender
from rkhp.integrators.tower_substep import tower_cost
from rkhp.studies.bench import DEFAULT_STEPS, default_methods
from rkhp.systems import get_system
from rkhp.systems.builtins import _built_in
from rkhp.taylor.jets import jet_space

SPEC = """name = "body"
family = "lie-poisson"
structure_constants = [[1, 2, 3, -1], [2, 3, 1, -1], [3, 1, 2, -1]]
hamiltonian = "x1^2/4 + x2^2/2 + 3*x3^2/4"
x0 = [0.4536, 0.0, 0.8912]
"""


def test_a_system_is_built_once_by_name():
    assert get_system("toda:12") is get_system("toda:12")
    assert get_system("rigid-body") is resolve_system("rigid-body")
    assert get_system("rigid-body", "shifted") is not get_system("rigid-body")


def test_a_spec_file_is_built_again_when_its_content_changes(tmp_path):
    path = tmp_path / "body.toml"
    path.write_text(SPEC)
    first = get_system(str(path))
    assert get_system(str(path)) is first
    path.write_text(SPEC.replace("x1^2/4", "x1^2/8"))
    edited = get_system(str(path))
    assert edited is not first
    assert edited.hamiltonian([1.0, 0.0, 0.0]) == 0.125 and first.hamiltonian([1.0, 0.0, 0.0]) == 0.25
    path.write_text(SPEC)
    assert get_system(str(path)) is first  # the same text: the system built from it


def test_a_method_file_is_resolved_again_when_its_content_changes(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('A = [["0", "0"], ["1/2", "0"]]\nb = ["0", "1"]\n')
    first = resolve_method(str(path))
    assert resolve_method(str(path)) is first and resolve_method("kahan-li8") is resolve_method("kahan-li8")
    path.write_text('A = [["0", "0"], ["1", "0"]]\nb = ["1/2", "1/2"]\n')
    assert list(resolve_method(str(path)).tableau.b_float) == [0.5, 0.5]


def test_a_built_in_composition_name_stands_for_it_whatever_files_exist(tmp_path, monkeypatch):
    """A built-in composition's name is its composition even beside a file of that name (which
    the resolver then never reads), while a built-in tableau's name gives way to a file."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "KAHAN-LI8").write_text("not a composition")
    (tmp_path / "rk4").write_text('A = [["0"]]\nb = ["1"]\n')
    method = resolve_method("KAHAN-LI8")
    assert method.kind == "composition" and method.composition.substeps == 17
    assert method is resolve_method("KAHAN-LI8")
    assert resolve_method("rk4").tableau.stages == 1


@pytest.mark.parametrize("name, method", [("charged-particle", "kahan-li8"), ("rigid-body", "kahan-li8"),
                                          ("rigid-body", "paper-three-stage"), ("lotka-volterra", "euler"),
                                          ("pendulum", "gauss2")])
def test_by_name_equals_resolved_objects_and_new_ones(name, method):
    """The same trajectory by name, with resolved objects, and on a system built afresh with
    prepared data built afresh (a new lender), bit for bit."""
    by_name = rkhp.integrate(name, method, 0.1, 12)
    again = rkhp.integrate(name, method, 0.1, 12)
    resolved = resolve_method(method).integrate(get_system(name), 0.1, 12)
    kept = driver.PREPARED
    driver.PREPARED = Lender()
    try:
        fresh = resolve_method(method).integrate(_built_in.__wrapped__(name, "symmetric"), 0.1, 12)
    finally:
        driver.PREPARED = kept
    for other in (again, resolved, fresh):
        np.testing.assert_array_equal(by_name.states, other.states)
        np.testing.assert_array_equal(by_name.newton_iterations, other.newton_iterations)
        assert by_name.extra == other.extra
    assert again.compile_seconds == 0.0


def test_a_run_between_leaves_no_trace():
    """Prepared data lent to a run from elsewhere with another step computes the same run again."""
    for name, method in (("rigid-body", "gauss2"), ("nambu", "tj4"), ("charged-particle", "kahan-li6")):
        system, m = get_system(name), resolve_method(method)
        first = m.integrate(system, 0.1, 15)
        m.integrate(system, -0.3, 4, x0=system.x0 * 1.1)
        np.testing.assert_array_equal(first.states, m.integrate(system, 0.1, 15).states)


@pytest.mark.parametrize("name, method", [("charged-particle", "kahan-li8"), ("rigid-body", "tj4"),
                                          ("rigid-body", "paper-three-stage"), ("lotka-volterra", "suzuki4")])
def test_an_ensemble_is_one_run_at_a_time(name, method):
    system, m = get_system(name), resolve_method(method)
    starts = system.x0 * (1.0 + 0.05 * np.random.default_rng(1).standard_normal((5, system.dim)))
    hs, counts = np.array([0.1, 0.05, -0.1, 0.2, 0.1]), np.array([10, 20, 7, 0, 3])
    alone = np.array([m.integrate(system, h, n, x0=x).final_state for x, h, n in zip(starts, hs, counts, strict=True)])
    for threads in (1, 2):
        np.testing.assert_array_equal(m.integrate_ensemble(system, hs, counts, starts, threads=threads), alone)
    same_step = m.integrate_ensemble(system, 0.1, 10, starts)
    np.testing.assert_array_equal(same_step[0], m.integrate(system, 0.1, 10, x0=starts[0]).final_state)


def test_an_ensemble_refuses_steps_of_another_length():
    system = get_system("rigid-body")
    with pytest.raises(rkhp.InputError, match="one value or one per start"):
        resolve_method("tj4").integrate_ensemble(system, [0.1, 0.2], 10, np.tile(system.x0, (3, 1)))


def test_the_tower_cost_counts_the_jet_tables():
    """C(2n + D, D) product terms (pairs of monomials of total degree at most D) and C(n + D, D)
    monomials, the sizes of the tables the tower builds."""
    for name, method in (("rigid-body", "rk4"), ("toda", "paper-three-stage"), ("heavy-top", "paper-two-stage")):
        system = get_system(name)
        cost = resolve_method(method).cost(system)
        space = jet_space(system.dim, cost.degree)
        assert (cost.pairs, cost.size) == (len(space.pa), space.size)
    assert tower_cost(get_system("toda:24"), "paper-three-stage").pairs == math.comb(52, 4)
    assert resolve_method("kahan-li8").cost(get_system("toda:24")) is None  # a direct form


def test_the_bench_defaults_leave_out_what_costs_too_much():
    kept, left_out = default_methods(get_system("rigid-body"), (10, 20), 3)
    assert [m.name for m in kept] == list(BENCH_METHODS) and not left_out
    kept, left_out = default_methods(get_system("toda:24"), DEFAULT_STEPS, 3)
    assert [name for name, _ in left_out] == ["paper-three-stage"] and left_out[0][1] > 60
    assert all(m.kind == "composition" for m in kept)


def test_a_costly_method_is_announced_before_the_work(run_cli):
    rc, out, err = run_cli("integrate", "rigid-body", "--method", "paper-three-stage", "--steps", "20000",
                           "--format", "json")
    assert rc == 0 and json.loads(out)["status"] == "ok"
    assert err.startswith("rkhp: note: paper-three-stage on rigid-body runs on Taylor polynomials of degree 4 "
                          "in 3 variables (210 product terms): about ")
    rc, out, err = run_cli("integrate", "rigid-body", "--steps", "20000", "--format", "json")
    assert rc == 0 and err == ""
