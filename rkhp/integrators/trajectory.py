"""The result of an integration: states, Newton counts, and a status that names any failure.

A failed run keeps only the states computed before the failure (never numbers past it), and says
at which step and time it failed and why (paper §5.2: the implicit equation alpha(x, psi(x)) = y
may have no solution for a large step): `cause` (a `rkhp.integrators.failure.Failure`) for
programs, `status` for people.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..base.errors import InputError, NumericalFailure
from ..base.provenance import provenance, write_output
from ..base.tables import csv_text
from .failure import Failure, failure_status

GROWTH = 100.0
"""A state counts as grown when its max-norm exceeds this times max(1, |y_0|) (`divergence`)."""
DIVERGENCE = 1e8
"""A grown state whose energy error exceeds this times max(1, |H(y_0)|) ends the run (`divergence`)."""

#: the file formats of a trajectory, by the file's suffix (docs/results.md)
FILE_SUFFIXES = (".csv", ".npz")
#: from this many states on, H is evaluated by the compiled loop (as rkhp.studies.invariants)
COMPILED_ENERGY_FROM = 20_000


@dataclass
class Trajectory:
    """States y_0..y_k at times t_0..t_k of one run: a plain record, built by every call of the
    integrators (not frozen: a frozen dataclass's constructor sets each field through
    object.__setattr__, a cost every call would pay; benchmarks/call_cost.py).

    Attributes:
        times: shape (k+1,).
        states: shape (k+1, n); for a failed run, only the steps before the failure.
        newton_iterations: shape (k,), Newton iterations per step (zeros for explicit peers).
        stage_sweeps: shape (k,), fixed-point sweeps per step: of the implicit stages (RKHP with
            an implicit tableau) and of the direct forms' Euler substeps (their unknowns swept
            before any chord iteration); zeros otherwise, empty for the other integrators.
        status: "ok", or a failure message naming the step, the time and the cause.
        failed_step: the 0-based index of the step that failed (step k goes from y_k to y_{k+1};
            it equals the number of completed steps, and states has failed_step + 1 rows), or
            None.
        cause: Failure.OK, or why the run failed (`rkhp.integrators.failure`).
        compile_seconds: time spent compiling (first call of a compiled kernel), apart from run time.
        run_seconds: wall time of the integration itself.
        method: name of the method; system: name of the system.
        extra: free-form details (e.g. Newton tolerance used).
        poisson: the PoissonSystem integrated (for the energy and Casimir columns), or None.
    """

    times: np.ndarray
    states: np.ndarray
    newton_iterations: np.ndarray
    stage_sweeps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    status: str = "ok"
    failed_step: int | None = None
    cause: Failure = Failure.OK
    compile_seconds: float = 0.0
    run_seconds: float = 0.0
    method: str = ""
    system: str = ""
    extra: dict = field(default_factory=dict)
    poisson: object = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        return self.cause == Failure.OK

    @property
    def final_state(self) -> np.ndarray:
        return self.states[-1]

    def raise_if_failed(self) -> Trajectory:
        """Return self when the run succeeded, else raise NumericalFailure with the status."""
        if not self.ok:
            raise NumericalFailure(self.status)
        return self

    def row_counts(self) -> tuple[np.ndarray, np.ndarray]:
        """Newton iterations and stage sweeps per state: 0 for y_0, then those of the step that
        reached y_k (zeros where the integrator does not count them)."""
        rows = len(self.states)
        out = []
        for counts in (self.newton_iterations, self.stage_sweeps):
            column = np.zeros(rows, dtype=np.int64)
            kept = np.asarray(counts, dtype=np.int64)[: rows - 1]
            column[1: 1 + len(kept)] = kept
            out.append(column)
        return out[0], out[1]

    def columns(self, every: int = 1, system=None) -> dict[str, np.ndarray]:
        """The columns of the trajectory's file (docs/results.md), as arrays: ``t``, ``x1..xn``,
        ``energy`` (H), ``casimir1..`` (the system's Casimirs), ``newton_iterations`` and
        ``stage_sweeps`` (those of the step that reached the row; 0 in the first row); every
        ``every``-th state from y_0, and always the last one. ``system``: the PoissonSystem
        (default: the one integrated)."""
        newton, sweeps = self.row_counts()
        rows = kept_rows(len(self.states), every)
        return state_columns(self._system(system), self.times[rows], self.states[rows], newton[rows],
                             sweeps[rows])

    def write(self, path, every: int = 1, record: dict | None = None, system=None, force: bool = False) -> Path:
        """Write :meth:`columns` to ``path``, CSV or NPZ by its suffix, with the provenance
        ``record`` (default: this process's, rkhp.base.provenance); an existing file only with
        ``force``. Returns the path."""
        return write_columns(path, self.columns(every, system), record, force)

    def _system(self, system):
        system = self.poisson if system is None else system
        if system is None:
            raise InputError("this trajectory does not hold its system: pass system=")
        return system


def kept_rows(count: int, every: int) -> np.ndarray:
    """Indices 0, K, 2K, ... of ``count`` rows, and the last one (K = ``every``)."""
    if isinstance(every, bool) or int(every) != every or every < 1:
        raise InputError(f"every must be a positive integer, got {every!r}")
    rows = np.arange(0, count, int(every))
    if count and rows[-1] != count - 1:
        rows = np.append(rows, count - 1)
    return rows


def energies(system, states) -> np.ndarray:
    """H at every row of ``states`` (the compiled loop for long runs)."""
    if len(states) >= COMPILED_ENERGY_FROM:
        from .energy import hamiltonian_values

        return hamiltonian_values(system, states)
    return np.fromiter((system.hamiltonian(x) for x in states), dtype=float, count=len(states))


def state_columns(system, times, states, newton, sweeps) -> dict[str, np.ndarray]:
    """The named columns of a file of states (docs/results.md): t, x1..xn, energy, casimir1..,
    newton_iterations, stage_sweeps."""
    states = np.asarray(states, dtype=np.float64).reshape(len(times), system.dim)
    columns = {"t": np.asarray(times, dtype=np.float64)}
    columns.update({f"x{i + 1}": states[:, i].copy() for i in range(system.dim)})
    columns["energy"] = energies(system, states)
    for k, C in enumerate(system.casimirs):
        columns[f"casimir{k + 1}"] = np.fromiter((C(x) for x in states), dtype=float, count=len(states))
    columns["newton_iterations"] = np.asarray(newton, dtype=np.int64)
    columns["stage_sweeps"] = np.asarray(sweeps, dtype=np.int64)
    return columns


def write_columns(path, columns: dict[str, np.ndarray], record: dict | None = None, force: bool = False) -> Path:
    """Write named columns as CSV (a provenance line, a header, one row per state; floats by repr,
    read back bit for bit) or NPZ (one array per column and ``provenance``, the record as a JSON
    string; np.load needs no pickle), chosen by the suffix of ``path``."""
    path = Path(path)
    record = provenance() if record is None else record
    suffix = path.suffix.lower()
    if suffix == ".csv":
        rows = zip(*(column.tolist() for column in columns.values()), strict=True)
        return write_output(path, csv_text(list(columns), rows, record), "trajectory file", force)
    if suffix == ".npz":
        buffer = io.BytesIO()
        np.savez(buffer, **columns, provenance=np.array(json.dumps(record, ensure_ascii=False)))
        return write_output(path, buffer.getvalue(), "trajectory file", force)
    raise InputError(f"trajectory file {path}: unknown extension {suffix or '(none)'}; the name must end in "
                     f"{' or '.join(FILE_SUFFIXES)}")



def _finite_and_bounded(states: np.ndarray) -> bool:
    """Whether every state is finite and none grew (|y_k| <= GROWTH max(1, |y_0|), max-norms):
    the run `divergence` passes, found from the largest component alone."""
    if states.size == 0:
        return True
    peak = float(np.abs(states).max())
    return np.isfinite(peak) and peak <= GROWTH * max(1.0, float(np.abs(states[0]).max()))


def divergence(system, states) -> int | None:
    """The index k of the first state y_k that has left every sane range, or None.

    The rule (docs/exit-status.md "Divergence"): y_k is non-finite, or it grew (|y_k| > GROWTH
    max(1, |y_0|), max-norms) and its energy error exceeds DIVERGENCE max(1, |H(y_0)|). The exact
    flow keeps H; a run that still approximates it, however coarsely, keeps its energy error
    near the energy's own size (`rkhp stress` calls a relative error above 1 "not bounded"), far
    below 1e8 times it, while a blow-up passes that within a few steps (H grows like a power of
    |y|). Growth alone is no divergence (a hyperbolic flow grows like e^t with H conserved), and
    requiring it first keeps H's evaluation to the few grown states.
    """
    states = np.asarray(states, dtype=float)
    if _finite_and_bounded(states):
        return None
    finite = np.isfinite(states).all(axis=1)
    bad = np.flatnonzero(~finite)
    first_bad = int(bad[0]) if bad.size else None
    size = np.abs(np.where(finite[:, None], states, 0.0)).max(axis=1, initial=0.0)
    grown = np.flatnonzero(finite & (size > GROWTH * max(1.0, size[0])))
    if grown.size:
        h0 = float(system.hamiltonian(states[0]))
        bound = DIVERGENCE * max(1.0, abs(h0))
        for k in grown:
            if first_bad is not None and k > first_bad:
                break
            try:
                with np.errstate(all="ignore"):
                    energy = float(system.hamiltonian(states[k]))
            except (OverflowError, FloatingPointError, ValueError, ZeroDivisionError):
                return int(k)  # H cannot even be evaluated there
            if not abs(energy - h0) <= bound:  # also catches an energy that overflows
                return int(k)
    return first_bad


def checked(trajectory: Trajectory, system) -> Trajectory:
    """The trajectory, or when it diverged (`divergence`), the same run ended before the state
    that diverged: cause Failure.DIVERGED (or NON_FINITE for a non-finite state) at the step that
    produced it."""
    k = divergence(system, trajectory.states)
    if k is None or k == 0:
        return trajectory
    cause = Failure.NON_FINITE if not np.isfinite(trajectory.states[k]).all() else Failure.DIVERGED
    step = k - 1
    h = float(trajectory.times[1] - trajectory.times[0]) if len(trajectory.times) > 1 else 0.0
    return replace(trajectory, times=trajectory.times[:k], states=trajectory.states[:k],
                   newton_iterations=trajectory.newton_iterations[:k],
                   stage_sweeps=trajectory.stage_sweeps[:k], cause=cause, failed_step=step,
                   status=failure_status(cause, step, h, system.domain))
