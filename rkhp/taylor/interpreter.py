"""The compiled tape interpreter: a tape evaluated in truncated Taylor arithmetic
(docs/theory.md §7; docs/engine.md).

`interpret(tape, D, space, work)` evaluates the main program of a `rkhp.taylor.tape.Tape` on the
work arrays `work` (:class:`TapeWork`: slot jets W, scratch S, degree bounds deg) at truncation
degree D <= space.degree, the inputs W[0:n_inputs] being set by the caller. Runs of elementary
rows go to `rkhp.taylor.rows.rows` (inlined); each composite row to its kernel
(`rkhp.taylor.composites`) through :func:`_composite`, the one dispatch of composite codes.
Sub-programs (rows before `tape.main`) run only when a composite kernel runs them. Degree 0 is
the value-only path (W[:, 0]), the same code with one coefficient per slot.

`run_tape`, compiled once per class of tapes, runs it on the tape, space and work arrays at
three addresses. Compiled code calls it at its address (:class:`Interpreter`), so that a compiled
unit does not link the interpreter's code in and optimise it once more, with the addresses of
copies that a loop takes once (:func:`address_of`, :func:`run_from`), so that a call passes
three addresses rather than every member of the three groups (docs/engine.md "The interpreter
through its address").

Python calls the interpreter of a tape's class too (``interpreter(tape)(tape, D, space, work)``),
so that one compiled interpreter per class serves every caller. `evaluate` is the Python-level
helper (values, or values and the Jacobian by forward mode).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from .compiler import NJIT_NORC, overload
from .compiler import numba as nb
from .composites import phimv, spray
from .jets import jet_space
from .ops import FIRST_COMPOSITE, PHIMV, SPRAY
from .rows import rows
from .tape import Tape, record_tape


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


@nb.njit(inline="always", **NJIT_NORC)
def interpret(tape, D, space, work):
    """Evaluate the main program of `tape` at degree D (see the module); allocates nothing.
    Inlined into `run_tape`, the interpreter of each class."""
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


@nb.njit(**NJIT_NORC)
def run_tape(tape_at, D, space_at, work_at):
    """The interpreter of a class of tapes: `interpret` of the tape, the jet space and the work
    arrays at these addresses (numba `CPointer`s, :func:`pointer_signature`), so that a call
    passes three addresses, not every member of the three groups (:func:`run_from`)."""
    interpret(tape_at[0], D, space_at[0], work_at[0])


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


@functools.cache
def plain_signature():
    """The signature every compiled interpreter is called with, ``none(tape, int64, space,
    work)``: numba's types of a plain `Tape`, a `JetSpace` and :class:`TapeWork` arrays (those of
    every tape, space and work arrays the library makes)."""
    tape = record_tape(1, lambda x, p: [x[0]])
    typeof = nb.typeof
    return nb.types.none(typeof(tape), nb.types.int64, typeof(jet_space(0, 0)), typeof(tape_work((tape,), 1)))


@functools.cache
def pointer_signature(tape_type=None):
    """The signature every class's `run_tape` is compiled for, ``none(tape*, int64, space*,
    work*)``: the addresses of a tape of numba type `tape_type` (default: the plain tape's), a
    `JetSpace` and :class:`TapeWork` arrays of :func:`plain_signature`. Every class's is the same
    in machine terms (three addresses and an integer)."""
    tape, _, space, work = plain_signature().args
    pointer = nb.types.CPointer
    return nb.types.none(pointer(tape if tape_type is None else tape_type), nb.types.int64,
                         pointer(space), pointer(work))


def _plain_member(value, what: str) -> None:
    """TypingError unless `value` (a numba type) is the plain signature's tape, space or work."""
    plain = plain_signature()
    if value not in (plain.args[0], plain.args[2], plain.args[3]):
        raise TypingError(f"{what} takes a plain tape, a jet space or work arrays, not {value}")


def _copy_address(context, builder, value, to):
    """A copy of `value` on the stack of the function being compiled (its entry block), as a
    pointer of numba type `to`."""
    return builder.bitcast(cgutils.alloca_once_value(builder, value), context.get_value_type(to))


@intrinsic
def address_of(typingctx, value):
    """The address of a copy of `value` (a plain tape, a jet space or work arrays) that lives as
    long as the compiled function it is taken in (its stack, the entry block), for
    :func:`run_from`. Taken once in a loop's function, the copy serves every call of the run."""
    _plain_member(value, "address_of")
    to = nb.types.CPointer(value)

    def address_codegen(context, builder, sig, args):
        return _copy_address(context, builder, args[0], to)

    return to(value), address_codegen


def _call(context, builder, address, pointers, degree):
    """The call of the interpreter at `address` with the three addresses and the degree."""
    signature = pointer_signature()
    call_conv = context.call_conv
    callee = builder.inttoptr(address, call_conv.get_function_type(
        signature.return_type, signature.args).as_pointer())
    tape, space, work = pointers
    status, _ = call_conv.call_function(builder, callee, signature.return_type, signature.args,
                                        [tape, degree, space, work])
    with cgutils.if_unlikely(builder, status.is_error):
        call_conv.return_status_propagate(builder, status)
    return context.get_dummy_value()


def _check_integers(name, address, D):
    if not isinstance(address, nb.types.Integer) or not isinstance(D, nb.types.Integer):
        raise TypingError(f"{name} takes integers for the address and D, not {address} and {D}")


@intrinsic
def run_from(typingctx, address, tape_at, D, space_at, work_at):
    """``run_tape`` at `address` (:attr:`Interpreter.address`) on the tape, space and work arrays
    at these addresses (:func:`address_of`): a call of its function in numba's own calling
    convention with three addresses and the degree (a typing error for other arguments)."""
    _check_integers("run_from", address, D)
    signature = pointer_signature()
    if (tape_at, space_at, work_at) != (signature.args[0], signature.args[2], signature.args[3]):
        raise TypingError(f"run_from takes the addresses of a plain tape, a jet space and work arrays, "
                          f"not {tape_at}, {space_at}, {work_at}")

    def run_from_codegen(context, builder, sig, args):
        degree = context.cast(builder, args[2], D, nb.types.int64)
        return _call(context, builder, args[0], (args[1], args[3], args[4]), degree)

    return nb.types.none(address, tape_at, D, space_at, work_at), run_from_codegen


@intrinsic
def run_at(typingctx, address, tape, D, space, work):
    """``run_tape`` at `address` (:attr:`Interpreter.address`) on `tape`, `space` and `work`
    themselves, of :func:`plain_signature` (a typing error otherwise): their copies are made at
    every call, which costs more than the call (docs/engine.md "The interpreter through its
    address"), so a loop takes their addresses once (:func:`address_of`, :func:`run_from`)."""
    _check_integers("run_at", address, D)
    if (tape, space, work) != tuple(plain_signature().args[i] for i in (0, 2, 3)):
        raise TypingError(f"run_at takes a plain tape, a jet space and work arrays, not {tape}, {space}, {work}")
    targets = pointer_signature().args

    def run_at_codegen(context, builder, sig, args):
        pointers = [_copy_address(context, builder, args[i], targets[j]) for i, j in ((1, 0), (3, 2), (4, 3))]
        degree = context.cast(builder, args[2], D, nb.types.int64)
        return _call(context, builder, args[0], pointers, degree)

    return nb.types.none(address, tape, D, space, work), run_at_codegen


@nb.njit(**NJIT_NORC)
def _call_at(address, tape, D, space, work):
    """`run_at` for a call from Python (:meth:`Interpreter.__call__`), compiled once for every class."""
    run_at(address, tape, D, space, work)


class Interpreter:
    """`run_tape` compiled for one class of tapes, called in compiled code at its address
    (:attr:`address`, an integer argument; :func:`run_from`) with the addresses of plain tapes
    (:func:`as_plain`), a jet space and work arrays (:func:`address_of`).

    A compiled caller calls it at its address instead of linking its code in: numba optimises
    and generates the code of each compiled unit with the units it calls linked in, so every unit
    that called the interpreter compiled it again, seconds per unit with the spray kernel. And
    since the caller sees plain tapes and an integer whatever the class, its code does not
    depend on the class: the step loops are compiled once for every class (docs/engine.md "The
    interpreter through its address"). The class only chooses which compiled interpreter the
    address is; every class is compiled for the addresses of arguments with the plain signature's
    machine layout (:func:`pointer_signature`, checked when the interpreter is made). The call is the one numba
    makes to a function it links, so an error status would reach the caller as from a linked
    function (the interpreter raises nothing). Made by :func:`interpreter`."""

    def __init__(self, compiled):
        self._compiled = compiled
        self._address = 0

    def load(self) -> int:
        """Compile the interpreter for this class, or load it from numba's cache, once in a
        process; returns its address, which every caller of the class uses."""
        if not self._address:
            compiled = run_tape.get_compile_result(self._compiled)
            self._address = compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name)
            if not self._address:
                raise RuntimeError(f"numba gave no address for the interpreter {self._compiled}")
        return self._address

    @property
    def address(self) -> int:
        """The address of the compiled interpreter (:meth:`load`), for :func:`run_from`."""
        return self.load()

    def __call__(self, tape, D, space, work) -> None:
        """The interpreter on `tape` (of this class), `space` and `work` from Python (:func:`run_at`)."""
        _call_at(self.address, as_plain(tape), np.int64(D), space, work)


