"""H's gradient and Hessian compiled per system (rkhp.integrators.derivatives, rkhp.taylor.generated;
docs/engine.md "Derivatives compiled per system").

Values from outside the code: the tape interpreter's forward-mode gradient (another evaluation of
the same H), Hessians in closed form (Lotka–Volterra's H = sum x_i - log x_i, a constant-pi system
with a cos term), and the Newton iterations the race issue names (at most three a substep at the
step sizes the compositions pick).
"""

from __future__ import annotations

import ctypes
import sys
import warnings

import numpy as np
import pytest

from rkhp.integrators import closed_euler, derivatives
from rkhp.integrators.closed_euler import closed_form, closed_work
from rkhp.integrators.direct_form import gradient
from rkhp.integrators.methods import resolve_method
from rkhp.systems import get_system
from rkhp.systems.families import family_system
from rkhp.systems.spec import system as spec_system
from rkhp.taylor import generated
from rkhp.taylor.kernel_cache import KernelCacheWarning
from rkhp.taylor.tape import functions as f

CONSTANT_PI = np.array([[0.0, 1.0, -0.5], [-1.0, 0.0, 0.25], [0.5, -0.25, 0.0]])


def constant_system(name="constant-cos"):
    """A constant pi on R^3 with H = (x1^2 + x2^2) / 2 - cos x3 + x1 x2 x3 / 10."""
    return family_system("constant", CONSTANT_PI,
                         lambda x: 0.5 * (x[0] * x[0] + x[1] * x[1]) - f.cos(x[2]) + 0.1 * x[0] * x[1] * x[2],
                         name=name, x0=(0.3, -0.2, 0.5), t_final=1.0)


def constant_hessian(x):
    return np.array([[1.0, 0.1 * x[2], 0.1 * x[1]], [0.1 * x[2], 1.0, 0.1 * x[0]],
                     [0.1 * x[1], 0.1 * x[0], np.cos(x[2])]])


def evaluate(address: int, x, n: int, what: int) -> np.ndarray:
    """The generated function at `address` on x (n + n^2 outputs at most): for H's derivatives,
    grad H (what = 0) or grad H then Hess H by rows (what = 1)."""
    pointer = ctypes.POINTER(ctypes.c_double)
    function = ctypes.CFUNCTYPE(None, pointer, pointer, ctypes.c_int64)(address)
    x = np.ascontiguousarray(x, dtype=np.float64)
    out = np.zeros(n + n * n)
    function(x.ctypes.data_as(pointer), out.ctypes.data_as(pointer), what)
    return out


def points(system, count=5, seed=7):
    x0 = np.asarray(system.x0, dtype=float)
    rng = np.random.default_rng(seed)
    return [np.abs(x0) * (1 + 0.2 * rng.standard_normal(x0.size)) if system.family == "log-canonical"
            else x0 + 0.3 * rng.standard_normal(x0.size) for _ in range(count)]


