"""The compiled kernels each kind of run starts, and whether they must be compiled first.

numba compiles a kernel on its first call and keeps it in its disk cache
(:mod:`rkhp.taylor.compiler`: one folder per version of the compiled sources), so the first run on
a machine, or after an upgrade, spends tens of seconds compiling before its first step.
:func:`cold_start` tells, before a run, which of the kernels it needs are not in the cache yet
and about how long compiling them takes, so that a front end can say so (the CLI prints one
line on a terminal; docs/methods.md). Nothing is compiled here.

A kernel named below is an entry point called from Python; the kernels it calls are compiled
with it (and cached with it). Kinds are those of :mod:`rkhp.integrators.methods` plus ``tape`` (the tape
interpreter, which every run uses to evaluate H), ``invariants`` (the compiled loop of H over a
trajectory used by the studies) and ``modified`` (the compiled loop of a modified Hamiltonian over
states, `rkhp.integrators.tree_jets`).
"""

from __future__ import annotations

import importlib
from typing import NamedTuple

from ..taylor.compiler import is_cached
from ..taylor.ops import BY_CODE


class Kernel(NamedTuple):
    """An entry kernel: module, function name, and its cold compile time in seconds of one core.

    ``seconds``: CPU seconds of one core (numba 0.68, one core of an AMD EPYC, a fresh process
    with an empty cache, the rigid body), kernels compiled in the order below, so each figure leaves
    out what the kernels before it had already compiled: `python benchmarks/compile.py --kernels`
    (docs/engine.md "Compile time"; one run on 2026-11-28). The figures weigh the
    compile notice; they are not limits."""

    module: str
    name: str
    seconds: float
    per_class: bool = False
    """Compiled for each class of tapes (the interpreter); the others take plain tapes and serve
    every class."""


TAPE = Kernel("rkhp.taylor.interpreter", "run_tape", 2.9, per_class=True)

COMPOSITE_SECONDS: dict[str, float] = {"spray": 17.4, "phimv": 1.1}
"""Cold compile seconds that a composite operation adds to a run whose tapes hold it (a tape class,
`rkhp.taylor.tape.Tape.composites`; numba compiles its kernel into the interpreter): the
interpreter's extra compile with that class, CPU seconds of `run_tape` compiled for that class
(nambu, heavy-top) less for the rigid body's (numba's compile events, one fresh process with an
empty cache per system, 2026-11-28); the entry kernels call the interpreter at its address
(`rkhp.taylor.interpreter.Interpreter`), so it adds nothing to theirs."""

KERNELS: dict[str, tuple[Kernel, ...]] = {
    "tape": (TAPE,),
    "invariants": (Kernel("rkhp.integrators.energy", "_hamiltonian_loop", 0.3),),
    # a modified Hamiltonian along a run (`rkhp integrate --modified`, the stress study's long
    # run): 1.8 s on a loaded machine where the tower's `drive` took 47.4 s (2026-12-06), scaled
    "modified": (Kernel("rkhp.integrators.tree_jets", "tree_values", 0.2),),
    "rkhp": (Kernel("rkhp.integrators.driver", "drive", 5.5),),
    # THP: the same loop over its own substeps (`rkhp.integrators.taylor`)
    "taylor": (Kernel("rkhp.integrators.driver", "drive", 5.5),),
    "classical": (Kernel("rkhp.integrators.classical", "_rk_loop", 1.3),),
    "implicit-midpoint": (Kernel("rkhp.integrators.classical", "_midpoint_loop", 3.0),),
    # the bench's peers compile nothing of rkhp's (scipy calls a field in plain arithmetic,
    # `rkhp.studies.peers`)
    "scipy": (),
    # compositions: the same loop over the same substeps (one step is a composition of one
    # substep); where a direct Euler form runs instead (compiled by `rkhp compile`; its tapes are
    # not of the system's class), the notice does not count it
    "composition": (Kernel("rkhp.integrators.driver", "drive", 5.5),),
}
"""Entry kernels per kind (the tape interpreter is added to every run)."""


class ColdStart(NamedTuple):
    """The kernels of a run missing from numba's cache and the estimated compile time."""

    kernels: tuple[str, ...]
    seconds: float

    def __bool__(self) -> bool:
        return bool(self.kernels)


def _dispatcher(kernel: Kernel):
    return getattr(importlib.import_module(kernel.module), kernel.name)


def cold_start(kinds, tape_class=None) -> ColdStart:
    """Which entry kernels of ``kinds`` (keys of :data:`KERNELS`; a run's methods' kinds, plus
    "invariants" for a study) numba's cache lacks, and their summed compile seconds. With
    ``tape_class`` (the class of the system's tapes, `rkhp.taylor.tape.common_class`), the
    interpreter (and a kernel `per_class`) is cold unless the cache holds it for that class, and
    a cold interpreter adds the :data:`COMPOSITE_SECONDS` of the class's composite operations;
    the other entry kernels take plain tapes whatever the class
    (`rkhp.taylor.interpreter.Interpreter`), so one compiled version serves every class."""
    from ..taylor.tape import Tape

    wanted = [TAPE]
    for kind in kinds:
        wanted += [k for k in KERNELS[kind] if k not in wanted]
    signature = None if tape_class is None else f"{tape_class.__name__}("
    plain = None if tape_class is None else f"{Tape.__name__}("
    cold = [k for k in wanted if not is_cached(_dispatcher(k), signature if k.per_class else plain)]
    seconds = sum(k.seconds for k in cold)
    if TAPE in cold and tape_class is not None:
        seconds += sum(COMPOSITE_SECONDS.get(BY_CODE[c].name, 0.0) for c in tape_class.composites)
    return ColdStart(tuple(f"{k.module}.{k.name}" for k in cold), seconds)


__all__ = ["Kernel", "KERNELS", "COMPOSITE_SECONDS", "ColdStart", "cold_start"]
