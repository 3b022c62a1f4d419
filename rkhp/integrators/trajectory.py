"""The result of an integration: states, Newton counts, and a status that names any failure.

A failed run keeps only the states computed before the failure (never numbers past it), and says
at which step and time it failed and why (paper §5.2: the implicit equation alpha(x, psi(x)) = y
may have no solution for a large step): `cause` (a `rkhp.integrators.failure.Failure`) for
programs, `status` for people.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..base.errors import NumericalFailure
from .failure import Failure


@dataclass(frozen=True)
class Trajectory:
    """States y_0..y_k at times t_0..t_k of one run.

    Attributes:
        times: shape (k+1,).
        states: shape (k+1, n); for a failed run, only the steps before the failure.
        newton_iterations: shape (k,), Newton iterations per step (zeros for explicit peers).
        stage_sweeps: shape (k,), sweeps of the implicit stages per step (RKHP with an implicit
            tableau; zeros otherwise, empty for the other integrators).
        status: "ok", or a failure message naming the step, the time and the cause.
        failed_step: the 0-based index of the step that failed (step k goes from y_k to y_{k+1};
            it equals the number of completed steps, and states has failed_step + 1 rows), or
            None.
        cause: Failure.OK, or why the run failed (`rkhp.integrators.failure`).
        compile_seconds: time spent compiling (first call of a compiled kernel), apart from run time.
        run_seconds: wall time of the integration itself.
        method: name of the method; system: name of the system.
        extra: free-form details (e.g. Newton tolerance used).
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
