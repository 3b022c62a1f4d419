"""Compiling ahead: numba's cache filled with the entry kernels of every class of tapes that the
built-in systems use, so that no run waits for a compile its user did not ask for (`rkhp
compile`, run by `make install`; docs/engine.md "Compile time").

numba compiles the tape interpreter once per class of tapes (`rkhp.taylor.tape.tape_class`: the
composite operations it must know), and the entry kernels of `rkhp.integrators.kernels` once for
every class (they take plain tapes and call the class's interpreter through its address:
`rkhp.taylor.interpreter.Interpreter`), except the direct forms of some families' methods. So
one system per class stands for its whole family: one step of each kind of method and the
compiled Hamiltonian of the studies compile every kernel a run of that family needs.

Each of those runs on one system is a part (`AHEAD_PARTS`); the parts run in ``jobs`` processes
side by side when numba's cache saves are locked (`rkhp.taylor.numba_patches.parallel_compiles_safe`),
else one after the other in this process, in two phases (`ahead_phases`): the parts that compile
(every class's Hamiltonian and direct forms, the first class's other parts: the shared kernels),
then the other classes' other parts, which load them (two processes compiling one kernel side by
side would each compile it).
"""

from __future__ import annotations

import time
from typing import NamedTuple

from ..base.executors import InProcess, LocalProcesses, available_cores, run_all
from ..trees.rooted import trees_up_to
from .kernels import KERNELS, cold_start
from .methods import resolve_method

#: the parts of a class's compile: the Hamiltonian (it compiles the class's tape interpreter), the
#: loop of a modified Hamiltonian over states (`rkhp.integrators.tree_jets.tree_values`), one
#: step of each kind of method (explicit and implicit RKHP being two specialisations of the
#: driver's loop over the tower's substeps; tj4, a composition of Euler steps: the loop over the
#: direct Euler form where the family has one, `rkhp.integrators.substeps`).
#: After the Hamiltonian (every other part calls the interpreter), the costliest cold compile first
#: (each part's CPU seconds: `benchmarks/compile_parts.py`, docs/engine.md "Compile time"): the
#: processes take the parts in this order, so that the long ones start early and the processes
#: finish together.
HAMILTONIAN = "hamiltonian"
MODIFIED = "modified"
AHEAD_PARTS = (HAMILTONIAN, "gauss2", "tj4", "rk4", "implicit-midpoint", "classical:rk4", "thp2", MODIFIED)
#: the parts that compile kernels of a class's or family's own (tj4: the driver's loop over the
#: direct Euler forms of the spray realisation and of closed-form families); the others' kernels
#: are shared by every class
FAMILY_PARTS = ("tj4",)


class Compiled(NamedTuple):
    """One class of tapes made ready: the built-in systems that use it, the entry kernels that
    were missing from the cache (empty: nothing to do), and the wall and CPU seconds its parts
    took, summed over the processes that ran them."""

    tape_class: str
    systems: tuple[str, ...]
    compiled: tuple[str, ...]
    seconds: float
    cpu_seconds: float


class PartTime(NamedTuple):
    """The wall and CPU seconds one part took in the process that ran it."""

    seconds: float
    cpu_seconds: float


class AheadRun(NamedTuple):
    """A whole compile: each class (`Compiled`), the processes that ran the parts and its wall
    seconds (with ``jobs`` above 1, less than the sum of the classes' seconds)."""

    classes: tuple[Compiled, ...]
    jobs: int
    seconds: float


def tape_classes() -> dict[type, tuple[str, ...]]:
    """Each class of tapes of the built-in systems (symmetric realisation), with its systems."""
    from ..systems import builtin_systems, get_system

    out: dict[type, list[str]] = {}
    for name in builtin_systems():
        out.setdefault(type(get_system(name).h_tape), []).append(name)
    return {cls: tuple(names) for cls, names in out.items()}


def prepare_part(system, part: str) -> None:
    """Run the entry kernels of one of `AHEAD_PARTS` once on ``system`` (one step)."""
    import numpy as np

    h = system.t_final / 1000
    if part == HAMILTONIAN:
        from .energy import hamiltonian_values

        hamiltonian_values(system, np.array([system.x0]))
    elif part == MODIFIED:
        from .tree_jets import tree_jets, tree_values

        jets = tree_jets(system, trees_up_to(2), 2, 0)
        tree_values(jets, np.zeros(1, np.int64), np.ones(1), np.array([system.x0], dtype=np.float64), np.zeros(1))
    else:
        resolve_method(part).integrate(system, h, 1)


