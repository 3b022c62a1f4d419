"""What one call of the tape interpreter at its address costs in compiled code, and how much of it
is the call itself (docs/engine.md "The interpreter through its address").

Run: python benchmarks/interpreter_call.py [--calls N]

In one process, each in a compiled loop of N calls (the minimum over 5 loops, ns per call), two
ways of calling a function compiled for `pointer_signature()` (the addresses of a plain tape, a
jet space and work arrays, and the degree):

- `run_at`, which copies the three groups to the stack at every call and passes their addresses;
- `run_from` with the addresses of copies taken once, before the loop (`address_of`): what the
  step loops do.

The functions: one whose body stores one integer (the cost of the call alone), and the rigid
body's interpreter on its H tape (8 rows) at degrees 0 and 2 (3 variables) and on a tape of one
row at degree 0. Each pair of calls is checked to leave the same work arrays.
"""

from __future__ import annotations

import argparse
import time

import numba as nb
import numpy as np

from rkhp.systems import get_system
from rkhp.taylor.compiler import NJIT_NORC
from rkhp.taylor.interpreter import (
    address_of,
    as_plain,
    interpreter,
    pointer_signature,
    run_at,
    run_from,
    tape_work,
)
from rkhp.taylor.jets import jet_space
from rkhp.taylor.tape import record_tape


@nb.njit(**NJIT_NORC)
def _store_only(tape_at, D, space_at, work_at):
    work_at[0].deg[0] = D + tape_at[0].n_inputs + space_at[0].degree


@nb.njit(**NJIT_NORC)
def _calls_copying(run, tape, D, space, work, count):
    for _ in range(count):
        run_at(run, tape, D, space, work)


@nb.njit(**NJIT_NORC)
def _calls_kept(run, tape, D, space, work, count):
    tape_at, space_at, work_at = address_of(tape), address_of(space), address_of(work)
    for _ in range(count):
        run_from(run, tape_at, D, space_at, work_at)


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


def _same_results(run, tape, D, space, work) -> bool:
    """Whether one call each way leaves the same work arrays (from the same inputs)."""
    first = tuple(array.copy() for array in work)
    _calls_copying(run, tape, D, space, work, 1)
    copying = tuple(array.copy() for array in work)
    for array, saved in zip(work, first, strict=True):
        array[...] = saved
    _calls_kept(run, tape, D, space, work, 1)
    return all(np.array_equal(a, b) for a, b in zip(copying, work, strict=True))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=1_000_000, help="calls per loop (1000000)")
    count = parser.parse_args().calls
    h_tape = get_system("rigid-body").h_tape
    one_row = record_tape(1, lambda x, p: [x[0]])
    space = jet_space(3, 2)
    work = tape_work((h_tape, one_row), space.size)
    work.W[:6, 0] = 0.5
    for k in range(3):
        work.W[k, 1 + k] = 1.0
    store = _address(_store_only, pointer_signature())
    rows = [("a body that stores one integer", store, as_plain(h_tape), 0),
            ("run_tape, H of the rigid body, degree 0", interpreter(h_tape).address, as_plain(h_tape), 0),
            ("run_tape, H of the rigid body, degree 2", interpreter(h_tape).address, as_plain(h_tape), 2),
            ("run_tape, a tape of one row, degree 0", interpreter(one_row).address, as_plain(one_row), 0)]
    print(f"ns per call (minimum of 5 loops of {count} calls): run_at (copies at every call), "
          "run_from (addresses kept for the loop); the same results")
    for label, address, tape, D in rows:
        copying = _ns_per_call(_calls_copying, address, tape, D, space, work, count)
        kept = _ns_per_call(_calls_kept, address, tape, D, space, work, count)
        same = _same_results(address, tape, D, space, work)
        print(f"{label:44s} {copying:7.1f} {kept:7.1f}  {same}")


if __name__ == "__main__":
    main()
