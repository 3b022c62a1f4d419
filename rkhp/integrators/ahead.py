"""Compiling ahead: numba's cache filled with the entry kernels of every class of tapes that the
built-in systems use, so that no run waits for a compile its user did not ask for (`rkhp
compile`, run by `make install`; docs/engine.md "Compile time").

numba compiles a kernel once per class of tapes (`rkhp.taylor.tape.tape_class`: the composite
operations the interpreter must know), so one system per class stands for its whole family: one
step of each kind of method (`AHEAD_METHODS`), the compiled Hamiltonian of the studies and the
vector field of the scipy peers compile every entry kernel of `rkhp.integrators.kernels`.
"""

from __future__ import annotations

import time
from typing import NamedTuple

from .kernels import KERNELS, cold_start
from .methods import resolve_method

#: one method of each kind, explicit and implicit RKHP being two specialisations of the step loop;
#: tj4, a composition of Euler steps: the composed loop, or on the spray realisation its direct form
AHEAD_METHODS = ("rk4", "gauss2", "thp2", "classical:rk4", "implicit-midpoint", "tj4")


class Compiled(NamedTuple):
    """One class of tapes made ready: the built-in systems that use it, the entry kernels that
    were missing from the cache (empty: nothing to do), and the wall and CPU seconds it took."""

    tape_class: str
    systems: tuple[str, ...]
    compiled: tuple[str, ...]
    seconds: float
    cpu_seconds: float


def tape_classes() -> dict[type, tuple[str, ...]]:
    """Each class of tapes of the built-in systems (symmetric realisation), with its systems."""
    from ..systems import builtin_systems, get_system

    out: dict[type, list[str]] = {}
    for name in builtin_systems():
        out.setdefault(type(get_system(name).h_tape), []).append(name)
    return {cls: tuple(names) for cls, names in out.items()}


def prepare(system) -> None:
    """Run every entry kernel once on ``system`` (one step of each of `AHEAD_METHODS`)."""
    import numpy as np

    from ..tableaux.compositions import load_composition
    from .classical import vector_field
    from .composed import integrate_composition
    from .energy import hamiltonian_values

    h = system.t_final / 1000
    for name in AHEAD_METHODS:
        resolve_method(name).integrate(system, h, 1)
    integrate_composition(system, load_composition("tj4"), h, 1)  # on the spray too (tj4 runs direct there)
    hamiltonian_values(system, np.array([system.x0]))
    vector_field(system)(system.x0)


def compile_ahead(on_class=None) -> list[Compiled]:
    """Fill numba's cache for every class of `tape_classes`, one after the other (numba's cache
    index of a kernel is one file: processes compiling side by side would overwrite each other's
    entries). ``on_class(Compiled)`` is called after each class (progress)."""
    from ..systems import get_system

    done = []
    for cls, names in tape_classes().items():
        cold = cold_start(tuple(KERNELS), cls)
        start, cpu = time.perf_counter(), time.process_time()
        prepare(get_system(names[0]))  # also when nothing is cold: a specialisation may be missing
        item = Compiled(cls.__name__, names, cold.kernels, time.perf_counter() - start, time.process_time() - cpu)
        done.append(item)
        if on_class is not None:
            on_class(item)
    return done


__all__ = ["AHEAD_METHODS", "Compiled", "tape_classes", "prepare", "compile_ahead"]
