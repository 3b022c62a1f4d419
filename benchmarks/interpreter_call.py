"""What one call of the tape interpreter at its address costs in compiled code, and how much of it
is the call itself (docs/engine.md "The interpreter through its address").

Run: python benchmarks/interpreter_call.py [--calls N]

In one process, each in a compiled loop of N calls (the minimum over 5 loops, ns per call):

- `run_at` of a function compiled for `plain_signature()` whose body stores one integer: the
  cost of the call alone, which passes the plain tape, the jet space and the work arrays
  member by member (numba's calling convention flattens every array into its fields);
- `run_at` of the rigid body's interpreter on its H tape (8 rows) at degrees 0 and 2 (3
  variables), and on a tape of one row at degree 0: the interpreter's cost per call with that
  share in it;
- the same bodies compiled to take the addresses of the tape, the space and the work arrays
  (numba's `CPointer`s), called with addresses that the loop makes once, before its calls (stack
  copies of the three groups): what a step loop that kept those addresses for a whole run would
  pay per call. Each version's results are compared with `run_at`'s (the same to the bit).
"""

from __future__ import annotations

import argparse
import time

import numba as nb
import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from rkhp.systems import get_system
from rkhp.taylor.compiler import NJIT_NORC
from rkhp.taylor.interpreter import as_plain, interpreter, plain_signature, run_at, run_tape, tape_work
from rkhp.taylor.jets import jet_space
from rkhp.taylor.tape import record


@nb.njit(**NJIT_NORC)
def _store_only(tape, D, space, work):
    work.deg[0] = D + tape.n_inputs + space.degree


@nb.njit(**NJIT_NORC)
def _calls(run, tape, D, space, work, count):
    for _ in range(count):
        run_at(run, tape, D, space, work)


def _pointer_signature():
    plain = plain_signature()
    tape, _, space, work = plain.args
    return types.none(types.CPointer(tape), types.int64, types.CPointer(space), types.CPointer(work))


_interpret = nb.njit(inline="always", **NJIT_NORC)(run_tape.py_func)
_store_inline = nb.njit(inline="always", **NJIT_NORC)(_store_only.py_func)


@nb.njit(**NJIT_NORC)
def _run_by_pointers(tape, D, space, work):
    _interpret(tape[0], D, space[0], work[0])


@nb.njit(**NJIT_NORC)
def _store_by_pointers(tape, D, space, work):
    _store_inline(tape[0], D, space[0], work[0])


@intrinsic
def _addresses(typingctx, tape, space, work):
    """Stack copies of the three groups, made where the caller's frame lives, and their addresses."""
    kept = types.UniTuple(types.voidptr, 3)

    def codegen(context, builder, signature, args):
        copies = [cgutils.alloca_once_value(builder, value) for value in args]
        return context.make_tuple(builder, kept, [builder.bitcast(c, cgutils.voidptr_t) for c in copies])

    return kept(tape, space, work), codegen


@intrinsic
def _run_from(typingctx, address, kept, D):
    """The function at `address` (of `_pointer_signature`) called with the kept addresses."""
    target = _pointer_signature()

    def codegen(context, builder, signature, args):
        call_conv = context.call_conv
        callee = builder.inttoptr(args[0], call_conv.get_function_type(
            target.return_type, target.args).as_pointer())
        tape, space, work = cgutils.unpack_tuple(builder, args[1], 3)
        types_ = [context.get_value_type(t) for t in target.args]
        degree = context.cast(builder, args[2], D, types.int64)
        status, _ = call_conv.call_function(builder, callee, target.return_type, target.args, [
            builder.bitcast(tape, types_[0]), degree, builder.bitcast(space, types_[2]),
            builder.bitcast(work, types_[3])])
        with cgutils.if_unlikely(builder, status.is_error):
            call_conv.return_status_propagate(builder, status)
        return context.get_dummy_value()

    return types.none(address, kept, D), codegen


@nb.njit(**NJIT_NORC)
def _calls_by_pointers(run, tape, D, space, work, count):
    kept = _addresses(tape, space, work)
    for _ in range(count):
        _run_from(run, kept, D)


def _address(dispatcher, signature) -> int:
    dispatcher.compile(signature)
    compiled = dispatcher.get_compile_result(signature)
    return compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name)


def _ns_per_call(calls, run, tape, D, space, work, count) -> float:
    calls(run, tape, D, space, work, 10)
    best = float("inf")
    for _ in range(5):
        start = time.perf_counter()
        calls(run, tape, D, space, work, count)
        best = min(best, time.perf_counter() - start)
    return best / count * 1e9


def _same_results(by_value, by_pointers, tape, D, space, work) -> bool:
    """Whether one call of each version leaves the same work arrays (the same inputs)."""
    first = tuple(array.copy() for array in work)
    _calls(by_value, tape, D, space, work, 1)
    after_value = tuple(array.copy() for array in work)
    for array, saved in zip(work, first, strict=True):
        array[...] = saved
    _calls_by_pointers(by_pointers, tape, D, space, work, 1)
    return all(np.array_equal(a, b) for a, b in zip(after_value, work, strict=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1_000_000, help="calls per loop (1000000)")
    count = parser.parse_args().calls
    h_tape = get_system("rigid-body").h_tape
    one_row = record(1, lambda x, p: [x[0]])
    space = jet_space(3, 2)
    work = tape_work((h_tape, one_row), space.size)
    work.W[:6, 0] = 0.5
    for k in range(3):
        work.W[k, 1 + k] = 1.0
    store = (_address(_store_only, plain_signature()), _address(_store_by_pointers, _pointer_signature()))
    interpreters = (interpreter(h_tape).address, _address(_run_by_pointers, _pointer_signature()))
    rows = [("a body that stores one integer", store, as_plain(h_tape), 0),
            ("run_tape, H of the rigid body, degree 0", interpreters, as_plain(h_tape), 0),
            ("run_tape, H of the rigid body, degree 2", interpreters, as_plain(h_tape), 2),
            ("run_tape, a tape of one row, degree 0", interpreters, as_plain(one_row), 0)]
    print(f"ns per call (minimum of 5 loops of {count} calls): at the address with the groups, "
          "with addresses kept for the loop; the same results")
    for label, (by_value, by_pointers), tape, D in rows:
        value = _ns_per_call(_calls, by_value, tape, D, space, work, count)
        pointers = _ns_per_call(_calls_by_pointers, by_pointers, tape, D, space, work, count)
        same = _same_results(by_value, by_pointers, tape, D, space, work)
        print(f"{label:44s} {value:7.1f} {pointers:7.1f}  {same}")


if __name__ == "__main__":
    main()
