"""The engine's state is named (docs/engine.md "The state of the step loop"): read from the sources
(nothing is imported or compiled), every compiled function of rkhp takes at most MAX_PARAMETERS
parameters (more go in small NamedTuples), the step loop's memo is indexed by its named slots
(`rkhp.integrators.engine_state.MEMO_HISTORY` ...) and StepBuffers is built with keywords."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "rkhp"
MAX_PARAMETERS = 10
COMPILERS = ("njit", "jit", "overload")
"""The callables that compile a function: numba's, and `rkhp.taylor.compiler.overload`."""


def _name(node: ast.AST) -> str:
    """The last name of a decorator or callee: ``nb.njit(**NJIT_NORC)`` -> "njit"."""
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def _calls_compiler(function: ast.FunctionDef) -> bool:
    return any(isinstance(n, ast.Call) and _name(n) in COMPILERS for n in ast.walk(function))


def compiled_functions(tree: ast.Module) -> list[ast.FunctionDef]:
    """The functions a module compiles: those decorated by a compiler, and the functions defined
    inside an `overload` implementation or inside a function that compiles what it builds (the
    implementations that they return)."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef):
            continue
        decorators = {_name(d) for d in node.decorator_list}
        if decorators & {"njit", "jit"}:
            found.append(node)
        if "overload" in decorators or _calls_compiler(node):
            found += [n for n in ast.walk(node) if isinstance(n, ast.FunctionDef) and n is not node]
    return found


def _parameters(function: ast.FunctionDef) -> int:
    a = function.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(PACKAGE.parent), ast.parse(path.read_text(encoding="utf-8"))


def test_the_scan_finds_the_compiled_functions():
    names = {f.name for _, tree in _modules() for f in compiled_functions(tree)}
    assert {"drive", "rkhp_step", "implicit_tower", "run_tape", "spray", "explicit_substep",
            "_value_stages", "one_kernel", "first_or_others"} <= names


def test_compiled_functions_take_at_most_ten_parameters():
    wide = [f"{path}:{f.lineno} {f.name} ({_parameters(f)})" for path, tree in _modules()
            for f in compiled_functions(tree) if _parameters(f) > MAX_PARAMETERS]
    assert not wide, f"compiled functions with more than {MAX_PARAMETERS} parameters: {wide}"


def test_memo_slots_are_named():
    numbered = [f"{path}:{n.lineno}" for path, tree in _modules() for n in ast.walk(tree)
                if isinstance(n, ast.Subscript) and _name(n.value) == "memo"
                and isinstance(n.slice, ast.Constant) and isinstance(n.slice.value, int)]
    assert not numbered, f"memo indexed by a number: {numbered}"


def test_step_buffers_are_built_with_keywords():
    positional = [f"{path}:{n.lineno}" for path, tree in _modules() for n in ast.walk(tree)
                  if isinstance(n, ast.Call) and _name(n) in ("StepBuffers", "StageNewtonWork") and n.args]
    assert not positional, f"positional construction: {positional}"


def test_memo_slots_are_distinct_and_fill_the_memo():
    from rkhp.integrators import engine_state

    slots = {name: value for name, value in vars(engine_state).items()
             if name.startswith("MEMO_") and name != "MEMO_SIZE"}
    assert sorted(slots.values()) == list(range(engine_state.MEMO_SIZE))


@pytest.mark.slow
def test_the_dispatch_of_several_composite_codes_runs_each_kernel():
    """No built-in system holds both composite codes, so the dispatch's test of the row's code
    (`rkhp.taylor.interpreter._dispatch`) is compiled here only: the tapes of toda (phimv) and
    charged-particle (spray) recast to the class of all codes give their own values and
    Jacobians."""
    import numpy as np

    from rkhp.systems import get_system
    from rkhp.taylor.interpreter import evaluate
    from rkhp.taylor.ops import PHIMV, SPRAY
    from rkhp.taylor.tape import tape_class

    every = tape_class((PHIMV, SPRAY))
    for name in ("toda", "charged-particle"):
        tape = get_system(name).alpha_tape
        inputs = np.linspace(0.1, 0.4, tape.n_inputs)
        own = evaluate(tape, inputs, 1, tape.n_inputs)
        recast = evaluate(every(*tape), inputs, 1, tape.n_inputs)
        assert all(np.array_equal(a, b) for a, b in zip(own, recast, strict=True)), name


def test_the_entry_kernels_take_plain_tapes_whatever_the_class():
    """The step loops call the interpreter of a system's class through its address
    (`rkhp.taylor.interpreter.Interpreter`) and see plain tapes, so one compiled version serves
    every class: after runs on the rigid body (no composite operation), toda (phimv) and
    charged-particle (spray), no entry kernel's signature names a composite class but those
    compiled per class (the interpreter, the field scipy calls), and the interpreter has one
    version per class; each run keeps its own system's energy."""
    import numpy as np

    from rkhp.integrators.kernels import KERNELS, TAPE, _dispatcher
    from rkhp.integrators.methods import resolve_method
    from rkhp.systems import get_system

    for name in ("rigid-body", "toda", "charged-particle"):
        system = get_system(name)
        for method in ("rk4", "classical:rk4"):
            trajectory = resolve_method(method).integrate(system, system.t_final / 1000, 2)
            assert np.isfinite(trajectory.states).all() and trajectory.states.shape == (3, system.dim)
            h0, h2 = (system.hamiltonian(x) for x in trajectory.states[[0, 2]])
            assert abs(h2 - h0) < 1e-8 * max(1.0, abs(h0)), (name, method)
    entry = {_dispatcher(k) for kernels in KERNELS.values() for k in kernels if not k.per_class}
    for kernel in entry:
        for signature in kernel.signatures:
            assert "Tape_" not in str(signature), (kernel, signature)
    classes = {str(sig[0]).split("(")[0] for sig in _dispatcher(TAPE).signatures}
    assert {"Tape", "Tape_phimv", "Tape_spray"} <= classes


