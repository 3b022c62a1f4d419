"""The compiled tape interpreter: a tape evaluated in truncated Taylor arithmetic
(docs/theory.md §7; docs/engine.md).

`run_tape(tape, D, space, work)` evaluates the main program of a `rkhp.taylor.tape.Tape` on the
work arrays `work` (:class:`TapeWork`: slot jets W, scratch S, degree bounds deg) at truncation
degree D <= space.degree, the inputs W[0:n_inputs] being set by the caller. Runs of elementary
rows go to `rkhp.taylor.rows.rows` (inlined); each composite row to its kernel
(`rkhp.taylor.composites`) through :func:`_composite`, the one dispatch of composite codes.
Sub-programs (rows before `tape.main`) run only when a composite kernel runs them. Degree 0 is
the value-only path (W[:, 0]), the same code with one coefficient per slot.

`evaluate` is the Python-level helper (values, or values and the Jacobian by forward mode).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .compiler import NJIT_NORC, overload
from .compiler import numba as nb
from .composites import phimv, spray
from .jets import jet_space
from .ops import FIRST_COMPOSITE, PHIMV, SPRAY
from .rows import rows


class TapeWork(NamedTuple):
    """The interpreter's work arrays: W (slots x jet size), S (scratch rows x jet size; the
    layout is `rkhp.taylor.ops`'), deg (slots,) int64."""

    W: np.ndarray
    S: np.ndarray
    deg: np.ndarray


def tape_work(tapes, size: int) -> TapeWork:
    """Work arrays for evaluating any of `tapes` with jets of `size` coefficients."""
    n_slots = max(t.n_slots for t in tapes)
    return TapeWork(np.zeros((n_slots, size)), np.zeros((max(t.scratch_rows for t in tapes), size)),
                    np.zeros(n_slots, dtype=np.int64))


@nb.njit(**NJIT_NORC)
def run_tape(tape, D, space, work):
    """Evaluate the main program of `tape` at degree D (see the module); allocates nothing."""
    W, S, deg = work.W, work.S, work.deg
    counts = space.counts
    for slot in range(tape.n_inputs):
        d = D
        while d > 0:
            nonzero = False
            for m in range(counts[d - 1], counts[d]):
                if W[slot, m] != 0.0:
                    nonzero = True
                    break
            if nonzero:
                break
            d -= 1
        deg[slot] = d
    ops = tape.ops
    n = ops.shape[0]
    r = tape.main
    while r < n:
        if ops[r, 0] >= FIRST_COMPOSITE:
            _composite(tape, r, W, D, space, S, deg)
            r += 1
        else:
            hi = r + 1
            while hi < n and ops[hi, 0] < FIRST_COMPOSITE:
                hi += 1
            rows(tape, r, hi, W, D, space, S, deg)
            r = hi


#: the kernel of each composite code (`rkhp.taylor.composites`)
COMPOSITE_KERNELS = {PHIMV: phimv, SPRAY: spray}


def _composite(tape, r, W, D, space, S, deg):
    """Run the composite row r of `tape` by its kernel (compiled code only: see below)."""
    raise NotImplementedError("compiled code only")


def _dispatch(codes):
    """The one dispatch of composite codes to their kernels (`COMPOSITE_KERNELS`), for a tape
    class whose composite codes are `codes`: nothing for none (a system without composite
    operations never compiles them), the kernel itself for one, else a test of the row's code
    against the first code and the dispatch of the others (inlined) when it differs."""
    if not codes:
        def no_kernel(tape, r, W, D, space, S, deg):
            pass

        return no_kernel
    kernel = COMPOSITE_KERNELS[codes[0]]
    if len(codes) == 1:
        def one_kernel(tape, r, W, D, space, S, deg):
            kernel(tape, r, W, D, space, S, deg)

        return one_kernel
    code = codes[0]
    others = nb.njit(inline="always", _nrt=False, error_model="numpy")(_dispatch(codes[1:]))

    def first_or_others(tape, r, W, D, space, S, deg):
        if tape.ops[r, 0] == code:
            kernel(tape, r, W, D, space, S, deg)
        else:
            others(tape, r, W, D, space, S, deg)

    return first_or_others


@overload(_composite, inline="always", jit_options=dict(_nrt=False, error_model="numpy"))
def _composite_kernels(tape, r, W, D, space, S, deg):
    """`_composite` compiled for the tape's class with the kernels of its composite codes only
    (`rkhp.taylor.tape.Tape`, `_dispatch`), inlined into the interpreter: a compiled unit of its
    own would optimise its kernels once more (docs/engine.md "Compile time")."""
    return _dispatch(tape.instance_class.composites)


def evaluate(tape, inputs: np.ndarray, degree: int = 0, n_vars: int = 0):
    """Evaluate a tape (Python-level helper).

    With degree 0 returns the output values for the given input values. With degree 1 and
    n_vars = len(inputs) returns (values, Jacobian (outputs x inputs)) by forward mode.
    """
    inputs = np.asarray(inputs, dtype=np.float64)
    nv = n_vars if degree > 0 else 0
    space = jet_space(nv, degree)
    work = tape_work((tape,), space.size)
    work.W[: len(inputs), 0] = inputs
    if degree > 0:
        for i in range(len(inputs)):
            work.W[i, 1 + i] = 1.0
    run_tape(tape, np.int64(degree), space, work)
    out = work.W[tape.outputs]
    if degree == 0:
        return out[:, 0].copy()
    return out[:, 0].copy(), out[:, 1: 1 + nv].copy()
