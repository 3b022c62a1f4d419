"""Dense output: the solution at any time of the run by a step of the method itself
(docs/solve.md "Dense output").

``sol(t)`` for t between the grid points t_n and t_{n+1} is one step of the same method, of size
t - t_n, from y_n (`rkhp.integrators.output_times`, as ``integrate --t-eval``): a Poisson map, so
every value lies on the symplectic leaf of y_0 and keeps the Casimirs to round-off, with the
method's order. It plays the part of scipy's ``OdeSolution``: called with a number it returns a
state of shape (n,), with an array of times an array of shape (n, len(t)).
"""

from __future__ import annotations

import numpy as np

from ..base.errors import InputError
from ..integrators.output_times import states_at
from ..integrators.trajectory import Trajectory


class DenseOutput:
    """The dense output of a constant-step run: ``ts`` (the grid, ending at the run's end or at a
    terminal event), ``t_min`` and ``t_max``; ``sol(t)`` as the module docstring says. Times
    outside [t_min, t_max] are refused (InputError): scipy's extrapolates."""

    def __init__(self, system, method, times: np.ndarray, states: np.ndarray):
        self._grid = Trajectory(np.asarray(times, dtype=np.float64), np.asarray(states, dtype=np.float64),
                                np.zeros(max(len(times) - 1, 0), dtype=np.int64), poisson=system)
        self._method = method
        self.ts = self._grid.times
        self.t_min, self.t_max = float(min(self.ts[0], self.ts[-1])), float(max(self.ts[0], self.ts[-1]))

    def __call__(self, t):
        values = np.asarray(t, dtype=np.float64)
        if values.ndim > 1:
            raise InputError("sol(t): t must be a number or a one-dimensional array of times")
        flat = values.reshape(-1)
        if flat.size == 0:
            return np.zeros((self._grid.states.shape[1], 0))
        direction = 1.0 if self.ts[-1] >= self.ts[0] else -1.0
        unique, inverse = np.unique(direction * flat, return_inverse=True)
        timed = states_at(self._grid, self._method, direction * unique)
        states = timed.states[inverse]
        return states[0] if values.ndim == 0 else states.T