def test_an_interpreter_is_made_only_for_the_plain_tape_layout():
    """The address of the interpreter compiled for a class is called as the plain tape's: made
    only when both have one machine layout."""
    from typing import NamedTuple

    import numpy as np

    from rkhp.systems import get_system
    from rkhp.taylor.compiler import numba as nb
    from rkhp.taylor.interpreter import _interpreter

    class Other(NamedTuple):
        ops: np.ndarray

    tape = get_system("charged-particle").h_tape
    assert _interpreter(nb.typeof(tape))._compiled.args[0] == nb.types.CPointer(nb.typeof(tape))
    with pytest.raises(TypeError, match="not laid out as"):
        _interpreter(nb.typeof(Other(np.zeros((1, 1), np.int64))))
    readonly = np.zeros((1, 5), np.int64)
    readonly.flags.writeable = False
    with pytest.raises(TypeError, match="not laid out as"):
        _interpreter(nb.typeof(type(tape)(readonly, *tape[1:])))


def test_a_call_at_an_address_takes_only_the_plain_signature():
    """`run_at` calls the interpreter at an address with the arguments every interpreter is
    compiled for: with the plain charged particle's H tape (of the spray class) it gives
    H = cos x1 + sin x2 (GeometricProblems.jl's MasslessChargedParticle); a tape of another
    machine layout (a read-only array) is a typing error, never a call."""
    import numpy as np
    from numba.core.errors import TypingError

    from rkhp.systems import get_system
    from rkhp.taylor.compiler import numba as nb
    from rkhp.taylor.interpreter import as_plain, interpreter, run_at, tape_work
    from rkhp.taylor.jets import jet_space

    @nb.njit
    def h_at(address, tape, space, work):
        run_at(address, tape, 0, space, work)
        return work.W[tape.outputs[0], 0]

    system = get_system("charged-particle")
    tape, space = system.h_tape, jet_space(0, 0)
    work = tape_work((tape,), space.size)
    x = np.array([0.3, -1.1])
    work.W[: x.size, 0] = x
    want = np.cos(x[0]) + np.sin(x[1])
    assert abs(h_at(interpreter(tape).address, as_plain(tape), space, work) - want) <= 1e-14 * abs(want)
    ops = tape.ops.copy()
    ops.flags.writeable = False
    with pytest.raises(TypingError, match="plain tape"):
        h_at(1, as_plain(tape)._replace(ops=ops), space, work)


def test_a_call_from_kept_addresses_is_the_call_at_the_address():
    """`run_from` on the addresses of copies taken once (`address_of`, what the step loops do)
    gives what `run_at` gives, H = cos x1 + sin x2 of the charged particle at several points;
    `address_of` takes only a plain tape, a jet space or work arrays."""
    import numpy as np
    from numba.core.errors import TypingError

    from rkhp.systems import get_system
    from rkhp.taylor.compiler import numba as nb
    from rkhp.taylor.interpreter import address_of, as_plain, interpreter, run_from, tape_work
    from rkhp.taylor.jets import jet_space

    @nb.njit
    def h_values(address, tape, space, work, points, out):
        tape_at, space_at, work_at = address_of(tape), address_of(space), address_of(work)
        for r in range(points.shape[0]):
            work.W[0, 0], work.W[1, 0] = points[r, 0], points[r, 1]
            run_from(address, tape_at, 0, space_at, work_at)
            out[r] = work.W[tape.outputs[0], 0]

    system = get_system("charged-particle")
    tape, space = system.h_tape, jet_space(0, 0)
    work = tape_work((tape,), space.size)
    points = np.array([[0.3, -1.1], [1.0, 2.0], [-0.5, 0.25]])
    out = np.empty(3)
    h_values(interpreter(tape).address, as_plain(tape), space, work, points, out)
    want = np.cos(points[:, 0]) + np.sin(points[:, 1])
    assert np.all(np.abs(out - want) <= 1e-14 * np.abs(want))

    @nb.njit
    def address_of_array(a):
        return address_of(a)

    with pytest.raises(TypingError, match="plain tape"):
        address_of_array(np.zeros(3))