def as_plain(tape) -> Tape:
    """The same tape as a plain `Tape`, its class erased from the type compiled code sees (the
    class chooses the :class:`Interpreter`)."""
    return Tape(*tape)


def _interpreter(tape_type) -> Interpreter:
    """The interpreter for tapes of numba type `tape_type`, whose members must be the plain
    tape's (so that its machine layout is the plain tape's), with the plain signature's jet space
    and work arrays (:func:`plain_signature`)."""
    plain = plain_signature()
    if tuple(getattr(tape_type, "types", ())) != tuple(plain.args[0].types):
        raise TypeError(f"{tape_type} is not laid out as {plain.args[0]}: no interpreter at an address")
    return Interpreter(pointer_signature(tape_type))


_INTERPRETERS: dict[type, Interpreter] = {}


def interpreter(tape) -> Interpreter:
    """The :class:`Interpreter` of `tape`'s class, one per class in a process; compiled, or
    loaded from numba's cache, when its address is first asked for."""
    cls = type(tape)
    if cls not in _INTERPRETERS:
        _INTERPRETERS[cls] = _interpreter(nb.typeof(tape))
    return _INTERPRETERS[cls]


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
    interpreter(tape)(tape, degree, space, work)
    out = work.W[tape.outputs]
    if degree == 0:
        return out[:, 0].copy()
    return out[:, 0].copy(), out[:, 1: 1 + nv].copy()