@pytest.mark.parametrize("name", ["rigid-body", "lotka-volterra", "pendulum", "heavy-top", "toda:12", "constant"])
def test_the_compiled_gradient_is_the_interpreted_one(name):
    system = constant_system() if name == "constant" else get_system(name)
    form = closed_form(system)
    assert form.derivatives_at != 0
    n = system.dim
    work = closed_work(form, n)
    for x in points(system):
        gradient(form, work, x, n)
        compiled = evaluate(form.derivatives_at, x, n, 0)[:n]
        np.testing.assert_allclose(compiled, work.g, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("name", ["lotka-volterra", "constant"])
def test_the_compiled_hessian_is_the_closed_form(name):
    system = constant_system() if name == "constant" else get_system(name)
    form = closed_form(system)
    assert form.exact and not form.hessian_constant  # Newton's method on a compiled Hessian
    n = system.dim
    for x in points(system):
        out = evaluate(form.derivatives_at, x, n, 1)
        expected = np.diag(1.0 / x**2) if name == "lotka-volterra" else constant_hessian(x)
        np.testing.assert_allclose(out[n:].reshape(n, n), expected, rtol=1e-15, atol=1e-16)


def test_a_pole_of_the_hessian_gives_inf_not_stale_values(capfd):
    """Lotka–Volterra's Hess H = diag(1 / x_i^2) at x1 = 0: IEEE division gives +inf (the closed
    form's limit), written into the output, with nothing on stderr (a cfunc cannot raise: an
    exception there would leave the output as it was)."""
    form = closed_form(get_system("lotka-volterra"))
    pointer = ctypes.POINTER(ctypes.c_double)
    function = ctypes.CFUNCTYPE(None, pointer, pointer, ctypes.c_int64)(form.derivatives_at)
    x = np.array([0.0, 2.0, 0.5])
    out = np.full(12, 7.0)
    function(x.ctypes.data_as(pointer), out.ctypes.data_as(pointer), 1)
    assert out[3] == np.inf and out[7] == 0.25 and out[11] == 4.0
    assert capfd.readouterr().err == ""


def forget_modules():
    """This process forgets every generated module it imported (another process would not know them)."""
    for key in list(generated._LOADED):
        sys.modules.pop(generated.module_name(key), None)
    generated._LOADED.clear()


def test_a_system_met_again_loads_its_module_without_generating_it(monkeypatch):
    system = constant_system("constant-again")
    first = derivatives.derivatives_at(system, hessian=True)
    assert first != 0
    x = points(system)[0]
    values = evaluate(first, x, 3, 1)
    forget_modules()

    def refuse(*args):
        raise AssertionError("generated again")

    monkeypatch.setattr("rkhp.systems.field_code.derivatives_code", refuse)
    again = derivatives.derivatives_at(system, hessian=True)
    assert again != 0
    np.testing.assert_array_equal(evaluate(again, x, 3, 1), values)


def test_a_folder_that_cannot_hold_the_module_leaves_the_tape_interpreted(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(generated, "generated_folder", lambda: blocker / "generated")
    monkeypatch.setattr("rkhp.taylor.kernel_cache._SAID", set())
    forget_modules()
    system = constant_system("constant-unkept")
    with pytest.warns(KernelCacheWarning, match="interpreted instead"):
        assert derivatives.derivatives_at(system, hessian=True) == 0
    closed_euler._FORMS.pop(system, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KernelCacheWarning)
        interpreted = closed_form(system)
        assert interpreted.derivatives_at == 0 and not interpreted.exact
        method = resolve_method("kahan-li6")
        by_tape = method.integrate(system, 0.1, 20).raise_if_failed().final_state
    monkeypatch.undo()
    closed_euler._FORMS.pop(system, None)
    assert closed_form(system).derivatives_at != 0
    compiled = method.integrate(system, 0.1, 20).raise_if_failed().final_state
    np.testing.assert_allclose(compiled, by_tape, rtol=1e-13, atol=1e-15)


def test_a_hamiltonian_without_plain_arithmetic_has_no_compiled_derivatives():
    # no built-in H holds a composite operation (one without a plain-arithmetic form, as so(3)*'s
    # closed form of alpha): its last row is made one
    from rkhp.taylor import ops as opcodes

    system = get_system("rigid-body")
    tape = system.h_tape
    ops = np.array(tape.ops, copy=True)
    ops[-1, 0] = next(op.code for op in opcodes.OPS if op.kind == opcodes.COMPOSITE)

    class Stub:
        name, dim = "stub", system.dim
        h_tape = tape._replace(ops=ops)

    assert derivatives.derivatives_at(Stub(), hessian=False) == 0


@pytest.mark.parametrize(("name", "method", "h"), [("lotka-volterra", "sofroniou-spaletta10", 0.185),
                                                   ("rigid-body", "sofroniou-spaletta10", 0.909),
                                                   ("pendulum", "kahan-li8", 0.25)])
def test_newton_takes_at_most_three_iterations_a_substep_at_the_race_steps(name, method, h):
    resolved = resolve_method(method)
    trajectory = resolved.integrate(get_system(name), h, 100).raise_if_failed()
    substeps = len(resolved.composition.gamma_float)
    assert trajectory.newton_iterations.mean() / substeps <= 3.0


def scaled_so3(scale="1e19"):
    """so(3) scaled by `scale`, from a spec's keys: the exact integer 10^19 is beyond int64."""
    entries = [["0", "-x3", "x2"], ["x3", "0", "-x1"], ["-x2", "x1", "0"]]
    return spec_system(family="general", poisson=[[f"{e}*{scale}" for e in row] for row in entries],
                       hamiltonian="x1^2/4 + x2^2/2 + 3*x3^2/4", x0=[0.4536, 0.0, 0.8912], t_final=1e-18)


@pytest.mark.parametrize("name", ["charged-particle", "nambu", "benchmarks/data/vortices-8.toml", "so(3) 1e19"])
def test_the_compiled_spray_field_is_the_interpreted_one(name):
    from rkhp.integrators.methods import resolve_system
    from rkhp.integrators.spray_euler import _field_derivatives, euler_work, spray_tapes
    from rkhp.systems.field_code import POINTS

    system = scaled_so3() if name == "so(3) 1e19" else resolve_system(name)
    tapes, n = spray_tapes(system), system.dim
    address = derivatives.spray_at(system, tapes.field)
    assert address != 0
    work = euler_work(tapes, n)
    outputs = tapes.field.outputs
    rng = np.random.default_rng(3)
    for y in points(system):
        work.p[:] = 0.2 * rng.standard_normal(n)
        out = evaluate(address, np.concatenate([y, work.p]), 2 * n, 2)[: n + 2 * n * n]
        _field_derivatives(y, np.int64(-1), tapes, work, n, np.int64(0), np.int64(2 * n))
        rows = work.W[outputs]
        np.testing.assert_allclose(out[:n], rows[:, 0], rtol=1e-14, atol=1e-16)
        np.testing.assert_allclose(out[n: n + n * n].reshape(n, n), rows[:, 1: 1 + n], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(out[n + n * n:].reshape(n, n), rows[:, 1 + n: 1 + 2 * n], rtol=1e-14, atol=0)
    # X at all the points in one call (a collocation's stages), with the last p
    ys = points(system)
    q = len(ys)
    at_once = evaluate(address, np.concatenate([np.zeros(n), work.p, *ys]), q * n, POINTS - q)[: q * n]
    for j, y in enumerate(ys):
        _field_derivatives(y, np.int64(-1), tapes, work, n, np.int64(0), np.int64(n))
        np.testing.assert_allclose(at_once[j * n: (j + 1) * n], work.W[outputs, 0], rtol=1e-14, atol=1e-16)