def timed_part(system_name: str, part: str) -> PartTime:
    """`prepare_part` on a built-in system, timed (a task of a pool: arguments by name)."""
    from ..systems import get_system

    start, cpu = time.perf_counter(), time.process_time()
    prepare_part(get_system(system_name), part)
    return PartTime(time.perf_counter() - start, time.process_time() - cpu)


class AheadTask(NamedTuple):
    """One part on the built-in system standing for its class (the arguments of `timed_part`)."""

    system: str
    part: str


def _compiles(first: str, part: str, firsts: list[str], family_firsts: set[str]) -> bool:
    """Whether `part` on `first` (a class's system) compiles kernels no part before it in the
    first phase compiles: a family part on the first class of its direct form, a shared part on
    the first class."""
    if part in FAMILY_PARTS:
        return first in family_firsts
    return first == firsts[0]


def ahead_phases(classes: dict[type, tuple[str, ...]]) -> tuple[list[AheadTask], list[AheadTask]]:
    """The tasks of every class in two phases. First what compiles: each class's Hamiltonian (its
    tape interpreter), then in the order of `AHEAD_PARTS` the first class's other parts (the
    kernels shared by all classes) and the `FAMILY_PARTS` of the first class of each direct Euler
    form (`rkhp.integrators.substeps.choose` for RKHP Euler: the classes of one form share its
    kernel); then
    the other parts, which load those kernels (that every kind of run finds them for every
    class)."""
    from ..systems import get_system
    from ..tableaux.files import load_tableau
    from .substeps import TOWER, choose

    euler = load_tableau("euler")
    firsts = [names[0] for names in classes.values()]
    forms: dict = {}
    for first in firsts:
        forms.setdefault(choose(get_system(first), euler).provider, first)
    family_firsts = {first for form, first in forms.items() if form is not TOWER}
    compiling = [AheadTask(first, HAMILTONIAN) for first in firsts]
    loading = []
    for part in AHEAD_PARTS[1:]:
        for first in firsts:
            task = AheadTask(first, part)
            (compiling if _compiles(first, part, firsts, family_firsts) else loading).append(task)
    return compiling, loading


def _class_times(system: str, tasks: list[AheadTask], times: list[PartTime]) -> PartTime:
    """The seconds of the parts run on ``system``, summed."""
    spent = [t for task, t in zip(tasks, times) if task.system == system]
    return PartTime(sum(t.seconds for t in spent), sum(t.cpu_seconds for t in spent))


def _progress(on_part, before: int, total: int):
    """`on_part` told of a phase's parts as parts of the whole run (None: no progress)."""
    if on_part is None:
        return None
    return lambda done, _: on_part(before + done, total)


def compile_ahead(jobs: int | None = None, on_part=None) -> AheadRun:
    """Fill numba's cache for every class of `tape_classes`, the parts in ``jobs`` processes
    (default: one per core this process may use), phase after phase (`ahead_phases`).

    One process (this one) when numba's cache saves are not locked (processes compiling side by
    side would overwrite each other's index entries) or when no entry kernel is cold (the parts
    then only load, and a cold specialisation is rare). ``on_part(done, total)`` is called after
    each part (progress). Each class runs also when nothing is cold: a specialisation may be
    missing."""
    from ..taylor.numba_patches import parallel_compiles_safe

    classes = tape_classes()
    cold = {cls: cold_start(tuple(KERNELS), cls) for cls in classes}
    phases = ahead_phases(classes)
    tasks = [task for phase in phases for task in phase]
    jobs = jobs or available_cores()
    if not parallel_compiles_safe() or not any(cold.values()):
        jobs = 1  # nothing cold: loading the cache once costs less than in each process
    jobs = max(1, min(jobs, len(tasks)))
    start = time.perf_counter()
    executor = LocalProcesses(jobs) if jobs > 1 else InProcess()
    times: list[PartTime] = []
    try:
        for phase in phases:
            times += run_all(executor, timed_part, phase, _progress(on_part, len(times), len(tasks)))
    except BaseException:
        if jobs > 1:
            executor.terminate()  # a part cut short saved nothing (numba saves whole files)
        raise
    finally:
        executor.close()
    done = tuple(Compiled(cls.__name__, names, cold[cls].kernels, *_class_times(names[0], tasks, times))
                 for cls, names in classes.items())
    return AheadRun(done, jobs, time.perf_counter() - start)


__all__ = ["AHEAD_PARTS", "FAMILY_PARTS", "MODIFIED", "Compiled", "PartTime", "AheadRun", "AheadTask",
           "tape_classes", "prepare_part", "timed_part", "ahead_phases", "compile_ahead"]
