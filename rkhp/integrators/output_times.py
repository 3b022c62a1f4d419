"""States at chosen times by a step of the method itself (docs/results.md "Output at chosen times").

For a time t between the grid points t_n and t_{n+1} of a run, the state is one step of the same
method, of size t - t_n (with its sign), from y_n. An RKHP step of any size is a Poisson map
(paper §5.2: the time-h flow of a modified Hamiltonian, docs/theory.md §11), so the state stays on
the symplectic leaf of y_0 and every Casimir keeps its value to round-off; an interpolation
between y_n and y_{n+1} would leave the leaf. Its error is that of y_n, O(h^p), plus the local
error of a step of size |t - t_n| <= |h|, O(h^(p+1)): the output has the method's order p.
A time on the grid is the grid state itself: t_n = n h is the grid time as the run computed it, so
a time within a few units of round-off of it (0.3 against 3 x 0.1 = 0.30000000000000004) counts
as t_n.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..base.bounds import MAX_OUTPUT_TIMES
from ..base.errors import InputError
from .methods import resolve_method
from .trajectory import state_columns, write_columns


@dataclass(frozen=True)
class TimedStates:
    """States of a run at chosen times.

    Attributes:
        times: shape (m,), the chosen times.
        states: shape (m, n).
        grid_index: shape (m,), the index n of the grid point t_n the state was stepped from.
        substeps: shape (m,), t - t_n (0 for a time on the grid).
        newton_iterations, stage_sweeps: shape (m,), those of the step of size t - t_n (0 on the
            grid and where the integrator does not count them).
        poisson: the PoissonSystem integrated.
    """

    times: np.ndarray
    states: np.ndarray
    grid_index: np.ndarray
    substeps: np.ndarray
    newton_iterations: np.ndarray
    stage_sweeps: np.ndarray
    poisson: object = field(default=None, repr=False, compare=False)

    def columns(self) -> dict[str, np.ndarray]:
        """The columns of a trajectory file (rkhp.integrators.trajectory.state_columns)."""
        return state_columns(self.poisson, self.times, self.states, self.newton_iterations, self.stage_sweeps)

    def write(self, path, record: dict | None = None, force: bool = False) -> Path:
        """Write :meth:`columns` as CSV or NPZ by the suffix of ``path`` (as a Trajectory); an
        existing file only with ``force``."""
        return write_columns(path, self.columns(), record, force)


def check_output_times(times, start: float, end: float, what: str = "t_eval", slack: float = 0.0) -> np.ndarray:
    """The chosen times as floats if each is finite and between ``start`` and ``end`` (either
    order: a backward run has end < start; ``slack`` widens the interval) and they run strictly
    from ``start`` towards ``end``; InputError naming ``what`` otherwise."""
    try:
        values = np.asarray(times, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{what}: the times must be numbers") from None
    if values.size == 0:
        raise InputError(f"{what}: no time given")
    if values.size > MAX_OUTPUT_TIMES:
        raise InputError(f"{what}: {values.size} times; at most {MAX_OUTPUT_TIMES}")
    if not np.all(np.isfinite(values)):
        raise InputError(f"{what}: every time must be finite")
    low, high = min(start, end) - slack, max(start, end) + slack
    outside = values[(values < low) | (values > high)]
    if outside.size:
        raise InputError(f"{what}: time {outside[0]:g} lies outside the run [{low:g}, {high:g}]")
    direction = 1.0 if end >= start else -1.0
    if values.size > 1 and not np.all(np.diff(values) * direction > 0):
        raise InputError(f"{what}: the times must be distinct and in the order of the run "
                         f"({'increasing' if direction > 0 else 'decreasing'})")
    return values


def states_at(trajectory, method, times, system=None) -> TimedStates:
    """The states of ``trajectory`` (a run of ``method``, a name or a Method) at ``times``: for
    each t, one step of the method of size t - t_n from the last grid point t_n reached before t
    (module docstring). ``system``: the PoissonSystem (default: the one integrated).

    Times past the last state of a failed run are refused (InputError), as are times outside the
    run or out of order (:func:`check_output_times`). A step that fails raises NumericalFailure.
    """
    method = resolve_method(method)
    system = trajectory.poisson if system is None else system
    if system is None:
        raise InputError("this trajectory does not hold its system: pass system=")
    grid = np.asarray(trajectory.times, dtype=np.float64)
    # the last grid time N h may miss the run's end T by round-off: T counts as inside
    slack = 4 * np.finfo(float).eps * max(abs(float(grid[0])), abs(float(grid[-1])))
    values = check_output_times(times, float(grid[0]), float(grid[-1]), slack=slack)
    direction = 1.0 if grid[-1] >= grid[0] else -1.0
    # n: the last grid point not past t in the direction of the run, or the grid point t rounds to
    index = np.searchsorted(direction * grid, direction * values, side="right") - 1
    ahead = np.minimum(index + 1, grid.size - 1)
    on_next = np.abs(grid[ahead] - values) <= slack
    index = np.where(on_next, ahead, index)
    m = values.size
    states = np.empty((m, system.dim))
    newton = np.zeros(m, dtype=np.int64)
    sweeps = np.zeros(m, dtype=np.int64)
    substeps = np.where(np.abs(values - grid[index]) <= slack, 0.0, values - grid[index])
    for k in range(m):
        start = trajectory.states[index[k]]
        if substeps[k] == 0.0:
            states[k] = start
            continue
        step = method.integrate(system, float(substeps[k]), 1, start).raise_if_failed()
        states[k] = step.states[-1]
        newton[k] = int(step.newton_iterations[0]) if step.newton_iterations.size else 0
        sweeps[k] = int(step.stage_sweeps[0]) if step.stage_sweeps.size else 0
    return TimedStates(values, states, index, substeps, newton, sweeps, poisson=system)
